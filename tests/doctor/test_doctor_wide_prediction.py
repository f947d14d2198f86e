"""Fixes whose stated noise is right, beside wheels whose twist noise is stated ten times too wide: the fixes'
innovations are smaller than what the filter's prediction alone claims between them, so no position_noise
brings their NIS up; the doctor names the odometry's twist_noise (which `fusiond tune` fits), not the GPS's.
Simulated: 120 s at 3 m/s, fixes of 0.3 m at 2 Hz stated as such, the wheels' noise 0.02 m/s stated 1.0."""

from __future__ import annotations

from fusiond.replay.run import run_samples

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate
from tests.support.verdicts import one


def _gps_position(odom: str):
    w = World(duration=120.0, speed=3.0, gps_rate=2.0, gps_sigma=0.3, seed=3)
    cfg = robot_config(gps="position_noise = [0.3, 0.3, 0.3]", odom=odom)
    return one(run_samples(simulate(w), cfg).verdicts(), "gps", "position")


def test_a_prediction_stated_too_wide_names_the_wheels_twist_noise():
    v = _gps_position("twist_noise = [1.0, 1.0, 1.0, 0.05, 0.05, 0.05]")
    assert v.level == "warn" and v.key == "sensors.wheel.twist_noise", v
    assert v.evidence["innovation_rms_m"] < v.evidence["prediction_alone_rms_m"], v.evidence
    assert _gps_position("").level == "ok"
