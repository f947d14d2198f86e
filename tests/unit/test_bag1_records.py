"""The ROS 1 record reader yields exactly what rosbags' `messages` yields: the same connections,
times and bytes in the same order (ties across connections and across bags included), and a
damaged chunk is still an error."""

from __future__ import annotations

import shutil
import threading
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from fusiond.config import ImuSensor, OdomSensor
from fusiond.replay import bag1_records
from fusiond.replay.bag import BagError, open_bag_samples

STORE = get_typestore(Stores.ROS1_NOETIC)
BYTES = "std_msgs/msg/ByteMultiArray"


def _both(paths: list[Path], pick=None) -> tuple[list, list]:
    with AnyReader(paths) as reader:
        assert bag1_records.supported(reader)
        conns = list(reader.connections) if pick is None else pick(list(reader.connections))
        ours = [(id(c), t, d) for c, t, d in bag1_records.messages(reader, conns)]
        theirs = [(id(c), t, bytes(d)) for c, t, d in reader.messages(connections=conns)]
    assert all(type(d) is bytes for _, _, d in ours)
    return ours, theirs


def test_the_jackal_bag_reads_as_rosbags_reads_it(jackal_bag: Path) -> None:
    ours, theirs = _both([jackal_bag])
    assert len(ours) == 6121 and ours == theirs
    ours, theirs = _both([jackal_bag], lambda conns: conns[::-1][:1])  # one connection, others skipped
    assert ours == theirs and 0 < len(ours) < 6121


