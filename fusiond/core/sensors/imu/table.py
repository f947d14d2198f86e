"""The IMU's [[sensors]] table (kind = "imu"): config.toml documents every key."""

from __future__ import annotations

import math
from typing import Literal

from ....config_tables import SensorTable, Vec3


class ImuSensor(SensorTable, tag="imu"):
    mahalanobis_threshold: float = math.inf  # gate on sqrt(NIS); inf disables
    adaptive: bool = False  # scale R from the innovation window
    adaptive_window: int = 50
    orientation: Literal["absolute", "relative", "roll_pitch", "off"] = "roll_pitch"
    angular_velocity: bool = False
    extrinsic_rpy: Vec3 = (0.0, 0.0, 0.0)
    orientation_noise: Vec3 | None = None  # std devs roll pitch yaw, rad
    gyro_noise: float | None = None  # std dev rad/s
    orientation_min_sigma: float = 0.001  # floor, rad
    orientation_max_sigma: float = 3.0  # above: "not measured"
    gyro_min_sigma: float = 0.0005  # floor, rad/s
    # cap, rad/s: a stated gyro noise above it is a driver's "unknown" (1e6), taken as this; used literally it turns
    # the attitude's covariance (and, at speed, the position's) into kilometres while the estimate itself is fine
    gyro_max_sigma: float = 0.2
    # highest rate (Hz) at which the orientation is fused (the gyro is taken at every sample); 0: every sample
    orientation_rate_hz: float = 100.0
    # orientation = "roll_pitch": after a silence of the IMU longer than filter.gap_s (a logging gap), turn
    # the heading by what the IMU's own yaw turned across it, less the yaw's measured drift, weighed against
    # what the (rescaled) wheels turned meanwhile (core/sensors/imu/gap_turn.py)
    yaw_across_gaps: bool = True
    gyro_scale_estimation: bool = False  # estimate the yaw-rate scale of the gyro (needs angular_velocity)
    tilt_from_gravity: bool = True  # no roll/pitch from the IMU's orientation: take them from the accelerometer
    gravity_tilt_noise: float = 0.05  # std dev (rad) of that roll/pitch at low dynamics
    # absolute yaw, as navsat_transform: yaw in ENU = reading + yaw_offset + magnetic_declination (rad)
    yaw_offset: float = 0.0  # e.g. pi/2 for an IMU that reads 0 facing north
    magnetic_declination: float = 0.0  # for a magnetometer's yaw (magnetic north), rad, west-positive (minus NOAA's)
    # beside a gps or absolute pose: what is left of the offset is estimated, with this prior (rad)
    # and random walk (rad/sqrt(s)); yaw_offset_sigma = 0 takes the corrected yaw as the heading
    yaw_offset_sigma: float = 0.5
    yaw_offset_walk: float = 0.05

    # What ``orientation`` means, asked by name so that no module outside this package reads its strings.
    @property
    def fuses_orientation(self) -> bool:
        """Is some part of the message's orientation fused (roll/pitch, and yaw in the yaw modes)?"""
        return self.orientation != "off"

    @property
    def fuses_yaw(self) -> bool:
        """Does the IMU observe the heading itself (an absolute or a relative yaw)?"""
        return self.orientation in ("absolute", "relative")

    @property
    def absolute_yaw(self) -> bool:
        """Is its yaw absolute (REP-103 ENU, a heading reference beside a GPS)?"""
        return self.orientation == "absolute"

    @property
    def relative_yaw(self) -> bool:
        """Is its yaw relative (its changes fused, its origin not)?"""
        return self.orientation == "relative"

    @property
    def roll_pitch_only(self) -> bool:
        """Are roll and pitch its only fused orientation (its yaw left to the gyro and the wheels)?"""
        return self.orientation == "roll_pitch"

    @property
    def orientation_rows(self) -> tuple[int, ...]:
        """The base rows (0 roll, 1 pitch, 2 yaw) its orientation updates fuse."""
        return (0, 1, 2) if self.fuses_yaw else (0, 1) if self.fuses_orientation else ()

    @property
    def tilt_from_imu(self) -> bool:
        """Does the IMU give the filter roll and pitch (from its orientation, or from gravity)?"""
        return self.fuses_orientation or self.tilt_from_gravity


__all__ = ["ImuSensor"]
