"""The twist's pitch in the body: the angle between the wheels' direction of travel and base x.

The filter's body frame is the one its attitude source defines: with roll/pitch from an IMU
(its orientation or its gravity) that is the IMU's, turned by ``extrinsic_rpy``. An IMU pitched
in its mount by an angle the configuration does not state (a phone on a windshield, 4 degrees)
leaves the body pitched by it against the vehicle, and the wheels' twist, integrated along body
x, climbs or sinks by that angle per metre driven. This block is that angle b: the twist the
wheels measure, (v, 0, 0) in the vehicle, is (cos b v, 0, sin b v) in the body,

    v' = R_y(b)^T v.

Like the wheel scale it is observable only from an absolute height (GPS altitude, an absolute
pose's z) while moving; with neither it is not in the state. Prior around 0 (the mount as
configured), a small random walk (a mount that settles). Over a short drive it is confounded with
a slowly wandering altitude: the GPS error model must say how slowly (core/layout.py).
"""

from __future__ import annotations

import math

from .state import ScalarInputBlock, Vec3


class TwistPitchBlock(ScalarInputBlock):
    """``release_sigma`` > 0: held (no variance) until an update finds the height's other explanation refuted,
    then given that prior (``ErrorStateEKF.reattribute``'s ``release``)."""

    name = "twist_pitch"
    corrects = "linear"
    kernel_code = 4  # _kernels.c BLOCK_TWIST_PITCH
    start = 0.0  # the mount as configured

    def __init__(self, sigma: float, walk: float, release_sigma: float = 0.0) -> None:
        super().__init__(sigma, walk)
        self.release_sigma = release_sigma

    def correct(self, xb: list[float], u: Vec3) -> Vec3:
        c, s = math.cos(xb[0]), math.sin(xb[0])
        return (c * u[0] - s * u[2], u[1], s * u[0] + c * u[2])

    def input_jacobian(self, xb: list[float], u: Vec3):
        c, s = math.cos(xb[0]), math.sin(xb[0])
        return ((-s * u[0] - c * u[2],), (0.0,), (c * u[0] - s * u[2],))

    def input_derivative(self, xb: list[float], u: Vec3) -> tuple[float, ...] | None:
        c, s = math.cos(xb[0]), math.sin(xb[0])
        return (c, 0.0, -s, 0.0, 1.0, 0.0, s, 0.0, c)

    def chain(self, G: tuple[float, ...], xb: list[float], u: Vec3):
        c, s = math.cos(xb[0]), math.sin(xb[0])
        a, b = -s * u[0] - c * u[2], c * u[0] - s * u[2]  # d v' / d b: (a, 0, b)
        return (G[0] * a + G[2] * b, G[3] * a + G[5] * b, G[6] * a + G[8] * b)


__all__ = ["TwistPitchBlock"]
