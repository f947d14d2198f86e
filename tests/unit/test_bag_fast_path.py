"""Replay reads odometry, IMU and GPS fixes straight from a bag's raw bytes (codecs.bag_fast_path), and
builds the standard type store only for a bag without message definitions. rosbags stays the authority:
these tests hold the fast path to exactly what rosbags' deserialisation gives, on the real Jackal ROS 1
bag, on the highway car's fixes, on fixes of every frame id length (CDR pads by where it ends), on
mutations of these messages, and on bags whose definitions differ."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
from pathlib import Path

import msgspec
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from fusiond.codecs import IMU, NAVSATFIX, ODOMETRY, bag_fast_path, flat_layout, typestore
from fusiond.core.sensors.gps.codec import gps_from_ros
from fusiond.core.sensors.imu.codec import imu_from_ros
from fusiond.core.sensors.odom.codec import odom_from_ros
from fusiond.config import ImuSensor, OdomSensor
from fusiond.replay.bag import open_bag_samples
from fusiond.core.sensors import GpsSample, ImuSample, OdomSample, codec_named, encode_sample
from tests.support.recordings import DATA

ROOT = Path(__file__).resolve().parents[2]
_KIND_OF = {ODOMETRY: "odom", IMU: "imu", NAVSATFIX: "gps"}


def _fast(store, msgtype: str, ros1: bool):
    """The bag reader of ``msgtype`` through its kind's codec, as replay asks for it."""
    return bag_fast_path(store, codec_named(_KIND_OF[msgtype]), msgtype, ros1=ros1)


JACKAL_TOPICS = {"/jackal_velocity_controller/odom": (ODOMETRY, odom_from_ros), "/imu/data": (IMU, imu_from_ros)}


@pytest.fixture(scope="module")
def jackal_raw(jackal_bag: Path) -> tuple[object, list[tuple[str, bytes]]]:
    """(the bag's own type store, [(msgtype, ROS 1 bytes)] of every odometry and IMU message)."""
    with AnyReader([jackal_bag]) as reader:
        conns = [c for c in reader.connections if c.topic in JACKAL_TOPICS]
        raw = [(c.msgtype, bytes(data)) for c, _, data in reader.messages(connections=conns)]
        return reader.typestore, raw


def _reference(store, msgtype: str, raw: bytes, ros1: bool) -> OdomSample | ImuSample | None:
    """rosbags' deserialisation + the *_from_ros converter; None where rosbags rejects the bytes."""
    from_ros = {ODOMETRY: odom_from_ros, IMU: imu_from_ros, NAVSATFIX: gps_from_ros}[msgtype]
    try:
        msg = store.deserialize_ros1(raw, msgtype) if ros1 else store.deserialize_cdr(raw, msgtype)
    except Exception:
        return None
    return from_ros(msg, "s")


def test_every_jackal_message_reads_as_rosbags_reads_it(jackal_raw) -> None:
    store, raw = jackal_raw
    assert len(raw) == 6121
    fast = {t: _fast(store, t, ros1=True) for t in (ODOMETRY, IMU)}
    assert None not in fast.values()  # the bag's definitions are the standard ones
    for msgtype, data in raw:
        got = fast[msgtype](data, "s")
        assert got is not None and got == _reference(store, msgtype, data, ros1=True)


@st.composite
def mutated_ros1(draw: st.DrawFn, raw: list[tuple[str, bytes]]) -> tuple[str, bytes]:
    """A Jackal message with a few bytes overwritten (string lengths included) and bytes cut or added."""
    msgtype, data = draw(st.sampled_from(raw[:200]))
    buf = bytearray(data)
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.one_of(st.integers(0, 24), st.integers(0, len(buf) - 1)))  # the header is where it branches
        buf[at] = draw(st.integers(0, 255))
    cut = draw(st.integers(-9, 9))
    buf = buf[:len(buf) + cut] if cut < 0 else buf + bytes(cut)
    return msgtype, bytes(buf)


