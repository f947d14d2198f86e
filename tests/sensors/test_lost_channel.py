"""A twist component that is no measurement (core/sensors/odom/lost_channel.py): a driver that lost its yaw
rate sends 0 with covariance 0, a perfect "not turning" by its own word. Against a fused gyro turning at
0.2 rad/s, well past the quiet bound (3 x (0.002 + 0.01) = 0.036 rad/s), five odometry messages of that
constant find it; a yaw rate that moves is never taken for lost, whatever its covariance."""

from __future__ import annotations

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.odom.lost_channel import LOST_AFTER

from tests.support.core_samples import make_config
from tests.support.sim_rest import RestWorld, Segment, simulate


def _run(lost: bool) -> tuple[FusionCore, list[float]]:
    world = RestWorld([Segment(2.0), Segment(4.0, speed=1.0, yaw_rate=0.2), Segment(2.0)], wheel_yaw_lost=lost,
                      ramp_s=0.5, odom_rate=50.0)
    core = FusionCore(make_config("roll_pitch"))
    measured_at: list[float] = []
    for s in simulate(world):
        core.ingest(s)
        if s.sensor == "wheel" and core.state.wheel_yaw_measured:
            measured_at.append(s.stamp)
    return core, measured_at


def test_a_yaw_rate_sent_as_zero_while_the_gyro_turns_is_taken_as_not_measured():
    core, measured_at = _run(lost=True)
    turn_start = 1000.0 + 2.0
    # measured (by its covariance) only until the turn has shown it: LOST_AFTER messages at 50 Hz, plus the ramp
    assert measured_at and max(measured_at) < turn_start + 0.5 + LOST_AFTER / 50.0 + 0.1
    assert not core.state.wheel_yaw_measured


def test_a_real_yaw_rate_stays_measured():
    core, measured_at = _run(lost=False)
    assert core.state.wheel_yaw_measured and max(measured_at) > 1000.0 + 7.5


def test_a_steady_turn_read_as_one_value_the_gyro_agrees_with_stays_measured():
    """A drive already turning at 0.2 rad/s from its first message, reading that one double every time (a
    simulation, or encoders whose ticks do not change in a steady turn): constant, and the gyro turns, but
    the gyro reads the same rate, so nothing says the value is not a measurement."""
    world = RestWorld([Segment(6.0, speed=1.0, yaw_rate=0.2)], odom_rate=50.0, gyro_sigma=0.002, wheel_sigma=0.0)
    core = FusionCore(make_config("roll_pitch"))
    wz = set()
    for s in simulate(world):
        core.ingest(s)
        if s.sensor == "wheel":
            wz.add(s.angular[2])
    assert wz == {0.2}  # the premise: one value, bit for bit
    assert core.state.wheel_yaw_measured
