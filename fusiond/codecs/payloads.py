"""Payload codecs: bytes on a Zenoh key <-> fusiond samples, and the CDR of published outputs.

Pure functions, no Zenoh import, so the live daemon, `fusiond play`, the bag
replay and the tests all share one definition of the wire formats. ROS 2 CDR is
exactly what `rosbags` (and so zenoh-bridge-ros2dds) puts on the wire, with the
4-byte encapsulation header. Every decoder raises only `DecodeError`, whose
`reason` is a stable code for per-reason rejection counters.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from functools import cache, lru_cache
from typing import TYPE_CHECKING, Annotated, Any, Final, Literal

import msgspec
import numpy as np

from fusiond.errors import CodecError
from fusiond.samples import GpsSample, ImuSample, OdomSample, PoseSample, Sample

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

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
POSE_TYPES: Final = (POSE_COV_STAMPED, POSE_STAMPED, ODOMETRY)
"""What a `kind = "pose"` sensor may carry (its `msgtype` says which: a CDR payload does not)."""

Encoding = Literal["ros2-cdr", "json", "msgpack"]
Payload = bytes | bytearray | memoryview


class DecodeError(CodecError):
    """A payload that cannot become a sample; `reason` is one of `REASONS`."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason
        self.detail = detail


# --------------------------------------------------------------------------- typestore