def _assert_reads_as_rosbags(got, expected) -> None:
    """Where the fast path answers, the sample rosbags gives; where rosbags rejects the bytes, no answer."""
    if got is not None:
        # the same values; a mutated double can be NaN, equal to the other path's only bit for bit
        assert got == expected or msgspec.msgpack.encode(got) == msgspec.msgpack.encode(expected)
    if expected is None:
        assert got is None


def test_mutated_ros1_messages_read_as_rosbags_or_not_at_all(jackal_raw) -> None:
    """Where the fast path answers, rosbags gives the same sample; where rosbags rejects the bytes,
    the fast path answers None (the replay then asks rosbags, which counts the message undecodable)."""
    store, raw = jackal_raw

    @given(case=mutated_ros1(raw))
    @settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    def check(case: tuple[str, bytes]) -> None:
        msgtype, data = case
        _assert_reads_as_rosbags(_fast(store, msgtype, ros1=True)(data, "s"),
                                 _reference(store, msgtype, data, ros1=True))

    check()


def test_a_ros1_stream_that_remembers_its_layout_reads_mutations_as_rosbags(jackal_raw) -> None:
    """One reader per type for every case, each mutated message after an intact one of its type: the
    remembered layout meets changed lengths, strings and string lengths, and still answers as rosbags."""
    store, raw = jackal_raw
    fast = {t: _fast(store, t, ros1=True) for t in (ODOMETRY, IMU)}
    intact = {t: next(d for m, d in raw if m == t) for t in (ODOMETRY, IMU)}

    @given(case=mutated_ros1(raw))
    @settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    def check(case: tuple[str, bytes]) -> None:
        msgtype, data = case
        assert fast[msgtype](intact[msgtype], "s") == _reference(store, msgtype, intact[msgtype], ros1=True)
        _assert_reads_as_rosbags(fast[msgtype](data, "s"), _reference(store, msgtype, data, ros1=True))

    check()


def test_cdr_fast_path_of_a_ros2_bag_reads_as_rosbags() -> None:
    store = typestore()
    odom = encode_sample(OdomSample("s", 12.25, (0.5, 0.0, 0.0), (0.0, 0.0, 0.1), tuple(range(36))), "ros2-cdr")
    imu = encode_sample(ImuSample("s", 12.5, (0.0, 0.0, 0.0, 1.0), (0.1,) * 9, (0.0, 0.0, 0.1), (0.2,) * 9),
                            "ros2-cdr")
    for msgtype, data in ((ODOMETRY, odom), (IMU, imu)):
        got = _fast(store, msgtype, ros1=False)(data, "s")
        assert got is not None and got == _reference(store, msgtype, data, ros1=False)


def test_a_bag_defining_the_type_differently_gets_no_fast_path() -> None:
    """A bag may define nav_msgs/msg/Odometry its own way: then rosbags reads it, by its definition."""
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg("std_msgs/Header header\nfloat32[36] covariance\n", ODOMETRY))
    store.register(get_types_from_msg("uint32 seq\ntime stamp\nstring frame_id\n", "std_msgs/msg/Header"))
    assert flat_layout(store, ODOMETRY) == ("uint32", "int32", "uint32", "string", *("float32",) * 36)
    assert _fast(store, ODOMETRY, ros1=True) is None
    assert _fast(store, IMU, ros1=True) is None  # not defined in this store at all
    assert flat_layout(store, IMU) is None
    store.register(get_types_from_msg("std_msgs/Header header\nfloat64 latitude\n", NAVSATFIX))
    assert _fast(store, NAVSATFIX, ros1=True) is None  # a NavSatFix of its own: no struct tail of the standard one
    # a pose sensor reading Odometry makes poses: the odometry kind's fast path is not its own
    assert bag_fast_path(typestore(), codec_named("pose"), ODOMETRY, ros1=False) is None


