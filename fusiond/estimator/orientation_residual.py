"""The orientation observation's residual and Jacobian: the reference the backends compute it by.

Roll, pitch and yaw of the attitude (fixed axes, the ROS covariance convention) and their derivatives
against the global attitude error. Apart from the observation models (``observations``), which choose
a backend to compute it, so that the reference backend (``backend.PythonBackend``) reads it from here
and the models import the backend, not the other way round.
"""

from __future__ import annotations

import math

import numpy as np

from . import rotation as rot
from .state import StateLayout

_MIN_COS_PITCH = 1e-3


def rpy_jacobian(q: rot.Quat) -> tuple[tuple[float, float, float], tuple[tuple[float, float, float], ...]]:
    """(roll, pitch, yaw) of q and d(rpy)/d(global dtheta) as three row tuples.

    Gravity in the body, g = R^T e_z, moves by R^T [e_z]x dtheta, i.e. by
    R^T (-dtheta_y, dtheta_x, 0): roll = atan2(g_y, g_z) and pitch = -asin(g_x)
    follow by the chain rule and have no dtheta_z term. Yaw = atan2(R10, R00).
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rot.matrix9(q)
    # rot.to_rpy(q) from the matrix's entries: the same float expressions, computed once
    roll = math.atan2(r21, r22)
    pitch = math.asin(max(-1.0, min(1.0, -r20)))
    yaw = math.atan2(r10, r00)
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


def rpy_residual(layout: StateLayout, x: np.ndarray, z_rpy: tuple[float, float, float],
                 rows: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(y, H) of ``orientation``, the reference: each residual wrapped, H's attitude columns from
    ``rpy_jacobian`` (the compiled backend's are the same expressions in C, held to the same bits by
    tests/unit/test_kernels.py)."""
    h, Hrpy = rpy_jacobian(x[3:7].tolist())
    H = np.zeros((len(rows), layout.error_dim))
    residual = []
    for k, i in enumerate(rows):  # H element by element: cheaper than a slice from nested lists
        residual.append(rot.wrap(z_rpy[i] - h[i]))
        H[k, 3], H[k, 4], H[k, 5] = Hrpy[i]
    return np.array(residual), H


__all__ = ["rpy_jacobian", "rpy_residual"]
