"""IMU noise calibration from a static recording with known noise."""

from __future__ import annotations

import numpy as np
import pytest

from fusiond.calibrate import calibrate
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample


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


def driving_straight(n=3000, rate=50.0, speed=1.0, seed=1):
    """A robot driving straight for a minute: the gyro stays near zero (mean rate far below 0.05 rad/s),
    but the floor shakes the accelerometer (0.4 m/s^2 of vibration, a typical wheeled robot on concrete)
    and the odometry reads its speed."""
    rng = np.random.default_rng(seed)
    imu, odom = [], []
    for k in range(n):
        t = 100.0 + k / rate
        acc = (rng.normal(0, 0.4), rng.normal(0, 0.4), 9.81 + rng.normal(0, 0.4))
        imu.append(ImuSample("imu", t, rot.from_rpy(0.0, 0.0, 0.3), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4),
                             tuple(rng.normal(0, 0.003, 3)), (1e-5, 0, 0, 0, 1e-5, 0, 0, 0, 1e-5), acc,
                             (1e-3, 0, 0, 0, 1e-3, 0, 0, 0, 1e-3)))
        if k % 2 == 0:
            odom.append(OdomSample("wheel", t, (speed + rng.normal(0, 0.01), 0.0, 0.0), (0.0, 0.0, 0.0),
                                   tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))))
    return imu, odom


def test_driving_straight_is_refused_by_the_odometry_and_the_accelerometer():
    imu, odom = driving_straight()
    with_odom = calibrate(imu, odom=odom)
    assert with_odom.refuse and any("odometry moved" in m for m in with_odom.motion)
    # without an odometry sensor the accelerometer spread (0.4 m/s^2, ~10x a static IMU's) still refuses
    alone = calibrate(imu)
    assert alone.refuse and any("accelerometer spread" in m for m in alone.motion)
    # the old test (mean gyro rate) alone would have called this static
    assert max(abs(b) for b in alone.gyro_bias) < 0.05


def test_a_static_recording_with_a_standing_odometry_is_accepted():
    imu = static_imu(n=3000)
    odom = [OdomSample("wheel", s.stamp, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0,) * 36) for s in imu[::2]]
    cal = calibrate(imu, odom=odom)
    assert cal.static and not cal.refuse and not cal.motion


def test_calibrate_imu_cli_refuses_a_moving_bag(jackal_bag):
    """The Jackal drives through its whole bag: exit 1 and a message saying why, no snippet."""
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    proc = subprocess.run([sys.executable, "-m", "fusiond", "calibrate-imu", "--bag", str(jackal_bag), "--config",
                           "examples/jackal.toml", "--duration", "30"], cwd=root, capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 1
    assert "not static" in proc.stderr and "odometry moved" in proc.stderr
    assert "orientation_noise" not in proc.stdout
