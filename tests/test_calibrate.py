"""IMU noise calibration from a static recording with known noise."""

from __future__ import annotations

import numpy as np
import pytest

from fusiond.calibrate import calibrate
from fusiond.estimator import rotation as rot
from fusiond.samples import ImuSample


def static_imu(n=6000, rate=100.0, ori_sigma=(0.01, 0.02, 0.05), gyro_sigma=0.003, bias=(0.001, -0.002, 0.003),
               seed=0, stated=1e-6):
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        r, p, y = (rng.normal(0, s) for s in ori_sigma)
        w = tuple(b + rng.normal(0, gyro_sigma) for b in bias)
        out.append(ImuSample("imu", 100.0 + k / rate, rot.from_rpy(r, p, 1.0 + y),
                             (stated, 0, 0, 0, stated, 0, 0, 0, stated), w, (stated, 0, 0, 0, stated, 0, 0, 0, stated)))
    return out


def test_calibration_recovers_the_noise_it_was_given():
    cal = calibrate(static_imu())
    assert cal.static and cal.rate_hz == pytest.approx(100.0)
    assert cal.orientation_sigma == pytest.approx((0.01, 0.02, 0.05), rel=0.05)
    assert cal.gyro_sigma == pytest.approx((0.003,) * 3, rel=0.05)
    assert cal.gyro_bias == pytest.approx((0.001, -0.002, 0.003), abs=2e-4)
    snippet = cal.snippet()
    assert "orientation_noise = [0.0" in snippet and "gyro_noise = 0.00" in snippet and "[filter]" in snippet
    assert "the messages state" in snippet  # the lying covariance is shown beside the measured one


def test_a_moving_imu_is_called_out():
    samples = static_imu(n=500, bias=(0.0, 0.0, 0.4))
    cal = calibrate(samples)
    assert not cal.static and "WARNING" in cal.snippet()


def test_too_few_samples_is_an_error():
    with pytest.raises(ValueError, match="at least 10"):
        calibrate(static_imu(n=5))
