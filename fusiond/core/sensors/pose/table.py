"""The pose sensor's [[sensors]] table (kind = "pose") and the ROS types it reads: config.toml
documents every key."""

from __future__ import annotations

import math
from typing import Literal

from ....config_tables import SensorTable, Vec2, Vec3


POSE_MSGTYPES = (
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "geometry_msgs/msg/PoseStamped",
    "nav_msgs/msg/Odometry",
)


class PoseSensor(SensorTable, tag="pose"):
    """An absolute (or, with differential, relative) pose: visual odometry, motion capture, ..."""

    timeout_s: float = 1.0
    mahalanobis_threshold: float = math.inf
    msgtype: Literal[
        "geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs/msg/PoseStamped", "nav_msgs/msg/Odometry"
    ] = "geometry_msgs/msg/PoseWithCovarianceStamped"
    differential: bool = False  # fuse deltas between consecutive poses (drifting origin) instead
    position_noise: Vec3 | None = None  # std devs x y z, m; replaces the message covariance
    orientation_noise: Vec3 | None = None  # std devs roll pitch yaw, rad
    position_min_sigma: float = 0.001  # floor, m
    orientation_min_sigma: float = 0.001  # floor, rad
    max_sigma: Vec2 = (100.0, 3.0)  # larger means "not measured": m, rad
    unknown_sigma: Vec2 = (0.1, 0.05)  # for a message without covariance (PoseStamped): m, rad
    extrinsic_xyz: Vec3 = (0.0, 0.0, 0.0)  # sensor (marker, camera) origin in base_link, m
    # sensor (marker, camera) orientation in base_link: fixed-axis roll, pitch, yaw, rad, as URDF
    extrinsic_rpy: Vec3 = (0.0, 0.0, 0.0)


__all__ = ["POSE_MSGTYPES", "PoseSensor"]
