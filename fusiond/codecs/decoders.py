"""Bytes -> samples: the decoder of one sensor's key (`make_decoder`), by kind and encoding,
and the decoders of the published pose and odometry.

Where the formats meet: a sensor's kind and encoding pick the struct fast path
(`cdr_fast_path`) with rosbags behind it, rosbags alone, or the JSON / msgpack Structs;
rosbags' (de)serialisers are generated here at construction, not on the first message.
Every decoder raises only `DecodeError`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Final

from fusiond.samples import GpsSample, ImuSample, OdomSample, PoseSample, Sample

from .cdr_fast_path import ImuFields, OdomFields, RepeatedLayout
from .from_ros import gps_from_ros, imu_from_ros, odom_from_ros, pose_from_ros
from .json_msgpack import structured_decoder
from .rosbags_cdr import deserialize, typestore
from .sample_encoders import encode_gps_sample, encode_imu_sample, encode_odom_sample, encode_pose_sample
from .wire import IMU, NAVSATFIX, ODOMETRY, POSE_COV_STAMPED, POSE_TYPES, Decoder, Payload, check_size

# kind -> (its ROS types, the first the default; rosbags message -> sample). Which of them a sensor reads is
# its kind descriptor's to say (core/sensors/kind.py); these are the codecs of the built-in kinds.
_KINDS: Final[dict[str, tuple[tuple[str, ...], Callable[[Any, str], Sample]]]] = {
    "odom": ((ODOMETRY,), odom_from_ros),
    "imu": ((IMU,), imu_from_ros),
    "gps": ((NAVSATFIX,), gps_from_ros),
    "pose": (POSE_TYPES, pose_from_ros),
}
# GPS and pose sensors run at 1-100 Hz: rosbags' generic path is fast enough for them.
_REPEATED: Final = {  # kind -> (child frame id?, the block's reader) of `RepeatedLayout`
    "odom": (True, OdomFields),
    "imu": (False, ImuFields),
}


def ros_msgtype(kind: str, msgtype: str | None = None) -> str:
    """The ROS 2 message type of a sensor kind (a pose sensor's own `msgtype` when given)."""
    if kind not in _KINDS:
        raise ValueError(f"unknown sensor kind {kind!r}, expected one of {sorted(_KINDS)}")
    types = _KINDS[kind][0]
    if msgtype is not None:
        if len(types) < 2 or msgtype not in types:  # only a kind reading several types has a choice
            article = "an" if kind[0] in "aeiou" else "a"
            raise ValueError(f"msgtype {msgtype!r} is not valid for {article} {kind} sensor")
        return msgtype
    return types[0]


def ros_converter(kind: str) -> Callable[[Any, str], Sample]:
    """rosbags message -> sample for a sensor kind (bag replay)."""
    return _KINDS[kind][1]


def make_decoder(kind: str, encoding: str, sensor: str, *, msgtype: str | None = None) -> Decoder:
    """The bytes -> sample function of one sensor; it raises only DecodeError.

    ``msgtype`` selects a pose sensor's ROS type (its config key `msgtype`; a CDR
    payload does not say). Without it a pose decoder takes whichever of the three
    pose types the payload parses as exactly (their CDR lengths differ).
    Unknown kind or encoding is a ValueError at construction: that is a
    configuration bug, not a bad message.
    """
    if kind not in _KINDS:
        raise ValueError(f"unknown sensor kind {kind!r}, expected one of {sorted(_KINDS)}")
    types, from_ros = _KINDS[kind]
    if len(types) > 1 and msgtype is None and encoding == "ros2-cdr":
        for t in types:
            _warm(t)

        def decode_any_type(payload: Payload) -> Sample:
            check_size(payload)
            for t in types:
                try:
                    return from_ros(typestore().deserialize_cdr(memoryview(payload), t), sensor)
                except Exception:
                    continue
            return from_ros(deserialize(payload, types[0]), sensor)  # raises the DecodeError

        return decode_any_type
    msgtype = ros_msgtype(kind, msgtype)

    if encoding != "ros2-cdr":
        return structured_decoder(kind, encoding, sensor)

    _warm(msgtype)
    repeated = _REPEATED.get(kind)
    if repeated is not None:  # odometry and IMU: the hot path of the daemon
        has_child_frame, fields = repeated
        layout = RepeatedLayout(has_child_frame, fields())
        read = layout.sample

        def decode_repeated(payload: Payload) -> Sample:
            if len(payload) != layout.length:  # the remembered length passed the size checks
                check_size(payload)
            sample = read(payload, sensor)
            if sample is not None:
                return sample
            return from_ros(deserialize(payload, msgtype), sensor)

        return decode_repeated

    return cdr_decoder(msgtype, from_ros, sensor)


def cdr_decoder(msgtype: str, from_ros: Callable[[Any, str], Any], sensor: str) -> Decoder:
    """ROS 2 CDR of ``msgtype`` (any type rosbags' typestore knows) -> sample, through rosbags and
    ``from_ros``: the decoder of a kind without a fast path of its own; raises only DecodeError."""
    _warm(msgtype)

    def decode_cdr(payload: Payload) -> Any:
        check_size(payload)
        return from_ros(deserialize(payload, msgtype), sensor)

    return decode_cdr


_warmed: set[str] = set()


def _warm(msgtype: str) -> None:
    """rosbags generates its (de)serialisers on first use (~0.1 s): pay that at startup, not on a message."""
    if msgtype in _warmed:
        return
    zero = OdomSample("", 0.0, (0.0,) * 3, (0.0,) * 3, (0.0,) * 36)
    if msgtype == ODOMETRY:
        raw = encode_odom_sample(zero, "ros2-cdr")
    elif msgtype == IMU:
        raw = encode_imu_sample(ImuSample("", 0.0, (0.0, 0.0, 0.0, 1.0), (0.0,) * 9, (0.0,) * 3, (0.0,) * 9),
                                "ros2-cdr")
    elif msgtype == NAVSATFIX:
        raw = encode_gps_sample(GpsSample("", 0.0, 0.0, 0.0, 0.0), "ros2-cdr")
    elif msgtype in POSE_TYPES:
        raw = encode_pose_sample(PoseSample("", 0.0, (0.0,) * 3, (0.0, 0.0, 0.0, 1.0)), "ros2-cdr", msgtype)
    else:  # a type without a sample encoder here (another kind's): its first message pays instead
        return
    typestore().deserialize_cdr(raw, msgtype)
    _warmed.add(msgtype)


def decode_pose_cdr(payload: Payload) -> Any:
    """A published pose (geometry_msgs/msg/PoseWithCovarianceStamped) as a rosbags message."""
    check_size(payload)
    return deserialize(payload, POSE_COV_STAMPED)


def decode_odometry_cdr(payload: Payload) -> Any:
    """A published nav_msgs/msg/Odometry as a rosbags message."""
    check_size(payload)
    return deserialize(payload, ODOMETRY)
