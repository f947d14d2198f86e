"""The struct fast path of a message that is a Header (+ child_frame_id) followed by one run of float64s
in little-endian ROS 2 CDR: the daemon's hot path (the odometry's and the IMU's messages).

Such a message has no padding inside its float64 block, so a little-endian payload unpacks with struct
calls, several times faster than the generic rosbags path. Which floats make the sample is the kind's to
say (its ``Fields``, in its package's ``codec``); the walk to the block, the checks and what repeats
between a stream's messages (``RepeatedLayout``, ``Covariances``) are here, the same for every kind.
Anything the fast path does not accept exactly as rosbags would is left to rosbags
(`rosbags_cdr.deserialize`), which stays the authority on errors; tests check both paths agree on
arbitrary bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from operator import itemgetter
from typing import Final, Protocol

from fusiond.samples import Sample

from .wire import Payload

U32: Final = struct.Struct("<I").unpack_from
_STAMP: Final = struct.Struct("<iI").unpack_from
_CDR_LE: Final = b"\x00\x01"


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


class Covariances:
    """The covariance blocks of one stream's messages (``starts``: their byte offsets in the float64 block,
    ``size`` float64s each), read once while their bytes repeat.

    A driver's covariances are its constants: the same bytes in every message. When all of them are the
    bytes of the previous message read, its tuples are returned again: equal values, one object. The
    samples a replay's doctor keeps for its end-of-run series then hold only the values that move, and
    the core's own "same covariance as before" checks compare an object with itself.

    The blocks are cut out of a payload by one ``itemgetter`` of slices, made for the block's offset and
    kept while it stays (a stream's frame ids fix it): this runs for every IMU message of the daemon, and
    one C call costs a third of a generator over the spans."""

    __slots__ = ("_starts", "_spans", "_unpack", "_at", "_cut", "_bytes", "_tuples")

    def __init__(self, starts: tuple[int, ...], size: int) -> None:
        self._starts = starts
        self._spans = tuple((start, start + 8 * size) for start in starts)
        self._unpack = struct.Struct(f"<{size}d").unpack_from
        self._at = 0  # the offset `_cut` is made for
        self._cut = self._cutter(0)
        self._bytes: object = None  # what `_cut` returned of the last payload read (a tuple with several blocks)
        self._tuples: tuple[tuple[float, ...], ...] = ()

    def read(self, buf: Payload, at: int) -> tuple[tuple[float, ...], ...]:
        if at != self._at:
            self._at, self._cut = at, self._cutter(at)
        blocks = self._cut(buf)
        if blocks != self._bytes:
            unpack = self._unpack
            self._bytes, self._tuples = blocks, tuple(unpack(buf, at + a) for a in self._starts)
        return self._tuples

    def _cutter(self, at: int) -> Callable[[Payload], object]:
        """The blocks of a payload whose float64 block is at ``at``: one slice, or a tuple of them."""
        return itemgetter(*(slice(at + a, at + b) for a, b in self._spans))


class Fields(Protocol):
    """A kind's reader of its message's float64 block (``KindCodec.repeated``): ``size`` bytes at offset ``at``
    of a payload, with the stamp and sensor name read before it, as the kind's sample. One reader per
    stream, so that it may keep what repeats between messages (``Covariances``)."""

    size: int

    def sample(self, buf: Payload, at: int, stamp: float, sensor: str) -> Sample: ...


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

    def sample(self, buf: Payload, sensor: str) -> Sample | None:
        """The payload's sample, None where rosbags must decide (``_block_offset``)."""
        at = self.at
        if len(buf) != self.length or buf[12:at] != self.middle or buf[:2] != _CDR_LE:
            at = _block_offset(buf, self.has_child_frame, self.fields.size)
            if at < 0:
                return None
            self.length, self.middle, self.at = len(buf), bytes(buf[12:at]), at
        sec, nanosec = _STAMP(buf, 4)
        return self.fields.sample(buf, at, sec + nanosec * 1e-9, sensor)


__all__ = ["U32", "Covariances", "Fields", "RepeatedLayout"]
