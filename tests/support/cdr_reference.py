"""Reference CDR encoders through rosbags: the tests compare the daemon's struct encoders against these.

Test-only, so they live here rather than in fusiond.codecs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fusiond.codecs import ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE, TYPESTORE, stamp_to_ros

_T = TYPESTORE.types


def _cov(values: Sequence[float] | np.ndarray, n: int) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    assert arr.size == n
    return arr


def _header(stamp: float, frame_id: str) -> Any:
    sec, nanosec = stamp_to_ros(stamp)
    return _T["std_msgs/msg/Header"](stamp=_T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec),
                                     frame_id=frame_id)


def _pose(position: Sequence[float], q: Sequence[float]) -> Any:
    return _T["geometry_msgs/msg/Pose"](
        position=_T["geometry_msgs/msg/Point"](x=float(position[0]), y=float(position[1]), z=float(position[2])),
        orientation=_T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])))


def _vec3(v: Sequence[float]) -> Any:
    return _T["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _serialize(msg: Any, msgtype: str) -> bytes:
    return bytes(TYPESTORE.serialize_cdr(msg, msgtype, little_endian=True))


def encode_pose_cdr_rosbags(
    stamp: float,
    frame_id: str,
    position: Sequence[float],
    quat_xyzw: Sequence[float],
    cov36: Sequence[float] | np.ndarray,
) -> bytes:
    """Reference implementation of `encode_pose_cdr` through rosbags (tests)."""
    msg = _T[POSE_COV_STAMPED](
        header=_header(stamp, frame_id),
        pose=_T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(position, quat_xyzw), covariance=_cov(cov36, 36)),
    )
    return _serialize(msg, POSE_COV_STAMPED)


def encode_odometry_cdr_rosbags(
    stamp: float,
    frame_id: str,
    child_frame_id: str,
    position: Sequence[float],
    quat_xyzw: Sequence[float],
    pose_cov36: Sequence[float] | np.ndarray,
    linear: Sequence[float],
    angular: Sequence[float],
    twist_cov36: Sequence[float] | np.ndarray,
) -> bytes:
    """Reference implementation of `encode_odometry_cdr` through rosbags (tests)."""
    msg = _T[ODOMETRY](
        header=_header(stamp, frame_id),
        child_frame_id=child_frame_id,
        pose=_T["geometry_msgs/msg/PoseWithCovariance"](pose=_pose(position, quat_xyzw), covariance=_cov(pose_cov36, 36)),
        twist=_T["geometry_msgs/msg/TwistWithCovariance"](
            twist=_T["geometry_msgs/msg/Twist"](linear=_vec3(linear), angular=_vec3(angular)), covariance=_cov(twist_cov36, 36),
        ),
    )
    return _serialize(msg, ODOMETRY)


def encode_tf_cdr_rosbags(stamp: float, frame_id: str, child_frame_id: str, position: Sequence[float],
                          quat_xyzw: Sequence[float]) -> bytes:
    """Reference implementation of `encode_tf_cdr` through rosbags (tests)."""
    q = quat_xyzw
    transform = _T["geometry_msgs/msg/TransformStamped"](
        header=_header(stamp, frame_id), child_frame_id=child_frame_id,
        transform=_T["geometry_msgs/msg/Transform"](
            translation=_vec3(position),
            rotation=_T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))),
    )
    return _serialize(_T[TF_MESSAGE](transforms=[transform]), TF_MESSAGE)


def encode_tf_tree_cdr_rosbags(stamp: float, transforms) -> bytes:
    """Reference implementation of `encode_tf_tree_cdr` through rosbags (tests)."""
    items = []
    for frame_id, child_frame_id, p, q in transforms:
        items.append(_T["geometry_msgs/msg/TransformStamped"](
            header=_header(stamp, frame_id), child_frame_id=child_frame_id,
            transform=_T["geometry_msgs/msg/Transform"](
                translation=_vec3(p),
                rotation=_T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                                            w=float(q[3])))))
    return _serialize(_T[TF_MESSAGE](transforms=items), TF_MESSAGE)
