"""Wheel speed against GPS speed: the wheels' scale error, measured on straight stretches.

Over chords of the fixes at least ten metres long the GPS distance is the truth up
to the fixes' noise (sigma * sqrt(2) per chord). The wheels' chord over the same
time is their speed dead-reckoned along the integrated gyro heading (exact over a
minute up to the bias, and a heading offset does not change a chord's length), so
curved stretches count too. The ratio of the sums is the scale the wheels are off by.
"""

from __future__ import annotations

import math

import numpy as np

from ...config import Config, GpsSensor, OdomSensor
from .heading import gps_sigma, track_segments
from .series import Series
from .verdict import Verdict, sensor_key

SCALE_TOLERANCE = 0.02  # a wheel scale within 2 % is not worth a state


def _cumulative(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.zeros(len(t))
    if len(t) > 1:
        dt = np.diff(t)
        out[1:] = np.cumsum(np.where(dt < 1.0, 0.5 * (v[1:] + v[:-1]) * dt, 0.0))
    return out


def speed_check(series: Series, cfg: Config, scales: dict[str, float] | None = None) -> Verdict | None:
    odom = next((s for s in cfg.sensors if isinstance(s, OdomSensor)), None)
    gps = next((s for s in cfg.sensors if isinstance(s, GpsSensor)), None)
    if odom is None or gps is None or len(series.gps_t) < 5 or len(series.odom_t) < 10:
        return None
    sigma = gps_sigma(series, gps)
    segs = track_segments(series, max(10.0, 20.0 * sigma), max_s=60.0)
    to = np.array(series.odom_t)
    if len(series.gyro_t) >= 10:
        heading = np.interp(to, np.array(series.gyro_t), np.array(series.gyro_heading))
    else:
        heading = np.array(series.odom_heading)
    v = np.array(series.odom_v)
    # dead-reckon the wheels with the (short-term exact) integrated gyro: chords compare, curves or not
    x = _cumulative(to, v * np.cos(heading))
    y = _cumulative(to, v * np.sin(heading))
    gps_sum = wheel_sum = 0.0
    n = 0
    for t0, t1, _, chord in segs:
        if t0 < to[0] or t1 > to[-1]:
            continue
        wheel = math.hypot(np.interp(t1, to, x) - np.interp(t0, to, x), np.interp(t1, to, y) - np.interp(t0, to, y))
        if wheel <= 0.0:
            continue
        gps_sum += chord
        wheel_sum += wheel
        n += 1
    if n < 3 or wheel_sum <= 0.0:
        return None
    scale = gps_sum / wheel_sum
    se = math.sqrt(2.0 * n) * sigma / wheel_sum
    evidence = {"wheel_scale_vs_gps": scale, "wheel_scale_se": se, "stretches": float(n)}
    estimated = (scales or {}).get("wheel_scale")
    if abs(scale - 1.0) > max(SCALE_TOLERANCE, 3.0 * se):
        if odom.scale_estimation:
            if estimated is not None and abs(estimated - scale) <= max(SCALE_TOLERANCE, 3.0 * se):
                return Verdict(odom.name, "speed", "ok",
                               f"the wheels read {100 * (1 / scale - 1):+.1f}% against the GPS over {n} straight "
                               f"stretches; the estimated wheel scale {estimated:.3f} matches ({scale:.3f} measured)",
                               evidence=evidence)
            return Verdict(odom.name, "speed", "warn",
                           f"the wheels read {100 * (1 / scale - 1):+.1f}% against the GPS (scale {scale:.3f} "
                           f"measured over {n} stretches) but the estimated wheel scale is "
                           f"{estimated if estimated is not None else float('nan'):.3f}: it has not converged; "
                           "filter.wheel_scale_sigma may be too small", "filter.wheel_scale_sigma", evidence=evidence)
        return Verdict(odom.name, "speed", "problem",
                       f"the wheels read {100 * (1 / scale - 1):+.1f}% against the GPS distance (true/wheel speed "
                       f"{scale:.3f} +- {se:.3f}, over {n} stretches): a tyre radius or slip error; "
                       "estimate the wheel scale", sensor_key(odom.name, "scale_estimation"),
                       "scale_estimation = true", evidence)
    return Verdict(odom.name, "speed", "ok",
                   f"wheel speed agrees with the GPS (scale {scale:.3f} +- {se:.3f} over {n} stretches)",
                   evidence=evidence)
