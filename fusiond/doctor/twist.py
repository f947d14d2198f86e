"""Odometry twist: a yaw rate that is not measured, slip against the gyro, the twist frame.

A driver that lost its yaw rate publishes 0 with covariance 0: to the filter a
perfect measurement of "not turning". Against the gyro it looks like slip in every
turn. The difference is in the numbers: slip reads a wrong rate, a lost component
reads exactly zero (with zero variance) while the gyro turns. That is "not
measured", declared with ``twist_measured``.
"""

from __future__ import annotations

import math
from itertools import chain

import numpy as np

from ..config import OdomSensor
from .settled import Settled
from .verdict import Verdict, sensor_key
from .thresholds import ALONG_SIN, MOVING_M_S, TURNED_RAD

CHUNK = 4096  # twists noted before they are summed (bounded memory)


class TwistStats:
    """Whole-run sums of |vx|, |vy| and |wz| of the accepted odometry (is the twist in the body frame?),
    and, over the moving messages whose own pose is turned beyond TURNED_RAD from the odom frame's x, how
    many point their twist along x (a body-frame twist: a world one would point where that pose heads).

    Fed one twist per accepted odometry message, so it only notes it; the sums are taken a chunk at a
    time by ``np.cumsum`` (adds in order: the same floats as adding one message at a time)."""

    def __init__(self) -> None:
        self._linear: list[tuple[float, float, float]] = []  # the samples' own tuples: nothing allocated
        self._angular: list[tuple[float, float, float]] = []
        self._orientation: list[tuple[float, float, float, float]] = []
        self._n = 0
        self._sums = [0.0, 0.0, 0.0]
        self._turned = 0
        self._along_x = 0

    def add(self, linear: tuple[float, float, float], angular: tuple[float, float, float],
            orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> None:
        self._linear.append(linear)
        self._angular.append(angular)
        self._orientation.append(orientation)
        if len(self._linear) >= CHUNK:
            self._settle()

    n = Settled("_n")
    abs_vx = Settled("_sums", 0)
    abs_vy = Settled("_sums", 1)
    abs_wz = Settled("_sums", 2)
    turned = Settled("_turned")  # moving messages whose pose yaw is beyond TURNED_RAD ...
    along_x = Settled("_along_x")  # ... whose twist points along the odom frame's x (body-frame, or the robot heads x)

    def _settle(self) -> None:
        n = len(self._linear)
        if not n:
            return
        linear = np.fromiter(chain.from_iterable(self._linear), dtype=float, count=3 * n).reshape(n, 3)
        angular = np.fromiter(chain.from_iterable(self._angular), dtype=float, count=3 * n).reshape(n, 3)
        q = np.fromiter(chain.from_iterable(self._orientation), dtype=float, count=4 * n).reshape(n, 4)
        self._linear, self._angular, self._orientation = [], [], []
        x, y, z, w = q.T
        pose_yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        direction = np.arctan2(linear[:, 1], linear[:, 0])
        turned = (np.hypot(linear[:, 0], linear[:, 1]) > MOVING_M_S) & (np.abs(np.sin(pose_yaw)) > math.sin(TURNED_RAD))
        self._turned += int(turned.sum())
        self._along_x += int((turned & (np.abs(np.sin(direction)) < ALONG_SIN)).sum())
        rows = np.abs(np.column_stack((linear[:, 0], linear[:, 1], angular[:, 2])))
        self._n += n
        self._sums = np.cumsum(np.concatenate(([self._sums], rows)), axis=0)[-1].tolist()


def twist_frame_verdict(odom: OdomSensor, t: TwistStats, min_updates: int = 50) -> Verdict | None:
    if t.n < min_updates or t.abs_vx + t.abs_vy < 1e-6:
        return None
    lateral = t.abs_vy / max(t.abs_vx + t.abs_vy, 1e-12)
    key = sensor_key(odom.name, "twist_frame")
    if odom.twist_frame == "world" and t.turned >= min_updates and t.along_x >= 0.9 * t.turned:
        # a world-frame twist points where the vehicle heads, which the message's own pose says: one that
        # keeps pointing along x while that pose turns away is a body-frame twist. Gentle curves (a highway:
        # 37 m off, otherwise blamed on the wheel scale and an IMU mounting) never make the turn-rate rule
        # below fire
        return Verdict(odom.name, "twist", "problem",
                       f"twist configured in the world frame, but in {100 * t.along_x / t.turned:.0f}% of the "
                       f"{t.turned} moving messages whose own pose is turned beyond {TURNED_RAD:g} rad from the odom "
                       "frame's x it points along x, not where that pose heads: it is a body-frame twist, and the "
                       "trajectory runs off sideways", key, 'twist_frame = "body"',
                       evidence={"twist_along_x_share": t.along_x / t.turned})
    if odom.twist_frame == "world" and lateral < 0.05 and t.abs_wz / t.n > 0.05:
        return Verdict(odom.name, "twist", "problem",
                       "twist configured in the world frame, but its lateral velocity stays near zero while "
                       "the robot turns: it is a body-frame twist, and the trajectory heading will run away",
                       key, 'twist_frame = "body"')
    if odom.twist_frame == "body" and lateral > 0.35:
        return Verdict(odom.name, "twist", "warn",
                       f"lateral velocity is {100 * lateral:.0f}% of the motion: a wheeled robot's body twist "
                       "has little; if the driver reports the twist in the odom frame, say so", key,
                       'twist_frame = "world"')
    return None
