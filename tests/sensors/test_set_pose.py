"""FusionCore.set_pose (robot_localization's set_pose) without Zenoh: what is reset, what survives."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator.rotation import from_rpy, to_rpy
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config


COV6 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
COV3 = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
GYRO_COV = (1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e-6)
BIAS = 0.01  # rad/s on the gyro's z axis


def drive(core: FusionCore, t0: float, t1: float, imu_yaw: float = 0.0, v: float = 0.5) -> None:
    """Odometry at 50 Hz (v m/s, no turn) and a biased gyro at 100 Hz reading a robot that does not turn."""
    k = 0
    while t0 + 0.01 * k <= t1 + 1e-9:
        t = t0 + 0.01 * k
        core.ingest(ImuSample("imu", t, from_rpy(0.0, 0.0, imu_yaw), COV3, (0.0, 0.0, BIAS), GYRO_COV))
        if k % 2 == 0:
            core.ingest(OdomSample("wheel", t, (v, 0.0, 0.0), (0.0, 0.0, 0.0), COV6))
        k += 1


def test_set_pose_resets_the_pose_and_history_and_keeps_the_gyro_bias():
    core = FusionCore(robot_config())
    drive(core, 10.0, 20.0, v=0.0)  # standing still: the gyro bias is learned
    bias = float(core.gyro_bias[2])
    assert bias == pytest.approx(BIAS, abs=2e-3)
    stamp = core.time
    cov = [0.0] * 36
    for i in range(6):
        cov[7 * i] = 0.04 if i < 3 else 0.01
    core.set_pose(stamp, (3.0, -2.0, 0.0), from_rpy(0.0, 0.0, 1.2), cov)
    est = core.estimate()
    assert est.stamp == stamp and est.position == (3.0, -2.0, 0.0)
    assert to_rpy(est.orientation)[2] == pytest.approx(1.2, abs=1e-12)
    P = np.reshape(est.pose_covariance, (6, 6))
    assert np.allclose(P, np.diag([0.04] * 3 + [0.01] * 3))
    assert est.linear == (0.0, 0.0, 0.0)  # the held twist is forgotten, as robot_localization zeroes it
    assert float(core.gyro_bias[2]) == bias  # a property of the sensor, not of the pose: kept
    # the history starts at the new pose: a sample older than it cannot be placed
    step = core.ingest(OdomSample("wheel", stamp - 0.05, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), COV6))
    assert not step.accepted and step.reason == "too_old"


def test_a_relative_imu_measures_its_offset_again_instead_of_pulling_yaw_back():
    core = FusionCore(robot_config(orientation="relative"))
    drive(core, 10.0, 12.0, imu_yaw=0.4)  # the IMU reads 0.4 rad while the filter starts at yaw 0
    core.set_pose(core.time, (0.0, 0.0, 0.0), from_rpy(0.0, 0.0, -1.0), [1e-4 if i % 7 == 0 else 0.0
                                                                          for i in range(36)])
    t = core.time
    drive(core, t + 0.01, t + 2.0, imu_yaw=0.4)
    # with the old offset (0.4) the IMU would say yaw 0 and pull the estimate there; re-measured
    # at the set pose it agrees with -1.0 (the gyro's bias is estimated, so heading holds)
    assert to_rpy(core.estimate().orientation)[2] == pytest.approx(-1.0, abs=0.02)


@pytest.mark.parametrize("args, problem", [
    ((math.nan, (0, 0, 0), (0, 0, 0, 1), [0.0] * 36), "stamp"),
    ((0.0, (0, 0, 0), (0, 0, 0, 1), [0.0] * 36), "stamp"),
    ((5.0, (0, math.inf, 0), (0, 0, 0, 1), [0.0] * 36), "position"),
    ((5.0, (0, 0, 0), (0, 0, 0, 0), [0.0] * 36), "orientation"),
    ((5.0, (0, 0, 0), (0, 0, 0, 1), [0.0] * 35), "covariance"),
    ((5.0, (0, 0, 0), (0, 0, 0, 1), [-1.0] + [0.0] * 35), "negative variance"),
])
def test_invalid_set_pose_raises_naming_the_problem_and_changes_nothing(args, problem):
    core = FusionCore(robot_config())
    drive(core, 10.0, 11.0)
    before = core.estimate()
    with pytest.raises(ValueError, match=problem):
        core.set_pose(*args)
    assert core.estimate() == before
