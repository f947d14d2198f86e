"""Odometry noise per second of travel, not per message; wheel scale on with GPS."""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config

SPEED, SIGMA_V, DURATION = 10.0, 0.1, 60.0


def _config(odom: str = "", extra: str = ""):
    return robot_config(odom=odom, imu=extra)


def _straight_drive(odom_rate: float) -> list:
    """A car driving straight along east at SPEED: odometry at ``odom_rate`` stating SIGMA_V on
    every twist component, a 100 Hz IMU (level, gyro at zero). Noise-free readings: the
    covariance does not depend on the noise drawn, only on the motion and what is stated."""
    cov = tuple(SIGMA_V**2 if i % 7 == 0 else 0.0 for i in range(36))
    out = []
    n_odom, n_imu = int(DURATION * odom_rate), int(DURATION * 100.0)
    for k in range(n_odom + 1):
        out.append(OdomSample("wheel", 1000.0 + k / odom_rate, (SPEED, 0.0, 0.0), (0.0, 0.0, 0.0), cov))
    for k in range(n_imu + 1):
        out.append(ImuSample("imu", 1000.0005 + k / 100.0, rot.from_rpy(0.0, 0.0, 0.0),
                             (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e6), (0.0, 0.0, 0.0), (4e-6, 0, 0, 0, 4e-6, 0, 0, 0, 4e-6)))
    out.sort(key=lambda s: s.stamp)
    return out


def _along_track_sigma(odom_rate: float, odom: str = "") -> float:
    core = FusionCore(_config(odom))
    for s in _straight_drive(odom_rate):
        assert core.ingest(s).accepted
    return math.sqrt(core.state.ekf.P[0, 0])  # east = along the track


@pytest.mark.long_sim
def test_10_and_83_hz_odometry_of_the_same_drive_end_with_the_same_covariance():
    """The stated twist sigma is a velocity error lasting tau = twist_correlation_s (0.5 s): over
    t >> tau the along-track variance is SIGMA_V^2 * 2 tau * t + process_noise^2 * t, whatever the
    message rate (zero-order hold of a constant speed: no discretisation error along the track).
    Per message (tau = 0) it would be SIGMA_V^2 * T * t: sqrt(83/10) = 2.9x apart."""
    slow, fast = _along_track_sigma(10.0), _along_track_sigma(83.0)
    assert fast == pytest.approx(slow, rel=0.10)
    expected = math.sqrt((SIGMA_V**2 * 2 * 0.5 + 0.002**2) * DURATION)  # 0.775 m
    assert slow == pytest.approx(expected, rel=0.10)
    # the old per-message model, still available as twist_correlation_s = 0, is rate dependent
    old_slow = _along_track_sigma(10.0, "twist_correlation_s = 0.0")
    old_fast = _along_track_sigma(83.0, "twist_correlation_s = 0.0")
    assert old_slow / old_fast > 2.5


GPS = '[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "gps"\n'
ABS_POSE = '[[sensors]]\nname = "mocap"\nkind = "pose"\nkey = "mocap"\n'
VO = '[[sensors]]\nname = "vo"\nkind = "pose"\nkey = "vo"\ndifferential = true\n'


@pytest.mark.parametrize("odom, extra, expected", [
    ("", "", False),  # nothing makes a wheel scale observable
    ("", VO, False),  # a drifting pose does not either
    ("", GPS, True),
    ("", ABS_POSE, True),
    ("scale_estimation = false", GPS, False),  # explicit opt-out
    ("scale_estimation = true", "", True),  # explicit opt-in
])
def test_wheel_scale_is_estimated_by_default_once_an_absolute_position_is_fused(odom, extra, expected):
    assert FusionCore(_config(odom, extra)).layout.has("wheel_scale") is expected
