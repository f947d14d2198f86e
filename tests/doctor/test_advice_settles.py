"""Advice settles: a noise the doctor measured, pasted once, is not asked for again (the figure is the
noise itself, not a step toward it)."""

from __future__ import annotations

import pytest

from fusiond.tune.advice import with_suggestion

from tests.support.configs import robot_config
from tests.support.sim import SimConfig
from tests.support.sim import simulate as simulate_imu
from tests.support.sim_rest import RestWorld, Segment
from tests.support.sim_rest import simulate as simulate_rest
from tests.support.verdicts import verdicts_of


def _gyro_stated_fifty_times_too_large():
    segments = [Segment(5.0), Segment(20.0, speed=0.5, yaw_rate=0.2), Segment(3.0),
                Segment(20.0, speed=0.5, yaw_rate=-0.2), Segment(3.0)]
    world = RestWorld(segments, gyro_bias=(0.002, -0.001, 0.006), gyro_sigma=0.003, gyro_stated_sigma=0.14,
                      ramp_s=0.5)
    return robot_config(), simulate_rest(world), "sensors.imu.gyro_noise"


def _orientation_stated_25_times_too_large():
    return (robot_config(imu="orientation_noise = [0.05, 0.05, 0.05]"),
            simulate_imu(SimConfig(duration=60.0, orientation_sigma=0.002)), "sensors.imu.orientation_noise")


@pytest.mark.parametrize("case", [_gyro_stated_fifty_times_too_large, _orientation_stated_25_times_too_large])
def test_a_pasted_noise_is_not_asked_for_again(case):
    cfg, samples, key = case()
    asked = [v for v in verdicts_of(cfg, samples) if v.key == key and v.suggestion]
    assert len(asked) == 1  # the doctor finds the misstated noise ...
    pasted, _ = with_suggestion(cfg, asked[0])
    again = [v for v in verdicts_of(pasted, samples) if v.key == key and v.suggestion]
    assert again == []  # ... and once it is pasted, has nothing more to ask of that key
