"""Bags as users have them: a recording split into several ROS 2 bags (a recorder's split by size or
duration, or two sessions) replayed as one, merged in time order by rosbags' reader as ROS 1 bags are; a ROS 2
bag directory whose metadata.yaml was never written; a ROS 1 topic whose type was re-registered under
another name."""

from __future__ import annotations

from pathlib import Path

import pytest

from fusiond.replay.run import replay

from tests.support.configs import robot_config
from tests.support.ros2_bags import write_ros2_bag
from tests.support.sim import SimConfig, simulate

pytestmark = pytest.mark.e2e


def _write(path: Path, samples: list) -> Path:
    return write_ros2_bag(path, samples)


def test_a_recording_split_into_two_ros2_bags_replays_as_the_whole(tmp_path):
    samples = simulate(SimConfig(duration=20.0, standstill=2.0))
    cut = len(samples) // 2
    whole = _write(tmp_path / "whole", samples)
    first, second = _write(tmp_path / "part1", samples[:cut]), _write(tmp_path / "part2", samples[cut:])
    cfg = robot_config(imu_key="imu")
    one = replay([whole], cfg, doctor=False, progress=False)
    both = replay([second, first], cfg, doctor=False, progress=False)  # in either order: merged by time
    assert both.trajectory == one.trajectory and len(one.trajectory) > 100
    assert both.applied == one.applied


def test_a_ros2_bag_directory_without_its_metadata_is_read_from_its_one_storage_file(tmp_path):
    """A recorder cut off before it wrote metadata.yaml leaves the .db3 whole: the directory is read from that
    file (rosbags reads it alone), with a log line saying so, instead of refused as not a bag."""
    from structlog.testing import capture_logs

    from fusiond.logs import configure

    samples = simulate(SimConfig(duration=10.0, standstill=2.0))
    cfg = robot_config(imu_key="imu")
    whole = _write(tmp_path / "whole", samples)
    expected = replay([whole], cfg, doctor=False, progress=False).trajectory
    (whole / "metadata.yaml").unlink()
    configure("warning")  # capture_logs keeps the level's filter: an earlier test's --quiet would drop warnings
    with capture_logs() as logs:  # read here, not in a forked child, for its log line to be captured
        got = replay([whole], cfg, doctor=False, progress=False, read_ahead=False).trajectory
    assert got == expected
    assert any(e["event"] == "bag_metadata_missing" for e in logs), logs


def test_a_ros1_topic_of_another_type_name_with_the_same_definition_is_read_as_its_kind(jackal_bag, tmp_path):
    """The Jackal's odometry re-registered by its driver as my_msgs/Odometry (the same fields, so the same ROS 1
    MD5): read as nav_msgs/Odometry, with a log line, and the replay is the original's to the byte. It was
    refused (no key to state another type)."""
    from rosbags.rosbag1 import Reader, Writer
    from structlog.testing import capture_logs

    from fusiond.config import load
    from fusiond.logs import configure

    renamed = tmp_path / "custom.bag"
    with Reader(jackal_bag) as reader:
        writer = Writer(renamed)
        writer.open()
        conns = {}
        for c in reader.connections:
            msgtype = "my_msgs/msg/Odometry" if c.msgtype == "nav_msgs/msg/Odometry" else c.msgtype
            conns[c.id] = writer.add_connection(c.topic, msgtype, msgdef=c.msgdef.data, md5sum=c.digest,
                                                callerid=c.ext.callerid, latching=c.ext.latching)
        for c, t, raw in reader.messages():
            writer.write(conns[c.id], t, raw)
        writer.close()
    cfg = load(Path(__file__).resolve().parents[2] / "examples" / "jackal.toml")
    original = replay([jackal_bag], cfg, doctor=False, progress=False).trajectory
    configure("warning")  # capture_logs keeps the level's filter: an earlier test's --quiet would drop warnings
    with capture_logs() as logs:  # read here, not in a forked child, for its log line to be captured
        got = replay([renamed], cfg, doctor=False, progress=False, read_ahead=False).trajectory
    assert got == original and len(got) > 1000
    assert any(e["event"] == "topic_read_as" and e["msgtype"] == "my_msgs/msg/Odometry" for e in logs), logs
    # `fusiond info` and `init` read it as its kind too, and say what the bag calls it
    from fusiond.bag_info import format_info, inspect_bags

    odom = next(t for t in inspect_bags([renamed]).topics if t.topic == "/jackal_velocity_controller/odom")
    assert (odom.msgtype, odom.recorded_as) == ("nav_msgs/msg/Odometry", "my_msgs/msg/Odometry"), odom
    assert "recorded as my_msgs/msg/Odometry" in format_info(inspect_bags([renamed]))
