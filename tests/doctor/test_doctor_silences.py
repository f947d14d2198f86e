"""A sensor silent while the wheels kept reporting (doctor/checks/silences.py): an IMU that drops out is
named, a GPS without a fix is said at level ok, and a logging gap of every sensor is neither."""

from __future__ import annotations

import pytest

from fusiond.core.sensors import ImuSample

from tests.support import sim_gps
from tests.support.configs import robot_config
from tests.support.sim import SimConfig, simulate
from tests.support.verdicts import verdicts_of

T0 = 1000.0  # the simulations' first stamp


def _inputs(verdicts, sensor: str) -> list:
    return [v for v in verdicts if v.sensor == sensor and v.channel == "input"]


def test_an_imu_that_drops_out_while_the_wheels_report_is_named():
    samples = [s for s in simulate(SimConfig(duration=40.0, standstill=2.0))
               if not (type(s) is ImuSample and T0 + 20.0 <= s.stamp < T0 + 25.0)]
    (v,) = _inputs(verdicts_of(robot_config(), samples), "imu")
    assert v.level == "warn" and "silent 1 time(s)" in v.message and "wheels' yaw rate alone" in v.message, v
    assert v.evidence["longest_s"] == pytest.approx(5.0, abs=0.3), v


def test_an_imu_lost_for_good_while_the_wheels_report_is_named():
    """The IMU stops 15 s into a 40 s drive and never comes back: no interval between its own stamps shows it,
    the wheels' last stamp does. It had gone unsaid (the live daemon said it; the replay's doctor did not)."""
    samples = [s for s in simulate(SimConfig(duration=40.0, standstill=2.0))
               if not (type(s) is ImuSample and s.stamp >= T0 + 15.0)]
    (v,) = _inputs(verdicts_of(robot_config(), samples), "imu")
    assert v.level == "warn" and "silent 1 time(s)" in v.message, v
    assert v.evidence["longest_s"] == pytest.approx(25.0, abs=0.3), v


def test_an_imu_lost_for_good_across_a_later_logging_gap_is_named_for_the_stretches_the_wheels_reported():
    """The IMU stops 10 s in; every sensor is silent from 20 s to 28 s (a logging gap); the wheels report the rest:
    the IMU's silence spans the gap, and it was said of no stretch (the odometry's own gap was inside it). It is
    silent twice, the longest the 12 s after the gap."""
    samples = [s for s in simulate(SimConfig(duration=40.0, standstill=2.0))
               if not (type(s) is ImuSample and s.stamp >= T0 + 10.0) and not T0 + 20.0 <= s.stamp < T0 + 28.0]
    (v,) = _inputs(verdicts_of(robot_config(), samples), "imu")
    assert "silent 2 time(s)" in v.message, v
    assert v.evidence["longest_s"] == pytest.approx(12.0, abs=0.3), v


def test_a_logging_gap_of_every_sensor_is_no_silence_of_one():
    samples = [s for s in simulate(SimConfig(duration=40.0, standstill=2.0))
               if not T0 + 20.0 <= s.stamp < T0 + 25.0]
    assert not [v for v in _inputs(verdicts_of(robot_config(), samples), "imu") if "silent" in v.message]


def test_a_gps_outage_is_said_at_level_ok_and_a_slow_receiver_is_no_outage():
    w = sim_gps.World(duration=90.0, gps_rate=5.0, gps_dropout=(30.0, 60.0))
    (v,) = _inputs(verdicts_of(robot_config(gps=""), sim_gps.simulate(w)), "gps")
    assert v.level == "ok" and "no usable fix for" in v.message and not v.suggestion, v
    assert v.evidence["longest_s"] == pytest.approx(30.0, abs=0.5) and v.evidence["outages"] == 1.0, v
    slow = sim_gps.World(duration=90.0, gps_rate=1.0)
    assert not _inputs(verdicts_of(robot_config(gps=""), sim_gps.simulate(slow)), "gps")
