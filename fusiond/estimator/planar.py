"""Two-D mode's hold (robot_localization's ``two_d_mode``): z, roll and pitch exactly 0.

The reference the backends are held to (``Backend.hold_planar``); the filter calls it through its
backend (``ErrorStateEKF.hold_planar``), twice a message in two-D mode.
"""

from __future__ import annotations

import math

import numpy as np

from .state import attitude_of

__all__ = ["hold_planar", "planar_mask"]


def hold_planar(x: np.ndarray, P: np.ndarray, nominal_zero: tuple[int, ...], error_zero) -> None:
    """In place: the attitude x[3:7] becomes the pure rotation about world z with the same heading, the
    listed nominal components (z, and what the layout adds, e.g. the x/y gyro bias) are set to 0, and
    the listed error components lose all variance and correlation in P: a state held at a value is
    known exactly, and nothing can be inferred through it. ``error_zero``: their indices (a tuple or an
    array), or ``planar_mask`` of them (one masked write instead of a row and a column write by index)."""
    qx, qy, qz, qw = attitude_of(x)
    if qx != 0.0 or qy != 0.0:
        half = 0.5 * math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        qx, qy, qz, qw = 0.0, 0.0, math.sin(half), math.cos(half)
        x[3], x[4], x[5], x[6] = qx, qy, qz, qw
    for i in nominal_zero:
        x[i] = 0.0
    if isinstance(error_zero, np.ndarray) and error_zero.ndim == 2:
        P[error_zero] = 0.0
    else:
        rows = np.asarray(error_zero, dtype=np.intp)
        P[rows, :] = 0.0
        P[:, rows] = 0.0


def planar_mask(error_zero: list[int], dim: int) -> np.ndarray:
    """The (dim, dim) mask of the rows and columns of the error components ``error_zero``: what
    ``hold_planar`` zeroes in P."""
    mask = np.zeros((dim, dim), dtype=bool)
    mask[error_zero, :] = True
    mask[:, error_zero] = True
    return mask
