"""Floors from the data: no fitted white noise below what the recording itself shows at rest.

A likelihood fit can take a white noise down where the data do not hold it up: a coloured error is
"explained" by a smaller white one, a slow wander by the state. The sensors' ``*_min_sigma`` floors
are constants; the recording says more. While the robot stands, every sensor reads its white noise
about a constant (a gyro its bias, the wheels zero, a GPS its slow error, an IMU's orientation the
attitude it holds), so the difference of two consecutive readings there has variance 2 sigma^2, plus
what a slow error moves in between: 2 s_m^2 (1 - exp(-dt / tau)) for a Gauss-Markov error the config
states (s_m, tau), taken off (the sensor's kind says what its error adds: ``SensorKind.difference_variance``).
A white noise below that is refuted by the standstills themselves.

The standstills are the filter's own (its odometry rest test, ``core/sensors/odom/rest.py``), as the
doctor's replay reports them (``doctor_values.diagnose``: the same replay gives the doctor's values). Within each, component i of a sensor gives n_i differences and
their mean square D_i; sigma_i^2 = D_i / 2. Squared differences of white noise overlap (d_k and
d_k+1 share a reading), so they carry about 2 n / 3 degrees of freedom (the figure the rest test
uses), and the floor is the one-sided lower bound of size FLOOR_ALPHA:

    floor_i^2 = (D_i / 2) nu / chi2(1 - FLOOR_ALPHA; nu),   nu = 2 n_i / 3.

A floor needs MIN_DIFFERENCES differences (a handful measures nothing). A component that reads
exactly the same at rest (wheels at zero) shows no noise and sets no floor. The floor is per
component, in the sensor's own axes (the message's, as its covariance is), so a parameter scaling
several components by one factor may go no lower than the highest of their floors allows.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ..config import Config
from ..core.diagnostics import chi2_ppf
from ..core.sensors.registry import kind_of
from ..estimator import rotation as rot
from ..estimator.geodesy import EnuFrame
from ..core.sensors import GpsSample
from .params import Param

FLOOR_ALPHA = 0.01  # a floor above the true noise one time in a hundred
MIN_DIFFERENCES = 20  # fewer consecutive differences at rest than this set no floor


@dataclass(frozen=True)
class Floor:
    """A parameter's floors measured at rest: one per component it scales (0: none), and from how much."""

    sigmas: tuple[float, ...]
    differences: int
    standstills: int

    def describe(self) -> str:
        shown = ", ".join(f"{f:.3g}" for f in self.sigmas if f > 0.0)
        return f"{shown} (measured at rest: {self.differences} differences over {self.standstills} standstill(s))"


def _geodetic(first) -> Callable[[GpsSample], tuple[float, ...]]:
    frame = EnuFrame(first.latitude, first.longitude, first.altitude)
    return lambda m: tuple(frame.enu(m.latitude, m.longitude, m.altitude))


# What each noise key is the noise of, read off a sample: (the values, differenced as a rotation?). The
# keys mean the same in every kind that has them (a pose's position_noise and a GPS's are both metres on
# its position), so the table is by key; a geodetic kind's position is its fix in ENU at its first.
_READINGS: dict[str, tuple[Callable[[Any], tuple[float, ...]], bool]] = {
    "twist_noise": (lambda m: (*m.linear, *m.angular), False),
    "gyro_noise": (lambda m: tuple(m.angular_velocity), False),
    "orientation_noise": (lambda m: tuple(m.orientation), True),
    "position_noise": (lambda m: tuple(m.position), False),
}


def _mean_squares(values: list[tuple[float, float, tuple[float, ...]]], rotation: bool) -> tuple[list[float], int]:
    """Per component, the sum of squared consecutive differences and their count, over (span, stamp, values)
    rows in stamp order; ``rotation``: the values are quaternions (x, y, z, w), differenced as the rotation
    vector of the relative rotation in the sensor's axes."""
    sums: list[float] = []
    n = 0
    prev = None
    for span, _stamp, v in values:
        if prev is not None and prev[0] == span:
            d = rot.log(rot.mul(rot.conj(prev[1]), v)) if rotation else [a - b for a, b in zip(v, prev[1])]
            if not sums:
                sums = [0.0] * len(d)
            for i, x in enumerate(d):
                sums[i] += float(x) * float(x)
            n += 1
        prev = (span, v)
    return sums, n


