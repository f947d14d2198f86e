"""A ROS 1 bag's messages, in exactly the order rosbags yields them, read from rosbags' own index.

rosbags' `Reader.messages` parses each record's header with its generic `Header` class (a dict
of every field, a seek and a read per field on a BytesIO) and merges the connections' indexes
with a Python-level comparison per step: about half the cost of a replay's bag reading. Here
the same index entries are ordered by one stable sort on their time (what ``heapq.merge`` of
the time-sorted per-connection lists gives: ties in connection order), each chunk is
decompressed once into bytes, and only the three header fields a message needs (op, conn,
time) are read. Several bags are merged as `AnyReader.messages` merges them. rosbags opens
the bag, parses the index and stays the reader whenever its internals are not the ones this
reads (`supported`).
"""

from __future__ import annotations

import struct
import threading
from collections.abc import Iterator, Sequence
from heapq import merge
from itertools import groupby
from operator import itemgetter
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import Connection

_U32 = struct.Struct("<I").unpack_from
_TIME = struct.Struct("<II").unpack_from
_MSGDATA, _CONNECTION = 2, 7  # record ops (rosbag format 2.0)
_by_time = itemgetter(0)


class RecordError(ValueError):
    """A chunk's record that does not read as the index says (what rosbags raises ReaderError for)."""


def supported(reader: AnyReader) -> bool:
    """Are the reader's bags ROS 1 bags opened by a rosbags whose index this reads?"""
    if reader.is2:
        return False
    for r in reader.readers:
        chunks = getattr(r, "chunks", None)
        if not isinstance(getattr(r, "indexes", None), dict) or not isinstance(chunks, dict) or r.bio is None:
            return False
        for c in chunks.values():
            if getattr(c, "_fields", None) != ("datasize", "datapos", "decompressor"):
                return False
            break
    return True


def messages(reader: AnyReader, connections: Sequence[Connection]) -> Iterator[tuple[Connection, int, bytes]]:
    """(connection, time ns, raw message) of ``connections`` as ``reader.messages(connections=...)``
    yields them; rosbags' own iterator when ``supported`` says no."""
    if not supported(reader):
        return reader.messages(connections=connections)
    generators = [_one_bag(owner, list(conns))
                  for owner, conns in groupby(sorted(connections, key=lambda c: id(c.owner)), key=lambda c: c.owner)]
    if len(generators) == 1:
        return generators[0]
    return merge(*generators, key=lambda m: m[1])


# A message record's header as rosbag (C++) writes it: the fields time, conn and op in that order
# (its sorted map); a header with exactly these bytes around the values reads as the loop below reads it
_TIME_CONN_OP = struct.Struct("<II5sIII5sII3sB")


def _header(buf: bytes, pos: int) -> tuple[int, Any, Any, int]:
    """(op, conn, time ns, end of the header) of the record at ``pos``; conn and time None if absent."""
    if len(buf) >= pos + 42:
        size, f1, n1, sec, nsec, f2, n2, conn, f3, n3, op = _TIME_CONN_OP.unpack_from(buf, pos)
        if (size == 38 and f1 == 13 and n1 == b"time=" and f2 == 9 and n2 == b"conn=" and f3 == 4
                and n3 == b"op="):
            return op, conn, sec * 1_000_000_000 + nsec, pos + 42
    (size,) = _U32(buf, pos)
    p = pos + 4
    end = p + size
    if end > len(buf):
        raise RecordError("record header beyond the chunk")
    op = conn = time = None
    while p < end:
        (flen,) = _U32(buf, p)
        p += 4
        fend = p + flen
        if fend > end:
            raise RecordError("declared field size is too large for header")
        eq = buf.find(b"=", p, fend)
        if eq < 0:
            raise RecordError("header field could not be parsed")
        name = buf[p:eq]
        if name == b"op":
            if fend - eq < 2:
                raise RecordError("op is not a uint8")
            op = buf[eq + 1]
        elif name == b"conn":
            if fend - eq < 5:
                raise RecordError("conn is not a uint32")
            (conn,) = _U32(buf, eq + 1)
        elif name == b"time":
            if fend - eq < 9:
                raise RecordError("time is not a ROS time")
            sec, nsec = _TIME(buf, eq + 1)
            time = sec * 1_000_000_000 + nsec
        p = fend
    if op is None:
        raise RecordError("record header without op")
    return op, conn, time, end


def _chunk_order(entries: list) -> list[int]:
    """The chunks' positions in the order the (time-sorted) index entries first reach them."""
    order: list[int] = []
    for _, pos, _ in entries:
        if not order or order[-1] != pos:
            order.append(pos)
    return order


class _Ahead:
    """``fn(arg)`` computed on a thread of its own; ``result()`` waits for it, then returns what it returned
    or raises what it raised. (A thread, not concurrent.futures: that imports logging, which a replay
    that logs nothing does not load.)"""

    __slots__ = ("_thread", "_value", "_error")

    def __init__(self, fn: Any, arg: Any) -> None:
        self._value: Any = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(fn, arg), name="bag-chunks", daemon=True)
        self._thread.start()

    def _run(self, fn: Any, arg: Any) -> None:
        try:
            self._value = fn(arg)
        except BaseException as err:  # noqa: BLE001 - handed to the reader's thread, raised there
            self._error = err

    def result(self) -> Any:
        self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value

    def wait(self) -> None:
        self._thread.join()


def _one_bag(reader: Any, connections: list[Connection]) -> Iterator[tuple[Connection, int, bytes]]:
    """The messages of one bag. Its chunks are read and decompressed one ahead on a thread of their own
    (``_Ahead``): bz2 and lz4 release the GIL, so on a second core the next chunk is ready when the
    messages of this one have been used (a replay's wall time; its CPU time is about the same). One chunk
    is read at a time, in chunk order, so the file is never read by two threads at once; what a read
    raises (a chunk cut short, a corrupt block) is raised here when the messages reach that chunk, as
    without the thread."""
    connmap = {c.id: c for c in reader.connections}
    entries = sorted([e for c in connections for e in reader.indexes[c.id]], key=_by_time)
    chunks, bio = reader.chunks, reader.bio

    def decompressed(pos: int) -> bytes:
        chunk = chunks[pos]
        bio.seek(chunk.datapos)
        raw = bio.read(chunk.datasize)
        if len(raw) != chunk.datasize:
            raise RecordError("chunk cut short")
        return bytes(chunk.decompressor(raw))

    order = _chunk_order(entries)
    U32 = _U32
    chunk_pos, buf, k = -1, b"", -1
    ahead = _Ahead(decompressed, order[0]) if order else None
    try:
        for entry in entries:
            t, pos, offset = entry
            if pos != chunk_pos:
                k += 1
                buf = ahead.result()  # chunk order[k]: the one reached now
                ahead = _Ahead(decompressed, order[k + 1]) if k + 1 < len(order) else None
                chunk_pos = pos
            while True:
                op, conn, time, p = _header(buf, offset)
                (size,) = U32(buf, p)
                p += 4
                if op != _CONNECTION:
                    break
                offset = p + size
            if op != _MSGDATA:
                raise RecordError("expected to find message data")
            end = p + size
            if end > len(buf):
                raise RecordError("message data beyond the chunk")
            if time != t:
                raise RecordError("message time differs from the index")
            yield connmap[conn], t, buf[p:end]
    finally:
        if ahead is not None:
            ahead.wait()  # stopped early or failed: the chunk read ahead must be done before the bag closes
