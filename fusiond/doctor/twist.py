"""Odometry twist over the run: what tells a body-frame twist from a world-frame one.

The replay feeds every accepted odometry message's twist (and the message's own pose) here; the sums
are what the twist-frame check (``checks/twist_frame.py``) judges: a wheeled robot's body twist has
little lateral velocity, and a world twist points where the message's pose heads. Beside them, how far the
messages' own positions travelled and how far their twists say the robot went over the same intervals: a
driver that fills the pose only (``checks/pose_only.py``) travels with a twist that never moves.
"""

from __future__ import annotations

import math
from itertools import chain

import numpy as np

from ..core.sensors.checks import MAX_SPEED
from .settled import Settled


TURNED_RAD = 0.3  # the message's own pose yaw this far from the odom frame's x: a world twist must follow it
ALONG_SIN = 0.05  # |sin| of the angle between the twist and an axis below this: the twist points along it
MOVING_M_S = 0.1  # speed above which a twist has a direction

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
        self._position: list[tuple[float, float, float]] = []
        self._stamp: list[float] = []
        self._last: tuple[float, float, float, float] | None = None  # the previous chunk's last (t, x, y, z)
        self._travel = [0.0, 0.0]  # the positions' path, the twists' (|v| dt) over the same intervals, m
        self._n = 0
        self._sums = [0.0, 0.0, 0.0]
        self._turned = 0
        self._along_x = 0
        self._along_pose = 0
        self._posed = 0

    def add(self, linear: tuple[float, float, float], angular: tuple[float, float, float],
            orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
            position: tuple[float, float, float] = (0.0, 0.0, 0.0), stamp: float = math.nan) -> None:
        self._linear.append(linear)
        self._angular.append(angular)
        self._orientation.append(orientation)
        self._position.append(position)
        self._stamp.append(stamp)
        if len(self._linear) >= CHUNK:
            self._settle()

    n = Settled("_n")
    abs_vx = Settled("_sums", 0)
    abs_vy = Settled("_sums", 1)
    abs_wz = Settled("_sums", 2)
    turned = Settled("_turned")  # moving messages whose pose yaw is beyond TURNED_RAD ...
    along_x = Settled("_along_x")  # ... whose twist points along the odom frame's x (body-frame, or the robot heads x)
    along_pose = Settled("_along_pose")  # ... whose twist points where that pose heads (world-frame)
    posed = Settled("_posed")  # messages carrying a pose orientation (not the identity of a driver that fills none)
    pose_travel = Settled("_travel", 0)  # m the messages' positions moved, message to message (resets left out) ...
    twist_travel = Settled("_travel", 1)  # ... and how far their twists say the robot went meanwhile, m

    def _settle(self) -> None:
        n = len(self._linear)
        if not n:
            return
        linear = np.fromiter(chain.from_iterable(self._linear), dtype=float, count=3 * n).reshape(n, 3)
        angular = np.fromiter(chain.from_iterable(self._angular), dtype=float, count=3 * n).reshape(n, 3)
        q = np.fromiter(chain.from_iterable(self._orientation), dtype=float, count=4 * n).reshape(n, 4)
        p = np.fromiter(chain.from_iterable(self._position), dtype=float, count=3 * n).reshape(n, 3)
        t = np.array(self._stamp, dtype=float)
        self._linear, self._angular, self._orientation, self._position, self._stamp = [], [], [], [], []
        self._add_travel(t, p, linear)
        x, y, z, w = q.T
        self._posed += int((~((x == 0.0) & (y == 0.0) & (z == 0.0) & (w == 1.0))).sum())
        pose_yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        direction = np.arctan2(linear[:, 1], linear[:, 0])
        turned = (np.hypot(linear[:, 0], linear[:, 1]) > MOVING_M_S) & (np.abs(np.sin(pose_yaw)) > math.sin(TURNED_RAD))
        self._turned += int(turned.sum())
        self._along_x += int((turned & (np.abs(np.sin(direction)) < ALONG_SIN)).sum())
        self._along_pose += int((turned & (np.abs(np.sin(direction - pose_yaw)) < ALONG_SIN)).sum())
        rows = np.abs(np.column_stack((linear[:, 0], linear[:, 1], angular[:, 2])))
        self._n += n
        self._sums = np.cumsum(np.concatenate(([self._sums], rows)), axis=0)[-1].tolist()

    def _add_travel(self, t: np.ndarray, p: np.ndarray, linear: np.ndarray) -> None:
        """The chunk's path of the positions and of the twists (each interval's |v| dt, v the message that ends
        it), message to message from the previous chunk's last; an interval not forward in time, or whose
        position jumped faster than the core takes any twist (MAX_SPEED: an odometry reset), is left out of both."""
        last = self._last
        if last is not None:
            t = np.concatenate(([last[0]], t))
            p = np.concatenate(([last[1:]], p))
        else:
            linear = linear[1:]
        self._last = (float(t[-1]), *p[-1].tolist())
        if len(t) < 2:
            return
        dt = np.diff(t)
        step = np.linalg.norm(np.diff(p, axis=0), axis=1)
        with np.errstate(invalid="ignore"):
            ok = (dt > 0.0) & np.isfinite(step) & (step <= MAX_SPEED * dt)
        driven = np.linalg.norm(linear, axis=1) * dt
        self._travel = [self._travel[0] + float(step[ok].sum()), self._travel[1] + float(driven[ok].sum())]
