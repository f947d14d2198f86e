"""The CDR of the fused outputs: pose (PoseWithCovarianceStamped), odometry (Odometry) and the
fused position (NavSatFix), plus the struct layout that TF reuses (`output_layout`).

Pose and odometry are on the daemon's latency path for every odometry sample, so they are
packed with struct, byte for byte what rosbags serialises (tests compare both on many inputs):
all but the stamp and the floats is fixed by the frame ids, so each message is one precompiled
struct call (`output_layout`, built once per frame ids). NavSatFix, published at GPS rate, is
built and serialised by rosbags.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Sequence
from functools import lru_cache
from typing import TYPE_CHECKING, Final

from .rosbags_cdr import float_array, ros_header, ros_types, serialize
from .wire import NAVSATFIX, stamp_to_ros

if TYPE_CHECKING:
    import numpy as np

_CDR_HEADER: Final = b"\x00\x01\x00\x00"
_STAMP_PACK: Final = struct.Struct("<iI").pack
_U32_PACK: Final = struct.Struct("<I").pack


def _cdr_prefix(stamp: float, strings: Sequence[str], head: bytes = _CDR_HEADER) -> bytearray:
    """``head`` (the encapsulation header, and what precedes the header field, e.g. a sequence
    length), header.stamp, the frame id strings, padding to the float64 block."""
    buf = bytearray(head)
    buf += _STAMP_PACK(*stamp_to_ros(stamp))
    for text in strings:
        pad = (len(buf) - 4) & 3
        if pad:
            buf += bytes(4 - pad)
        raw = text.encode()
        buf += _U32_PACK(len(raw) + 1)
        buf += raw
        buf += b"\x00"
    pad = (len(buf) - 4) & 7
    if pad:
        buf += bytes(8 - pad)
    return buf


@lru_cache(maxsize=64)
def output_layout(head: bytes, strings: tuple[str, ...], floats: int) -> tuple[Callable[..., bytes], bytes, bytes]:
    """(pack, head, middle) of an output message whose every byte but the stamp and the float64 block
    is fixed by its frame ids: `pack(head, sec, nanosec, middle, *floats)` is the whole message in
    one precompiled struct call, the same bytes as `_cdr_prefix` + the block (the middle is
    `_cdr_prefix`'s own output after the stamp: string lengths, strings, terminators, padding)."""
    prefix = bytes(_cdr_prefix(0.0, strings, head))
    middle = prefix[len(head) + 8:]
    return struct.Struct(f"<{len(head)}siI{len(middle)}s{floats}d").pack, head, middle


def _floats(values: Sequence[float] | np.ndarray, n: int) -> Sequence[float]:
    if isinstance(values, (list, tuple)) and len(values) == n:
        return values
    return float_array(values, n).tolist()


def encode_pose_cdr(
    stamp: float,
    frame_id: str,
    position: Sequence[float],
    quat_xyzw: Sequence[float],
    cov36: Sequence[float] | np.ndarray,
) -> bytes:
    """The fused pose as geometry_msgs/msg/PoseWithCovarianceStamped (covariance over x y z roll pitch yaw)."""
    x, y, z = position
    qx, qy, qz, qw = quat_xyzw
    pack, head, middle = output_layout(_CDR_HEADER, (frame_id,), 43)
    sec, nanosec = stamp_to_ros(stamp)
    return pack(head, sec, nanosec, middle, x, y, z, qx, qy, qz, qw, *_floats(cov36, 36))


def encode_odometry_cdr(
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
    """The fused state as nav_msgs/msg/Odometry (twist in child_frame_id, as ROS defines it)."""
    x, y, z = position
    qx, qy, qz, qw = quat_xyzw
    vx, vy, vz = linear
    wx, wy, wz = angular
    pack, head, middle = output_layout(_CDR_HEADER, (frame_id, child_frame_id), 85)
    sec, nanosec = stamp_to_ros(stamp)
    return pack(head, sec, nanosec, middle, x, y, z, qx, qy, qz, qw, *_floats(pose_cov36, 36), vx, vy, vz, wx, wy, wz,
                *_floats(twist_cov36, 36))


def encode_navsat_cdr(stamp: float, frame_id: str, lat: float, lon: float, alt: float,
                      cov9: Sequence[float]) -> bytes:
    """The fused position as sensor_msgs/msg/NavSatFix (what navsat_transform publishes as
    gps/filtered): status FIX, covariance known (ENU, m^2)."""
    T = ros_types()
    msg = T[NAVSATFIX](
        header=ros_header(stamp, frame_id),
        status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=float(lat), longitude=float(lon), altitude=float(alt),
        position_covariance=float_array(cov9, 9),
        position_covariance_type=3,
    )
    return serialize(msg, NAVSATFIX)