def _at_rest(samples: Sequence[object], kind: type, name: str, spans: Sequence[tuple[float, float]],
             values: Callable, offset: float) -> list[tuple[int, float, tuple[float, ...]]]:
    """(span index, stamp, values) of the sensor's samples inside a standstill, in stamp order; a sample is
    placed at its stamp shifted by the sensor's ``stamp_offset_s`` (``offset``), as the filter takes it."""
    rows = []
    for s in samples:
        if type(s) is not kind or s.sensor != name:  # type: ignore[attr-defined]
            continue
        if getattr(s, "status", 0) < 0:
            continue  # a GPS message without a fix: not a position
        stamp = s.stamp + offset  # type: ignore[attr-defined]
        for k, (t0, t1) in enumerate(spans):
            if t0 <= stamp <= t1:
                rows.append((k, stamp, values(s)))
                break
    rows.sort(key=lambda r: (r[0], r[1]))
    return rows


def _floors(sums: list[float], n: int, slow: Sequence[float] = ()) -> list[float]:
    """Per component, the lower bound of its white sigma (module doc); ``slow``: the variance a slow error
    adds to a difference, per component, taken off."""
    if n < MIN_DIFFERENCES:
        return [0.0] * len(sums)
    nu = 2.0 * n / 3.0
    q = chi2_ppf(1.0 - FLOOR_ALPHA, nu)
    out = []
    for i, total in enumerate(sums):
        var = 0.5 * (total / n - (slow[i] if i < len(slow) else 0.0))
        out.append(math.sqrt(var * nu / q) if var > 0.0 else 0.0)
    return out


def _mean_step(rows: list[tuple[int, float, tuple[float, ...]]]) -> float:
    """The mean time between consecutive readings at rest, s."""
    steps = [b[1] - a[1] for a, b in zip(rows, rows[1:]) if a[0] == b[0]]
    return sum(steps) / len(steps) if steps else 0.0


def measured_floors(cfg: Config, samples: Sequence[object], params: Sequence[Param],
                    spans: Sequence[tuple[float, float]]) -> dict[str, Floor]:
    """The floors the recording's standstills (``spans``: the filter's, in filter time, as
    ``doctor_values.diagnose`` returns them) set on ``params``' noises, by parameter name (module doc)."""
    wanted = {(p.table, p.key) for p in params if not p.skipped}
    if not wanted or not spans:
        return {}
    offsets = {s.name: s.stamp_offset_s for s in cfg.sensors}
    by_key: dict[tuple[str, str], tuple[list[float], int]] = {}
    for sensor in cfg.sensors:
        kind = kind_of(sensor)
        for key, (read, rotation) in _READINGS.items():
            if (sensor.name, key) not in wanted or getattr(sensor, "differential", False):
                continue  # a differential pose's noise is of its deltas, not of its readings
            if kind.geodetic and key == "position_noise":
                first = next((m for m in samples if type(m) is kind.sample_type and m.sensor == sensor.name
                              and m.status >= 0), None)  # type: ignore[attr-defined]
                if first is None:
                    continue
                read = _geodetic(first)
            rows = _at_rest(samples, kind.sample_type, sensor.name, spans, read, offsets.get(sensor.name, 0.0))
            sums, n = _mean_squares(rows, rotation)
            slow = kind.difference_variance(sensor, _mean_step(rows))  # its slow error's share (module doc)
            floors = _floors(sums, n, slow)
            if key == "gyro_noise":  # one noise for three axes: none may be refuted (module doc)
                floors = [min(floors)] if floors and min(floors) > 0.0 else [0.0]
            by_key[(sensor.name, key)] = (floors, n)
    out: dict[str, Floor] = {}
    for p in params:
        found = by_key.get((p.table, p.key))
        if found is None or p.skipped:
            continue
        floors, n = found
        sigmas = tuple(floors) if p.indices is None else tuple(floors[i] if i < len(floors) else 0.0
                                                               for i in p.indices)
        if any(f > 0.0 for f in sigmas):
            out[p.name] = Floor(sigmas, n, len(spans))
    return out


def with_floors(params: Sequence[Param], floors: dict[str, Floor]) -> list[Param]:
    """``params`` with the measured floors attached (``Param.measured``, ``Param.measured_note``)."""
    return [replace(p, measured=floors[p.name].sigmas, measured_note=floors[p.name].describe()) if p.name in floors
            else p for p in params]


__all__ = ["FLOOR_ALPHA", "Floor", "MIN_DIFFERENCES", "measured_floors", "with_floors"]
