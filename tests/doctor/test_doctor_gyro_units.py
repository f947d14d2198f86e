"""A gyro published in deg/s (``checks/gyro_units.py``): the wheels' yaw rate and the IMU's own yaw turn
pi/180 of the gyro's. Simulated: the robot weaves (0.3 rad/s), the gyro's rates multiplied by 180/pi."""

from __future__ import annotations

import math

import msgspec
import pytest

from fusiond.core.sensors import ImuSample
from fusiond.doctor.checks.gyro_units import in_degrees

from tests.support.core_samples import make_config
from tests.support.sim import SimConfig, simulate
from tests.support.verdicts import verdicts_of


def _in_degrees(samples):
    return [msgspec.structs.replace(s, angular_velocity=tuple(math.degrees(w) for w in s.angular_velocity))
            if type(s) is ImuSample else s for s in samples]


@pytest.mark.parametrize("orientation", ["roll_pitch", "absolute"])
def test_a_gyro_in_degrees_per_second_is_named_and_explains_the_imus_other_findings(orientation):
    samples = _in_degrees(simulate(SimConfig(duration=30.0, standstill=2.0)))
    verdicts = verdicts_of(make_config(orientation=orientation), samples)
    units = [v for v in verdicts if v.channel == "units"]
    assert len(units) == 1 and units[0].sensor == "imu" and units[0].level == "problem", verdicts
    assert "degrees per second" in units[0].message and "REP 103" in units[0].message
    assert all(in_degrees(k) for k in units[0].evidence.values()) and units[0].evidence, units[0]
    others = [v for v in verdicts if v.sensor == "imu" and v.channel == "orientation" and v.level != "ok"]
    assert all("explained by imu/units" in v.message for v in others), others


def test_a_gyro_in_radians_gets_no_units_verdict():
    verdicts = verdicts_of(make_config(orientation="absolute"), simulate(SimConfig(duration=30.0, standstill=2.0)))
    assert not [v for v in verdicts if v.channel == "units"], verdicts


@pytest.mark.parametrize("k, degrees", [(math.pi / 180, True), (1 / 40.0, True), (1 / 100.0, True), (1.0, False),
                                        (2.3, False), (0.3, False), (1 / 15.0, False), (57.3, False)])
def test_only_a_scale_near_pi_over_180_is_the_unit(k, degrees):
    """A skid-steer's wheels read 0.3-3 times the turn; a unit is 57.3 times."""
    assert in_degrees(k) is degrees
