"""An AHRS whose orientation turns NaN for a stretch while its gyro keeps reading: the orientation's rows are
refused (counted, logged), the gyro of the same message is fused. Refusing the whole sample stopped the heading
for the stretch (the F1/10 car's AHRS with NaN quaternions for 10 s: 87 deg off for good)."""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import ImuSample, OdomSample
from fusiond.estimator import rotation as rot

from tests.support.configs import robot_config

RATE = 0.5  # rad/s about z, read by the gyro; the wheels' yaw rate is not measured (their covariance says so)
COV = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)


def _samples(nan_from: float, nan_to: float) -> list:
    """3 s at 100 Hz of an IMU turning at RATE (its orientation following the turn, NaN in [nan_from, nan_to)),
    and the wheels at 50 Hz driving at 1 m/s with their yaw rate marked not measured."""
    wcov = tuple((1e-4 if i < 21 else 1e6) if i % 7 == 0 else 0.0 for i in range(36))
    out = []
    for k in range(301):
        t = 100.0 + k * 0.01
        q = rot.from_rpy(0.0, 0.0, RATE * (t - 100.0))
        if nan_from <= t < nan_to:
            q = (math.nan,) * 4
        out.append(ImuSample("imu", t, q, COV, (0.0, 0.0, RATE), (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)))
        if k % 2 == 0:
            out.append(OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), wcov))
    return out


def _run(samples: list) -> tuple[float, FusionCore]:
    core = FusionCore(robot_config(orientation="roll_pitch"))
    for s in samples:
        core.ingest(s)
    return rot.yaw(tuple(core.pose()[1][3:7].tolist())), core


def test_a_nan_orientation_keeps_the_gyro_of_its_message():
    clean, _ = _run(_samples(math.inf, math.inf))
    yaw, core = _run(_samples(101.0, 102.0))  # a third of the run with NaN quaternions
    assert yaw == pytest.approx(clean, abs=0.01)  # the gyro turned the heading through the NaN stretch
    assert yaw == pytest.approx(RATE * 3.0, abs=0.05)
    imu = core.sensors.index(next(s for s in core.sensors if s.name == "imu"))
    assert not core.stats[imu].dropped  # no sample lost: its rate was fused
    assert core.models[imu].policy.orientation_dropped == {"non_finite": 100}  # ... and its orientation counted


def test_a_nan_acceleration_is_counted_and_the_rest_of_its_message_fused():
    """An accelerometer reading NaN for a stretch: its gravity tilt is left out of those messages, counted (it
    went unseen: 77 gravity updates of the highway car vanished with no count), their gyro fused."""
    from fusiond.core.sensors.imu import ImuPolicy
    from fusiond.config import ImuSensor

    policy = ImuPolicy(ImuSensor(name="imu", key="imu", orientation="off", angular_velocity=True))
    acc_cov = (0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01)
    msg = ImuSample("imu", 1.0, (0.0, 0.0, 0.0, 1.0), (-1.0,) + (0.0,) * 8, (0.0, 0.0, RATE),
                    (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6), (math.nan, 0.0, 9.81), acc_cov)
    got = policy.convert(msg)
    assert got.accel is None and got.gyro is not None and policy.acceleration_dropped == 1
