"""Bag reading on the real Jackal ROS 1 bag and on ROS 2 bags written here with rosbags."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from rosbags.rosbag2 import Writer

from fusiond.config import ImuSensor, OdomSensor
from fusiond.replay.bag import BagError, iter_raw_cdr, open_bag_samples
from fusiond.core.sensors import ImuSample, OdomSample, make_decoder
from fusiond.codecs import IMU, ODOMETRY, TYPESTORE

JACKAL_ODOM_KEY = "jackal_velocity_controller/odom"
JACKAL_IMU_KEY = "imu/data"
WHEEL = OdomSensor(name="wheel", key=JACKAL_ODOM_KEY)
IMU_SENSOR = ImuSensor(name="imu", key=JACKAL_IMU_KEY)
SENSORS = [WHEEL, IMU_SENSOR]


def _decoders() -> dict[str, object]:
    return {"wheel": make_decoder("odom", "ros2-cdr", "wheel"), "imu": make_decoder("imu", "ros2-cdr", "imu")}


@pytest.fixture(scope="module")
def jackal_samples(jackal_bag: Path) -> list[OdomSample | ImuSample]:
    with open_bag_samples([jackal_bag], SENSORS) as bag:
        assert bag.total == 6121
        assert bag.topics == {"wheel": "/" + JACKAL_ODOM_KEY, "imu": "/" + JACKAL_IMU_KEY}
        assert bag.missing == []
        samples = list(bag)
        assert bag.decode_errors == 0
    return samples


def test_jackal_counts_and_stamps(jackal_samples: list[OdomSample | ImuSample]) -> None:
    odom = [s for s in jackal_samples if isinstance(s, OdomSample)]
    imu = [s for s in jackal_samples if isinstance(s, ImuSample)]
    assert (len(odom), len(imu)) == (3060, 3061)
    assert {s.sensor for s in odom} == {"wheel"} and {s.sensor for s in imu} == {"imu"}
    assert odom[0].stamp == pytest.approx(47.584, abs=1e-9)
    assert all(math.isfinite(s.stamp) for s in jackal_samples)
    assert len(odom[0].twist_covariance) == 36 and len(imu[0].orientation_covariance) == 9


def test_jackal_raw_cdr_is_bag_order_and_decodes_to_the_same_samples(
    jackal_bag: Path, jackal_samples: list[OdomSample | ImuSample]
) -> None:
    raw = list(iter_raw_cdr([jackal_bag], SENSORS))
    times = [t for t, _, _ in raw]
    assert times == sorted(times)
    decoders = _decoders()
    assert [decoders[s.name](cdr) for _, s, cdr in raw] == jackal_samples  # same samples, same order
    # ROS 1 header seq is gone: the payload is exactly what rosbags serialises for ROS 2.
    _, _, first = raw[0]
    msgtype = IMU if raw[0][1].name == "imu" else ODOMETRY
    again = TYPESTORE.serialize_cdr(TYPESTORE.deserialize_cdr(first, msgtype), msgtype, little_endian=True)
    assert first == bytes(again)


def test_wrong_type_names_the_topic(jackal_bag: Path) -> None:
    with pytest.raises(BagError) as err:
        open_bag_samples([jackal_bag], [OdomSensor(name="wheel", key=JACKAL_IMU_KEY)])
    text = str(err.value)
    assert "/imu/data" in text and "sensor_msgs/msg/Imu" in text and "nav_msgs/msg/Odometry" in text


def test_missing_topics(jackal_bag: Path) -> None:
    with open_bag_samples([jackal_bag], [WHEEL, ImuSensor(name="imu2", key="imu/other")]) as bag:
        assert bag.missing == ["imu2"]
        assert bag.total == 3060
        assert bag.topics == {"wheel": "/" + JACKAL_ODOM_KEY}
    with pytest.raises(BagError, match="none of the configured topics"):
        open_bag_samples([jackal_bag], [OdomSensor(name="wheel", key="odom")])


def test_missing_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="no such bag"):
        open_bag_samples([tmp_path / "nope.bag"], SENSORS)


def test_unreadable_bag(tmp_path: Path) -> None:
    (tmp_path / "junk.bag").write_bytes(b"#ROSBAG V2.0\n" + bytes(100))
    with pytest.raises(BagError, match="not a readable ROS 1/ROS 2 bag"):
        open_bag_samples([tmp_path / "junk.bag"], SENSORS)
    with pytest.raises(BagError, match="mix"):
        open_bag_samples([tmp_path / "junk.bag", tmp_path], SENSORS)


def test_a_ros1_bag_cut_short_is_refused_with_how_to_repair_it(jackal_bag: Path, tmp_path: Path) -> None:
    """A recording cut short (the recorder killed) has its chunks but not the index ROS 1 writes last."""
    cut = tmp_path / "cut.bag"
    data = jackal_bag.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match="rosbag reindex"):
        open_bag_samples([cut], [WHEEL])


def test_several_ros1_bags_merge(jackal_bag: Path) -> None:
    with open_bag_samples([jackal_bag, jackal_bag], [WHEEL]) as bag:
        assert bag.total == 2 * 3060
        stamps = [s.stamp for s in bag]
    assert len(stamps) == 2 * 3060 and stamps[0] == stamps[1]


def _write_ros2_bag(path: Path, messages: list[tuple[str, str, int, bytes]]) -> None:
    with Writer(path, version=9) as writer:
        connections: dict[str, object] = {}
        for topic, msgtype, t, data in messages:
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            writer.write(connections[topic], t, data)


def test_ros2_bag_from_jackal_cdr(jackal_bag: Path, tmp_path: Path) -> None:
    """The CDR that `play` publishes, recorded as a ROS 2 bag, replays to the same samples."""
    raw = list(iter_raw_cdr([jackal_bag], SENSORS))[:200]
    rows = [("/" + s.key, ODOMETRY if s.name == "wheel" else IMU, t, cdr) for t, s, cdr in raw]
    rows.append(("/" + JACKAL_ODOM_KEY, ODOMETRY, raw[-1][0] + 1, b"\x00\x01\x00\x00garbage"))
    _write_ros2_bag(tmp_path / "ros2", rows)
    decoders = _decoders()
    with open_bag_samples([tmp_path / "ros2"], SENSORS) as bag:
        assert bag.total == 201
        samples = list(bag)
        assert bag.decode_errors == 1
    assert samples == [decoders[s.name](cdr) for _, s, cdr in raw]
    assert [cdr for _, _, cdr in iter_raw_cdr([tmp_path / "ros2"], SENSORS)][:200] == [cdr for _, _, cdr in raw]


def test_ros2_topic_without_leading_slash(jackal_bag: Path, tmp_path: Path) -> None:
    raw = [r for r in iter_raw_cdr([jackal_bag], [IMU_SENSOR])][:5]
    _write_ros2_bag(tmp_path / "bare", [(JACKAL_IMU_KEY, IMU, t, cdr) for t, _, cdr in raw])
    with open_bag_samples([tmp_path / "bare"], SENSORS) as bag:
        assert bag.topics == {"imu": JACKAL_IMU_KEY} and bag.missing == ["wheel"]
        assert len(list(bag)) == 5


def test_a_ros2_bag_directory_named_dot_bag(tmp_path: Path) -> None:
    """rosbags reads a '.bag' suffix as ROS 1: a link of that name to a ROS 2 bag is followed, a
    directory really named so is a clear error, not 'Is a directory'."""
    bag = tmp_path / "real_bag"
    with Writer(bag, version=9) as writer:
        conn = writer.add_connection("/odom", ODOMETRY, typestore=TYPESTORE)
        from fusiond.core.sensors import encode_sample

        for k in range(3):
            s = OdomSample("wheel", 10.0 + 0.1 * k, (0.1, 0.0, 0.0), (0.0, 0.0, 0.0), (1e-4,) * 36)
            writer.write(conn, int(s.stamp * 1e9), encode_sample(s, "ros2-cdr"))
    link = tmp_path / "run.bag"
    link.symlink_to(bag, target_is_directory=True)
    sensors = [OdomSensor(name="wheel", key="odom")]
    with open_bag_samples([link], sensors) as samples:
        assert len(list(samples)) == 3
    named = tmp_path / "named.bag"
    bag.rename(named)
    with pytest.raises(BagError, match="named \\*.bag"):
        with open_bag_samples([named], sensors):
            pass


def test_what_is_no_bag_is_said_in_the_users_words(tmp_path: Path) -> None:
    """An empty directory is no ROS 2 bag for want of metadata.yaml; a .bag file that does not start as
    one is no ROS 1 bag: each said as such, not as rosbags' own exception."""
    with pytest.raises(BagError, match="not a readable ROS 1/ROS 2 bag .a ROS 2 bag directory holds metadata.yaml"):
        open_bag_samples([tmp_path], SENSORS)
    (tmp_path / "photo.bag").write_bytes(bytes(range(200)))
    with pytest.raises(BagError, match="not a readable ROS 1/ROS 2 bag .a ROS 1 bag starts with '#ROSBAG V2.0'"):
        open_bag_samples([tmp_path / "photo.bag"], SENSORS)
