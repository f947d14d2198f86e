"""An IMU driver that marks its angular-velocity covariance unknown (``[0] = -1``) while publishing the rates
(seen on a race car). sensor_msgs/Imu reads that as "no angular velocity", and so does fusiond, unless the user
states the gyro's noise (``gyro_noise``, documented as replacing the message covariance): then the rates are
fused. Without it the heading would come from the wheels alone."""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config

RATE = 0.5  # rad/s: the gyro's turn; the wheels say straight (yaw rate 0), so only the gyro can turn the pose
UNKNOWN = (-1.0,) + (0.0,) * 8


def _samples() -> list:
    """2 s of the IMU reading RATE about z with covariance -1 (100 Hz), the wheels driving straight (50 Hz)."""
    wcov = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    out = []
    for k in range(201):
        t = 100.0 + k * 0.01
        out.append(ImuSample("imu", t, (0.0, 0.0, 0.0, 1.0), UNKNOWN, (0.0, 0.0, RATE), UNKNOWN))
        if k % 2 == 0:
            out.append(OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), wcov))
    return out


def _turn(cfg_imu: str) -> float:
    """Yaw after ``_samples``."""
    core = FusionCore(robot_config(imu=cfg_imu, orientation="off"))
    for s in _samples():
        core.ingest(s)
    return rot.yaw(tuple(core.pose()[1][3:7].tolist()))


def test_gyro_noise_fuses_rates_whose_covariance_says_unknown():
    """With gyro_noise the 2 s at 0.5 rad/s turn the pose by 1 rad (the first sample starts the clock: 2.0 s
    of integration, to a step); without it the rates are not fused and the straight wheels hold yaw at 0."""
    assert _turn("gyro_noise = 0.005") == pytest.approx(RATE * 2.0, abs=0.01)
    assert math.isclose(_turn(""), 0.0, abs_tol=1e-9)


def test_the_doctor_takes_the_same_rates():
    """The doctor's series takes the rates the core fuses: with gyro_noise stated, the gyro's z mean over the
    run is the 0.5 rad/s it read (to its noise), and its stated noise is gyro_noise, not the -1."""
    from fusiond.replay.run import run_samples

    series = run_samples(_samples(), robot_config(imu="gyro_noise = 0.005", orientation="off")).doctor.series()
    assert series.gyro_z and all(z == pytest.approx(RATE) for z in series.gyro_z)
    assert series.gyro_stated_sigma == pytest.approx(0.005)
