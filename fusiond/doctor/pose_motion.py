"""A differential pose sensor's motion in base_link's axes, against the direction a wheeled robot moves in.

A wheeled base (differential drive, skid steer, Ackermann at its rear axle) moves along its own x: no sideways,
no vertical motion in its own frame, whatever the slope. A camera's visual odometry reports its deltas in its
own axes; turned into base_link's by the configured mount (``extrinsic_rpy``) and with the lever arm's share of
each turn taken out (``extrinsic_xyz``), they point along x when the mount is right. A mount turned by a yaw
delta or a pitch dp beyond the configured one shows them leaning: sideways by -sin(delta), up by sin(dp) of
every forward metre. So the summed deltas, each signed by the wheels' direction (reversing moves along -x), give
the mount's error: delta = -atan2(sum lateral, sum forward), dp = atan2(sum vertical, sum forward); each with its
standard error from the deltas' own scatter about that line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..core.sensors.registry import kind_of
from ..estimator import mat3
from ..estimator import observations as obs
from ..estimator import rotation as rot

__all__ = ["MountFit", "PoseMotion"]


@dataclass(frozen=True)
class MountFit:
    """The mount's error the deltas show: yaw and pitch (rad) beyond the configured ones, their standard errors,
    how many deltas and how far (m) they went in all, along their summed direction in the ground plane."""

    yaw: float
    yaw_se: float
    pitch: float
    pitch_se: float
    n: int
    forward_m: float


class _Sums:
    """One sensor's running sums: its previous message, the signed deltas' sums and sums of squares."""

    __slots__ = ("prev", "n", "fwd", "lat", "up", "lat2", "up2", "fwd2", "lat_fwd", "up_fwd", "up_lat")

    def __init__(self) -> None:
        self.prev: tuple | None = None
        self.n = 0
        self.fwd = self.lat = self.up = 0.0
        self.lat2 = self.up2 = self.fwd2 = self.lat_fwd = self.up_fwd = self.up_lat = 0.0


class PoseMotion:
    """Every differential pose sensor's deltas, turned into base_link's axes, signed by the wheels' direction
    (``add``: every sample in arrival order; the odometry's forward speed is the latest one's)."""

    def __init__(self, sensors) -> None:
        self._mounts = {}
        for s in sensors:
            if getattr(s, "differential", False):  # a sensor whose deltas are fused (a pose table's key)
                self._mounts[s.name] = (rot.from_rpy(*s.extrinsic_rpy), tuple(s.extrinsic_xyz))
        self._odom = next((s.name for s in sensors if kind_of(s).drives_prediction), None)
        self._sums = {name: _Sums() for name in self._mounts}
        self.sensors = tuple(self._mounts)
        self._speed = 0.0  # the odometry's latest forward speed (its sign: forward or reversing)

    def add(self, sample) -> None:
        name = sample.sensor
        if name == self._odom:
            linear = getattr(sample, "linear", None)
            if linear is not None and math.isfinite(linear[0]):
                self._speed = linear[0]
            return
        sums = self._sums.get(name)
        if sums is None:
            return
        position, q = getattr(sample, "position", None), getattr(sample, "orientation", None)
        if position is None or q is None or not all(map(math.isfinite, (*position, *q))):
            return
        prev, sums.prev = sums.prev, (tuple(position), rot.normalize(tuple(q)))
        if prev is None or self._speed == 0.0:
            return
        mount, lever = self._mounts[name]
        # in base_link's axes at the sensor's origin, as the filter reads the delta, less what a turn moves the lever by
        p, turn = obs.turned_delta(mount, *obs.relative_pose(prev[0], prev[1], sums.prev[0], sums.prev[1]))
        r = mat3.apply(rot.matrix9(turn), lever)
        moved = (r[0] - lever[0], r[1] - lever[1], r[2] - lever[2])
        sign = 1.0 if self._speed > 0.0 else -1.0
        fwd, lat, up = (sign * (p[0] - moved[0]), sign * (p[1] - moved[1]), sign * (p[2] - moved[2]))
        sums.n += 1
        sums.fwd += fwd
        sums.lat += lat
        sums.up += up
        sums.fwd2 += fwd * fwd
        sums.lat2 += lat * lat
        sums.up2 += up * up
        sums.lat_fwd += lat * fwd
        sums.up_fwd += up * fwd
        sums.up_lat += up * lat

    def fit(self, name: str) -> MountFit | None:
        """The mount's error ``name``'s deltas show (module doc); None before two deltas or without a net motion."""
        sums = self._sums.get(name)
        if sums is None or sums.n < 2:
            return None
        n = sums.n
        along = math.hypot(sums.fwd, sums.lat)  # the deltas' sum in the ground plane: its direction is -delta
        if not along > 0.0:
            return None
        c, s = sums.fwd / along, sums.lat / along
        # each delta's component across that direction, and along it: the scatter about the line gives the angle's
        # standard error, sqrt(n var) / (the summed motion along it), as a ratio estimator's
        across2 = s * s * sums.fwd2 - 2.0 * s * c * sums.lat_fwd + c * c * sums.lat2
        along2 = c * c * sums.fwd2 + 2.0 * c * s * sums.lat_fwd + s * s * sums.lat2
        up_along = c * sums.up_fwd + s * sums.up_lat
        k = sums.up / along
        rest_up = max(sums.up2 - 2.0 * k * up_along + k * k * along2, 0.0)
        dof = max(n - 1, 1)
        return MountFit(-math.atan2(sums.lat, sums.fwd), math.sqrt(n * max(across2, 0.0) / dof) / along,
                        math.atan2(sums.up, along), math.sqrt(n * rest_up / dof) / along, n, along)
