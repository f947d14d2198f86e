"""Covariance resets are counted once each: in propagate and in update alike, and not again when a
late sample makes the core re-apply the prediction that reset.

The fault is injected by writing a non-finite or overflowing value into P (no valid input can make
P non-finite: the policies reject non-finite and implausible values), which is the state a
numerically broken model would leave.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import ErrorStateEKF, PoseBlock, StateLayout
from fusiond.estimator import observations as obs

from tests.support.core_samples import imu, make_config, odom

# the injected overflow is the point; numpy says so on the way
pytestmark = pytest.mark.filterwarnings("ignore:(overflow|invalid value) encountered:RuntimeWarning")


def test_update_that_overflows_p_resets_and_says_so():
    """Position-attitude correlation of 1e160 with an attitude variance of 0.01: S stays finite,
    but K S K^T has (1e160)^2 / S ~ 1e322 in the position block, which overflows."""
    layout = StateLayout([PoseBlock(0.1, 0.1)])
    ekf = ErrorStateEKF(layout)
    ekf.P[0, 3] = ekf.P[3, 0] = 1e160
    y, H, R = obs.orientation(layout, ekf.x, (0.01, 0.0, 0.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4), (0, 1, 2))
    res = ekf.update(y, H, R)
    assert not res.rejected and res.covariance_reset
    assert ekf.resets == 1
    np.testing.assert_array_equal(ekf.P, layout.initial_covariance())
    res = ekf.update(y, H, R)  # a healthy update after the reset: nothing more counted
    assert not res.covariance_reset and ekf.resets == 1


def test_core_counts_a_reset_inside_an_update():
    core = FusionCore(make_config(orientation="absolute", gyro=False))
    core.ingest(imu(1.0))
    core.ingest(odom(1.0))
    assert core.covariance_resets == 0
    P = core.state.ekf.P
    P[0, 3] = P[3, 0] = 1e160  # survives the prediction to 1.01 (the robot stands: F P F^T ~ P)
    step = core.ingest(imu(1.01))
    assert step.accepted
    assert core.covariance_resets == 1
    assert np.isfinite(core.state.ekf.P).all()


def test_core_counts_a_reset_inside_a_prediction_once_across_re_application():
    """A reset in the prediction from 1.0 to 1.02, then a late sample at 1.01: the core rewinds to
    the (broken) state after 1.0, predicts to 1.01 (reset there now) and re-applies 1.02. One
    broken covariance, one reset counted (the old code counted the re-applied one again)."""
    core = FusionCore(make_config(orientation="absolute", gyro=False))
    core.ingest(imu(1.0))
    core.ingest(odom(1.0))
    core.state.ekf.P[0, 0] = math.inf  # the live state ...
    core.history.after[-1].ekf.P[0, 0] = math.inf  # ... and its snapshot, so a rewind meets it again
    core.ingest(odom(1.02))
    assert core.covariance_resets == 1
    step = core.ingest(imu(1.01))
    assert step.accepted and step.late
    assert core.covariance_resets == 1
    assert core.state.ekf.resets == 1  # the newest timeline has had exactly one reset
    assert np.isfinite(core.state.ekf.P).all()
