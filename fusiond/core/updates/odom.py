"""Odometry: the twist is the motion input (held until the next message), not an update.

Once the gyro drives heading the wheels' yaw rate is not fused; it only checks
the gyro (channel ``yaw_rate``), so that skid-steer slip and hand-turning show.
It also tells the core when the robot stands still (for the gyro bias).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ..diagnostics import DiagnosticsRecord
from ..sensors import OdomInput
from .imu import quiet_bound

if TYPE_CHECKING:
    from ..fusion import FusionCore
    from ..state import FilterState


def apply_odom(core: "FusionCore", s: FilterState, idx: int, inp: OdomInput, stamp: float, emit: bool, late: bool):
    s.linear, s.linear_cov = inp.linear, inp.linear_cov
    s.wheel_angular, s.wheel_angular_cov = inp.angular, inp.angular_cov
    s.wheel_yaw_measured = inp.yaw_rate_measured
    if inp.stationary:
        if s.still_since is None:
            s.still_since = stamp
    else:
        s.still_since = None
    if not emit or s.gyro is None or not inp.yaw_rate_measured:
        return []
    if stamp - s.gyro_last[1] > core.timeout(s.gyro_last[0], s):
        return []
    # The wheels' yaw rate is not fused once the gyro drives heading; it only
    # checks the gyro, so that skid and hand-turning show up as slip.
    x = s.ekf.x
    gyro_z = s.gyro[2] - (float(x[core.bias_z_nominal]) if core.has_bias else 0.0)
    if core.has_gyro_scale:
        gyro_z *= float(x[core.gyro_scale_nominal])
    var = inp.angular_cov[8] + s.gyro_cov[8]
    if core.has_bias:
        e = core.bias_z_error
        var += float(s.ekf.P[e, e])
    r = inp.angular[2] - gyro_z
    # Flagged: a wheel rate that misses the gyro's by more than slip_threshold, or wheels reading
    # exactly zero while the gyro turns beyond the standstill quiet bound (the vehicle coasting or
    # turned with its drive at rest: not a wheel measurement of the turn at all).
    quiet = quiet_bound(math.sqrt(s.gyro_cov[8]), core.cfg.filter.gyro_bias_sigma)
    slip = abs(r) > core.sensors[idx].slip_threshold or (inp.stationary and abs(gyro_z) > quiet)
    return [
        DiagnosticsRecord(stamp, core.sensors[idx].name, ["yaw_rate"], [r], [var], r * r / var, 1, slip,
                          channel="yaw_rate", late=late)
    ]
