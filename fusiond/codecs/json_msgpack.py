"""The JSON / msgpack wire format of the sensors: the Structs of the odometry and IMU kinds (a kind whose
codecs live in its own package, the GPS's and the pose's, declares its Struct there), the decoder of a sensor's
JSON or msgpack key given its kind's Struct, and the encoding of a Struct as either.

For sensors that do not speak ROS 2 CDR: the ROS fields flattened into one object per message,
`stamp` in seconds. The Structs' docstrings are the format's documentation (README points here).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any

import msgspec

from fusiond.samples import ImuSample, OdomSample, Sample

from .wire import Decoder, DecodeError, Payload, check_size

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Cov9 = Annotated[tuple[float, ...], msgspec.Meta(min_length=9, max_length=9)]
Cov36 = Annotated[tuple[float, ...], msgspec.Meta(min_length=36, max_length=36)]


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




def odom_from_message(m: OdomMessage, sensor: str) -> OdomSample:
    return OdomSample(sensor, m.stamp, m.linear, m.angular, m.twist_covariance, m.position, m.orientation)


def imu_from_message(m: ImuMessage, sensor: str) -> ImuSample:
    return ImuSample(
        sensor, m.stamp, m.orientation, m.orientation_covariance, m.angular_velocity,
        m.angular_velocity_covariance, m.linear_acceleration, m.linear_acceleration_covariance,
    )


def structured_decoder(wire_type: type, from_message: Callable[[Any, str], Sample], encoding: str,
                       sensor: str) -> Decoder:
    """The bytes -> sample function of a sensor whose kind's Struct is ``wire_type`` (made a sample by
    ``from_message``) on a `json` or `msgpack` key; it raises only DecodeError. Another encoding is a
    ValueError."""
    if encoding == "json":
        parser: Any = msgspec.json.Decoder(wire_type)
        syntax = "json_invalid"
    elif encoding == "msgpack":
        parser = msgspec.msgpack.Decoder(wire_type)
        syntax = "msgpack_invalid"
    else:
        raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")

    def decode_structured(payload: Payload) -> Sample:
        check_size(payload)
        try:
            message = parser.decode(payload)
        except msgspec.ValidationError as exc:
            raise DecodeError("schema_invalid", str(exc)) from None
        except msgspec.DecodeError as exc:
            raise DecodeError(syntax, str(exc)) from None
        if not math.isfinite(message.stamp):
            raise DecodeError("schema_invalid", f"stamp must be finite, got {message.stamp}")
        return from_message(message, sensor)

    return decode_structured


_json_encoder = msgspec.json.Encoder()
_msgpack_encoder = msgspec.msgpack.Encoder()


def encode_structured(message: msgspec.Struct, encoding: str) -> bytes:
    """``message`` as ``encoding`` (`json` or `msgpack`; another is a ValueError)."""
    if encoding == "json":
        return _json_encoder.encode(message)
    if encoding == "msgpack":
        return _msgpack_encoder.encode(message)
    raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")


__all__ = ["Cov9", "Cov36", "ImuMessage", "OdomMessage", "Quat", "Vec3", "encode_structured", "imu_from_message",
           "odom_from_message", "structured_decoder"]
