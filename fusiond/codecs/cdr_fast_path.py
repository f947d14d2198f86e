"""The struct fast path of Odometry and Imu in little-endian ROS 2 CDR: the daemon's hot path.

Odometry and Imu are a Header (+ child_frame_id) followed by one run of float64s with no
padding inside it, so a little-endian payload unpacks with struct calls, several times faster
than the generic rosbags path (and a stream's repeated covariances are read once: ``ImuFields``). Anything the fast path does not accept exactly as rosbags
would is left to rosbags (`rosbags_cdr.deserialize`), which stays the authority on errors;
tests check both paths agree on arbitrary bytes.
"""

from __future__ import annotations

import struct
from typing import Final

from fusiond.samples import ImuSample, OdomSample

from .wire import Payload

U32: Final = struct.Struct("<I").unpack_from
_STAMP: Final = struct.Struct("<iI").unpack_from
_CDR_LE: Final = b"\x00\x01"

_D9: Final = struct.Struct("<9d").unpack_from
_D36: Final = struct.Struct("<36d").unpack_from
# the values of a block that move from message to message, the covariances between them skipped
_IMU_MOVING: Final = struct.Struct("<4d72x3d72x3d72x").unpack_from  # orientation, angular velocity, acceleration
_ODOM_MOVING: Final = struct.Struct("<3d4d288x3d3d288x").unpack_from  # position, orientation, linear, angular


def _skip_string(buf: Payload, pos: int) -> int:
    """End of the CDR string at body offset `pos` (body = buf[4:]), -1 where rosbags would reject it."""
    (length,) = U32(buf, 4 + pos)
    end = pos + 4 + length
    if length < 1 or end + 4 > len(buf) or buf[end + 3] != 0:
        return -1
    str(buf[pos + 8 : end + 3], "utf-8")  # rosbags decodes frame ids; invalid UTF-8 raises here
    return end


def _block_offset(buf: Payload, has_child_frame: bool, size: int) -> int:
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
    end = pos + size
    if end + 4 > len(buf) or len(buf) - 4 - end > 3:  # rosbags tolerates up to 3 padding bytes
        return -1
    return pos + 4


class ImuFields:
    """An Imu float64 block (at offset ``at`` of a payload) as an ImuSample: orientation and its covariance,
    angular velocity and its, linear acceleration and its.

    A driver's covariances are its constants: the same bytes in every message. When all three are the
    bytes of the previous message read, their tuples are that message's, and only the ten values that
    move are unpacked. Equal values, one object: the samples a replay's doctor keeps for its end-of-run
    series hold ten floats each instead of 37, and the core's own "same covariance as before" checks
    compare an object with itself. One reader per stream (it remembers that stream's covariances)."""

    __slots__ = ("_bytes", "_tuples")
    size: Final = 37 * 8  # bytes: 37 float64s

    def __init__(self) -> None:
        self._bytes: tuple[bytes, ...] | None = None
        self._tuples: tuple[tuple[float, ...], ...] = ((), (), ())

    def sample(self, buf: Payload, at: int, stamp: float, sensor: str) -> ImuSample:
        covariances = (buf[at + 32 : at + 104], buf[at + 128 : at + 200], buf[at + 224 : at + 296])
        if covariances == self._bytes:
            oc, gc, ac = self._tuples
        else:
            oc, gc, ac = _D9(buf, at + 32), _D9(buf, at + 128), _D9(buf, at + 224)
            self._bytes, self._tuples = covariances, (oc, gc, ac)
        v = _IMU_MOVING(buf, at)
        return ImuSample(sensor, stamp, v[0:4], oc, v[4:7], gc, v[7:10], ac)


class OdomFields:
    """An Odometry float64 block as an OdomSample: pose position, orientation (its covariance is not
    read), twist linear, angular and covariance; the twist covariance shared with the previous message's
    when its bytes are the same (``ImuFields``): 13 values unpacked instead of 85."""

    __slots__ = ("_bytes", "_tuple")
    size: Final = 85 * 8  # bytes: pose position, orientation, covariance (0:43), twist (43:85)

    def __init__(self) -> None:
        self._bytes: bytes | None = None
        self._tuple: tuple[float, ...] = ()

    def sample(self, buf: Payload, at: int, stamp: float, sensor: str) -> OdomSample:
        covariance = buf[at + 392 : at + 680]
        if covariance == self._bytes:
            tc = self._tuple
        else:
            tc = _D36(buf, at + 392)
            self._bytes, self._tuple = covariance, tc
        v = _ODOM_MOVING(buf, at)
        return OdomSample(sensor, stamp, v[7:10], v[10:13], tc, v[0:3], v[3:7])


Fields = ImuFields | OdomFields


class RepeatedLayout:
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

    __slots__ = ("has_child_frame", "fields", "length", "middle", "at")

    def __init__(self, has_child_frame: bool, fields: Fields) -> None:
        self.has_child_frame = has_child_frame
        self.fields = fields
        self.length = -1  # length of the remembered payload (-1: none yet)
        self.middle = b""  # its bytes [12, at)
        self.at = 0  # offset of its float64 block

    def sample(self, buf: Payload, sensor: str) -> ImuSample | OdomSample | None:
        """The payload's sample, None where rosbags must decide (``_block_offset``)."""
        at = self.at
        if len(buf) != self.length or buf[12:at] != self.middle or buf[:2] != _CDR_LE:
            at = _block_offset(buf, self.has_child_frame, self.fields.size)
            if at < 0:
                return None
            self.length, self.middle, self.at = len(buf), bytes(buf[12:at]), at
        sec, nanosec = _STAMP(buf, 4)
        return self.fields.sample(buf, at, sec + nanosec * 1e-9, sensor)
