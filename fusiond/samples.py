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


class GpsSample(msgspec.Struct, gc=False):
    """sensor_msgs/NavSatFix: WGS84 position; the core converts it to ENU at the datum."""

    sensor: str
    stamp: float
    latitude: float  # degrees
    longitude: float  # degrees
    altitude: float  # m above the ellipsoid
    status: int = 0  # NavSatStatus.status: -1 no fix, 0 fix, 1 SBAS, 2 GBAS (RTK)
    position_covariance: tuple[float, ...] = (0.0,) * 9  # ENU, row-major, m^2
    covariance_type: int = 0  # 0 unknown, 1 approximated, 2 diagonal known, 3 known


Sample = msgspec.Struct
"""Any kind's sample: a msgspec Struct whose first fields are ``sensor`` and ``stamp``. The odometry's,
IMU's and GPS's are here; another kind declares its own in its package (the pose's:
``fusiond.core.sensors.pose.sample``)."""

__all__ = ["GpsSample", "ImuSample", "OdomSample", "Sample"]
