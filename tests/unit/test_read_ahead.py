"""A bag read ahead in a forked child gives what reading it in turn gives: the header, the samples in
order, the decode-error count, the BagError of a bag that cannot be opened and of one damaged halfway
(after the samples before the damage); a child that dies is read for here, past what it sent; stopping
early leaves no child. And a replay reading ahead makes the same trajectory as one reading in turn."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

from fusiond.config import ImuSensor, OdomSensor, loads
from fusiond.logs import configure
from fusiond.replay import bag1_records, read_ahead
from fusiond.replay.bag import BagError, iter_raw_cdr, open_bag_samples
from fusiond.replay.read_ahead import BATCH, ReadAhead, reading_ahead
from fusiond.replay.run import replay, tum_text
from fusiond.processes import workers_available

pytestmark = pytest.mark.skipif(workers_available() < 2, reason="a bag is read ahead on Linux with 2+ CPUs")

STORE = get_typestore(Stores.ROS2_HUMBLE)
ODOMETRY, IMU = "nav_msgs/msg/Odometry", "sensor_msgs/msg/Imu"
SENSORS = [OdomSensor(name="wheel", key="jackal_velocity_controller/odom"), ImuSensor(name="imu", key="imu/data"),
           ImuSensor(name="absent", key="no/such/topic")]


def _in_turn(paths: list[Path]) -> tuple[list, list[str], dict[str, str], int, int]:
    with open_bag_samples(paths, SENSORS) as bag:
        samples = list(bag)
        return samples, bag.missing, bag.bag_topics, bag.total, bag.decode_errors


def _child_gone(pid: int) -> bool:
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def test_the_jackal_bag_read_ahead_is_the_bag_read_in_turn(jackal_bag: Path) -> None:
    samples, missing, topics, total, errors = _in_turn([jackal_bag])
    with ReadAhead([jackal_bag], SENSORS).opened() as ahead:
        assert (ahead.missing, ahead.bag_topics, ahead.total) == (missing, topics, total) == (["absent"], topics, 6121)
        got = list(ahead)
        assert ahead.complete and ahead.decode_errors == errors == 0
    assert got == samples and len(got) == 6121
    assert _child_gone(ahead.pid)


def test_undecodable_messages_are_counted_as_in_turn(jackal_bag: Path, tmp_path: Path) -> None:
    """A ROS 2 bag of the Jackal's first messages with garbage among them (ROS 2: no fast path)."""
    sensors = SENSORS[:2]
    raw = list(iter_raw_cdr([jackal_bag], sensors))[:300]
    with Writer(tmp_path / "ros2", version=9) as writer:
        conns = {s.name: writer.add_connection("/" + s.key, ODOMETRY if s.name == "wheel" else IMU,
                                               typestore=STORE) for s in sensors}
        for k, (t, s, cdr) in enumerate(raw):
            writer.write(conns[s.name], t, b"\x00\x01\x00\x00garbage" if k % 50 == 7 else cdr)
    with open_bag_samples([tmp_path / "ros2"], sensors) as bag:
        samples, errors = list(bag), bag.decode_errors
    with ReadAhead([tmp_path / "ros2"], sensors).opened() as ahead:
        assert list(ahead) == samples and ahead.decode_errors == errors == 6
    assert len(samples) == 294


def test_a_bag_that_cannot_be_opened_raises_its_bag_error(tmp_path: Path) -> None:
    with pytest.raises(BagError) as in_turn:
        open_bag_samples([tmp_path / "nothing.bag"], SENSORS)
    ahead = ReadAhead([tmp_path / "nothing.bag"], SENSORS)
    with pytest.raises(BagError) as read_ahead:
        ahead.opened()
    assert str(read_ahead.value) == str(in_turn.value)
    assert _child_gone(ahead.pid)


