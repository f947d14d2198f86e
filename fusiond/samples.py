"""Transport-agnostic sensor samples: what every codec produces and the fusion core consumes.

Plain msgspec Structs (no numpy) so that codecs stay cheap and samples can be
serialised for tests and tools. Covariances are row-major, as in ROS messages.
"""

from __future__ import annotations

import msgspec


class OdomSample(msgspec.Struct, gc=False):
    """Wheel odometry: the twist drives the prediction; the pose is kept only for plots."""

    sensor: str
    stamp: float
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    twist_covariance: tuple[float, ...]  # 36, row-major (vx vy vz wx wy wz)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # x y z w


class ImuSample(msgspec.Struct, gc=False):
    """IMU in its own frame; the core applies the sensor's extrinsic rotation."""

    sensor: str
    stamp: float
    orientation: tuple[float, float, float, float]  # x y z w
    orientation_covariance: tuple[float, ...]  # 9, row-major; [0] == -1 means "no orientation"
    angular_velocity: tuple[float, float, float]
    angular_velocity_covariance: tuple[float, ...]  # 9
    linear_acceleration: tuple[float, float, float] = (0.0, 0.0, 0.0)
    linear_acceleration_covariance: tuple[float, ...] = (0.0,) * 9


Sample = OdomSample | ImuSample
