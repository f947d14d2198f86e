"""The plain EKF (scripts/plain_ekf.py), the benchmark's textbook filter, on the Jackal bag configured as
robot_localization's test was: a sanity pin that it runs on a real bag and ends near robot_localization's
final pose. Skipped without the shared recordings (../shared/data), as the real-recordings benchmark is."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tests.support.scripts import load_script

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data"
RL_FINAL = (1.0206, 3.4292, 0.7419)  # robot_localization's EKF on this bag (its test suite)

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.skipif(not DATA.exists(), reason=f"the shared recordings are not in {DATA} (see docs/RESULTS.md)"),
]


def _plain():
    return load_script("plain_ekf")


def test_plain_ekf_ends_near_robot_localizations_final_pose_on_the_jackal_bag():
    from fusiond.config import load

    bag = ROOT / "data" / "jackal_test2.bag"
    if not bag.exists():
        bag = DATA / "jackal_test2.bag"
    traj = _plain().run([bag], load(ROOT / "examples" / "jackal_rl.toml"))
    assert traj.shape[0] == 3060  # one pose per odometry message
    assert np.all(np.isfinite(traj))
    assert np.all(np.diff(traj[:, 0]) >= 0.0)  # in header-stamp order
    np.testing.assert_allclose(np.linalg.norm(traj[:, 4:8], axis=1), 1.0, atol=1e-9)
    d = math.dist(traj[-1, 1:4], RL_FINAL)
    assert d < 2.0, f"the plain EKF ends {d:.3f} m from robot_localization's final pose"


def test_plain_ekf_with_a_gps_publishes_from_its_first_fix_on():
    """The highway car with its GPS: the odometry begins before the first fix, and before it the filter's
    position is the datum's, not the car's (a recording that starts away from its datum scored the plain EKF
    hundreds of metres off there). Its first pose is at or after the first fix, as fusiond's is."""
    from rosbags.highlevel import AnyReader

    from fusiond.config import load

    bag = DATA / "comma2k19_ex1"
    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic in ("/fix", "/odom")]
        first = {}
        for c, _, raw in reader.messages(connections=conns):
            h = reader.deserialize(raw, c.msgtype).header.stamp
            first.setdefault(c.topic, h.sec + 1e-9 * h.nanosec)
            if len(first) == 2:
                break
    assert first["/odom"] < first["/fix"]  # the case this is about
    traj = _plain().run([bag], load(ROOT / "examples" / "comma2k19.toml"))
    assert traj[0, 0] >= first["/fix"] - 1e-6
