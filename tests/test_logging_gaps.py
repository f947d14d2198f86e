"""Logging gaps: no input outlives its sensor, whatever the length of the gap.

A logger that stops every sensor for tens of seconds used to leave the last twist
and gyro rate inside one long prediction step: the pose jumped by speed x gap and
the attitude integrated the last rates. The simulated robot drives at 1 m/s while
turning; every sensor is silent for 26.4 s.
"""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot

from .sim import SimConfig, simulate
from .test_fusion_core import make_config

GAP_START, GAP = 1010.0, 26.4  # sim stamps start at 1000 s


@pytest.mark.parametrize("orientation", ["roll_pitch", "absolute"])
def test_a_long_gap_moves_the_pose_by_at_most_speed_times_timeout(orientation):
    sim = SimConfig(duration=40.0, odom_rate=50.0, imu_rate=100.0, gyro_bias=(0.02, -0.02, 0.0))
    samples = [s for s in simulate(sim) if not GAP_START <= s.stamp < GAP_START + GAP]
    core = FusionCore(make_config(orientation))
    before = [s for s in samples if s.stamp < GAP_START]
    after = [s for s in samples if s.stamp >= GAP_START]
    for s in before:
        core.ingest(s)
    t0, x0 = core.pose()
    x0 = x0.copy()
    for k, s in enumerate(after):
        step = core.ingest(s)
        if step.accepted:  # the new timeline confirmed (held samples applied)
            break
    t1, x1 = core.pose()
    # The robot drives at 1 m/s and turns at |w| <= 0.3 rad/s (tests/sim.py). Inputs are held
    # for the odometry/gyro timeout (0.2 s at 50/100 Hz: max(timeout_s, 3 periods)); after the
    # gap the filter integrates the held post-gap samples (t1 - (GAP_START + GAP)). Anything
    # beyond that bound is the gap integrated with stale inputs (26.4 m before the fix).
    timeout = 0.2
    post = t1 - (GAP_START + GAP)
    assert 0.0 < post < 1.5
    moved = math.dist(x0[0:3], x1[0:3])
    assert moved <= 1.0 * (timeout + post) + 0.05
    # Attitude: the gyro's last rates (x/y bias 0.02 rad/s) are held for 0.2 s at most, the yaw
    # rate likewise; before the fix, 26.4 s of them tumbled the attitude by ~0.5 rad.
    r0, p0, y0 = rot.to_rpy(tuple(x0[3:7].tolist()))
    r1, p1, y1 = rot.to_rpy(tuple(x1[3:7].tolist()))
    if orientation == "roll_pitch":
        assert abs(rot.wrap(y1 - y0)) <= 0.3 * (timeout + post) + 0.05
    else:  # the IMU's absolute yaw brings the heading back to the truth after the gap
        yaw_true = min(sim.truth, key=lambda r: abs(r[0] - t1))[3]
        assert abs(rot.wrap(y1 - yaw_true)) < 0.05
    assert abs(r1 - r0) <= 0.03 * (timeout + post) + 0.02 and abs(p1 - p0) <= 0.03 * (timeout + post) + 0.02
    # and the covariance says the filter lost track over the gap (inflated, not over-confident)
    assert core.state.ekf.P[0, 0] >= core.cfg.filter.gap_inflation[0] ** 2 * (GAP - core.cfg.filter.gap_s) * 0.99


def test_a_gap_shorter_than_the_jump_threshold_is_bounded_too():
    """A 3 s gap (below jump_s) is one prediction step: split at each sensor's timeout."""
    sim = SimConfig(duration=20.0, odom_rate=50.0, imu_rate=100.0)
    samples = [s for s in simulate(sim) if not 1010.0 <= s.stamp < 1013.0]
    core = FusionCore(make_config("roll_pitch"))
    for s in samples:
        if s.stamp >= 1013.0:
            t0, x0 = core.pose()
            x0 = x0.copy()
            step = core.ingest(s)
            assert step.accepted
            t1, x1 = core.pose()
            break
        core.ingest(s)
    # held input 0.2 s at 1 m/s, then the first sample after the gap is predicted to at zero speed
    assert math.dist(x0[0:3], x1[0:3]) <= 1.0 * 0.2 + 1e-6
    assert t1 - t0 > 2.9