@cache
def typestore() -> Typestore:
    """The Humble type store (Odometry, Imu and the pose messages have the same wire format in
    every ROS 2 distro), built on first use: importing its type definitions takes ~70 ms, which a
    replay of a bag that carries its own definitions (every ROS 1 bag; ROS 2 bags written with
    them) and the fast paths below never need. `TYPESTORE` is the same object."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def __getattr__(name: str) -> Any:
    if name == "TYPESTORE":  # the old constant, now built when first asked for
        return typestore()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _types() -> dict[str, Any]:
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


def _deserialize(payload: Payload, msgtype: str) -> Any:
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


# --------------------------------------------------------------------------- stamps


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


def _ros_time(stamp: float) -> Any:
    sec, nanosec = stamp_to_ros(stamp)
    return _types()["builtin_interfaces/msg/Time"](sec=sec, nanosec=nanosec)


# --------------------------------------------------------------------------- ROS message -> sample


def odom_from_ros(msg: Any, sensor: str) -> OdomSample:
    """A rosbags nav_msgs/msg/Odometry (ROS 1 or ROS 2 typestore) as an OdomSample."""
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


def imu_from_ros(msg: Any, sensor: str) -> ImuSample:
    """A rosbags sensor_msgs/msg/Imu (ROS 1 or ROS 2 typestore) as an ImuSample."""
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


def gps_from_ros(msg: Any, sensor: str) -> GpsSample:
    """A rosbags sensor_msgs/msg/NavSatFix (ROS 1 or ROS 2 typestore) as a GpsSample."""
    stamp = msg.header.stamp
    return GpsSample(
        sensor, stamp.sec + stamp.nanosec * 1e-9, float(msg.latitude), float(msg.longitude), float(msg.altitude),
        int(msg.status.status), tuple(msg.position_covariance.tolist()), int(msg.position_covariance_type),
    )


def pose_from_ros(msg: Any, sensor: str) -> PoseSample:
    """PoseStamped, PoseWithCovarianceStamped or the pose of an Odometry as a PoseSample."""
    stamp = msg.header.stamp
    pose = msg.pose
    cov: tuple[float, ...] = ()
    if hasattr(pose, "covariance"):  # PoseWithCovariance (also inside Odometry)
        cov = tuple(pose.covariance.tolist())
        pose = pose.pose
    p, q = pose.position, pose.orientation
    return PoseSample(sensor, stamp.sec + stamp.nanosec * 1e-9, (p.x, p.y, p.z), (q.x, q.y, q.z, q.w), cov)


# --------------------------------------------------------------------------- CDR fast path
#
# Odometry and Imu are a Header (+ child_frame_id) followed by one run of float64s
# with no padding inside it, so a little-endian payload unpacks with one struct call,
# about 4x faster than the generic rosbags path. Anything the fast path does not
# accept exactly as rosbags would falls back to rosbags, which stays the authority
# on errors; tests check both paths agree on arbitrary bytes.

_U32 = struct.Struct("<I").unpack_from
_STAMP = struct.Struct("<iI").unpack_from
_ODOM_BLOCK = struct.Struct("<85d")
_IMU_BLOCK = struct.Struct("<37d")
_CDR_LE = b"\x00\x01"


def _skip_string(buf: Payload, pos: int) -> int:
    """End of the CDR string at body offset `pos` (body = buf[4:]), -1 where rosbags would reject it."""
    (length,) = _U32(buf, 4 + pos)
    end = pos + 4 + length
    if length < 1 or end + 4 > len(buf) or buf[end + 3] != 0:
        return -1
    str(buf[pos + 8 : end + 3], "utf-8")  # rosbags decodes frame ids; invalid UTF-8 raises here
    return end


def _block_offset(buf: Payload, has_child_frame: bool, block: struct.Struct) -> int:
    """Offset in `buf` of the float64 block after the header (and child frame id), -1 where rosbags
    would reject the payload (or it is not little-endian CDR: then rosbags decides)."""
    if len(buf) < 16 or buf[:2] != _CDR_LE:
        return -1
    try:
        pos = _skip_string(buf, 8)
        if pos >= 0 and has_child_frame:
            pos = _skip_string(buf, (pos + 3) & -4)
    except (struct.error, UnicodeDecodeError):
        return -1
    if pos < 0:
        return -1
    pos = (pos + 7) & -8
    end = pos + block.size
    if end + 4 > len(buf) or len(buf) - 4 - end > 3:  # rosbags tolerates up to 3 padding bytes
        return -1
    return pos + 4


def _fast_block(buf: Payload, has_child_frame: bool, block: struct.Struct) -> tuple[float, tuple[float, ...]] | None:
    at = _block_offset(buf, has_child_frame, block)
    if at < 0:
        return None
    sec, nanosec = _STAMP(buf, 4)
    return sec + nanosec * 1e-9, block.unpack_from(buf, at)


class _RepeatedLayout:
    """The struct fast path for one sensor's stream, skipping what repeats from message to message.

    A sensor sends the same frame ids in every message, so its payloads have the same length
    and the same bytes from the end of header.stamp (offset 12) to the float64 block: the
    string lengths, the strings, their terminators and the padding. Only the stamp and the
    floats change. `decode` remembers the length and those bytes of the last payload
    `_block_offset` accepted; a payload that has both (and the little-endian CDR identifier)
    has its block at the same offset and passes every check `_block_offset` would make on
    it, byte for byte the same, so it is unpacked at once, without looking at its strings
    again: at 1 kHz that is most of the decoder's Python calls. Anything else (another
    length, another frame id, garbage) takes `_block_offset`'s full checks, exactly as
    before, and becomes the remembered layout if it passes.
    """

    __slots__ = ("has_child_frame", "block", "length", "middle", "at")

    def __init__(self, has_child_frame: bool, block: struct.Struct) -> None:
        self.has_child_frame = has_child_frame
        self.block = block
        self.length = -1  # length of the remembered payload (-1: none yet)
        self.middle = b""  # its bytes [12, at)
        self.at = 0  # offset of its float64 block

    def decode(self, buf: Payload) -> tuple[float, tuple[float, ...]] | None:
        """(stamp, floats) as `_fast_block` returns them, None where it returns None."""
        at = self.at
        if len(buf) != self.length or buf[12:at] != self.middle or buf[:2] != _CDR_LE:
            at = _block_offset(buf, self.has_child_frame, self.block)
            if at < 0:
                return None
            self.length, self.middle, self.at = len(buf), bytes(buf[12:at]), at
        sec, nanosec = _STAMP(buf, 4)
        return sec + nanosec * 1e-9, self.block.unpack_from(buf, at)


def _odom_from_block(got: tuple[float, tuple[float, ...]] | None, sensor: str) -> OdomSample | None:
    """An OdomSample from (stamp, float64 block) as the CDR and ROS 1 readers return it: pose position,
    orientation, covariance (0:43), then twist linear, angular, covariance (43:85)."""
    if got is None:
        return None
    stamp, d = got
    return OdomSample(sensor, stamp, d[43:46], d[46:49], d[49:85], d[0:3], d[3:7])


def _imu_from_block(got: tuple[float, tuple[float, ...]] | None, sensor: str) -> ImuSample | None:
    """An ImuSample from (stamp, float64 block): orientation and its covariance, angular velocity and its
    covariance, linear acceleration and its covariance."""
    if got is None:
        return None
    stamp, d = got
    return ImuSample(sensor, stamp, d[0:4], d[4:13], d[13:16], d[16:25], d[25:28], d[28:37])


def _fast_odom(buf: Payload, sensor: str) -> OdomSample | None:
    return _odom_from_block(_fast_block(buf, True, _ODOM_BLOCK), sensor)


def _fast_imu(buf: Payload, sensor: str) -> ImuSample | None:
    return _imu_from_block(_fast_block(buf, False, _IMU_BLOCK), sensor)


# --------------------------------------------------------------------------- bag fast paths
#
# A bag replay reads the same two messages thousands of times a second. ROS 2 bags hold
# the CDR above; ROS 1 bags hold ROS 1 serialisation: the same fields with a `seq` in the
# header, strings without a terminator and no alignment, so one struct call reads the
# float64 block as well. A bag carries its own message definitions, which may differ from
# the standard ones under the same name: a fast path is used only for a type whose
# definition in the bag's store (rosbags parsed it) has exactly the layout it reads.

_ROS1_HEAD = struct.Struct("<IiI").unpack_from  # header.seq, header.stamp.sec, header.stamp.nanosec


def _ros1_string_end(buf: Payload, pos: int) -> int:
    """End of the ROS 1 string at `pos` (length prefix, no terminator), -1 where rosbags would reject it."""
    (length,) = _U32(buf, pos)
    end = pos + 4 + length
    if end > len(buf):
        return -1
    str(buf[pos + 4 : end], "utf-8")  # rosbags decodes the string; invalid UTF-8 raises here
    return end


def _ros1_block(buf: Payload, has_child_frame: bool, block: struct.Struct) -> tuple[float, tuple[float, ...]] | None:
    try:
        _, sec, nanosec = _ROS1_HEAD(buf, 0)
        pos = _ros1_string_end(buf, 12)
        if pos >= 0 and has_child_frame:
            pos = _ros1_string_end(buf, pos)
        if pos < 0 or pos + block.size != len(buf):  # rosbags rejects any size mismatch in ROS 1
            return None
        return sec + nanosec * 1e-9, block.unpack_from(buf, pos)
    except (struct.error, UnicodeDecodeError):
        return None


def _fast_odom_ros1(buf: Payload, sensor: str) -> OdomSample | None:
    return _odom_from_block(_ros1_block(buf, True, _ODOM_BLOCK), sensor)


def _fast_imu_ros1(buf: Payload, sensor: str) -> ImuSample | None:
    return _imu_from_block(_ros1_block(buf, False, _IMU_BLOCK), sensor)


_HEADER_LAYOUT: Final = ("int32", "uint32", "string")  # stamp.sec, stamp.nanosec, frame_id
_FAST_LAYOUTS: Final = {
    ODOMETRY: (*_HEADER_LAYOUT, "string", *("float64",) * 85),  # + child_frame_id, pose, twist
    IMU: (*_HEADER_LAYOUT, *("float64",) * 37),
}
_FAST_PATHS: Final = {
    (ODOMETRY, False): _fast_odom, (ODOMETRY, True): _fast_odom_ros1,
    (IMU, False): _fast_imu, (IMU, True): _fast_imu_ros1,
}


def flat_layout(store: Typestore, msgtype: str) -> tuple[str, ...] | None:
    """The base types of a message's fields in wire order, nested messages and fixed arrays
    expanded, from the field definitions in ``store``; None when it holds a variable-length
    sequence (no fixed layout) or a type the store does not know."""
    from rosbags.interfaces import Nodetype

    out: list[str] = []

    def walk(name: str) -> bool:
        fields = store.fielddefs.get(name)
        if fields is None:
            return False
        for _, (node, detail) in fields[1]:
            if node == Nodetype.BASE:
                out.append(detail[0])
            elif node == Nodetype.NAME:
                if not walk(detail):
                    return False
            elif node == Nodetype.ARRAY and detail[0][0] == Nodetype.BASE:
                out.extend([detail[0][1][0]] * detail[1])
            elif node == Nodetype.ARRAY and detail[0][0] == Nodetype.NAME:
                for _ in range(detail[1]):
                    if not walk(detail[0][1]):
                        return False
            else:
                return False
        return True

    return tuple(out) if walk(msgtype) else None


def bag_fast_path(store: Typestore, msgtype: str, ros1: bool) -> Callable[[Payload, str], Sample | None] | None:
    """The struct reader of a bag's raw messages of ``msgtype`` (ROS 1 or ROS 2 CDR), when the
    bag's definition of it (in ``store``, the bag reader's type store) has the standard layout.

    It returns the sample, or None for a message it does not read exactly as rosbags would
    (big-endian CDR, bad strings, wrong size): deserialise those with rosbags, the authority
    on errors. None when ``msgtype`` has no fast path or the bag defines it differently.
    """
    want = _FAST_LAYOUTS.get(msgtype)
    if want is None:
        return None
    if ros1:
        want = ("uint32", *want)  # header.seq
    return _FAST_PATHS[msgtype, ros1] if flat_layout(store, msgtype) == want else None


# --------------------------------------------------------------------------- JSON / msgpack wire format

_Vec3 = tuple[float, float, float]
_Quat = tuple[float, float, float, float]
_Cov9 = Annotated[tuple[float, ...], msgspec.Meta(min_length=9, max_length=9)]
_Cov36 = Annotated[tuple[float, ...], msgspec.Meta(min_length=36, max_length=36)]


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
    linear: _Vec3
    angular: _Vec3
    twist_covariance: _Cov36
    position: _Vec3 = (0.0, 0.0, 0.0)
    orientation: _Quat = (0.0, 0.0, 0.0, 1.0)


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
    orientation: _Quat
    orientation_covariance: _Cov9
    angular_velocity: _Vec3
    angular_velocity_covariance: _Cov9
    linear_acceleration: _Vec3 = (0.0, 0.0, 0.0)
    linear_acceleration_covariance: _Cov9 = (0.0,) * 9


class GpsMessage(msgspec.Struct, kw_only=True):
    """A GPS fix on a `json` or `msgpack` key (sensor_msgs/NavSatFix's fields).

    - `stamp`: seconds; `latitude`, `longitude` in degrees (WGS84), `altitude` in m.
    - `status`: NavSatStatus.status (-1 no fix: skipped and counted; default 0).
    - `position_covariance`: 9 numbers, row-major ENU, m^2 (default zeros), and
      `position_covariance_type` (0 unknown, default; 1 approximated; 2 diagonal; 3 known).
    """

    stamp: float
    latitude: float
    longitude: float
    altitude: float = 0.0
    status: int = 0
    position_covariance: _Cov9 = (0.0,) * 9
    position_covariance_type: int = 0


class PoseMessage(msgspec.Struct, kw_only=True):
    """A pose on a `json` or `msgpack` key: `stamp`, `position` [x, y, z] m, `orientation`
    [x, y, z, w], optional `covariance` (36 numbers, row-major over x y z roll pitch yaw)."""

    stamp: float
    position: _Vec3
    orientation: _Quat
    covariance: _Cov36 | None = None


def _gps_from_message(m: GpsMessage, sensor: str) -> GpsSample:
    return GpsSample(sensor, m.stamp, m.latitude, m.longitude, m.altitude, m.status, m.position_covariance,
                     m.position_covariance_type)


def _pose_from_message(m: PoseMessage, sensor: str) -> PoseSample:
    return PoseSample(sensor, m.stamp, m.position, m.orientation, m.covariance or ())


def _odom_from_message(m: OdomMessage, sensor: str) -> OdomSample:
    return OdomSample(sensor, m.stamp, m.linear, m.angular, m.twist_covariance, m.position, m.orientation)


def _imu_from_message(m: ImuMessage, sensor: str) -> ImuSample:
    return ImuSample(
        sensor, m.stamp, m.orientation, m.orientation_covariance, m.angular_velocity,
        m.angular_velocity_covariance, m.linear_acceleration, m.linear_acceleration_covariance,
    )


# --------------------------------------------------------------------------- decoders

Decoder = Callable[[Payload], Sample]

def _no_fast_path(buf: Payload, sensor: str) -> None:
    return None  # GPS and pose sensors run at 1-100 Hz: rosbags' generic path is fast enough


_KINDS: Final = {
    "odom": (ODOMETRY, _fast_odom, odom_from_ros, OdomMessage, _odom_from_message),
    "imu": (IMU, _fast_imu, imu_from_ros, ImuMessage, _imu_from_message),
    "gps": (NAVSATFIX, _no_fast_path, gps_from_ros, GpsMessage, _gps_from_message),
    "pose": (POSE_COV_STAMPED, _no_fast_path, pose_from_ros, PoseMessage, _pose_from_message),
}


_REPEATED: Final = {  # kind -> (child frame id?, float64 block, sample builder) of `_RepeatedLayout`
    "odom": (True, _ODOM_BLOCK, _odom_from_block),
    "imu": (False, _IMU_BLOCK, _imu_from_block),
}


def ros_msgtype(kind: str, msgtype: str | None = None) -> str:
    """The ROS 2 message type of a sensor kind (a pose sensor's own `msgtype` when given)."""
    if kind not in _KINDS:
        raise ValueError(f"unknown sensor kind {kind!r}, expected one of {sorted(_KINDS)}")
    if msgtype is not None:
        if kind != "pose" or msgtype not in POSE_TYPES:
            article = "an" if kind[0] in "aeiou" else "a"
            raise ValueError(f"msgtype {msgtype!r} is not valid for {article} {kind} sensor")
        return msgtype
    return _KINDS[kind][0]


def ros_converter(kind: str) -> Callable[[Any, str], Sample]:
    """rosbags message -> sample for a sensor kind (bag replay)."""
    return _KINDS[kind][2]


def _check_size(payload: Payload) -> None:
    n = len(payload)
    if n == 0:
        raise DecodeError("empty_payload", "empty payload")
    if n > MAX_PAYLOAD:
        raise DecodeError("oversized", f"{n} bytes > {MAX_PAYLOAD}")


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
    _, fast, from_ros, wire_type, from_message = _KINDS[kind]
    if kind == "pose" and msgtype is None and encoding == "ros2-cdr":
        for t in POSE_TYPES:
            _warm(t)

        def decode_any_pose(payload: Payload) -> Sample:
            _check_size(payload)
            for t in POSE_TYPES:
                try:
                    return from_ros(typestore().deserialize_cdr(memoryview(payload), t), sensor)
                except Exception:
                    continue
            return from_ros(_deserialize(payload, POSE_COV_STAMPED), sensor)  # raises the DecodeError

        return decode_any_pose
    msgtype = ros_msgtype(kind, msgtype)

    if encoding == "ros2-cdr":
        _warm(msgtype)
        repeated = _REPEATED.get(kind)
        if repeated is not None:  # odometry and IMU: the hot path of the daemon
            has_child_frame, block, from_block = repeated
            layout = _RepeatedLayout(has_child_frame, block)
            unpack = layout.decode

            def decode_repeated(payload: Payload) -> Sample:
                if len(payload) != layout.length:  # the remembered length passed the size checks
                    _check_size(payload)
                sample = from_block(unpack(payload), sensor)
                if sample is not None:
                    return sample
                return from_ros(_deserialize(payload, msgtype), sensor)

            return decode_repeated

        def decode_cdr(payload: Payload) -> Sample:
            _check_size(payload)
            sample = fast(payload, sensor)
            if sample is not None:
                return sample
            return from_ros(_deserialize(payload, msgtype), sensor)

        return decode_cdr

    if encoding == "json":
        parser: Any = msgspec.json.Decoder(wire_type)
        syntax = "json_invalid"
    elif encoding == "msgpack":
        parser = msgspec.msgpack.Decoder(wire_type)
        syntax = "msgpack_invalid"
    else:
        raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")

    def decode_structured(payload: Payload) -> Sample:
        _check_size(payload)
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
    else:
        raw = encode_pose_sample(PoseSample("", 0.0, (0.0,) * 3, (0.0, 0.0, 0.0, 1.0)), "ros2-cdr", msgtype)
    typestore().deserialize_cdr(raw, msgtype)
    _warmed.add(msgtype)


def decode_pose_cdr(payload: Payload) -> Any:
    """A published pose (geometry_msgs/msg/PoseWithCovarianceStamped) as a rosbags message."""
    _check_size(payload)
    return _deserialize(payload, POSE_COV_STAMPED)


def decode_odometry_cdr(payload: Payload) -> Any:
    """A published nav_msgs/msg/Odometry as a rosbags message."""
    _check_size(payload)
    return _deserialize(payload, ODOMETRY)


# --------------------------------------------------------------------------- encoders

_json_encoder = msgspec.json.Encoder()
_msgpack_encoder = msgspec.msgpack.Encoder()


def _cov(values: Sequence[float] | np.ndarray, n: int) -> np.ndarray:
    arr = np.asarray(values, dtype=np.float64).reshape(-1)
    if arr.size != n:
        raise ValueError(f"covariance must have {n} elements, got {arr.size}")
    return arr


def _serialize(msg: Any, msgtype: str) -> bytes:
    return bytes(typestore().serialize_cdr(msg, msgtype, little_endian=True))


def _structured(message: msgspec.Struct, encoding: str) -> bytes:
    if encoding == "json":
        return _json_encoder.encode(message)
    if encoding == "msgpack":
        return _msgpack_encoder.encode(message)
    raise ValueError(f"unknown encoding {encoding!r}, expected ros2-cdr, json or msgpack")


def _pose(position: Sequence[float], quat_xyzw: Sequence[float]) -> Any:
    x, y, z = (float(v) for v in position)
    qx, qy, qz, qw = (float(v) for v in quat_xyzw)
    T = _types()
    return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                                      orientation=T["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw))


def _vec3(v: Sequence[float]) -> Any:
    return _types()["geometry_msgs/msg/Vector3"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


def encode_odom_sample(sample: OdomSample, encoding: str) -> bytes:
    """What a wheel-odometry publisher puts on the key (CDR: frames odom -> base_link, zero pose covariance)."""
    if encoding == "ros2-cdr":
        return encode_odometry_cdr(
            sample.stamp, "odom", "base_link", sample.position, sample.orientation, np.zeros(36),
            sample.linear, sample.angular, sample.twist_covariance,
        )
    return _structured(
        OdomMessage(
            stamp=sample.stamp, linear=sample.linear, angular=sample.angular,
            twist_covariance=sample.twist_covariance, position=sample.position, orientation=sample.orientation,
        ),
        encoding,
    )


def encode_imu_sample(sample: ImuSample, encoding: str) -> bytes:
    """What an IMU publisher puts on the key (CDR: frame base_link)."""
    if encoding == "ros2-cdr":
        q = sample.orientation
        T = _types()
        msg = T[IMU](
            header=T["std_msgs/msg/Header"](stamp=_ros_time(sample.stamp), frame_id="base_link"),
            orientation=T["geometry_msgs/msg/Quaternion"](x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
            orientation_covariance=_cov(sample.orientation_covariance, 9),
            angular_velocity=_vec3(sample.angular_velocity),
            angular_velocity_covariance=_cov(sample.angular_velocity_covariance, 9),
            linear_acceleration=_vec3(sample.linear_acceleration),
            linear_acceleration_covariance=_cov(sample.linear_acceleration_covariance, 9),
        )
        return _serialize(msg, IMU)
    return _structured(
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


def encode_navsat_cdr(stamp: float, frame_id: str, lat: float, lon: float, alt: float,
                      cov9: Sequence[float]) -> bytes:
    """The fused position as sensor_msgs/msg/NavSatFix (what navsat_transform publishes as
    gps/filtered): status FIX, covariance known (ENU, m^2)."""
    T = _types()
    msg = T[NAVSATFIX](
        header=T["std_msgs/msg/Header"](stamp=_ros_time(stamp), frame_id=frame_id),
        status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
        latitude=float(lat), longitude=float(lon), altitude=float(alt),
        position_covariance=_cov(cov9, 9),
        position_covariance_type=3,
    )
    return _serialize(msg, NAVSATFIX)


def encode_gps_sample(sample: GpsSample, encoding: str) -> bytes:
    """What a GPS driver puts on the key (CDR: sensor_msgs/msg/NavSatFix, frame gps)."""
    if encoding == "ros2-cdr":
        T = _types()
        msg = T[NAVSATFIX](
            header=T["std_msgs/msg/Header"](stamp=_ros_time(sample.stamp), frame_id="gps"),
            status=T["sensor_msgs/msg/NavSatStatus"](status=int(sample.status), service=1),
            latitude=float(sample.latitude), longitude=float(sample.longitude), altitude=float(sample.altitude),
            position_covariance=_cov(sample.position_covariance, 9),
            position_covariance_type=int(sample.covariance_type),
        )
        return _serialize(msg, NAVSATFIX)
    return _structured(
        GpsMessage(stamp=sample.stamp, latitude=sample.latitude, longitude=sample.longitude,
                   altitude=sample.altitude, status=sample.status, position_covariance=sample.position_covariance,
                   position_covariance_type=sample.covariance_type),
        encoding,
    )


def encode_pose_sample(sample: PoseSample, encoding: str, msgtype: str = POSE_COV_STAMPED) -> bytes:
    """What a pose publisher puts on the key, as ``msgtype`` (CDR; frame map, child base_link)."""
    if encoding == "ros2-cdr":
        T = _types()
        header = T["std_msgs/msg/Header"](stamp=_ros_time(sample.stamp), frame_id="map")
        pose = _pose(sample.position, sample.orientation)
        cov = _cov(sample.covariance or (0.0,) * 36, 36)
        if msgtype == POSE_STAMPED:
            return _serialize(T[POSE_STAMPED](header=header, pose=pose), POSE_STAMPED)
        if msgtype == POSE_COV_STAMPED:
            msg = T[POSE_COV_STAMPED](header=header, pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=cov))
            return _serialize(msg, POSE_COV_STAMPED)
        if msgtype == ODOMETRY:
            return encode_odometry_cdr(sample.stamp, "map", "base_link", sample.position, sample.orientation, cov,
                                       (0.0,) * 3, (0.0,) * 3, np.zeros(36))
        raise ValueError(f"msgtype {msgtype!r} is not a pose type, expected one of {POSE_TYPES}")
    return _structured(
        PoseMessage(stamp=sample.stamp, position=sample.position, orientation=sample.orientation,
                    covariance=sample.covariance or None),
        encoding,
    )


def encode_sample(sample: Sample, encoding: str, msgtype: str | None = None) -> bytes:
    """Any sample as its sensor would publish it (``msgtype``: a pose sensor's ROS type)."""
    if isinstance(sample, OdomSample):
        return encode_odom_sample(sample, encoding)
    if isinstance(sample, ImuSample):
        return encode_imu_sample(sample, encoding)
    if isinstance(sample, GpsSample):
        return encode_gps_sample(sample, encoding)
    return encode_pose_sample(sample, encoding, msgtype or POSE_COV_STAMPED)


# The published outputs are encoded with struct, byte for byte what rosbags serialises
# (tests compare both on many inputs): they are on the daemon's latency path for every
# odometry sample. All but the stamp and the floats is fixed by the frame ids, so each
# message is one precompiled struct call (`_output_layout`, built once per frame ids).

_CDR_HEADER: Final = b"\x00\x01\x00\x00"
_STAMP_PACK = struct.Struct("<iI").pack
_U32_PACK = struct.Struct("<I").pack


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
def _output_layout(head: bytes, strings: tuple[str, ...], floats: int) -> tuple[Callable[..., bytes], bytes, bytes]:
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
    return _cov(values, n).tolist()


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
    pack, head, middle = _output_layout(_CDR_HEADER, (frame_id,), 43)
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
    pack, head, middle = _output_layout(_CDR_HEADER, (frame_id, child_frame_id), 85)
    sec, nanosec = stamp_to_ros(stamp)
    return pack(head, sec, nanosec, middle, x, y, z, qx, qy, qz, qw, *_floats(pose_cov36, 36), vx, vy, vz, wx, wy, wz,
                *_floats(twist_cov36, 36))
