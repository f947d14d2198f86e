"""A sensor silent while the wheels kept reporting: an IMU whose driver or link dropped out, a GPS without a fix.

A logging gap silences every sensor, and the gap checks speak of it. A silence of one sensor while the
odometry goes on is the sensor's own: the filter held none of its input past its timeout, so the heading
turned by the wheels' yaw rate alone (an IMU) or the position was dead-reckoned (a GPS) for its length,
and what the estimate does there is the other sensors' doing. Said so that a track bent in those seconds
is not read as a fault of the config; an IMU that drops out is a fault of its own (a USB or serial link, a
driver), a GPS that loses its fix under a bridge is not.
"""

from __future__ import annotations

import statistics

import numpy as np

from ..check import BaseCheck
from ..evidence import Evidence
from ..streams import MAX_STEP_S
from ..verdict import Verdict

__all__ = ["Silences", "silences"]

# A GPS is silent when no usable fix comes for this many of its typical intervals, and at least MAX_STEP_S:
# a 1 Hz receiver that skips one fix is not (two missing in a row at 10 Hz are 0.3 s, within any timeout)
GPS_SILENT_PERIODS = 5.0


def silences(t: list[float] | np.ndarray, longer_than: float, odom_t: list[float] | np.ndarray
             ) -> list[tuple[float, float]]:
    """(start, length s) of each interval between consecutive stamps ``t`` longer than ``longer_than`` across
    which the odometry kept reporting (split at the odometry's own intervals that long: a logging gap of every
    sensor is no silence of this one). The odometry's first and last stamps bound ``t`` too: a sensor that
    starts late or stops for good (an IMU lost 20 s into a 60 s drive) is silent there as well."""
    ts, to = np.asarray(t, dtype=float), np.asarray(odom_t, dtype=float)
    if ts.size < 2 or to.size == 0:
        return []
    bounded = np.concatenate(([to[0]] if to[0] < ts[0] else [], ts, [to[-1]] if to[-1] > ts[-1] else []))
    d = np.diff(bounded)
    out = []
    for i in np.nonzero(d > longer_than)[0].tolist():
        a, b = bounded[i], bounded[i + 1]
        inside = to[np.searchsorted(to, a, side="right"):np.searchsorted(to, b, side="left")]
        if not inside.size:
            continue
        # split at the odometry's own gaps (a logging gap silences every sensor): each stretch the odometry
        # reported through, longer than ``longer_than``, is this sensor's silence (an IMU dead from 60 s of a run
        # with a 26 s logging gap at 117 s is silent 60-117 s and 143-160 s, not in the gap)
        edges = np.concatenate(([a], inside, [b]))
        cuts = np.nonzero(np.diff(edges) > longer_than)[0]
        starts = np.concatenate(([0], cuts + 1))
        ends = np.concatenate((cuts, [len(edges) - 1]))
        for lo, hi in zip(starts.tolist(), ends.tolist()):
            if edges[hi] - edges[lo] > longer_than:
                out.append((float(edges[lo]), float(edges[hi] - edges[lo])))
    return out


class Silences(BaseCheck):
    """An IMU or a GPS silent while the wheels kept reporting."""

    name = "silences"
    group = "run"
    listed_after = ("drops",)  # both speak of the sensor's input: what it dropped first

    def run(self, ev: Evidence) -> list[Verdict]:
        series, t0 = ev.series, ev.t0 if ev.t0 is not None else 0.0
        out = []
        imu = ev.imu
        if imu is not None and len(series.gyro_t) >= 2:
            found = silences(series.gyro_t, MAX_STEP_S, series.odom_t)
            if found:
                at, longest = max(found, key=lambda s: s[1])
                wheels = ev.odom is not None and ev.odom.twist_measured[5]
                meanwhile = ("the wheels' yaw rate alone turned the heading meanwhile (see wheel/yaw_rate for how "
                             "it agrees with the gyro)" if wheels else "nothing turned the heading meanwhile")
                out.append(Verdict(imu.name, "input", "warn",
                                   f"the IMU was silent {len(found)} time(s) for more than {MAX_STEP_S:g} s while the "
                                   f"wheels kept reporting (the longest {longest:.1f} s, {at - t0:.1f} s in): its "
                                   f"gyro drove nothing then, {meanwhile}. An IMU that drops out is its link or "
                                   "driver (USB, serial): check its logs for resets",
                                   evidence={"silences": float(len(found)), "longest_s": longest}))
        gps = ev.gps
        if gps is not None and len(series.gps_t) >= 3:
            # statistics' median: numpy's imports numpy.ma on first use, a sixth of the doctor's whole time
            period = float(statistics.median(np.diff(series.gps_t).tolist()))
            found = silences(series.gps_t, max(GPS_SILENT_PERIODS * period, MAX_STEP_S), series.odom_t)
            if found:
                at, longest = max(found, key=lambda s: s[1])
                out.append(Verdict(gps.name, "input", "ok",
                                   f"no usable fix for {longest:.1f} s from {at - t0:.1f} s in ({len(found)} outage(s) "
                                   f"of more than {GPS_SILENT_PERIODS:g} fix intervals while the wheels kept "
                                   "reporting): the position was dead-reckoned across it (an underpass, a lost lock), "
                                   "and what the estimate did there is the other sensors' doing",
                                   evidence={"outages": float(len(found)), "longest_s": longest}))
        return out