def test_two_bags_merge_as_rosbags_merges_them(jackal_bag: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy.bag"
    shutil.copy(jackal_bag, copy)  # every time twice: ties across bags
    ours, theirs = _both([jackal_bag, copy])
    assert len(ours) == 2 * 6121 and ours == theirs


@pytest.mark.parametrize("compression", [None, Writer.CompressionFormat.LZ4, Writer.CompressionFormat.BZ2])
def test_ties_connection_records_and_chunks_read_as_rosbags_reads_them(tmp_path: Path, compression) -> None:
    """Three connections (two on one topic), equal times across them, times out of write order,
    several chunks (small threshold) each opening with its connection records."""
    path = tmp_path / "ties.bag"
    writer = Writer(path)
    if compression is not None:
        writer.set_compression(compression)
    writer.chunk_threshold = 2000
    with writer:
        conns = [writer.add_connection("/a", BYTES, typestore=STORE),
                 writer.add_connection("/a", BYTES, typestore=STORE, callerid="other"),
                 writer.add_connection("/b", BYTES, typestore=STORE)]
        for k in range(400):
            t = 1_000_000_000 + (k // 3) * 1000 - (500 if k % 7 == 0 else 0)
            writer.write(conns[k % 3], t, bytes([k % 256]) * (k % 50 + 1))
    ours, theirs = _both([path])
    assert len(ours) == 400 and ours == theirs
    ours, theirs = _both([path], lambda c: [c[2], c[0]])
    assert ours == theirs and len({i for i, _, _ in ours}) == 2


def test_a_damaged_chunk_is_a_bag_error(jackal_bag: Path, tmp_path: Path) -> None:
    data = bytearray(jackal_bag.read_bytes())
    data[200_000:220_000] = bytes(range(256)) * 78 + bytes(32)
    damaged = tmp_path / "damaged.bag"
    damaged.write_bytes(bytes(data))
    sensors = [OdomSensor(name="wheel", key="jackal_velocity_controller/odom"), ImuSensor(name="imu", key="imu/data")]
    with pytest.raises(BagError, match="not a readable ROS 1/ROS 2 bag"):
        with open_bag_samples([damaged], sensors) as bag:
            list(bag)


def _damaged_chunk(jackal_bag: Path, tmp_path: Path, k: int) -> tuple[Path, int]:
    """The bag with the compressed data of its k-th chunk (in read order) overwritten, and how many of
    its messages come before that chunk."""
    with AnyReader([jackal_bag]) as reader:
        r = reader.readers[0]
        entries = sorted([e for c in reader.connections for e in r.indexes[c.id]], key=lambda e: e.time)
        order = bag1_records._chunk_order(entries)
        chunk = r.chunks[order[k]]
        before = next(i for i, e in enumerate(entries) if e.chunk_pos == order[k])
    data = bytearray(jackal_bag.read_bytes())
    data[chunk.datapos + 100 : chunk.datapos + 600] = bytes(500)
    damaged = tmp_path / "damaged_chunk.bag"
    damaged.write_bytes(bytes(data))
    return damaged, before


def test_chunks_read_ahead_raise_where_their_messages_begin(jackal_bag: Path, tmp_path: Path) -> None:
    """The next chunk is decompressed on a thread while this one's messages are used: a chunk that does
    not decompress is still an error only once every message before it has been yielded."""
    damaged, before = _damaged_chunk(jackal_bag, tmp_path, 3)
    got = []
    with AnyReader([damaged]) as reader:
        with pytest.raises(Exception) as err:
            for message in bag1_records.messages(reader, list(reader.connections)):
                got.append(message)
    assert len(got) == before > 0
    assert not isinstance(err.value, AssertionError)
    with pytest.raises(BagError, match="not a readable ROS 1/ROS 2 bag"):
        with open_bag_samples([damaged], [ImuSensor(name="imu", key="imu/data")]) as bag:
            list(bag)


def test_an_iteration_stopped_early_leaves_no_reading_thread(jackal_bag: Path) -> None:
    with AnyReader([jackal_bag]) as reader:
        messages = bag1_records.messages(reader, list(reader.connections))
        first = [next(messages) for _ in range(10)]
        messages.close()  # the thread reading ahead is waited for here, before the bag closes
        assert len(first) == 10
        assert not [t for t in threading.enumerate() if t.name.startswith("bag-chunks")]


def test_a_record_whose_time_is_not_the_index_time_is_refused() -> None:
    """The reader checks each record against the index, as rosbags asserts it."""
    def field(name: bytes, value: bytes) -> bytes:
        return len(name + b"=" + value).to_bytes(4, "little") + name + b"=" + value

    header = field(b"op", b"\x02") + field(b"conn", (0).to_bytes(4, "little")) + field(b"time", bytes(8))
    record = len(header).to_bytes(4, "little") + header + (3).to_bytes(4, "little") + b"abc"
    assert bag1_records._header(record, 0) == (2, 0, 0, 4 + len(header))
    with pytest.raises(bag1_records.RecordError):
        bag1_records._header(record[:20], 0)


def test_rosbags_c_plus_plus_header_layout_reads_as_the_general_parser_reads_it(jackal_bag: Path) -> None:
    """The time, conn, op header rosbag (C++) writes takes one struct read; any other byte in its
    frame (a field length, a name) sends it through the general parser, which reads the same."""
    def field(name: bytes, value: bytes) -> bytes:
        return len(name + b"=" + value).to_bytes(4, "little") + name + b"=" + value

    def record(*fields: bytes) -> bytes:
        header = b"".join(fields)
        return len(header).to_bytes(4, "little") + header + (1).to_bytes(4, "little") + b"x"

    time = (47).to_bytes(4, "little") + (5_000_000).to_bytes(4, "little")
    cpp = record(field(b"time", time), field(b"conn", (3).to_bytes(4, "little")), field(b"op", b"\x02"))
    other = record(field(b"conn", (3).to_bytes(4, "little")), field(b"time", time), field(b"op", b"\x02"))
    longer = record(field(b"time", time), field(b"conn", (3).to_bytes(4, "little")), field(b"op", b"\x02\x00"))
    assert bag1_records._header(b"pad" + cpp, 3) == (2, 3, 47_005_000_000, 3 + 42)
    assert bag1_records._header(other, 0) == (2, 3, 47_005_000_000, 42)
    assert bag1_records._header(longer, 0) == (2, 3, 47_005_000_000, 43)
    with AnyReader([jackal_bag]) as reader:  # the Jackal bag's records have the C++ layout
        r = reader.readers[0]
        entry = r.indexes[reader.connections[0].id][0]
        chunk = r.chunks[entry.chunk_pos]
        r.bio.seek(chunk.datapos)
        buf = chunk.decompressor(r.bio.read(chunk.datasize))
    assert buf[entry.offset + 8 : entry.offset + 13] == b"time="
    assert bag1_records._header(buf, entry.offset)[2] == entry.time
