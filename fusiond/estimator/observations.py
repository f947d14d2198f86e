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


def rpy_jacobian(q: rot.Quat) -> tuple[tuple[float, float, float], np.ndarray]:
    """(roll, pitch, yaw) of q and d(rpy)/d(global dtheta), a 3x3 matrix."""
    roll, pitch, yaw = rot.to_rpy(q)
    R = rot.matrix(q)
    cp = max(math.cos(pitch), _MIN_COS_PITCH)
    cr, sr = math.cos(roll), math.sin(roll)
    # gravity in body g = R^T e_z moves by R^T [e_z]x dtheta
    M = R.T[:, 0:2] @ np.array(((0.0, -1.0, 0.0), (1.0, 0.0, 0.0)))
    H = np.empty((3, 3))
    H[0] = (cr * M[1] - sr * M[2]) / cp
    H[1] = -M[0] / cp
    c2 = max(R[0, 0] ** 2 + R[1, 0] ** 2, _MIN_COS_PITCH**2)
    H[2] = (-R[0, 0] * R[2, 0] / c2, -R[1, 0] * R[2, 0] / c2, 1.0)
    return (roll, pitch, yaw), H


def orientation(
    layout: StateLayout, x: np.ndarray, z_rpy: tuple[float, float, float], cov: np.ndarray, rows: tuple[int, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observe the selected roll/pitch/yaw rows of the attitude."""
    q = (float(x[3]), float(x[4]), float(x[5]), float(x[6]))
    h, Hrpy = rpy_jacobian(q)
    y = np.array([rot.wrap(z_rpy[i] - h[i]) for i in rows])
    H = np.zeros((len(rows), layout.error_dim))
    H[:, 3:6] = Hrpy[list(rows)]
    R = cov[np.ix_(rows, rows)]
    return y, H, R


def zero_rate(
    layout: StateLayout, x: np.ndarray, gyro: np.ndarray, cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At standstill the true rate is zero, so the gyro reads its bias: z = b + noise."""
    bs = layout.nominal["gyro_bias"]
    y = gyro - x[bs]
    H = np.zeros((3, layout.error_dim))
    H[:, layout.error["gyro_bias"]] = np.eye(3)
    return y, H, cov
