"""The IMU kind's wire formats (``CODEC``, a ``fusiond.codecs.KindCodec``): sensor_msgs/Imu read from a bag
or from ROS 2 CDR, its JSON / msgpack Struct (``ImuMessage``), its encoder (``encode_imu_sample``) and its
struct fast path (``ImuFields``).

Imported only when a decoder or encoder of an IMU is first asked for (``ImuKind.codec``), so that the
fusion core loads without the codecs and rosbags. An IMU runs at up to 1 kHz: its float64 block is read
with struct (``fusiond.codecs.cdr_fast_path`` walks to it, and ``bag_readers`` in a bag's raw messages),
rosbags behind it for anything the fast path does not accept.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any, Final

import msgspec

from ....codecs.cdr_fast_path import Covariances
from ....codecs.json_msgpack import Cov9, Quat, Vec3, encode_structured
from ....codecs.kind_codec import KindCodec
from ....codecs.rosbags_cdr import float_array, ros_header, ros_types, serialize
from ....codecs.wire import IMU, Payload
from .sample import ImuSample


class ImuMessage(msgspec.Struct, kw_only=True):
    """IMU on a `json` or `msgpack` key: one object per message, in the IMU's own frame.

    - `stamp`: seconds (float), the measurement time.
    - `orientation`: quaternion [x, y, z, w]; `orientation_covariance`: 9 numbers,
      row-major 3x3 over roll, pitch, yaw (rad^2); its first element -1 means
      "no orientation", as in sensor_msgs/Imu.
    - `angular_velocity`: [x, y, z] rad/s; `angular_velocity_covariance`: 9 numbers.
    - `linear_acceleration` [x, y, z] m/s^2 and `linear_acceleration_covariance`
      (9): optional, default zeros.

    Unknown fields are ignored; wrong lengths or types reject the message.
    """

    stamp: float
    orientation: Quat
    orientation_covariance: Cov9
    angular_velocity: Vec3
    angular_velocity_covariance: Cov9
    linear_acceleration: Vec3 = (0.0, 0.0, 0.0)
    linear_acceleration_covariance: Cov9 = (0.0,) * 9


def imu_from_ros(msg: Any, sensor: str) -> ImuSample:
    """A rosbags sensor_msgs/msg/Imu (ROS 1 or ROS 2 typestore: the fields used are named the same in every
    store) as an ImuSample."""
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


def imu_from_message(m: ImuMessage, sensor: str) -> ImuSample:
    """A decoded ``ImuMessage`` as an ImuSample."""
    return ImuSample(
        sensor, m.stamp, m.orientation, m.orientation_covariance, m.angular_velocity,
        m.angular_velocity_covariance, m.linear_acceleration, m.linear_acceleration_covariance,
    )


def _vec3(v: Sequence[float]) -> Any:
    return ros_types()["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def encode_imu_sample(sample: ImuSample, encoding: str, msgtype: str = IMU) -> bytes:
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


# the values of the block that move from message to message, the covariances between them skipped
_IMU_MOVING: Final = struct.Struct("<4d72x3d72x3d72x").unpack_from  # orientation, angular velocity, acceleration


class ImuFields:
    """An Imu float64 block (at offset ``at`` of a payload) as an ImuSample: orientation and its covariance,
    angular velocity and its, linear acceleration and its; the three covariances read once while they
    repeat (``Covariances``), so only ten of the 37 values are unpacked a message. One reader per stream."""

    __slots__ = ("_covariances",)
    size: Final = 37 * 8  # bytes: 37 float64s

    def __init__(self) -> None:
        self._covariances = Covariances((32, 128, 224), 9)

    def sample(self, buf: Payload, at: int, stamp: float, sensor: str) -> ImuSample:
        oc, gc, ac = self._covariances.read(buf, at)
        v = _IMU_MOVING(buf, at)
        return ImuSample(sensor, stamp, v[0:4], oc, v[4:7], gc, v[7:10], ac)


# An IMU runs at up to 1 kHz: the struct fast path reads it (``repeated``: no child_frame_id).
CODEC: Final = KindCodec("imu", ImuSample, (IMU,), imu_from_ros, encode_imu_sample, ImuMessage, imu_from_message,
                         (False, ImuFields), ImuSample("", 0.0, (0.0, 0.0, 0.0, 1.0), (0.0,) * 9, (0.0,) * 3, (0.0,) * 9))

__all__ = ["CODEC", "ImuFields", "ImuMessage", "encode_imu_sample", "imu_from_message", "imu_from_ros"]