def _fixes(store, ros1: bool) -> list[bytes]:
    """NavSatFix messages of every frame id length from 0 to 8 (CDR aligns the fields after the frame id by
    where it ends), with a negative status, a covariance and each covariance type, in ROS 1 or CDR."""
    T = store.types
    out = []
    for n in range(9):
        stamp = T["builtin_interfaces/msg/Time"](sec=1_600_000_000 + n, nanosec=123_456_789 * n % 10**9)
        header = (T["std_msgs/msg/Header"](seq=n, stamp=stamp, frame_id="g" * n) if ros1
                  else T["std_msgs/msg/Header"](stamp=stamp, frame_id="g" * n))
        msg = T[NAVSATFIX](
            header=header, status=T["sensor_msgs/msg/NavSatStatus"](status=n % 4 - 1, service=n + 1),
            latitude=37.7 + n * 1e-6, longitude=-122.4 - n * 1e-6, altitude=40.0 + n,
            position_covariance=np.arange(9, dtype=np.float64) * (n + 0.5), position_covariance_type=n % 4)
        out.append(bytes(store.serialize_ros1(msg, NAVSATFIX) if ros1 else store.serialize_cdr(msg, NAVSATFIX)))
    return out


@pytest.mark.parametrize("ros1", [False, True], ids=["ros2-cdr", "ros1"])
def test_gps_fixes_of_every_frame_id_length_read_as_rosbags(ros1: bool) -> None:
    """A bag's fixes are read by struct (the GPS codec's ``tail``), so that a replay's reading child needs no
    numpy for rosbags' covariance array: the same samples rosbags and ``gps_from_ros`` make."""
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    fast = _fast(store, NAVSATFIX, ros1)
    assert fast is not None
    for data in _fixes(store, ros1):
        got = fast(data, "s")
        assert got is not None and got == _reference(store, NAVSATFIX, data, ros1)


@st.composite
def mutated(draw: st.DrawFn, raw: list[bytes]) -> bytes:
    """A message with a few bytes overwritten (the frame id's length and the status among them) and bytes
    cut or added (CDR's end padding among them)."""
    buf = bytearray(draw(st.sampled_from(raw)))
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.one_of(st.integers(0, 28), st.integers(0, len(buf) - 1)))
        buf[at] = draw(st.integers(0, 255))
    cut = draw(st.integers(-9, 9))
    return bytes(buf[:len(buf) + cut] if cut < 0 else buf + bytes(cut))


@pytest.mark.parametrize("ros1", [False, True], ids=["ros2-cdr", "ros1"])
def test_mutated_gps_fixes_read_as_rosbags_or_not_at_all(ros1: bool) -> None:
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    fast = _fast(store, NAVSATFIX, ros1)
    raw = _fixes(store, ros1)

    @given(data=mutated(raw))
    @settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
    def check(data: bytes) -> None:
        _assert_reads_as_rosbags(fast(data, "s"), _reference(store, NAVSATFIX, data, ros1))

    check()


@pytest.mark.skipif(not (DATA / "comma2k19_ex1").exists(), reason="needs ../shared/data/comma2k19_ex1 (the highway car)")
def test_every_fix_of_the_highway_car_reads_as_rosbags_reads_it() -> None:
    with AnyReader([DATA / "comma2k19_ex1"]) as reader:
        fast = _fast(reader.typestore, NAVSATFIX, ros1=False)
        conns = [c for c in reader.connections if c.msgtype == NAVSATFIX]
        raw = [bytes(data) for _, _, data in reader.messages(connections=conns)]
        assert fast is not None and len(raw) == 579
        for data in raw:
            got = fast(data, "s")
            assert got is not None and got == _reference(reader.typestore, NAVSATFIX, data, ros1=False)


