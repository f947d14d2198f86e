"""What every codec shares: the ROS type names fusiond reads, the payload types and size limit,
`DecodeError` with its reason codes, and float stamps as ROS time.

Its own module so that the decoders, the encoders and the rosbags layer name the formats and
report a bad payload the same way without importing one another. Every decoder raises only
`DecodeError`, whose `reason` is a stable code for per-reason rejection counters.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Final, Literal

from fusiond.errors import CodecError
from fusiond.samples import Sample

MAX_PAYLOAD: Final = 64 * 1024
"""Larger payloads are rejected before parsing: no sensor message fusiond reads is near this."""

REASONS: Final = (
    "empty_payload", "oversized", "cdr_invalid", "wrong_type",
    "json_invalid", "msgpack_invalid", "schema_invalid",
)
"""Every `DecodeError.reason`, so counters can be created up front."""

ODOMETRY: Final = "nav_msgs/msg/Odometry"
IMU: Final = "sensor_msgs/msg/Imu"
POSE_COV_STAMPED: Final = "geometry_msgs/msg/PoseWithCovarianceStamped"
POSE_STAMPED: Final = "geometry_msgs/msg/PoseStamped"
NAVSATFIX: Final = "sensor_msgs/msg/NavSatFix"

Encoding = Literal["ros2-cdr", "json", "msgpack"]
Payload = bytes | bytearray | memoryview
Decoder = Callable[[Payload], Sample]


class DecodeError(CodecError):
    """A payload that cannot become a sample; `reason` is one of `REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


def check_size(payload: Payload) -> None:
    """DecodeError for an empty payload or one over `MAX_PAYLOAD`, before any parsing."""
    n = len(payload)
    if n == 0:
        raise DecodeError("empty_payload", "empty payload")
    if n > MAX_PAYLOAD:
        raise DecodeError("oversized", f"{n} bytes > {MAX_PAYLOAD}")


def stamp_to_ros(stamp: float) -> tuple[int, int]:
    """Float seconds -> (sec, nanosec) rounded to the nearest ns, nanosec in [0, 1e9)."""
    if not math.isfinite(stamp):
        raise ValueError(f"stamp must be finite, got {stamp}")
    sec = math.floor(stamp)
    nanosec = round((stamp - sec) * 1e9)  # exact for stamp >= 0
    if nanosec >= 1_000_000_000:
        sec += 1
        nanosec -= 1_000_000_000
    if not -(2**31) <= sec < 2**31:
        raise ValueError(f"stamp {stamp} does not fit builtin_interfaces/Time (int32 seconds)")
    return sec, nanosec
