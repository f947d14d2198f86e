"""ROS 2 CDR through rosbags: the type store, deserialising a payload (naming the type actually
sent when it is another), and building and serialising messages from the store's classes.

rosbags is the codec: its CDR is exactly what ROS 2 and zenoh-bridge-ros2dds put on the wire,
with the 4-byte encapsulation header. The struct fast paths elsewhere defer to it on anything
they do not read exactly as it would, so it stays the authority on errors.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from typing import TYPE_CHECKING, Any, Final

from .wire import IMU, ODOMETRY, POSE_COV_STAMPED, DecodeError, Payload, stamp_to_ros

if TYPE_CHECKING:
    import numpy as np
    from rosbags.typesys.store import Typestore


@cache
def typestore() -> Typestore:
    """The Humble type store (Odometry, Imu and the pose messages have the same wire format in
    every ROS 2 distro), built on first use: importing its type definitions takes ~70 ms, which a
    replay of a bag that carries its own definitions (every ROS 1 bag; ROS 2 bags written with
    them) and the struct fast paths never need. `fusiond.codecs.TYPESTORE` is the same object."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def ros_types() -> dict[str, Any]:
    """Message classes of the type store, by ROS type name (for the rosbags-built encoders)."""
    return typestore().types


# Stamped types a misconfigured key plausibly carries. Only types that start with a
# Header (a NUL-terminated string) are probed: header-less types such as Twist
# accept almost any bytes of the right length and would misname garbage.
_PROBE_TYPES: Final = (
    ODOMETRY, IMU, POSE_COV_STAMPED,
    "geometry_msgs/msg/TwistWithCovarianceStamped", "geometry_msgs/msg/TwistStamped",
    "geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/NavSatFix", "sensor_msgs/msg/MagneticField",
)


def deserialize(payload: Payload, msgtype: str) -> Any:
    """rosbags deserialisation that fails only with DecodeError, naming the type actually sent if it can."""
    try:
        return typestore().deserialize_cdr(memoryview(payload), msgtype)
    except Exception as exc:  # rosbags raises SerdeError, IndexError, struct.error, ... on garbage
        for other in _PROBE_TYPES:
            if other == msgtype:
                continue
            try:
                typestore().deserialize_cdr(memoryview(payload), other)
            except Exception:
                continue
            raise DecodeError("wrong_type", f"payload is a {other}, expected {msgtype}") from None
        raise DecodeError("cdr_invalid", f"not a valid {msgtype}: {exc}") from exc


def serialize(msg: Any, msgtype: str) -> bytes:
    """A rosbags message as little-endian ROS 2 CDR."""
    return bytes(typestore().serialize_cdr(msg, msgtype, little_endian=True))


def ros_time(stamp: float) -> Any:
    """A builtin_interfaces/msg/Time of float seconds (see `stamp_to_ros`)."""
    sec, nanosec = stamp_to_ros(stamp)
    return ros_types()["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


def ros_header(stamp: float, frame_id: str) -> Any:
    """A std_msgs/msg/Header."""
    return ros_types()["std_msgs/msg/Header"](stamp=ros_time(stamp), frame_id=frame_id)


def float_array(values: Sequence[float] | np.ndarray, n: int) -> np.ndarray:
    """``values`` as the flat float64 array of ``n`` elements a rosbags array field holds
    (a covariance); ValueError for any other length."""
    import numpy as np  # here: only an encoder makes rosbags' arrays, and a bag is read without numpy

    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size != n:
        raise ValueError(f"covariance must have {n} elements, got {arr.size}")
    return arr
