"""A robot without an IMU (wheel odometry and a GPS) gets the doctor's verdicts like any other: the IMU's series
stay empty instead of failing on a mounting that is not there."""

from __future__ import annotations

from fusiond.config import loads
from fusiond.replay.run import run_samples

from tests.support.sim_gps import World, simulate

CONFIG = """
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
[[sensors]]
name = "gps"
kind = "gps"
key = "gps"
"""


def test_odometry_and_gps_without_an_imu_are_diagnosed():
    result = run_samples(simulate(World(duration=60.0, gps_rate=5.0)), loads(CONFIG))
    verdicts = result.verdicts()
    assert {v.sensor for v in verdicts} >= {"wheel", "gps"}, verdicts
    series = result.doctor.series()
    assert series.odom_t and series.gps_t and not series.gyro_t and not series.acc_t
