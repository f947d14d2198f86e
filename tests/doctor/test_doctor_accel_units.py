"""An accelerometer published in g (``checks/accel_units.py``): named as the driver's unit, whether the filter
reads its tilt from gravity or fuses the IMU's own attitude; one in m/s^2 is not, however it is mounted."""

from __future__ import annotations

import math

import pytest

from fusiond.doctor.checks.accel_units import IN_G_SHARE

from tests.support.configs import robot_config
from tests.support.sim_mount import MountWorld, simulate
from tests.support.verdicts import verdicts_of

G = 9.80665


def _units(verdicts):
    return [v for v in verdicts if v.sensor == "imu" and v.channel == "units"]


@pytest.mark.parametrize("orientation_absent, orientation", [(True, "off"), (False, "roll_pitch")])
def test_an_accelerometer_in_g_is_named(orientation_absent, orientation):
    world = MountWorld(duration=30.0, orientation_absent=orientation_absent, accel_scale=1.0 / G)
    found = _units(verdicts_of(robot_config(orientation=orientation), simulate(world)))
    assert len(found) == 1, found
    v = found[0]
    assert v.level == "warn" and "reads in g" in v.message and "REP 103" in v.message, v
    assert v.evidence["in_g_share"] > IN_G_SHARE and v.evidence["samples"] > 1000, v


@pytest.mark.parametrize("mount", [(0.0, 0.0, 0.0), (math.pi, 0.0, 0.0), (0.0, 0.0, -math.pi / 2)])
def test_an_accelerometer_in_metres_per_second_squared_is_not(mount):
    world = MountWorld(duration=30.0, orientation_absent=True, imu_mount_rpy=mount)
    assert _units(verdicts_of(robot_config(orientation="off"), simulate(world))) == []
