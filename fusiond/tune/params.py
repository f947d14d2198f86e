"""Which config keys `fusiond tune` fits, where each starts, and how a fitted value enters a Config.

A *parameter* is one positive scale on some components of one config key: the linear and the
angular part of an odometry's ``twist_noise`` are two parameters (six free standard deviations
would ask more of a recording than it holds), the horizontal and the vertical of a GPS's
``position_noise`` two more, and so its Gauss-Markov error's size (``error_sigma``, or without
``error_tau_s`` the vertical one's ``vertical_error_sigma``) and time constant; a pose sensor's
position and orientation noise one each. The optimiser works on the logarithm of each scale, so every value
stays positive and a factor of 2 is the same step whatever the unit.

Each key starts from the config's value. Where the config leaves it unset (None: the messages'
covariances are used) it starts from what the messages state: the median standard deviation over
the recording, through the same floors and "not measured" rules the sensor's policy applies
(``core/sensors/``), so that the start reproduces what the filter did with the messages. A key
that cannot start that way is listed with the reason (``Param.skipped``), not fitted:

- the messages say an axis is not measured (or give no covariance at all): an override would
  declare it measured and fuse it, which is a change of model, not of noise;
- the config holds 0 (a log-parameter cannot start there);
- no message of the sensor is in the recording.

An odometry whose messages mark some twist components "not measured" (the Jackal's wx, wy at
1e6) gets, with a tuned ``twist_noise``, a ``twist_measured`` that marks them so: the override
then leaves them exactly as the messages did (not used, default noise).

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
import statistics
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import msgspec

from ..config import Config, GpsSensor, ImuSensor, OdomSensor, PoseSensor
from ..core.layout import state_layout
from ..core.sensors.imu.axes import seen_axes
from ..core.sensors.registry import kind_of
from ..errors import ConfigError
from ..samples import GpsSample, ImuSample, OdomSample, PoseSample

FILTER = "filter"  # the table name of filter.* parameters (sensor parameters use the sensor's name)
SIGNIFICANT = 4  # digits of a tuned value


@dataclass(frozen=True)
class Param:
    """One tunable scale: ``base`` (the key's whole value at the start) with ``indices`` of it
    (None: the key is a scalar) multiplied by exp(theta)."""

    name: str  # what --keys names and the table shows: "imu.gyro_noise", "wheel.twist_noise.linear"
    table: str  # "filter" or the sensor's name
    key: str  # the config field
    indices: tuple[int, ...] | None
    base: float | tuple[float, ...] = 1.0
    source: str = "config"  # where base came from: "config", "messages (median)" or "unstated: measured, at most"
    unit: str = ""
    skipped: str = ""  # not tunable in this recording, and why
    # other keys of the same table set together with this one when it changes
    companions: tuple[tuple[str, object], ...] = field(default=())
    floor: float = 0.0  # the sensor's floor on this noise (``*_min_sigma``): no fitted value goes below it

    def lowest(self) -> float:
        """The smallest log-scale the fit may take: down to the floor (never above 0: a start the
        user put below the floor may stay there)."""
        start = self.start()
        smallest = min(start) if isinstance(start, tuple) else start
        if self.floor <= 0.0 or not smallest > 0.0:
            return -math.inf
        return min(0.0, math.log(self.floor / smallest))

    @property
    def group(self) -> tuple[str, str]:
        return (self.table, self.key)

    def start(self) -> float | tuple[float, ...]:
        """The components this parameter scales, at the start."""
        if self.indices is None:
            return self.base  # type: ignore[return-value]
        return tuple(self.base[i] for i in self.indices)  # type: ignore[index]


def rounded(v: float) -> float:
    return float(f"{v:.{SIGNIFICANT}g}")


def _median(values: Iterable[float]) -> float | None:
    vals = [v for v in values if v == v]
    return statistics.median(vals) if vals else None


def _sensor_samples(samples: Sequence[object], name: str, kind: type) -> list:
    return [s for s in samples if type(s) is kind and s.sensor == name]  # type: ignore[attr-defined]


def _odom_params(s: OdomSensor, samples: Sequence[object]) -> list[Param]:
    names = (f"{s.name}.twist_noise.linear", f"{s.name}.twist_noise.angular")
    groups = ((0, 1, 2), (3, 4, 5))
    if s.twist_noise is not None:
        base = tuple(s.twist_noise)
        if any(v <= 0.0 for v in base):
            return [Param(n, s.name, "twist_noise", g, base, skipped="0 in the config") for n, g in zip(names, groups)]
        return [Param(n, s.name, "twist_noise", tuple(i for i in g if s.twist_measured[i]), base, unit=u, floor=f)
                for n, g, u, f in zip(names, groups, ("m/s", "rad/s"), s.twist_min_sigma)]
    mine = _sensor_samples(samples, s.name, OdomSample)
    if not mine:
        return [Param(n, s.name, "twist_noise", g, skipped="no messages") for n, g in zip(names, groups)]
    floors = [s.twist_min_sigma[0]] * 3 + [s.twist_min_sigma[1]] * 3
    caps = [s.twist_max_sigma[0]] * 3 + [s.twist_max_sigma[1]] * 3
    unmeasured = [s.twist_unmeasured_sigma[0]] * 3 + [s.twist_unmeasured_sigma[1]] * 3
    base, measured = [], []
    for i in range(6):
        var = _median(m.twist_covariance[7 * i] for m in mine if len(m.twist_covariance) == 36)
        ok = s.twist_measured[i] and var is not None and 0.0 <= var < caps[i] ** 2 and math.isfinite(var)
        measured.append(bool(ok))
        base.append(max(math.sqrt(var), floors[i]) if ok else unmeasured[i])  # type: ignore[arg-type]
    companions = () if all(measured) else (("twist_measured", tuple(measured)),)
    out = []
    for n, g, u, f in zip(names, groups, ("m/s", "rad/s"), s.twist_min_sigma):
        idx = tuple(i for i in g if measured[i])
        out.append(Param(n, s.name, "twist_noise", idx, tuple(base), "messages (median)", u,
                         "" if idx else "no component measured", companions, f))
    return out


def _imu_params(s: ImuSensor, samples: Sequence[object]) -> list[Param]:
    out = []
    mine = _sensor_samples(samples, s.name, ImuSample)
    if s.angular_velocity:
        name = f"{s.name}.gyro_noise"
        if s.gyro_noise is not None:
            out.append(Param(name, s.name, "gyro_noise", None, s.gyro_noise, unit="rad/s",
                             skipped="" if s.gyro_noise > 0.0 else "0 in the config", floor=s.gyro_min_sigma))
        else:
            stated = [m.angular_velocity_covariance for m in mine
                      if len(m.angular_velocity_covariance) == 9 and m.angular_velocity_covariance[0] != -1.0]
            var = _median(c[k] for c in stated for k in (0, 4, 8))
            if var is None or not math.isfinite(var) or var < 0.0:
                out.append(Param(name, s.name, "gyro_noise", None, unit="rad/s", skipped=(
                    "no messages" if not mine else "the messages state no gyro covariance (an override would "
                    "start fusing the rates)")))
            else:
                out.append(Param(name, s.name, "gyro_noise", None, max(math.sqrt(var), s.gyro_min_sigma),
                                 "messages (median)", "rad/s", floor=s.gyro_min_sigma))
    if s.fuses_orientation:
        name = f"{s.name}.orientation_noise"
        # the IMU axes (the key's own, before extrinsic_rpy) that land on the base rows the mode fuses
        rows = seen_axes(s.extrinsic_rpy, s.orientation_rows)
        if s.orientation_noise is not None:
            base = tuple(s.orientation_noise)
            out.append(Param(name, s.name, "orientation_noise", rows, base, unit="rad",
                             skipped="" if all(base[i] > 0.0 for i in rows) else "0 in the config",
                             floor=s.orientation_min_sigma))
        else:
            stated = [m.orientation_covariance for m in mine
                      if len(m.orientation_covariance) == 9 and m.orientation_covariance[0] != -1.0]
            medians = [_median(c[4 * k] for c in stated) for k in range(3)]
            if not stated:
                out.append(Param(name, s.name, "orientation_noise", rows, unit="rad", skipped=(
                    "no messages" if not mine else "the messages carry no orientation")))
            elif any(v is None or not (0.0 <= v < s.orientation_max_sigma**2) for v in medians):
                out.append(Param(name, s.name, "orientation_noise", rows, unit="rad", skipped=(
                    "the messages state an axis not measured (an override would fuse it)")))
            else:
                base = tuple(max(math.sqrt(v), s.orientation_min_sigma) for v in medians)  # type: ignore[arg-type]
                out.append(Param(name, s.name, "orientation_noise", rows, base, "messages (median)", "rad",
                                 floor=s.orientation_min_sigma))
    return out


def _gps_sigmas(s: GpsSensor, m: GpsSample) -> tuple[float, float, float] | None:
    """The per-axis sigma the GPS policy takes from one fix (``GpsPolicy.convert``), None for no fix."""
    if m.status < 0:
        return None
    c = m.position_covariance
    if _gps_unstated(m):
        return tuple(s.unknown_position_sigma)  # type: ignore[return-value]
    if len(c) != 9 or not all(map(math.isfinite, c)) or min(c[0], c[4], c[8]) < 0.0:
        return None
    f = s.position_min_sigma
    return (max(math.sqrt(c[0]), f), max(math.sqrt(c[4]), f), max(math.sqrt(c[8]), f))


def _gps_error_params(s: GpsSensor) -> list[Param]:
    """The Gauss-Markov error states' size and time constant: all three axes with ``error_tau_s``,
    else the vertical one (``vertical_error_*``). Off in the config (0) stays off: switching a state
    on is a change of model, not of noise."""
    if s.error_tau_s > 0.0 and s.error_sigma is not None:
        base = tuple(s.error_sigma)
        out = [Param(f"{s.name}.error_sigma.{part}", s.name, "error_sigma", g, base, unit="m",
                     skipped="" if all(base[i] > 0.0 for i in g) else "0 in the config")
               for part, g in (("horizontal", (0, 1)), ("vertical", (2,)))]
        return out + [Param(f"{s.name}.error_tau_s", s.name, "error_tau_s", None, s.error_tau_s, unit="s")]
    if s.vertical_error_sigma > 0.0 and s.vertical_error_tau_s > 0.0:
        return [Param(f"{s.name}.vertical_error_sigma", s.name, "vertical_error_sigma", None, s.vertical_error_sigma,
                      unit="m"),
                Param(f"{s.name}.vertical_error_tau_s", s.name, "vertical_error_tau_s", None, s.vertical_error_tau_s,
                      unit="s")]
    return []


SPAN_TAUS = 3.0  # time constants a recording must span for a Gauss-Markov error to be fitted (below)


def _gps_params(s: GpsSensor, samples: Sequence[object]) -> list[Param]:
    """The GPS's noise and error-model parameters, less those of an axis whose error the recording cannot
    identify. A Gauss-Markov error decorrelates over its time constant tau: a recording shorter than
    SPAN_TAUS of them holds fewer than three independent stretches of it, and there its error is a slow
    offset the fixes share, which their innovations cannot tell from the truth. Fitted anyway, the
    likelihood takes it for the truth: on the highway car's 60 s (altitude tau 300 s) the vertical
    white noise went to 0.01 m and the error to 5 mm, and z followed the fixes' altitude (1.14 m off the
    reference, against 0.54 m as configured), which no held-back fix shows (they share the offset)."""
    params = _gps_noise_params(s, samples) + _gps_error_params(s)
    stamps = [m.stamp for m in _sensor_samples(samples, s.name, GpsSample)]
    if len(stamps) < 2:
        return params
    span = max(stamps) - min(stamps)
    taus = {}
    if s.error_tau_s > 0.0 and s.error_sigma is not None:
        taus = {"horizontal": s.error_tau_s, "vertical": s.error_tau_s}
    elif s.vertical_error_sigma > 0.0 and s.vertical_error_tau_s > 0.0:
        taus = {"vertical": s.vertical_error_tau_s}
    slow = {part: tau for part, tau in taus.items() if span < SPAN_TAUS * tau}
    if not slow:
        return params
    out = []
    for p in params:
        part = "vertical" if p.key.startswith("vertical_error") else p.name.rsplit(".", 1)[-1]
        tau = slow.get(part, max(slow.values()) if p.key == "error_tau_s" else None)
        if tau is not None and not p.skipped:
            p = replace(p, skipped=f"the recording spans {span:.0f} s, less than {SPAN_TAUS:g} time constants of the "
                                   f"{part} error ({tau:g} s): its slow error cannot be told from the truth")
        out.append(p)
    return out


def _gps_noise_params(s: GpsSensor, samples: Sequence[object]) -> list[Param]:
    names = (f"{s.name}.position_noise.horizontal", f"{s.name}.position_noise.vertical")
    groups = ((0, 1), (2,))
    if s.position_noise is not None:
        base = tuple(s.position_noise)
        return [Param(n, s.name, "position_noise", g, base, unit="m",
                      skipped="" if all(base[i] > 0.0 for i in g) else "0 in the config", floor=s.position_min_sigma)
                for n, g in zip(names, groups)]
    fixes = [x for x in (_gps_sigmas(s, m) for m in _sensor_samples(samples, s.name, GpsSample)) if x is not None]
    if not fixes:
        return [Param(n, s.name, "position_noise", g, unit="m", skipped="no fixes") for n, g in zip(names, groups)]
    base = tuple(statistics.median(f[k] for f in fixes) for k in range(3))
    # one key: an axis stated "not measured" leaves both parts alone (an override would fuse it)
    bad = "the fixes state an axis not measured (an override would fuse it)" \
        if any(b >= s.max_sigma for b in base) else ""
    # fixes that state nothing have their horizontal noise measured by the filter (estimate_unknown_noise):
    # the default is then only its upper bound, and the table says so
    fixes_unstated = sum(_gps_unstated(m) for m in _sensor_samples(samples, s.name, GpsSample)) > len(fixes) / 2
    sources = ("unstated: measured, at most" if fixes_unstated and s.estimate_unknown_noise else "messages (median)",
               "messages (median)")
    return [Param(n, s.name, "position_noise", g, base, src, "m", bad, floor=s.position_min_sigma)
            for n, g, src in zip(names, groups, sources)]


def _gps_unstated(m: GpsSample) -> bool:
    """A fix valid but without a stated accuracy (``GpsPolicy.convert`` takes the unknown default)."""
    c = m.position_covariance
    return m.status >= 0 and (m.covariance_type == 0 or (len(c) == 9 and c[0] == 0.0 and c[4] == 0.0 and c[8] == 0.0))


def _pose_params(s: PoseSensor, samples: Sequence[object]) -> list[Param]:
    """position_noise and orientation_noise, one scale each (all three axes): from the config, else
    from the messages' median variances (``unknown_sigma`` for a message without covariance)."""
    out = []
    mine = _sensor_samples(samples, s.name, PoseSample)
    for key, rows, floor, cap, unknown, unit in (
            ("position_noise", (0, 1, 2), s.position_min_sigma, s.max_sigma[0], s.unknown_sigma[0], "m"),
            ("orientation_noise", (3, 4, 5), s.orientation_min_sigma, s.max_sigma[1], s.unknown_sigma[1], "rad")):
        name = f"{s.name}.{key}"
        given = getattr(s, key)
        if given is not None:
            base = tuple(given)
            out.append(Param(name, s.name, key, (0, 1, 2), base, unit=unit, floor=floor,
                             skipped="" if all(v > 0.0 for v in base) else "0 in the config"))
            continue
        if not mine:
            out.append(Param(name, s.name, key, (0, 1, 2), unit=unit, skipped="no messages"))
            continue
        variances = [_median(m.covariance[7 * r] if len(m.covariance) == 36 else unknown**2 for m in mine)
                     for r in rows]
        if any(v is None or not (0.0 <= v < cap**2) for v in variances):
            out.append(Param(name, s.name, key, (0, 1, 2), unit=unit, skipped=(
                "the messages state an axis not measured (an override would fuse it)")))
            continue
        base = tuple(max(math.sqrt(v), floor) for v in variances)  # type: ignore[arg-type]
        out.append(Param(name, s.name, key, (0, 1, 2), base, "messages (median)", unit, floor=floor))
    return out


# Which keys of a sensor kind's table the tuner fits (the module doc): a tuning policy, so kept here with
# the tuner rather than in the kind's package; a kind without an entry has nothing to tune.
_KIND_PARAMS: dict[str, Callable[[Any, Sequence[object]], list[Param]]] = {
    "odom": _odom_params,
    "imu": _imu_params,
    "gps": _gps_params,
    "pose": _pose_params,
}


def tunable_params(cfg: Config, samples: Sequence[object] = ()) -> list[Param]:
    """Every parameter of the module doc for this config, in config order; those that cannot be
    fitted carry the reason in ``skipped``. Without samples, keys left unset in the config are
    listed as skipped ("no messages"): enough to check --keys before a bag is read."""
    out: list[Param] = []
    for s in cfg.sensors:
        params = _KIND_PARAMS.get(kind_of(s).name)
        if params is not None:
            out += params(s, samples)
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
