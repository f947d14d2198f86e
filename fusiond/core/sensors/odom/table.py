"""The odometry's [[sensors]] table (kind = "odom"): config.toml documents every key."""

from __future__ import annotations

from typing import Literal

from ....config_tables import SensorTable, Vec2, Vec6


class OdomSensor(SensorTable, tag="odom"):
    twist_frame: Literal["body", "world"] = "body"
    twist_noise: Vec6 | None = None  # std devs vx vy vz wx wy wz, replace message covariance
    twist_min_sigma: Vec2 = (0.01, 0.01)  # floors: linear m/s, angular rad/s
    twist_max_sigma: Vec2 = (10.0, 10.0)  # above: "not measured" (input zero, default noise)
    twist_unmeasured_sigma: Vec2 = (0.1, 0.1)  # noise of a "not measured" component: m/s, rad/s
    slip_threshold: float = 0.3  # rad/s wheel-vs-gyro yaw rate that flags slip
    # which of vx vy vz wx wy wz the driver measures; false: not used as an input, not slip-checked
    twist_measured: tuple[bool, bool, bool, bool, bool, bool] = (True, True, True, True, True, True)
    # estimate a wheel speed scale (v' = s v); None: on exactly when a gps or absolute pose sensor
    # makes it observable; false: an explicit opt-out
    scale_estimation: bool | None = None
    # estimate the pitch of the wheels' twist in the body (an IMU pitched in its mount beyond extrinsic_rpy);
    # needs an absolute height (GPS altitude, an absolute pose's z) to be observable, and is ignored without one.
    # "auto": in the state, held at the mount as configured until the GPS's vertical error state is found
    # holding more than its model allows (the climb is then the twist's: core/sensors/gps/model.py)
    pitch_estimation: bool | Literal["auto"] = "auto"
    twist_correlation_s: float = 0.5  # the linear twist covariance is a velocity error lasting this long, s
    # m/s^2: a drive that drops to exactly zero faster than a vehicle can stop: the vehicle is taken
    # to coast on, slowing at coast_decel (+- coast_decel * t) until it stops (core/sensors/odom/model.py); 0: off
    coast_decel: float = 0.5
    # the driver fills the pose only (as robot_pose_ekf read it) and leaves the twist zero: the twist is taken from
    # consecutive messages' poses, in the body (core/sensors/odom/pose_twist.py; twist_frame is then not read)
    twist_from_pose: bool = False


__all__ = ["OdomSensor"]