def test_a_chunk_damaged_halfway_raises_after_the_samples_before_it(jackal_bag: Path, tmp_path: Path) -> None:
    with AnyReader([jackal_bag]) as reader:
        r = reader.readers[0]
        entries = sorted([e for c in reader.connections for e in r.indexes[c.id]], key=lambda e: e.time)
        order = bag1_records._chunk_order(entries)
        chunk = r.chunks[order[3]]
    data = bytearray(jackal_bag.read_bytes())
    data[chunk.datapos + 100: chunk.datapos + 600] = bytes(500)
    damaged = tmp_path / "damaged_chunk.bag"
    damaged.write_bytes(bytes(data))
    before: list = []
    with pytest.raises(BagError) as in_turn, open_bag_samples([damaged], SENSORS) as bag:
        for s in bag:
            before.append(s)
    got: list = []
    with pytest.raises(BagError) as read_ahead, ReadAhead([damaged], SENSORS).opened() as ahead:
        for s in ahead:
            got.append(s)
    assert got == before and len(got) > BATCH
    assert str(read_ahead.value) == str(in_turn.value)


def _dies_at(monkeypatch: pytest.MonkeyPatch, tag: str, nth: int) -> None:
    """The child (forked after this) ends without a word as it is about to send its nth ``tag`` frame."""
    real, sent = read_ahead._write, {"n": 0}

    def write(fd: int, frame: tuple[str, object]) -> None:
        if frame[0] == tag:
            sent["n"] += 1
            if sent["n"] == nth:
                os._exit(9)
        real(fd, frame)

    monkeypatch.setattr(read_ahead, "_write", write)


