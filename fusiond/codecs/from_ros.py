"""rosbags messages -> fusiond samples: Odometry and Imu (the GPS and pose kinds convert their own
messages, in their packages).

Separate from the CDR decoding because a message may come from elsewhere than a ROS 2
payload: a bag replay hands over rosbags messages of a ROS 1 or ROS 2 type store, and
these read both (the fields they use are named the same in every store).
"""

from __future__ import annotations

from typing import Any

from fusiond.samples import ImuSample, OdomSample


def odom_from_ros(msg: Any, sensor: str) -> OdomSample:
    """A rosbags nav_msgs/msg/Odometry (ROS 1 or ROS 2 typestore) as an OdomSample."""
    stamp = msg.header.stamp
    pose = msg.pose.pose
    twist = msg.twist.twist
    p, q, v, w = pose.position, pose.orientation, twist.linear, twist.angular
    return OdomSample(
        sensor,
        stamp.sec + stamp.nanosec * 1e-9,
        (v.x, v.y, v.z),
        (w.x, w.y, w.z),
        tuple(msg.twist.covariance.tolist()),
        (p.x, p.y, p.z),
        (q.x, q.y, q.z, q.w),
    )


def imu_from_ros(msg: Any, sensor: str) -> ImuSample:
    """A rosbags sensor_msgs/msg/Imu (ROS 1 or ROS 2 typestore) as an ImuSample."""
    stamp = msg.header.stamp
    q, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
    return ImuSample(
        sensor,
        stamp.sec + stamp.nanosec * 1e-9,
        (q.x, q.y, q.z, q.w),
        tuple(msg.orientation_covariance.tolist()),
        (w.x, w.y, w.z),
        tuple(msg.angular_velocity_covariance.tolist()),
        (a.x, a.y, a.z),
        tuple(msg.linear_acceleration_covariance.tolist()),
    )



__all__ = ["imu_from_ros", "odom_from_ros"]
