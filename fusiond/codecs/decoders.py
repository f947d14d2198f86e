"""Bytes -> samples: the decoder of one sensor's key (`decoder_for`), by its kind's codec
(`kind_codec.KindCodec`, handed in by the caller) and encoding, and the decoders of the published pose and
odometry.

Where the formats meet: a sensor's kind and encoding pick the struct fast path
(`cdr_fast_path`) with rosbags behind it, rosbags alone, or the kind's JSON / msgpack Struct;
rosbags' (de)serialisers are generated here at construction, not on the first message.
Every decoder raises only `DecodeError`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from fusiond.samples import Sample

from .cdr_fast_path import RepeatedLayout
from .json_msgpack import structured_decoder
from .kind_codec import KindCodec
from .rosbags_cdr import deserialize, typestore
from .wire import ODOMETRY, POSE_COV_STAMPED, Decoder, Payload, check_size


def ros_msgtype(codec: KindCodec, msgtype: str | None = None) -> str:
    """The ROS 2 message type of a sensor of the kind of ``codec`` (a sensor's own choice ``msgtype`` when its
    kind reads several)."""
    types = codec.ros_types
    if msgtype is not None:
        if len(types) < 2 or msgtype not in types:  # only a kind reading several types has a choice
            article = "an" if codec.name[0] in "aeiou" else "a"
            raise ValueError(f"msgtype {msgtype!r} is not valid for {article} {codec.name} sensor")
        return msgtype
    return types[0]


def decoder_for(codec: KindCodec, encoding: str, sensor: str, *, msgtype: str | None = None) -> Decoder:
    """The bytes -> sample function of one sensor of the kind of ``codec``; it raises only DecodeError.

    ``msgtype`` selects the ROS type of a kind that reads several (a pose sensor's config key
    `msgtype`; a CDR payload does not say). Without it such a decoder takes whichever of its types
    the payload parses as exactly (the pose types' CDR lengths differ).
    An unknown encoding is a ValueError at construction: that is a configuration bug, not a bad message.
    """
    types, from_ros = codec.ros_types, codec.from_ros
    if len(types) > 1 and msgtype is None and encoding == "ros2-cdr":
        for t in types:
            _warm(codec, t)

        def decode_any_type(payload: Payload) -> Sample:
            check_size(payload)
            for t in types:
                try:
                    return from_ros(typestore().deserialize_cdr(memoryview(payload), t), sensor)
                except Exception:
                    continue
            return from_ros(deserialize(payload, types[0]), sensor)  # raises the DecodeError

        return decode_any_type
    msgtype = ros_msgtype(codec, msgtype)

    if encoding != "ros2-cdr":
        if codec.message_type is None or codec.from_message is None:
            if encoding in ("json", "msgpack"):
                raise ValueError(f"sensor kind {codec.name!r} reads ros2-cdr only, got {encoding!r}")
            raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")
        return structured_decoder(codec.message_type, codec.from_message, encoding, sensor)

    _warm(codec, msgtype)
    repeated = codec.repeated
    if repeated is not None:  # a kind read at the daemon's highest rates (the odometry, the IMU): its hot path
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

    def decode_cdr(payload: Payload) -> Any:
        check_size(payload)
        return from_ros(deserialize(payload, msgtype), sensor)

    return decode_cdr


_warmed: set[str] = set()


def _warm(codec: KindCodec, msgtype: str) -> None:
    """rosbags generates its (de)serialisers on first use (~0.1 s): pay that at startup, not on a message,
    by decoding the CDR the kind's encoder makes of its ``zero`` sample (a kind without them: its first
    message pays instead)."""
    if msgtype in _warmed or codec.encode is None or codec.zero is None:
        return
    typestore().deserialize_cdr(codec.encode(codec.zero, "ros2-cdr", msgtype), msgtype)
    _warmed.add(msgtype)


def decode_pose_cdr(payload: Payload) -> Any:
    """A published pose (geometry_msgs/msg/PoseWithCovarianceStamped) as a rosbags message."""
    check_size(payload)
    return deserialize(payload, POSE_COV_STAMPED)


def decode_odometry_cdr(payload: Payload) -> Any:
    """A published nav_msgs/msg/Odometry as a rosbags message."""
    check_size(payload)
    return deserialize(payload, ODOMETRY)


__all__ = ["cdr_decoder", "decode_odometry_cdr", "decode_pose_cdr", "decoder_for", "ros_msgtype"]
