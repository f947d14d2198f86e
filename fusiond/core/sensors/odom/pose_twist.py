"""The twist of an odometry whose driver fills only the pose (``twist_from_pose``).

robot_pose_ekf read a wheel odometry's pose, and drivers written for it may leave the twist at zero: taken as
it is, the robot never moves. The body's motion between two messages is in their poses: the rotation
dq = q0^-1 q1 (a rotation vector phi over dt: the angular velocity phi / dt, in the body) and the displacement
p1 - p0, turned into the body at the middle of the turn (q0 Exp(phi / 2)), over dt: the linear velocity. It is
the mean over the interval the message closes, so it follows the true twist by half an interval; its errors are
the drive's, not the pose's (an integrated pose does not jitter), so its noise is the table's twist_noise, else
the floors twist_min_sigma.

A message with nothing before it to difference (the first, one after more than gap_s, one stamped no later
than the one before it, one without a usable orientation) says nothing of the twist: its twist is "not
measured" (input zero, the default noise), and the next one differences from it, if it moved on in time.
"""

from __future__ import annotations

import math

import msgspec

from ....estimator import mat3
from ....estimator import rotation as rot
from ..checks import finite, near_unit
from .sample import OdomSample

__all__ = ["POSE_PATH_M", "PoseDifferences"]

# A metre of path: far beyond what an integrated pose moves while its robot stands (it does not jitter; a standing
# drive's pose creeps by an encoder tick at most). A pose that travels that far while the twist says the robot
# went nowhere is a driver that fills the pose only (``fusiond info``/``init``, the doctor's ``pose_only``).
POSE_PATH_M = 1.0

_ZERO3 = (0.0, 0.0, 0.0)
# a variance beyond every twist_max_sigma: each component "not measured" (OdomPolicy._twist_noise)
UNMEASURED = tuple(math.inf if i % 7 == 0 else 0.0 for i in range(36))
FLOORED = (0.0,) * 36  # each variance at its floor (twist_min_sigma), unless twist_noise states it


def _not_measured(s: OdomSample) -> OdomSample:
    """``s`` saying nothing of the twist: zero, each component "not measured"."""
    return msgspec.structs.replace(s, linear=_ZERO3, angular=_ZERO3, twist_covariance=UNMEASURED)


class PoseDifferences:
    """Each odometry message with the twist its pose and the previous message's imply (module doc), in the order
    they are given. One per consumer: the core's odometry policy and the doctor each keep their own, fed the
    same messages in the same order."""

    def __init__(self, gap_s: float) -> None:
        self.gap_s = gap_s  # the filter's gap_s: a longer interval is a logging gap, not one motion
        self._prev: tuple[float, tuple, tuple] | None = None  # (stamp, position, unit orientation)

    def __call__(self, s: OdomSample) -> OdomSample:
        stamp, q = s.stamp, near_unit(s.orientation) if len(s.orientation) == 4 else None
        usable = 0.0 < stamp < math.inf and q is not None and len(s.position) == 3 and finite(s.position)
        prev = self._prev
        if not usable or (prev is not None and not stamp > prev[0]):
            return _not_measured(s)
        self._prev = (stamp, s.position, q)
        if prev is None or stamp - prev[0] > self.gap_s:
            return _not_measured(s)
        dt = stamp - prev[0]
        q0, p0 = prev[2], prev[1]
        phi = rot.log(rot.mul(rot.conj(q0), q))
        middle = rot.mul(q0, rot.exp(0.5 * phi[0], 0.5 * phi[1], 0.5 * phi[2]))
        p1 = s.position
        moved = mat3.apply_transposed(rot.matrix9(middle), (p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]))
        k = 1.0 / dt
        return msgspec.structs.replace(s, linear=(moved[0] * k, moved[1] * k, moved[2] * k),
                                       angular=(phi[0] * k, phi[1] * k, phi[2] * k), twist_covariance=FLOORED)
