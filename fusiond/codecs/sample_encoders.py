"""Samples -> bytes as their sensor would publish them, in any of the three encodings.

The inverse of the decoders: `fusiond play` publishes bags with it, the benchmarks and the
tests build their inputs with it, and the decoders warm rosbags' serialisers on its output.
ROS 2 CDR is built and serialised by rosbags, except Odometry: `encode_odometry_cdr` packs the
same bytes with struct. JSON and msgpack are the Structs of `json_msgpack`. A sample of a kind whose
codecs live in its own package (the GPS's, the pose's) is encoded by that kind's codec (`encode_sample`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fusiond.samples import ImuSample, OdomSample, Sample

from .json_msgpack import ImuMessage, OdomMessage, encode_structured
from .kind_codec import codec_of
from .output_encoders import encode_odometry_cdr
from .rosbags_cdr import float_array, ros_header, ros_types, serialize
from .wire import IMU


def _vec3(v: Sequence[float]) -> Any:
    return ros_types()["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def encode_odom_sample(sample: OdomSample, encoding: str) -> bytes:
    """What a wheel-odometry publisher puts on the key (CDR: frames odom -> base_link, zero pose covariance)."""
    if encoding == "ros2-cdr":
        return encode_odometry_cdr(
            sample.stamp, "odom", "base_link", sample.position, sample.orientation, np.zeros(36),
            sample.linear, sample.angular, sample.twist_covariance,
        )
    return encode_structured(
        OdomMessage(
            stamp=sample.stamp, linear=sample.linear, angular=sample.angular,
            twist_covariance=sample.twist_covariance, position=sample.position, orientation=sample.orientation,
        ),
        encoding,
    )


def encode_imu_sample(sample: ImuSample, encoding: str) -> bytes:
    """What an IMU publisher puts on the key (CDR: frame base_link)."""
    if encoding == "ros2-cdr":
        q = sample.orientation
        T = ros_types()
        msg = T[IMU](
            header=ros_header(sample.stamp, "base_link"),
            orientation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
            orientation_covariance=float_array(sample.orientation_covariance, 9),
            angular_velocity=_vec3(sample.angular_velocity),
            angular_velocity_covariance=float_array(sample.angular_velocity_covariance, 9),
            linear_acceleration=_vec3(sample.linear_acceleration),
            linear_acceleration_covariance=float_array(sample.linear_acceleration_covariance, 9),
        )
        return serialize(msg, IMU)
    return encode_structured(
        ImuMessage(
            stamp=sample.stamp, orientation=sample.orientation,
            orientation_covariance=sample.orientation_covariance,
            angular_velocity=sample.angular_velocity,
            angular_velocity_covariance=sample.angular_velocity_covariance,
            linear_acceleration=sample.linear_acceleration,
            linear_acceleration_covariance=sample.linear_acceleration_covariance,
        ),
        encoding,
    )


def encode_sample(sample: Sample, encoding: str, msgtype: str | None = None) -> bytes:
    """Any sample as its sensor would publish it, by its kind's codec (``msgtype``: the ROS type of a kind
    that reads several, a pose sensor's; its kind's first by default)."""
    codec = codec_of(sample)
    if codec.encode is None:
        raise ValueError(f"sensor kind {codec.name!r} has no encoder")
    return codec.encode(sample, encoding, msgtype or codec.ros_types[0])


__all__ = ["encode_imu_sample", "encode_odom_sample", "encode_sample"]
