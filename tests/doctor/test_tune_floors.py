"""Floors from the data (tune/floors.py): no fitted white noise below what the standstills show."""

from __future__ import annotations

import math

import pytest

from fusiond.tune.doctor_values import diagnose
from fusiond.tune.floors import FLOOR_ALPHA, measured_floors
from fusiond.tune.params import Param, tunable_params

from tests.support.configs import robot_config
from tests.support.sim_rest import RestWorld, Segment, simulate

GYRO_SIGMA = 0.003
REST_NOISE = 0.02
# three standstills (5, 3, 3 s) between drives
STOPS = [Segment(5.0), Segment(20.0, speed=0.5, yaw_rate=0.2), Segment(3.0),
         Segment(20.0, speed=0.5, yaw_rate=-0.2), Segment(3.0), Segment(5.0, speed=0.5)]


@pytest.fixture(scope="module")
def noisy_rest():
    """Three standstills (5, 3, 3 s) between drives; the wheels read 0.02 of noise at rest, the gyro 0.003 while
    its messages state 0.14."""
    world = RestWorld(STOPS, gyro_bias=(0.002, -0.001, 0.006), gyro_sigma=GYRO_SIGMA, gyro_stated_sigma=0.14,
                      ramp_s=0.5, rest_noise=REST_NOISE)
    return simulate(world)


def test_the_standstills_measure_each_noise_from_below(noisy_rest):
    """The gyro's floor and the wheels' forward-speed and yaw-rate floors sit just under the simulated noise
    (a lower bound of size 1 %: over ~1,000 differences, within 10 % below it); the components the wheels read
    exactly 0 at rest set none."""
    cfg = robot_config()
    _, spans = diagnose(cfg, noisy_rest)
    assert len(spans) == 3
    params = tunable_params(cfg, noisy_rest)
    floors = measured_floors(cfg, noisy_rest, params, spans)
    gyro = floors["imu.gyro_noise"].sigmas[0]
    assert 0.9 * GYRO_SIGMA < gyro < GYRO_SIGMA, gyro
    twist = {p.name: p for p in params}
    linear = floors["wheel.twist_noise.linear"]
    by_index = dict(zip(twist["wheel.twist_noise.linear"].indices, linear.sigmas))
    assert 0.9 * REST_NOISE < by_index[0] < REST_NOISE, by_index
    assert all(v == 0.0 for i, v in by_index.items() if i != 0)
    angular = dict(zip(twist["wheel.twist_noise.angular"].indices, floors["wheel.twist_noise.angular"].sigmas))
    assert 0.9 * REST_NOISE < angular[5] < REST_NOISE, angular
    assert FLOOR_ALPHA == 0.01


def test_a_vehicle_settling_after_it_stops_does_not_lift_the_floor():
    """The standstills of the test above, the vehicle rocking on its suspension for 0.25 s after each stop (every
    gyro axis 0.03 rad/s noisier, ten times its noise) while its wheels read zero. The filter confirms rest only
    standstill_s (0.3 s) after the wheels read zero, and the floors are measured over the doctor's standstills,
    which start there: the gyro's floor is the noise at rest as above (within 10 % below it), where the rocking
    alone, ~50 differences of variance 2 x 0.03^2 among ~1,000 of 2 x 0.003^2, would lift a floor taken from the
    wheels' first zero to ~0.007."""
    cfg = robot_config()
    assert cfg.filter.standstill_s > 0.25  # the simulation has the trait: the rocking ends before rest is confirmed
    world = RestWorld(STOPS, gyro_bias=(0.002, -0.001, 0.006), gyro_sigma=GYRO_SIGMA, ramp_s=0.5,
                      settle_s=0.25, settle_sigma=0.03)
    samples = simulate(world)
    _, spans = diagnose(cfg, samples)
    floors = measured_floors(cfg, samples, tunable_params(cfg, samples), spans)
    gyro = floors["imu.gyro_noise"].sigmas[0]
    assert 0.9 * GYRO_SIGMA < gyro < GYRO_SIGMA, gyro


def test_a_floor_bounds_the_fit_from_below_and_never_lifts_a_start():
    """lowest() is the log-scale at which the highest-bound component reaches its floor; a start already below
    the measured noise may stay (0: the fit keeps it), as with the sensor's constant floor."""
    p = Param("imu.orientation_noise", "imu", "orientation_noise", (0, 1, 2), (0.02, 0.01, 0.04), floor=0.001,
              measured=(0.002, 0.004, 0.001))
    assert p.lowest() == pytest.approx(math.log(0.4))  # the y axis: 0.01 x 0.4 = its floor 0.004
    assert p.held_by_measured()
    below = Param("imu.gyro_noise", "imu", "gyro_noise", None, 0.001, floor=0.0001, measured=(0.003,))
    assert below.lowest() == 0.0
    plain = Param("imu.gyro_noise", "imu", "gyro_noise", None, 0.01, floor=0.001)
    assert plain.lowest() == pytest.approx(math.log(0.1)) and not plain.held_by_measured()


def test_a_robot_that_never_stands_sets_no_floor():
    world = RestWorld([Segment(20.0, speed=0.5, yaw_rate=0.2)], gyro_sigma=GYRO_SIGMA, ramp_s=0.5)
    samples = simulate(world)
    cfg = robot_config()
    _, spans = diagnose(cfg, samples)
    assert measured_floors(cfg, samples, tunable_params(cfg, samples), spans) == {}


def test_the_table_says_when_a_value_stays_below_what_the_standstills_show(noisy_rest):
    """A gyro_noise the user set at 0.001 for a gyro reading 0.003 at rest: the fit may move it, but where it
    ends below the measured floor the table says so."""
    from fusiond.tune import tune
    from fusiond.tune.fit import format_table

    cfg = robot_config(imu="gyro_noise = 0.0005")
    result = tune(noisy_rest, cfg, keys=["imu.gyro_noise"], budget_s=300.0)
    row = next(r for r in result.rows if r.param.name == "imu.gyro_noise")
    after = row.after if row.after is not None else row.param.start()
    assert (after < 0.9 * GYRO_SIGMA) == ("below the noise the recording shows at rest" in row.note), (after, row.note)
    assert "measured at rest" in format_table(result) or after >= 0.9 * GYRO_SIGMA


def test_what_a_slow_error_adds_between_two_readings_is_the_kinds_answer():
    """The floors take off what a configured Gauss-Markov error moves between two readings at rest,
    2 sigma^2 (1 - exp(-dt / tau)) an axis, and the sensor's kind says it: the GPS's with ``error_tau_s``
    (every axis) or its vertical one alone; a kind without a slow error adds nothing."""
    from fusiond.config import loads
    from fusiond.core.sensors import kind_of

    tables = '[[sensors]]\nname = "wheel"\nkind = "odom"\nkey = "odom"\n[[sensors]]\nname = "fix"\nkind = "gps"\nkey = "gps"\n'
    wheel, fix = loads(tables + 'error_tau_s = 50.0\nerror_sigma = [0.5, 0.5, 1.0]\n').sensors
    alt = loads(tables + 'vertical_error_sigma = 2.0\nvertical_error_tau_s = 100.0\n').sensors[1]
    step = 1.0 - math.exp(-0.2 / 50.0)
    assert kind_of(fix).difference_variance(fix, 0.2) == pytest.approx([0.5 * step, 0.5 * step, 2.0 * step])
    assert kind_of(alt).difference_variance(alt, 0.2) == pytest.approx([0.0, 0.0, 8.0 * (1.0 - math.exp(-0.002))])
    assert kind_of(wheel).difference_variance(wheel, 0.2) == []
