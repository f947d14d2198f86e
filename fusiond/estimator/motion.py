"""Odometry-driven motion model.

The wheel twist is a control input, not a measurement: position moves by
R(q) v dt (body-frame twist) or v dt (world-frame twist), attitude by the
body rate, which comes either from the wheels' yaw rate or from the gyro.
Input blocks of the state (gyro bias, wheel scale) correct the input first
and get their columns of F by the chain rule through ``G_linear``/``G_angular``.

Input noise: a message covariance is per sample. Held over a sample period T,
white per-sample noise integrates to a random walk of variance sigma^2 * T * dt,
so Q = G (Sigma * T / dt) G^T, independent of how finely the interval is split
by other sensors' messages.
"""

from __future__ import annotations

import math

import numpy as np

from . import rotation as rot
from .state import StateLayout

_I3 = np.eye(3)


class MotionInput:
    """The inputs held between messages (zero-order hold), with their noise."""

    __slots__ = (
        "linear", "linear_cov", "linear_period",
        "angular", "angular_cov", "angular_period",
        "from_gyro", "world_frame",
    )

    def __init__(self) -> None:
        self.linear = np.zeros(3)
        self.linear_cov = np.zeros((3, 3))
        self.linear_period = 0.0
        self.angular = np.zeros(3)
        self.angular_cov = np.zeros((3, 3))
        self.angular_period = 0.0
        self.from_gyro = False
        self.world_frame = False

    def copy(self) -> "MotionInput":
        c = MotionInput.__new__(MotionInput)
        c.linear = self.linear  # arrays are replaced, never mutated in place
        c.linear_cov = self.linear_cov
        c.linear_period = self.linear_period
        c.angular = self.angular
        c.angular_cov = self.angular_cov
        c.angular_period = self.angular_period
        c.from_gyro = self.from_gyro
        c.world_frame = self.world_frame
        return c


def propagate_state(layout: StateLayout, x: np.ndarray, u: MotionInput, dt: float) -> np.ndarray:
    """f(x, u, dt): the exact function the filter runs (used by numeric Jacobian tests)."""
    return predict(layout, x, u, dt, np.zeros(6))[0]


def predict(
    layout: StateLayout, x: np.ndarray, u: MotionInput, dt: float, pose_noise_var: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Propagate the nominal state over dt; return (x_new, F, Q) in error space."""
    n = layout.error_dim
    v = u.linear
    w = u.angular
    corrections = []
    for blk in layout.input_blocks:
        if not blk.applies(u.from_gyro):
            continue
        xb = x[layout.nominal[blk.name]]
        if blk.corrects == "linear":
            corrections.append(("linear", layout.error[blk.name], blk.input_jacobian(xb, v)))
            v = blk.correct(xb, v)
        else:
            corrections.append(("angular", layout.error[blk.name], blk.input_jacobian(xb, w)))
            w = blk.correct(xb, w)

    q0 = (float(x[3]), float(x[4]), float(x[5]), float(x[6]))
    R0 = rot.matrix(q0)
    F = np.eye(n)
    x_new = x.copy()
    if u.world_frame:
        G_lin = _I3 * dt
        x_new[0:3] += v * dt
    else:
        G_lin = R0 * dt
        dp = R0 @ v * dt
        x_new[0:3] += dp
        F[0:3, 3:6] = -rot.skew(dp)
    wx, wy, wz = float(w[0]) * dt, float(w[1]) * dt, float(w[2]) * dt
    q1 = rot.normalize(rot.mul(q0, rot.exp(wx, wy, wz)))
    x_new[3:7] = q1
    G_ang = rot.matrix(q1) @ rot.right_jacobian(wx, wy, wz) * dt

    for which, cols, J in corrections:
        if which == "linear":
            F[0:3, cols] = G_lin @ J
        else:
            F[3:6, cols] = G_ang @ J

    Q = np.zeros((n, n))
    if dt > 0.0:
        if u.linear_period > 0.0:
            Q[0:3, 0:3] = G_lin @ (u.linear_cov * (u.linear_period / dt)) @ G_lin.T
        if u.angular_period > 0.0:
            Q[3:6, 3:6] = G_ang @ (u.angular_cov * (u.angular_period / dt)) @ G_ang.T
        d = np.diagonal(Q).copy()
        d[0:6] += pose_noise_var * dt
        d += layout.random_walk_var * dt
        np.fill_diagonal(Q, d)
    return x_new, F, Q
