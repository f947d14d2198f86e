"""The odometry kind's wire formats (``CODEC``, a ``fusiond.codecs.KindCodec``): nav_msgs/Odometry read from
a bag or from ROS 2 CDR, its JSON / msgpack Struct (``OdomMessage``), its encoder (``encode_odom_sample``)
and its struct fast path (``OdomFields``).

Imported only when a decoder or encoder of an odometry sensor is first asked for (``OdomKind.codec``), so
that the fusion core loads without the codecs and rosbags. Wheel odometry runs at up to 1 kHz and drives
the prediction: its float64 block is read with struct (``fusiond.codecs.cdr_fast_path`` walks to it, and
``bag_readers`` in a bag's raw messages), rosbags behind it for anything the fast path does not accept.
"""

from __future__ import annotations

import struct
from typing import Any, Final

import msgspec

from ....codecs.cdr_fast_path import Covariances
from ....codecs.json_msgpack import Cov36, Quat, Vec3, encode_structured
from ....codecs.kind_codec import KindCodec
from ....codecs.output_encoders import encode_odometry_cdr
from ....codecs.wire import ODOMETRY, Payload
from .sample import OdomSample


class OdomMessage(msgspec.Struct, kw_only=True):
    """Wheel odometry on a `json` or `msgpack` key: one object per message.

    - `stamp`: seconds (float), the measurement time, as header.stamp in ROS.
    - `linear`, `angular`: twist [x, y, z] in m/s and rad/s, in the sensor's `twist_frame`.
    - `twist_covariance`: 36 numbers, row-major 6x6 over (vx vy vz wx wy wz).
    - `position` [x, y, z] (default [0, 0, 0]) and `orientation` [x, y, z, w]
      (default [0, 0, 0, 1]): optional, used for plots only.

    Example: `{"stamp": 12.5, "linear": [0.4, 0, 0], "angular": [0, 0, 0.1],
    "twist_covariance": [0.001, 0, ..., 0.01]}`. Unknown fields are ignored;
    wrong lengths or types reject the message.
    """

    stamp: float
    linear: Vec3
    angular: Vec3
    twist_covariance: Cov36
    position: Vec3 = (0.0, 0.0, 0.0)
    orientation: Quat = (0.0, 0.0, 0.0, 1.0)


def odom_from_ros(msg: Any, sensor: str) -> OdomSample:
    """A rosbags nav_msgs/msg/Odometry (ROS 1 or ROS 2 typestore: the fields used are named the same in every
    store) as an OdomSample."""
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


def odom_from_message(m: OdomMessage, sensor: str) -> OdomSample:
    """A decoded ``OdomMessage`` as an OdomSample."""
    return OdomSample(sensor, m.stamp, m.linear, m.angular, m.twist_covariance, m.position, m.orientation)


def encode_odom_sample(sample: OdomSample, encoding: str, msgtype: str = ODOMETRY) -> bytes:
    """What a wheel-odometry publisher puts on the key (CDR: frames odom -> base_link, zero pose covariance;
    packed with struct, the same bytes rosbags would make)."""
    if encoding == "ros2-cdr":
        return encode_odometry_cdr(
            sample.stamp, "odom", "base_link", sample.position, sample.orientation, (0.0,) * 36,
            sample.linear, sample.angular, sample.twist_covariance,
        )
    return encode_structured(
        OdomMessage(
            stamp=sample.stamp, linear=sample.linear, angular=sample.angular,
            twist_covariance=sample.twist_covariance, position=sample.position, orientation=sample.orientation,
        ),
        encoding,
    )


# the values of the block that move from message to message, the covariances between them skipped
_ODOM_MOVING: Final = struct.Struct("<3d4d288x3d3d288x").unpack_from  # position, orientation, linear, angular


class OdomFields:
    """An Odometry float64 block as an OdomSample: pose position, orientation (its covariance is not
    read), twist linear, angular and covariance; the twist covariance read once while it repeats
    (``Covariances``): 13 values unpacked a message instead of 85. One reader per stream."""

    __slots__ = ("_covariances",)
    size: Final = 85 * 8  # bytes: pose position, orientation, covariance (0:43), twist (43:85)

    def __init__(self) -> None:
        self._covariances = Covariances((392,), 36)

    def sample(self, buf: Payload, at: int, stamp: float, sensor: str) -> OdomSample:
        (tc,) = self._covariances.read(buf, at)
        v = _ODOM_MOVING(buf, at)
        return OdomSample(sensor, stamp, v[7:10], v[10:13], tc, v[0:3], v[3:7])


# Odometry runs at up to 1 kHz: the struct fast path reads it (``repeated``: it has a child_frame_id).
CODEC: Final = KindCodec("odom", OdomSample, (ODOMETRY,), odom_from_ros, encode_odom_sample, OdomMessage,
                         odom_from_message, (True, OdomFields), OdomSample("", 0.0, (0.0,) * 3, (0.0,) * 3, (0.0,) * 36))

__all__ = ["CODEC", "OdomFields", "OdomMessage", "encode_odom_sample", "odom_from_message", "odom_from_ros"]
