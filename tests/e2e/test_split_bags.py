"""A recording split into several ROS 2 bags (a recorder's split by size or duration, or two sessions) is
replayed as one: rosbags' reader merges them in time order, as it does ROS 1 bags."""

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

    samples = simulate(SimConfig(duration=10.0, standstill=2.0))
    cfg = robot_config(imu_key="imu")
    whole = _write(tmp_path / "whole", samples)
    expected = replay([whole], cfg, doctor=False, progress=False).trajectory
    (whole / "metadata.yaml").unlink()
    with capture_logs() as logs:  # read here, not in a forked child, for its log line to be captured
        got = replay([whole], cfg, doctor=False, progress=False, read_ahead=False).trajectory
    assert got == expected
    assert any(e["event"] == "bag_metadata_missing" for e in logs), logs
