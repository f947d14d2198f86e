"""The pose kind's wire formats (``CODEC``, a ``fusiond.codecs.KindCodec``): its ROS messages
(PoseWithCovarianceStamped, PoseStamped, Odometry's pose) read from a bag or from ROS 2 CDR through
rosbags, its JSON / msgpack Struct (``PoseMessage``), and its encoder (``encode_pose_sample``).

Imported only when a decoder or encoder of a pose sensor is first asked for (``PoseKind.codec``), so
that the fusion core loads without the codecs and rosbags; rosbags' generic path reads a pose (a pose
sensor runs at 1-100 Hz).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import msgspec

from ....codecs.json_msgpack import Cov36, Quat, Vec3, encode_structured
from ....codecs.kind_codec import KindCodec
from ....codecs.output_encoders import encode_odometry_cdr
from ....codecs.rosbags_cdr import float_array, ros_header, ros_types, serialize
from ....codecs.wire import ODOMETRY, POSE_COV_STAMPED, POSE_STAMPED
from .sample import PoseSample
from .table import POSE_MSGTYPES


class PoseMessage(msgspec.Struct, kw_only=True):
    """A pose on a `json` or `msgpack` key: `stamp`, `position` [x, y, z] m, `orientation`
    [x, y, z, w], optional `covariance` (36 numbers, row-major over x y z roll pitch yaw)."""

    stamp: float
    position: Vec3
    orientation: Quat
    covariance: Cov36 | None = None


def pose_from_ros(msg: Any, sensor: str) -> PoseSample:
    """PoseStamped, PoseWithCovarianceStamped or the pose of an Odometry (a rosbags message of a ROS 1 or
    ROS 2 store) as a PoseSample."""
    stamp = msg.header.stamp
    pose = msg.pose
    cov: tuple[float, ...] = ()
    if hasattr(pose, "covariance"):  # PoseWithCovariance (also inside Odometry)
        cov = tuple(pose.covariance.tolist())
        pose = pose.pose
    p, q = pose.position, pose.orientation
    return PoseSample(sensor, stamp.sec + stamp.nanosec * 1e-9, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), cov)


def pose_from_message(m: PoseMessage, sensor: str) -> PoseSample:
    """A decoded ``PoseMessage`` as a PoseSample (no covariance: ``()``)."""
    return PoseSample(sensor, m.stamp, m.position, m.orientation, m.covariance or ())


def _pose(position: Sequence[float], quat_xyzw: Sequence[float]) -> Any:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    T = ros_types()
    return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                      orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))


def encode_pose_sample(sample: PoseSample, encoding: str, msgtype: str = POSE_COV_STAMPED) -> bytes:
    """What a pose publisher puts on the key, as ``msgtype`` (CDR; frame map, child base_link)."""
    if encoding == "ros2-cdr":
        T = ros_types()
        header = ros_header(sample.stamp, "map")
        pose = _pose(sample.position, sample.orientation)
        cov = float_array(sample.covariance or (0.0,) * 36, 36)
        if msgtype == POSE_STAMPED:
            return serialize(T[POSE_STAMPED](header=header, pose=pose), POSE_STAMPED)
        if msgtype == POSE_COV_STAMPED:
            msg = T[POSE_COV_STAMPED](header=header, pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov))
            return serialize(msg, POSE_COV_STAMPED)
        if msgtype == ODOMETRY:
            return encode_odometry_cdr(sample.stamp, "map", "base_link", sample.position, sample.orientation, cov,
                                       (0.0,) * 3, (0.0,) * 3, (0.0,) * 36)
        raise ValueError(f"msgtype {msgtype!r} is not a pose type, expected one of {POSE_MSGTYPES}")
    return encode_structured(
        PoseMessage(stamp=sample.stamp, position=sample.position, orientation=sample.orientation,
                    covariance=sample.covariance or None),
        encoding,
    )


CODEC = KindCodec("pose", PoseSample, POSE_MSGTYPES, pose_from_ros, encode_pose_sample, PoseMessage,
                  pose_from_message, None, PoseSample("", 0.0, (0.0,) * 3, (0.0, 0.0, 0.0, 1.0)))

__all__ = ["CODEC", "PoseMessage", "encode_pose_sample", "pose_from_message", "pose_from_ros"]
