"""Measurement models: innovation y = z [-] h(x), Jacobian H on the error state, noise R.

Orientation is observed as fixed-axis roll, pitch, yaw (the ROS covariance
convention), each residual wrapped to [-pi, pi]. Euler angles of q and -q are
equal, which settles the quaternion sign ambiguity. Against the global attitude
error, roll and pitch have an exactly zero yaw column, so a roll/pitch-only
update cannot move heading (nor, through it, position).
"""

from __future__ import annotations

import math

import numpy as np

from . import rotation as rot
from .state import StateLayout

# Roll/pitch/yaw rows used by each IMU orientation mode.
ORIENTATION_ROWS: dict[str, tuple[int, ...]] = {
    "absolute": (0, 1, 2),
    "relative": (0, 1, 2),
    "roll_pitch": (0, 1),
}
RPY_NAMES = ("roll", "pitch", "yaw")
_MIN_COS_PITCH = 1e-3


def rpy_jacobian(q: rot.Quat) -> tuple[tuple[float, float, float], tuple[tuple[float, float, float], ...]]:
    """(roll, pitch, yaw) of q and d(rpy)/d(global dtheta) as three row tuples.

    Gravity in the body, g = R^T e_z, moves by R^T [e_z]x dtheta, i.e. by
    R^T (-dtheta_y, dtheta_x, 0): roll = atan2(g_y, g_z) and pitch = -asin(g_x)
    follow by the chain rule and have no dtheta_z term. Yaw = atan2(R10, R00).
    """
    roll, pitch, yaw = rot.to_rpy(q)
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot.matrix9(q)
    cp = max(math.cos(pitch), _MIN_COS_PITCH)
    cr, sr = math.cos(roll), math.sin(roll)
    # d g_i / d (dtheta_x, dtheta_y) = (R[1][i], -R[0][i])
    gx = (r10, -r00)
    gy = (r11, -r01)
    gz = (r12, -r02)
    h_roll = ((cr * gy[0] - sr * gz[0]) / cp, (cr * gy[1] - sr * gz[1]) / cp, 0.0)
    h_pitch = (-gx[0] / cp, -gx[1] / cp, 0.0)
    c2 = max(r00 * r00 + r10 * r10, _MIN_COS_PITCH**2)
    h_yaw = (-r00 * r20 / c2, -r10 * r20 / c2, 1.0)
    return (roll, pitch, yaw), (h_roll, h_pitch, h_yaw)


def orientation(
    layout: StateLayout, x: np.ndarray, z_rpy: tuple[float, float, float], cov: tuple[float, ...],
    rows: tuple[int, ...],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observe the selected roll/pitch/yaw rows of the attitude; cov is row-major 3x3 (9-tuple)."""
    h, Hrpy = rpy_jacobian((float(x[3]), float(x[4]), float(x[5]), float(x[6])))
    y = np.array([rot.wrap(z_rpy[i] - h[i]) for i in rows])
    H = np.zeros((len(rows), layout.error_dim))
    H[:, 3:6] = [Hrpy[i] for i in rows]
    R = np.array([[cov[3 * i + j] for j in rows] for i in rows])
    return y, H, R


def zero_rate(
    layout: StateLayout, x: np.ndarray, gyro: tuple[float, float, float], cov: tuple[float, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At standstill the true rate is zero, so the gyro reads its bias: z = b + noise."""
    bs = layout.nominal["gyro_bias"]
    y = np.array(gyro) - x[bs]
    H = np.zeros((3, layout.error_dim))
    H[:, layout.error["gyro_bias"]] = _I3
    return y, H, np.array(cov).reshape(3, 3)


_I3 = np.eye(3)
