"""Which config keys `fusiond tune` fits, where each starts, and how a fitted value enters a Config.

A *parameter* (``Param``) is one positive scale on some components of one config key. Which keys of
a sensor's table are parameters, each sensor's kind says (``SensorKind.tunables``, in the kind's
package: the linear and the angular part of an odometry's ``twist_noise`` are two, the horizontal
and the vertical of a GPS's ``position_noise`` two more, an IMU's ``orientation_noise`` on the axes
its mount lands on the fused rows, ...); the filter's process noise and gyro bias walk are added
here. The optimiser works on the logarithm of each scale, so every value stays positive and a
factor of 2 is the same step whatever the unit.

Each key starts from the config's value. Where the config leaves it unset (None: the messages'
covariances are used) it starts from what the messages state: the median standard deviation over
the recording, through the same floors and "not measured" rules the sensor's policy applies
(``core/sensors/``), so that the start reproduces what the filter did with the messages. A key
that cannot start that way is listed with the reason (``Param.skipped``), not fitted:

- the messages say an axis is not measured (or give no covariance at all): an override would
  declare it measured and fuse it, which is a change of model, not of noise;
- the config holds 0 (a log-parameter cannot start there);
- no message of the sensor is in the recording.

A fitted noise stays at or above the sensor's floor (``twist_min_sigma``, ``gyro_min_sigma``,
``orientation_min_sigma``, ``position_min_sigma``): below it the filter believes no message, and
the likelihood of readings that are smooth rather than white (an IMU's roll/pitch is its own
filter's output) drives R toward zero: on the Jackal bag, unbounded, orientation_noise went to
6.7e-5 rad beside a gyro_noise six times its datasheet's. The table says when a value sits there.

Values written into a config are rounded to 4 significant digits, and every evaluation is made
with the rounded value, so the config written is the config scored.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import msgspec

from ..config import Config
from ..core.layout import state_layout
from ..core.sensors.registry import kind_of
from ..core.sensors.tunable import Param
from ..errors import ConfigError

FILTER = "filter"  # the table name of filter.* parameters (sensor parameters use the sensor's name)
SIGNIFICANT = 4  # digits of a tuned value


def rounded(v: float) -> float:
    return float(f"{v:.{SIGNIFICANT}g}")


def tunable_params(cfg: Config, samples: Sequence[object] = ()) -> list[Param]:
    """Every parameter of the module doc for this config, in config order; those that cannot be
    fitted carry the reason in ``skipped``. Without samples, keys left unset in the config are
    listed as skipped ("no messages"): enough to check --keys before a bag is read."""
    out: list[Param] = []
    for s in cfg.sensors:
        out += kind_of(s).tunables(s, samples)
    fc = cfg.filter
    for i, part, unit in ((0, "position", "m/sqrt(s)"), (1, "attitude", "rad/sqrt(s)")):
        out.append(Param(f"filter.process_noise.{part}", FILTER, "process_noise", (i,), tuple(fc.process_noise),
                         unit=unit, skipped="" if fc.process_noise[i] > 0.0 else "0 in the config"))
    if state_layout(cfg).has("gyro_bias"):
        out.append(Param("filter.gyro_bias_walk", FILTER, "gyro_bias_walk", None, fc.gyro_bias_walk,
                         unit="rad/s/sqrt(s)", skipped="" if fc.gyro_bias_walk > 0.0 else "0 in the config"))
    return out


def select(params: Sequence[Param], keys: Sequence[str] | None) -> list[Param]:
    """The parameters ``keys`` names (all when None): a name, or a prefix of names at a dot
    ("wheel.twist_noise" is both of its parts, "filter" all filter keys). An unknown key is a
    ConfigError listing the tunable names."""
    if keys is None:
        return list(params)
    chosen: list[Param] = []
    for k in keys:
        k = k.strip()
        hits = [p for p in params if p.name == k or p.name.startswith(k + ".")]
        if not k or not hits:
            names = ", ".join(p.name for p in params) or "none"
            raise ConfigError(f"--keys: unknown key {k!r}; tunable with this config: {names}")
        chosen += [p for p in hits if p not in chosen]
    return [p for p in params if p in chosen]  # config order


def _table(cfg: Config, table: str):
    return cfg.filter if table == FILTER else cfg.sensor(table)


def value(cfg: Config, p: Param) -> float | tuple[float, ...] | None:
    """The components ``p`` scales as ``cfg`` has them (None: unset, the messages' covariances)."""
    v = getattr(_table(cfg, p.table), p.key)
    if v is None or p.indices is None:
        return v
    return tuple(v[i] for i in p.indices)


def apply(cfg: Config, params: Sequence[Param], theta: Sequence[float | None]) -> Config:
    """``cfg`` with each parameter whose theta is not None set to base x exp(theta) (rounded);
    parameters sharing a key (the two parts of a twist_noise) compose, the components no
    parameter scales keep the base. A theta of None leaves the key as ``cfg`` has it."""
    groups: dict[tuple[str, str], list[tuple[Param, float]]] = {}
    for p, t in zip(params, theta):
        if t is not None and not p.skipped:
            groups.setdefault(p.group, []).append((p, t))
    if not groups:
        return cfg
    tables: dict[str, dict[str, object]] = {}
    for (table, key), members in groups.items():
        base = members[0][0].base
        changes = tables.setdefault(table, {})
        if members[0][0].indices is None:
            changes[key] = rounded(base * math.exp(members[0][1]))  # type: ignore[operator]
        else:
            vec = [rounded(b) for b in base]  # type: ignore[union-attr]
            for p, t in members:
                for i in p.indices:  # type: ignore[union-attr]
                    vec[i] = rounded(base[i] * math.exp(t))  # type: ignore[index]
            changes[key] = tuple(vec)
        for name, companion in members[0][0].companions:
            changes[name] = companion
    new_filter = cfg.filter
    sensors = list(cfg.sensors)
    for table, changes in tables.items():
        if table == FILTER:
            new_filter = msgspec.structs.replace(cfg.filter, **changes)
        else:
            i = next(k for k, s in enumerate(sensors) if s.name == table)
            sensors[i] = msgspec.structs.replace(sensors[i], **changes)
    return msgspec.structs.replace(cfg, filter=new_filter, sensors=sensors)


def sensor_of(p: Param) -> str | None:
    """The sensor whose updates a parameter is judged by (None: a filter key, all of them)."""
    return None if p.table == FILTER else p.table


__all__ = ["FILTER", "Param", "apply", "rounded", "select", "sensor_of", "tunable_params", "value"]
