"""The doctor's standstills are the filter's: a drive that reads noise at rest still stands still.

A small robot's wheels read 0.02 m/s and rad/s of white noise while it stands, and its IMU states 0.14 rad/s
for a gyro of 0.003. The core's rest test (core/sensors/odom/rest.py) finds the three standstills; the
doctor measures the gyro over the same ones, so it can say the stated noise is fifty times too large. Judged
by bins reading exactly zero, it would have found none and said nothing about the gyro's noise.
"""

from __future__ import annotations

import re

import pytest

from fusiond.doctor.gyro import standstill_episodes
from fusiond.replay.run import run_samples

from tests.support.configs import robot_config
from tests.support.sim_rest import RestWorld, Segment, simulate
from tests.support.verdicts import one

GYRO_SIGMA = 0.003
STATED = 0.14
STANDSTILLS = (5.0, 3.0, 3.0)


def _run(rest_noise: float):
    a, b, c = STANDSTILLS
    segments = [Segment(a), Segment(20.0, speed=0.5, yaw_rate=0.2), Segment(b),
                Segment(20.0, speed=0.5, yaw_rate=-0.2), Segment(c), Segment(10.0, speed=0.5, yaw_rate=0.1)]
    world = RestWorld(segments, gyro_bias=(0.002, -0.001, 0.006), gyro_sigma=GYRO_SIGMA, gyro_stated_sigma=STATED,
                      ramp_s=0.5, rest_noise=rest_noise)
    return run_samples(simulate(world), robot_config())


@pytest.mark.parametrize("rest_noise", [0.0, 0.02])
def test_the_standstills_of_a_noisy_drive_are_found_and_the_gyro_measured_over_them(rest_noise):
    """Exact zeros or 0.02 of noise at rest: three standstills, each nearly as long as simulated (less the
    rest test's window and the ramps), and the gyro's noise named from them within 20 % (each holds over
    200 readings: the median's own spread is a few per cent)."""
    result = _run(rest_noise)
    episodes = standstill_episodes(result.doctor.series(), result.core.cfg.filter.standstill_s)
    assert len(episodes) == len(STANDSTILLS), episodes
    for e, length in zip(episodes, STANDSTILLS):
        assert length - 1.5 < e.t1 - e.t0 <= length, (e, length)
    v = one(result.verdicts(), "imu", "gyro_bias")
    assert v.key == "sensors.imu.gyro_noise" and "overstated" in v.message, v
    value = float(re.search(r"gyro_noise = ([0-9.]+)", v.suggestion).group(1))
    assert value == pytest.approx(GYRO_SIGMA, rel=0.2), v


def test_without_the_filter_s_standstills_a_noisy_drive_shows_none():
    """The same noisy run judged by bins reading exactly zero (what a doctor fed no standstills uses):
    none, which is why the filter's own are reported to it."""
    result = _run(0.02)
    series = result.doctor.series()
    series.rest_spans = []
    assert standstill_episodes(series, result.core.cfg.filter.standstill_s) == []
