"""The sensor kinds fusiond knows, by their config `kind` tag: one ``SensorKind`` descriptor each.

Everything outside ``core/sensors/`` that depends on a sensor's kind asks here (``kind_of``)
rather than testing config classes: the config's [[sensors]] union (``config_types``), the state
layout, the fusion core, the decoders, the bag reader, the daemon, replay and the tuner. A new
kind is a module (or package) beside the others with its descriptor, and one ``register`` call.
"""

from __future__ import annotations

from typing import Any

from .gps import GpsKind
from .imu import ImuKind
from .kind import SensorKind
from .odom import OdomKind
from .pose import PoseKind

KINDS: dict[str, SensorKind] = {}


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
    """The descriptor of a `kind` tag; a ValueError listing the known ones for another."""
    try:
        return KINDS[name]
    except KeyError:
        raise ValueError(f"unknown sensor kind {name!r}, expected one of {sorted(KINDS)}") from None


def config_types() -> tuple[type, ...]:
    """The [[sensors]] tables, in registration order: the tagged union a config's sensors decode as."""
    return tuple(k.config_type for k in KINDS.values())


for _kind in (OdomKind(), ImuKind(), GpsKind(), PoseKind()):
    register(_kind)

__all__ = ["KINDS", "config_types", "kind_named", "kind_of", "register", "unregister"]
