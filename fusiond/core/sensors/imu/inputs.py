"""The filter input one IMU message becomes: a base-frame attitude observation and gyro rate."""

from __future__ import annotations

import msgspec

from ....estimator import rotation as rot


class ImuInput(msgspec.Struct, gc=False):
    """Base-frame attitude observation (roll, pitch, yaw rows usable) and gyro rate; 9-tuple covariances.
    A Struct: one is made per message, and its C constructor costs a fifth of a dataclass's.

    The attitude is kept as the base-frame quaternion and turned into roll/pitch/yaw (``rpy``) only
    when the model fuses it: an IMU faster than ``orientation_rate_hz`` has most of its orientations
    thinned, and their angles would be computed for nothing."""

    attitude: tuple[float, float, float, float] | None
    rpy_cov: tuple[float, ...] | None
    rows: tuple[int, ...]
    gyro: tuple[float, float, float] | None
    gyro_cov: tuple[float, ...] | None
    accel: tuple[float, float, float] | None = None  # base-frame specific force, when gravity gives the tilt
    yaw_measured: bool = False  # the message's yaw is measured (its variance below orientation_max_sigma^2)

    @property
    def rpy(self) -> tuple[float, float, float] | None:
        """Fixed-axis roll, pitch, yaw of ``attitude`` (None without one)."""
        return None if self.attitude is None else rot.to_rpy(self.attitude)


__all__ = ["ImuInput"]
