"""The IMU kind's sample: what its decoders make (``codec``) and its model converts (``model``)."""

from __future__ import annotations

import msgspec


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


__all__ = ["ImuSample"]
