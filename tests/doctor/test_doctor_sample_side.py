"""A doctor's sample part made apart (``Doctor.sample_side``, as a replay's reading child makes it) and adopted by
a doctor fed only the run's records and estimates (``Doctor.adopt``) says what one doctor fed everything says."""

from __future__ import annotations

import pytest

from fusiond.doctor import Doctor
from fusiond.errors import DoctorError
from fusiond.replay.run import Runner

from tests.support import sim_gps
from tests.support.configs import robot_config


def _run(cfg, samples, apart: bool):
    runner = Runner(cfg, keep_trace=False)
    runner.samples_to_doctor = not apart
    for s, keep in zip(samples, runner.core.snapshot_plan(samples)):
        runner.feed(s, keep)
    if apart:
        side = Doctor(cfg)
        for s in samples:
            side.add_sample(s)
        runner.doctor.adopt(side.sample_side())
    return runner.result()


@pytest.mark.parametrize("world", [
    sim_gps.World(duration=60.0, standstill=5.0, speed=2.0, gps_rate=10.0),
    sim_gps.World(duration=60.0, standstill=3.0, speed=8.0, wheel_scale=1.05, gps_rate=5.0),
], ids=["slow", "wheel_scale"])
def test_an_adopted_sample_part_gives_the_verdicts_and_series_of_one_doctor(world):
    cfg = robot_config(gps="")
    samples = sim_gps.simulate(world)
    whole, apart = _run(cfg, samples, apart=False), _run(cfg, samples, apart=True)
    assert apart.doctor.series() == whole.doctor.series()
    series = whole.doctor.series()
    assert series.rest_spans and series.est_t and series.gps_t and series.odom_t and series.gyro_t
    assert apart.doctor.t0 == whole.doctor.t0
    assert apart.verdicts() == whole.verdicts() and len(whole.verdicts()) > 3


def test_a_doctor_fed_samples_does_not_adopt_another_part():
    cfg = robot_config(gps="")
    samples = sim_gps.simulate(sim_gps.World(duration=10.0, gps_rate=5.0))
    fed, other = Doctor(cfg), Doctor(cfg)
    for s in samples:
        fed.add_sample(s)
        other.add_sample(s)
    with pytest.raises(DoctorError, match="twice"):
        fed.adopt(other.sample_side())