def test_a_child_that_dies_halfway_loses_nothing(jackal_bag: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from structlog.testing import capture_logs  # here: imported at collection, structlog would cache every logger

    configure("warning")  # capture_logs keeps the level's filter: an earlier test's --quiet would drop the warning
    samples, *_ = _in_turn([jackal_bag])
    _dies_at(monkeypatch, "batch", 3)
    with capture_logs() as logs, ReadAhead([jackal_bag], SENSORS).opened() as ahead:
        got = list(ahead)
        assert ahead.decode_errors == 0 and not ahead.complete
    assert got == samples
    reruns = [e for e in logs if e["event"] == "read_ahead_rerun"]
    assert len(reruns) == 1 and reruns[0]["samples_taken"] == 2 * BATCH
    assert _child_gone(ahead.pid)


def test_a_child_that_dies_before_the_bags_are_open_loses_nothing(jackal_bag: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    from structlog.testing import capture_logs

    configure("warning")
    samples, missing, *_ = _in_turn([jackal_bag])
    _dies_at(monkeypatch, "opened", 1)
    with capture_logs() as logs, ReadAhead([jackal_bag], SENSORS).opened() as ahead:
        assert ahead.missing == missing
        assert list(ahead) == samples
    assert [e["samples_taken"] for e in logs if e["event"] == "read_ahead_rerun"] == [0]


def test_stopping_early_stops_the_child(jackal_bag: Path) -> None:
    ahead = ReadAhead([jackal_bag], SENSORS).opened()
    samples = iter(ahead)
    first = [next(samples) for _ in range(5)]
    samples.close()  # the consumer stops: the child is killed and reaped
    assert len(first) == 5 and _child_gone(ahead.pid)
    never_opened = ReadAhead([jackal_bag], SENSORS)
    never_opened.close()
    assert _child_gone(never_opened.pid)


def test_one_cpu_reads_in_turn(jackal_bag: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("fusiond.replay.read_ahead.workers_available", lambda: 1)
    assert reading_ahead([jackal_bag], SENSORS) is None


JACKAL = """
[[sensors]]
kind = "odom"
name = "wheel"
key = "jackal_velocity_controller/odom"
[[sensors]]
kind = "imu"
name = "imu"
key = "imu/data"
"""


@pytest.mark.parametrize("lookahead", [False, True])
def test_a_replay_reading_ahead_makes_the_same_trajectory(jackal_bag: Path, lookahead: bool) -> None:
    """With ``lookahead`` the first samples keep their snapshots and the plan takes over once the child is
    done: the estimates are those of planning over the recording read in full."""
    cfg = loads(JACKAL)
    kept: list = []

    def through(samples):
        for s in samples:
            kept.append(s)
            yield s

    ahead = replay([jackal_bag], cfg, progress=False, doctor=False, lookahead=lookahead, through=through)
    in_turn = replay([jackal_bag], cfg, progress=False, doctor=False, lookahead=lookahead, read_ahead=False)
    assert tum_text(ahead.trajectory) == tum_text(in_turn.trajectory) and ahead.poses > 3000
    assert len(kept) == ahead.messages == in_turn.messages == 6121


def test_late_samples_land_on_their_snapshots_when_read_ahead(jackal_bag: Path, tmp_path: Path) -> None:
    """The Jackal's messages recorded as a ROS 2 bag with every seventh one received 0.15 s late (its stamp
    unchanged): late samples land inside the history, on the snapshots the plan kept for them."""
    rows = [(t + (150_000_000 if k % 7 == 3 else 0), s, cdr)
            for k, (t, s, cdr) in enumerate(iter_raw_cdr([jackal_bag], SENSORS[:2]))]
    with Writer(tmp_path / "late", version=9) as writer:
        conns = {s.name: writer.add_connection("/" + s.key, ODOMETRY if s.name == "wheel" else IMU,
                                               typestore=STORE) for s in SENSORS[:2]}
        for t, s, cdr in sorted(rows, key=lambda row: row[0]):
            writer.write(conns[s.name], t, cdr)
    cfg = loads(JACKAL)
    ahead = replay([tmp_path / "late"], cfg, progress=False, doctor=False, lookahead=True)
    in_turn = replay([tmp_path / "late"], cfg, progress=False, doctor=False, lookahead=True, read_ahead=False)
    assert tum_text(ahead.trajectory) == tum_text(in_turn.trajectory)
    assert ahead.core.stats[1].late > 400 and ahead.poses > 3000


def _verdict_texts(result) -> list[str]:
    return [f"{v.sensor}/{v.channel} {v.level} {v.message} {v.suggestion}" for v in result.verdicts()]


def test_the_doctors_sample_part_made_in_the_child_is_the_one_made_here(jackal_bag: Path) -> None:
    """Asked for the doctor's sample part, the child sends it after the samples: the same series, repeats and
    earliest stamp as a doctor fed the same samples here; the child is reaped once it is taken."""
    from fusiond.doctor import Doctor

    cfg = loads(JACKAL)
    here = Doctor(cfg)
    for s in _in_turn([jackal_bag])[0]:
        here.add_sample(s)
    mine = here.sample_side()
    with ReadAhead([jackal_bag], cfg.sensors, cfg).opened() as ahead:
        assert ahead.feeds_doctor and len(list(ahead)) == 6121
        side = ahead.doctor_side()
    assert side is not None and _child_gone(ahead.pid)
    assert side.collector.series == mine.collector.series and len(side.collector.series.odom_t) > 100
    assert (side.t0, side.repeats, side.lost.odom, side.lost.imu) == (mine.t0, mine.repeats, mine.lost.odom,
                                                                     mine.lost.imu)


@pytest.mark.parametrize("case", ["adopted", "child_fails", "too_long"])
def test_a_replay_whose_child_makes_the_doctors_sample_part_says_what_one_in_turn_says(
        jackal_bag: Path, monkeypatch: pytest.MonkeyPatch, case: str) -> None:
    """The replay's doctor adopts the child's sample part; when the child sends none (it failed at it), or keeps
    none (a recording longer than the pipe's backlog), it is fed the samples in the replay: the verdicts, the
    series and the trajectory are those of the doctor fed everything in one process."""
    from fusiond.doctor import Doctor

    cfg = loads(JACKAL)
    if case == "child_fails":  # the child, forked after this, fails at its doctor's part and sends nothing
        def fails(self):
            raise RuntimeError("no sample part")
        monkeypatch.setattr(Doctor, "sample_side", fails)
    if case == "too_long":  # a backlog of two batches: the Jackal's 6,121 messages are more
        monkeypatch.setattr(read_ahead, "BACKLOG", 2)
    adopted = []
    real_adopt = Doctor.adopt
    monkeypatch.setattr(Doctor, "adopt", lambda self, side: (adopted.append(side), real_adopt(self, side)))
    reading = reading_ahead([jackal_bag], cfg.sensors, cfg)
    ahead = replay([jackal_bag], cfg, progress=False, lookahead=True, reading=reading)
    assert reading.feeds_doctor == (case != "too_long") and _child_gone(reading.pid)
    assert len(adopted) == (1 if case == "adopted" else 0)
    in_turn = replay([jackal_bag], cfg, progress=False, lookahead=True, read_ahead=False)
    assert _verdict_texts(ahead) == _verdict_texts(in_turn) and len(_verdict_texts(in_turn)) >= 2
    assert ahead.doctor.series() == in_turn.doctor.series()
    assert tum_text(ahead.trajectory) == tum_text(in_turn.trajectory)
