"""Scale-factor states: wheel speed scale and gyro yaw-rate scale.

Each is an ``InputBlock``: it corrects one motion input and supplies two
Jacobians, d u'/d (its error) and d u'/d u, so the motion model chains its
columns of F (and the input noise) without knowing what the block is. Neither
scale is observable from odometry and IMU alone: distance needs an absolute
position, turn angle an absolute heading (GPS or a pose sensor). Both get a
prior around 1 and a small random walk (tyre wear, temperature).
"""

from __future__ import annotations

from .state import ScalarInputBlock, Vec3


class WheelScaleBlock(ScalarInputBlock):
    """Wheel speed scale s: v' = s v (tyre radius, skid-steer track slip along the body)."""

    name = "wheel_scale"
    corrects = "linear"
    kernel_code = 2  # _kernels.c BLOCK_WHEEL_SCALE
    start = 1.0  # the input as measured

    def correct(self, xb: list[float], u: Vec3) -> Vec3:
        s = xb[0]
        return (s * u[0], s * u[1], s * u[2])

    def input_jacobian(self, xb: list[float], u: Vec3):
        return ((u[0],), (u[1],), (u[2],))

    def input_derivative(self, xb: list[float], u: Vec3) -> tuple[float, ...] | None:
        s = xb[0]
        return (s, 0.0, 0.0, 0.0, s, 0.0, 0.0, 0.0, s)

    def chain(self, G: tuple[float, ...], xb: list[float], u: Vec3):
        g0, g1, g2, g3, g4, g5, g6, g7, g8 = G
        a, b, c = u
        return (g0 * a + g1 * b + g2 * c, g3 * a + g4 * b + g5 * c, g6 * a + g7 * b + g8 * c)


class GyroScaleBlock(ScalarInputBlock):
    """Yaw-axis gyro scale k: w' = (wx, wy, k wz), applied after the bias (k (w_z - b_z)).

    Only the base-frame z axis turns far enough for its scale to be observable;
    the IMU's extrinsic rotation has already brought the rate into base_link.
    """

    name = "gyro_scale"
    corrects = "angular"
    kernel_code = 3  # _kernels.c BLOCK_GYRO_SCALE
    start = 1.0  # the input as measured

    def applies(self, from_gyro: bool) -> bool:
        return from_gyro

    def correct(self, xb: list[float], u: Vec3) -> Vec3:
        return (u[0], u[1], xb[0] * u[2])

    def input_jacobian(self, xb: list[float], u: Vec3):
        return ((0.0,), (0.0,), (u[2],))

    def input_derivative(self, xb: list[float], u: Vec3) -> tuple[float, ...] | None:
        return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, xb[0])

    def chain(self, G: tuple[float, ...], xb: list[float], u: Vec3):
        wz = u[2]
        return (G[2] * wz, G[5] * wz, G[8] * wz)
