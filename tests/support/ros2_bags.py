"""Samples written as a ROS 2 bag (sqlite3) through the real codec, for the tests that replay a bag."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from rosbags.rosbag2 import Writer

from fusiond.codecs import typestore
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample

TYPES = {OdomSample: "nav_msgs/msg/Odometry", ImuSample: "sensor_msgs/msg/Imu"}
TOPICS = {"wheel": "/odom", "imu": "/imu"}


def write_ros2_bag(path: Path, samples: Iterable[object], topics: dict[str, str] | None = None,
                   types: dict[type, str] | None = None) -> Path:
    """``samples`` (in stamp order) as the ROS 2 bag ``path``: each sensor's on ``topics[sensor]``, its
    message type ``types[type(sample)]`` (defaults: the odometry and the IMU on /odom and /imu)."""
    topics, types = topics or TOPICS, types or TYPES
    store = typestore()
    with Writer(path, version=9) as writer:
        conns = {}
        for s in samples:
            msgtype = types[type(s)]
            if s.sensor not in conns:
                conns[s.sensor] = writer.add_connection(topics[s.sensor], msgtype, typestore=store)
            writer.write(conns[s.sensor], int(s.stamp * 1e9), encode_sample(s, "ros2-cdr", msgtype=msgtype))
    return path
