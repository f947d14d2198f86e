"""Struct readers of a bag's raw messages (ROS 1 and ROS 2) of a kind whose codec has a struct fast path
(``KindCodec.repeated``: the odometry's and the IMU's; ``KindCodec.tail``: the GPS's), and the check that a
bag defines the kind's type with the layout that fast path reads before it is used (`bag_fast_path`).

A bag replay reads those messages thousands of times a second. ROS 2 bags hold the CDR of
`cdr_fast_path`; ROS 1 bags hold ROS 1 serialisation: the same fields with a `seq` in the header, strings
without a terminator and no alignment, before the same float64 block, read by the kind's ``Fields`` as
`cdr_fast_path` reads it. A bag carries its own message definitions, which may differ from the standard
ones under the same name: a fast path is used only for a type whose definition in the bag's store (rosbags
parsed it) has exactly the layout it reads (a Header, the child_frame_id where the kind has one, the
float64 block).
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import TYPE_CHECKING, Final

from fusiond.samples import Sample

from .cdr_fast_path import _CDR_LE, _STAMP, U32, Fields, RepeatedLayout, _skip_string
from .kind_codec import KindCodec, TailFields
from .wire import Payload

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

_ROS1_HEAD: Final = struct.Struct("<IiI").unpack_from  # header.seq, header.stamp.sec, header.stamp.nanosec


def _ros1_string_end(buf: Payload, pos: int) -> int:
    """End of the ROS 1 string at `pos` (length prefix, no terminator), -1 where rosbags would reject it."""
    (length,) = U32(buf, pos)
    end = pos + 4 + length
    if end > len(buf):
        return -1
    str(buf[pos + 4 : end], "utf-8")  # rosbags decodes the string; invalid UTF-8 raises here
    return end


def _ros1_offset(buf: Payload, has_child_frame: bool, size: int) -> int:
    """Offset of the float64 block after the ROS 1 header (and child frame id), -1 where rosbags would
    reject the message."""
    try:
        pos = _ros1_string_end(buf, 12)
        if pos >= 0 and has_child_frame:
            pos = _ros1_string_end(buf, pos)
    except (struct.error, UnicodeDecodeError):
        return -1
    if pos < 0 or pos + size != len(buf):  # rosbags rejects any size mismatch in ROS 1
        return -1
    return pos


class _Ros1Stream:
    """One topic's ROS 1 reader, skipping what repeats from message to message (as
    `cdr_fast_path.RepeatedLayout` does for CDR): a topic's messages carry the same frame ids,
    so they have the same length and the same bytes from the end of the header's stamp (offset
    12) to the float64 block. A message with the length and those bytes of the last one
    `_ros1_offset` accepted passes every check it would make, byte for byte the same: its block
    is read at once (``fields``: the covariances shared while they repeat). Anything else takes
    `_ros1_offset`'s full checks."""

    __slots__ = ("has_child_frame", "fields", "length", "middle")

    def __init__(self, has_child_frame: bool, fields: Fields) -> None:
        self.has_child_frame, self.fields = has_child_frame, fields
        self.length = -1  # length of the remembered message (-1: none yet)
        self.middle = b""  # its bytes [12, length - block size)

    def __call__(self, buf: Payload, sensor: str) -> Sample | None:
        n = len(buf)
        at = n - self.fields.size
        if not (n == self.length and buf[12:at] == self.middle):
            if n < 12 or _ros1_offset(buf, self.has_child_frame, self.fields.size) < 0:
                return None
            self.length, self.middle = n, bytes(buf[12:at])
        _, sec, nanosec = _ROS1_HEAD(buf, 0)
        return self.fields.sample(buf, at, sec + nanosec * 1e-9, sensor)


_HEADER_LAYOUT: Final = ("int32", "uint32", "string")  # stamp.sec, stamp.nanosec, frame_id
# a base type's struct code (little-endian; its size is its CDR alignment)
_CODES: Final = {"int8": "b", "uint8": "B", "int16": "h", "uint16": "H", "int32": "i", "uint32": "I",
                 "int64": "q", "uint64": "Q", "float32": "f", "float64": "d"}