def _ros2_bag(path: Path, n: int = 40) -> Path:
    with Writer(path, version=9) as writer:
        odom = writer.add_connection("/odom", ODOMETRY, typestore=typestore())
        imu = writer.add_connection("/imu", IMU, typestore=typestore())
        for k in range(n):
            t = 100.0 + 0.02 * k
            writer.write(odom, int(t * 1e9), encode_sample(
                OdomSample("wheel", t, (0.5, 0.0, 0.0), (0.0, 0.0, 0.1), (1e-3,) * 36), "ros2-cdr"))
            writer.write(imu, int(t * 1e9) + 1000, encode_sample(
                ImuSample("imu", t + 1e-6, (0.0, 0.0, 0.0, 1.0), (1e-4,) * 9, (0.0, 0.0, 0.1), (1e-5,) * 9), "ros2-cdr"))
    return path


SENSORS = [OdomSensor(name="wheel", key="odom"), ImuSensor(name="imu", key="imu")]


def test_a_ros2_bag_without_definitions_is_read_with_the_standard_types(tmp_path: Path) -> None:
    """Bags recorded before Iron hold no message definitions: rosbags needs a default type store,
    and the replay builds the Humble one for them only. The samples are those of the same bag with
    its definitions."""
    with_defs = _ros2_bag(tmp_path / "with")
    without = _ros2_bag(tmp_path / "without")
    db = next(without.glob("*.db3"))
    with sqlite3.connect(db) as conn:
        conn.execute("DELETE FROM message_definitions")
    with pytest.raises(Exception, match="default_typestore"):  # what rosbags says of such a bag
        with AnyReader([without]):
            pass
    with open_bag_samples([with_defs], SENSORS) as a, open_bag_samples([without], SENSORS) as b:
        first, second = list(a), list(b)
        assert b.decode_errors == 0
    assert len(first) == 80 and first == second


def test_a_config_loads_and_a_bag_is_read_without_numpy(tmp_path: Path) -> None:
    """A replay forks its reading child once the config is loaded (``replay.read_ahead``); the child opens and
    reads the bags while this process imports numpy and the filter. Neither the config's load (the kinds'
    models are imported when a filter is built: ``ModelIn``) nor reading odometry, IMU and GPS fixes from a
    bag (struct fast paths) imports numpy, so the two really overlap."""
    bag = tmp_path / "bag"
    with Writer(bag, version=9) as writer:
        conns = {t: writer.add_connection(f"/{key}", t, typestore=typestore())
                 for t, key in ((ODOMETRY, "odom"), (IMU, "imu"), (NAVSATFIX, "fix"))}
        for k in range(20):
            t = 100.0 + 0.1 * k
            for msgtype, sample in (
                    (ODOMETRY, OdomSample("wheel", t, (0.5, 0.0, 0.0), (0.0, 0.0, 0.1), (1e-3,) * 36)),
                    (IMU, ImuSample("imu", t, (0.0, 0.0, 0.0, 1.0), (1e-4,) * 9, (0.0, 0.0, 0.1), (1e-5,) * 9)),
                    (NAVSATFIX, GpsSample("gps", t, 37.7, -122.4, 40.0, 0, (4.0,) * 9, 2))):
                writer.write(conns[msgtype], int(t * 1e9), encode_sample(sample, "ros2-cdr"))
    code = ("import sys\nfrom fusiond.config import load\nfrom fusiond.replay.bag import open_bag_samples\n"
            "cfg = load('examples/comma2k19.toml')\n"
            f"with open_bag_samples([{str(bag)!r}], cfg.sensors) as b:\n"
            "    print(len(list(b)), b.decode_errors, 'numpy' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "60 0 False"


def test_replay_imports_neither_the_standard_type_store_nor_zenoh(jackal_bag: Path) -> None:
    """`fusiond replay` of a bag with definitions does not pay for the Humble store or Zenoh."""
    code = ("import sys\nfrom fusiond.cli import main\n"
            f"rc = main(['replay', {str(jackal_bag)!r}, '--config', 'examples/jackal.toml', '--quiet'])\n"
            "print(rc, sorted(m for m in sys.modules if m.endswith('ros2_humble') or m.split('.')[0] == 'zenoh'))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "0 []"
