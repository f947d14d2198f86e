"""The odom frame's continuity on a replayed recording (REP-105): the largest amount by which a step
between two consecutive published poses exceeds what the odometry's twist allows over it.

Read from what `fusiond replay --tum` writes (one line per odometry message: the pose the daemon
would have published then) beside the odometry's own speeds in the bag, so the check sees the
published track, not the filter's internals.
"""

from __future__ import annotations

import bisect
import math
from pathlib import Path

from fusiond.config import Config
from fusiond.replay.bag import open_bag_samples
from fusiond.core.sensors import OdomSample

__all__ = ["STEP_MARGIN_M", "excess_steps", "odom_speeds", "read_tum"]

STEP_MARGIN_M = 0.05  # what a step may exceed the odometry's motion by


def read_tum(path: Path) -> list[tuple[float, tuple[float, float, float]]]:
    """(stamp, position) per TUM line."""
    rows = []
    for line in path.read_text().splitlines():
        f = line.split()
        rows.append((float(f[0]), (float(f[1]), float(f[2]), float(f[3]))))
    return rows


def odom_speeds(bags: list[Path], cfg: Config) -> dict[float, float]:
    """The odometry's linear speed (m/s) at each of its header stamps (plus the sensor's stamp_offset_s)."""
    odom = next(s for s in cfg.sensors if type(s).__struct_config__.tag == "odom")
    speeds: dict[float, float] = {}
    with open_bag_samples(bags, [odom]) as bag:
        for s in bag:
            if isinstance(s, OdomSample):
                speeds[s.stamp + odom.stamp_offset_s] = math.hypot(*s.linear)
    return speeds


def excess_steps(track: list[tuple[float, tuple[float, float, float]]], speeds: dict[float, float]
                 ) -> list[tuple[float, float, float]]:
    """(stamp, step m, allowed m) of every step between consecutive poses longer than the odometry's
    largest speed over it (from the message held at its start to the last one inside it) times its
    duration, plus STEP_MARGIN_M."""
    stamps = sorted(speeds)
    out = []
    for (t0, p0), (t1, p1) in zip(track, track[1:]):
        if t1 <= t0:
            continue  # a late odometry message answered at a stamp already published
        lo = max(bisect.bisect_right(stamps, t0) - 1, 0)
        hi = bisect.bisect_right(stamps, t1)
        v = max((speeds[t] for t in stamps[lo:hi]), default=0.0)
        allowed = v * (t1 - t0) + STEP_MARGIN_M
        step = math.dist(p0, p1)
        if step > allowed:
            out.append((t1, step, allowed))
    return out
