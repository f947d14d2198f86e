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
