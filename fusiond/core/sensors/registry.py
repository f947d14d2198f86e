"""The sensor kinds fusiond knows, by their config `kind` tag: one ``SensorKind`` descriptor each.

Everything outside ``core/sensors/`` that depends on a sensor's kind asks here (``kind_of``)
rather than testing config classes: the config's [[sensors]] union (``config_types``), the state
layout, the fusion core, the decoders, the bag reader, the daemon, replay and the tuner. A new
kind is a module (or package) beside the others with its descriptor, and one ``register`` call;
an installed package adds one by naming its descriptor under the ``fusiond.sensor_kinds`` entry
point group (``discover``), found when a config names a kind not registered yet, so that a run
that names only the built-in kinds never scans the installed packages.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import Any

from .gps import GpsKind
from .imu import ImuKind
from .kind import SensorKind
from .odom import OdomKind
from .pose import PoseKind

KINDS: dict[str, SensorKind] = {}
ENTRY_POINT_GROUP = "fusiond.sensor_kinds"  # name = the kind's tag, value = its SensorKind (class or instance)
_discovered = False


def register(kind: SensorKind) -> SensorKind:
    """Make a kind known under its `kind` tag (its config table's msgspec tag); returns it. Registering
    the same tag again replaces the descriptor (a test's toy kind, reloaded)."""
    tag = kind.config_type.__struct_config__.tag
    if tag != kind.name:
        raise ValueError(f"sensor kind {kind.name!r}: its config table {kind.config_type.__name__} is tagged {tag!r}")
    KINDS[kind.name] = kind
    return kind


def unregister(name: str) -> None:
    """Forget a kind (a test's toy kind, after the test)."""
    KINDS.pop(name, None)


def kind_of(cfg: Any) -> SensorKind:
    """The descriptor of a configured sensor (its table's `kind` tag)."""
    return KINDS[type(cfg).__struct_config__.tag]


def kind_named(name: str) -> SensorKind:
    """The descriptor of a `kind` tag (an installed package's, ``discover``); a ValueError listing the
    known ones for another."""
    require((name,))
    try:
        return KINDS[name]
    except KeyError:
        raise ValueError(f"unknown sensor kind {name!r}, expected one of {sorted(KINDS)}") from None


def require(names: Iterable[object]) -> None:
    """Make the kinds ``names`` tags known if an installed package offers them: ``discover`` once, the
    first time a tag is not registered (names that are not strings are left to the config's checks)."""
    if not _discovered and any(isinstance(n, str) and n not in KINDS for n in names):
        discover()


def discover(entry_points: Iterable[Any] | None = None) -> list[SensorKind]:
    """Register the kinds installed packages declare under ``ENTRY_POINT_GROUP`` (``entry_points``: those
    of ``importlib.metadata`` by default), each a ``SensorKind`` subclass or instance named by its tag;
    returns the kinds registered. A tag already registered keeps its descriptor (a package does not
    replace a built-in kind); an entry that fails to load, or names another tag than its kind's, is a
    warning and is skipped, so that one broken package leaves the others usable."""
    global _discovered
    if entry_points is None:
        from importlib.metadata import entry_points as installed

        _discovered = True
        entry_points = installed(group=ENTRY_POINT_GROUP)
    added = []
    for ep in entry_points:
        if ep.name in KINDS:
            continue
        try:
            found = ep.load()
            kind = found() if isinstance(found, type) else found
            if not isinstance(kind, SensorKind) or kind.name != ep.name:
                raise TypeError(f"{ep.value} is not a SensorKind named {ep.name!r}")
            added.append(register(kind))
        except Exception as err:  # noqa: BLE001 - a third party's package: any failure is its own
            warnings.warn(f"sensor kind {ep.name!r} from {ep.value}: not loaded: {err}", RuntimeWarning, stacklevel=2)
    return added


def kind_reading(msgtype: str) -> SensorKind | None:
    """The registered kind whose messages are ``msgtype`` (its ``ros_types``), the installed packages' kinds
    discovered first (once): what `fusiond info` and `init` name for a topic of a type none of the built-in
    kinds reads. None when no kind reads it."""
    if not _discovered:
        discover()
    return next((k for k in KINDS.values() if msgtype in k.ros_types), None)


def config_types() -> tuple[type, ...]:
    """The [[sensors]] tables, in registration order: the tagged union a config's sensors decode as."""
    return tuple(k.config_type for k in KINDS.values())


for _kind in (OdomKind(), ImuKind(), GpsKind(), PoseKind()):
    register(_kind)

__all__ = ["ENTRY_POINT_GROUP", "KINDS", "config_types", "discover", "kind_named", "kind_of", "kind_reading", "register",
           "require", "unregister"]