class _TailReader:
    """A message that is a Header then fixed-size base fields (``KindCodec.tail``), read with one struct
    call after the frame id: the fields' values, as rosbags gives them (Python ints and floats), go to
    the kind's ``make``. CDR aligns each field to its size from the body's start, so the padding depends on
    where the frame id ends (modulo 8): one struct per such end, made when first met. It returns None for a
    message it does not read exactly as rosbags would (big-endian CDR, a bad string, a size rosbags rejects:
    any other in ROS 1, more than 3 padding bytes at the end in CDR), which rosbags then decides."""

    __slots__ = ("types", "make", "ros1", "_structs")

    def __init__(self, fields: TailFields, ros1: bool) -> None:
        self.types, self.make = fields
        self.ros1 = ros1
        self._structs: dict[int, struct.Struct] = {}

    def _struct(self, start: int) -> struct.Struct:
        """The fields' struct from body offset ``start`` (ROS 1: no alignment)."""
        key = 0 if self.ros1 else start % 8
        found = self._structs.get(key)
        if found is None:
            codes, pos = ["<"], key
            for name in self.types:
                size = struct.calcsize(_CODES[name])
                pad = 0 if self.ros1 else -pos % size
                codes.append("x" * pad + _CODES[name])
                pos += pad + size
            found = self._structs[key] = struct.Struct("".join(codes))
        return found

    def __call__(self, buf: Payload, sensor: str) -> Sample | None:
        try:
            if self.ros1:
                at = _ros1_string_end(buf, 12) if len(buf) >= 16 else -1
                fields = self._struct(0)
                if at < 0 or at + fields.size != len(buf):
                    return None
                _, sec, nanosec = _ROS1_HEAD(buf, 0)
            else:
                end = _skip_string(buf, 8) if len(buf) >= 16 and buf[:2] == _CDR_LE else -1
                if end < 0:
                    return None
                fields, at = self._struct(end), 4 + end
                if not 0 <= len(buf) - at - fields.size <= 3:
                    return None
                sec, nanosec = _STAMP(buf, 4)
        except (struct.error, UnicodeDecodeError):
            return None
        values = fields.unpack_from(buf, at)
        return self.make(values, sec + nanosec * 1e-9, sensor)  # type: ignore[no-any-return]


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


def _defines(store: Typestore, msgtype: str, body: tuple[str, ...], ros1: bool) -> bool:
    """Does the bag's store define ``msgtype`` as a Header (ROS 1's with its seq) followed by ``body``'s base
    types (``flat_layout``'s names), the layout a struct reader reads?"""
    head = ("uint32", *_HEADER_LAYOUT) if ros1 else _HEADER_LAYOUT  # ROS 1: header.seq first
    return flat_layout(store, msgtype) == (*head, *body)


def bag_fast_path(store: Typestore, codec: KindCodec, msgtype: str,
                  ros1: bool) -> Callable[[Payload, str], Sample | None] | None:
    """The struct reader of a bag's raw messages of ``msgtype`` (ROS 1 or ROS 2 CDR) for a sensor of the kind
    whose codec is ``codec``, when the codec has a struct fast path for that type (``repeated`` or ``tail``, of
    its first ROS type) and the bag's definition of it (in ``store``, the bag reader's type store) has the
    layout that fast path reads.

    A reader remembers its stream's layout and covariances (`_Ros1Stream`, `RepeatedLayout`): one per
    topic. It returns the sample, or None for a message it does not read exactly as rosbags would
    (big-endian CDR, bad strings, wrong size): deserialise those with rosbags, the authority on errors.
    None when the codec has no fast path for ``msgtype`` or the bag defines it differently.
    """
    if msgtype != codec.ros_types[0]:
        return None
    if codec.repeated is None:
        if codec.tail is None or not _defines(store, msgtype, codec.tail[0], ros1):
            return None
        return _TailReader(codec.tail, ros1)
    has_child_frame, fields = codec.repeated
    body = (*(("string",) if has_child_frame else ()), *("float64",) * (fields.size // 8))
    if not _defines(store, msgtype, body, ros1):
        return None
    if ros1:
        return _Ros1Stream(has_child_frame, fields())
    return RepeatedLayout(has_child_frame, fields()).sample


__all__ = ["bag_fast_path", "flat_layout"]
