"""orientation_noise lives in the IMU's own axes: the doctor's figure and tune's fitted components name the
same axes through the mount (core/sensors/imu/axes.py)."""

from __future__ import annotations

import math

from fusiond.core.sensors.imu.axes import seen_axes, weights
from fusiond.core.sensors import ImuSample
from fusiond.tune.params import tunable_params

from tests.support.configs import robot_config

# An IMU on its side: roll pi/2, yaw -pi/2. Its x lands on base pitch, its y on base yaw, its z on base roll.
SIDEWAYS = (math.pi / 2, 0.0, -math.pi / 2)


def test_weights_are_the_squared_mount():
    W = weights(SIDEWAYS)
    for k in range(3):
        assert math.isclose(sum(W[k]), 1.0)  # a rotation's rows are unit vectors
    assert math.isclose(W[1][0], 1.0, abs_tol=1e-12) and math.isclose(W[2][1], 1.0, abs_tol=1e-12)
    assert math.isclose(W[0][2], 1.0, abs_tol=1e-12)


def test_seen_axes_follow_the_mount():
    assert seen_axes((0.0, 0.0, 0.0), (0, 1)) == (0, 1)
    assert seen_axes(SIDEWAYS, (0, 1)) == (0, 2)  # base roll and pitch come from the IMU's z and x
    assert seen_axes(SIDEWAYS, (0, 1, 2)) == (0, 1, 2)
    assert seen_axes((0.0, 0.0, math.pi / 4), (0, 1)) == (0, 1)  # a yawed mount mixes roll and pitch only


def test_tune_fits_the_imu_axes_that_land_on_the_fused_rows():
    cfg = robot_config(imu="extrinsic_rpy = [1.5707963267948966, 0.0, -1.5707963267948966]")
    cov = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
    samples = [ImuSample("imu", 10.0 + 0.01 * k, (0.0, 0.0, 0.0, 1.0), cov, (0.0, 0.0, 0.0),
                         (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6), (0.0, 0.0, 9.8), (-1.0,) + (0.0,) * 8)
               for k in range(20)]
    param = next(p for p in tunable_params(cfg, samples) if p.key == "orientation_noise")
    assert param.indices == (0, 2) and not param.skipped
