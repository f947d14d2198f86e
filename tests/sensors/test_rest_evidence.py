"""Standstill from evidence (core/sensors/odom/rest.py): the wheels at rest within their own noise.

The test's size is ``standstill_alpha`` (0.01): a true standstill's window is refused that often,
less the approximations (Student's t by Cornish-Fisher, the overlapping differences' degrees of
freedom), so the refused share is held to 2 alpha. Its power is physics: over a window of N
readings under noise sigma a creep c shows as t = c sqrt(N) / sigma. At 50 Hz over 0.3 s (N = 15)
under 0.03 m/s: 0.12 m/s is t = 15.5, far past the bound (~4.6 for two components at alpha / 2);
a Jackal turning in place reads 0.009 rad/s under 0.002 of noise: t = 17.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.odom.rest import rest_window, running_noise

from tests.support.core_samples import make_config
from tests.support.sim_rest import RestWorld, Segment, simulate

ALPHA = 0.01
SPAN = 0.3
FORWARD_AND_YAW = (True, False, False, False, False, True)


def _rest_share(speed: float, sigma: float, yaw_rate: float = 0.0, yaw_sigma: float | None = None,
                rate: float = 50.0, n: int = 20000, seed: int = 3) -> float:
    """The share of messages the rest test calls at rest, for a stream of a constant forward speed and
    yaw rate under white noise (the first 100 messages, the noise track's warm-up, left out)."""
    rng = np.random.default_rng(seed)
    yaw_sigma = sigma if yaw_sigma is None else yaw_sigma
    window, track, rest = (), None, 0
    for k in range(n):
        stamp = k / rate
        values = (speed + rng.normal(0.0, sigma), 0.0, 0.0, 0.0, 0.0, yaw_rate + rng.normal(0.0, yaw_sigma))
        track = running_noise(track, values, stamp, 1.0 / rate)
        window, at_rest = rest_window(window, values, FORWARD_AND_YAW, track[1], stamp, SPAN, ALPHA)
        rest += at_rest and k >= 100
    return rest / (n - 100)


@pytest.mark.parametrize("sigma, rate", [(0.03, 50.0), (0.03, 10.0), (0.001, 50.0), (0.0002, 50.0)])
def test_a_noisy_standstill_is_refused_no_more_than_its_stated_rate(sigma, rate):
    assert 1.0 - _rest_share(0.0, sigma, rate=rate, n=20000 if rate > 10 else 6000) <= 2 * ALPHA


@pytest.mark.parametrize("rate", [50.0, 10.0])
def test_a_creep_is_not_rest(rate):
    assert _rest_share(0.12, 0.03, rate=rate, n=20000 if rate > 10 else 6000) <= ALPHA


def test_a_slow_turn_in_place_is_not_rest():
    """The Jackal's wheels read a quarter of a turn in place: 0.009 rad/s under 0.002 of jitter, while its
    driver states 0.17 rad/s; by the stated noise it would be rest, by its own it is not."""
    assert _rest_share(0.0, 0.001, yaw_rate=0.009, yaw_sigma=0.002) == 0.0


def test_exact_zeros_are_rest_at_once():
    window, track = (), None
    for k, v in enumerate((0.5, 0.5, 0.0)):
        values = (v, 0.0, 0.0, 0.0, 0.0, 0.0)
        track = running_noise(track, values, k * 0.02, 0.02)
        window, at_rest = rest_window(window, values, FORWARD_AND_YAW, track[1], k * 0.02, SPAN, ALPHA)
    assert not at_rest  # a window of one reading decides nothing ...
    core = FusionCore(make_config("roll_pitch"))
    world = RestWorld([Segment(1.0, speed=0.5), Segment(1.0)], ramp_s=0.3)
    stills = []
    for s in simulate(world):
        core.ingest(s)
        stills.append(core.state.still_since)
    assert any(x is not None for x in stills)  # ... but a drive reading exactly zero says so itself


BIAS_Z = 0.0175  # 1 deg/s: the car of the held-out table, whose bias the exact-zero rule never learned


def _car(rest: Segment, seed: int = 5) -> tuple[FusionCore, list]:
    world = RestWorld([rest, Segment(20.0, speed=5.0, yaw_rate=0.05), Segment(20.0, speed=8.0, yaw_rate=-0.04)],
                      gyro_bias=(0.0, 0.0, BIAS_Z), rest_noise=0.03, ramp_s=2.0, seed=seed)
    core = FusionCore(make_config("roll_pitch"))
    records = []
    for s in simulate(world):
        records.extend(r for r in core.ingest(s).records if r.channel == "gyro_bias")
    return core, records


def test_a_car_whose_wheels_read_noise_at_rest_learns_its_gyro_bias():
    """14 s at rest with 0.03 m/s of wheel noise, then 40 s of driving: the z bias of 1 deg/s is learned
    at the standstill (each 0.3 s window of 30 gyro readings of 0.002: sigma 3.7e-4, ~40 windows), so
    the heading after the drive errs by the bias's residual times 40 s, not 0.0175 x 40 s = 40 deg."""
    core, records = _car(Segment(14.0))
    assert records and all(r.stamp < 1000.0 + 14.0 for r in records)
    assert core.gyro_bias[2] == pytest.approx(BIAS_Z, abs=1e-3)


def test_a_creeping_turn_teaches_no_bias():
    """The same car creeping at 0.12 m/s round a bend of 0.004 rad/s (inside the gyro's quiet bound, so
    only the wheels can tell): no standstill, no bias update from it."""
    _, records = _car(Segment(14.0, speed=0.12, yaw_rate=0.004))
    assert not [r for r in records if r.stamp < 1000.0 + 14.0]


def _heading_rms_deg(imu_lines: str) -> float:
    import math

    from fusiond.estimator.rotation import to_rpy

    from tests.support.configs import robot_config

    segments = [Segment(5.0), Segment(20.0, speed=0.5, yaw_rate=0.2), Segment(3.0),
                Segment(20.0, speed=0.5, yaw_rate=-0.2), Segment(3.0), Segment(30.0, speed=0.5, yaw_rate=0.1)]
    world = RestWorld(segments, gyro_bias=(0.002, -0.001, 0.006), gyro_sigma=0.003, gyro_stated_sigma=0.14,
                      ramp_s=0.5)
    samples = simulate(world)
    truth = np.array(world.truth)
    core = FusionCore(robot_config(imu=imu_lines))
    errors = []
    for s in samples:
        if core.ingest(s).publish and core.initialised:
            t, pose = core.pose()
            k = min(int(np.searchsorted(truth[:, 0], t)), len(truth) - 1)
            d = to_rpy(pose[3:7])[2] - truth[k, 3]
            errors.append(math.degrees(math.atan2(math.sin(d), math.cos(d))))
    return float(np.sqrt(np.mean(np.square(errors))))


def test_a_gyro_stating_fifty_times_its_noise_learns_its_bias_as_if_told_the_truth():
    """A small indoor robot's IMU states 0.14 rad/s for a 0.003 rad/s gyro. Each standstill window of 30
    readings teaches the bias with the scatter it shows (0.003 / sqrt(30)), not the stated 0.14 / sqrt(30),
    which would leave the 0.006 rad/s z bias mostly unlearned (3.2 deg RMS of heading over the run where
    the measured noise gives 0.13). So the config a new user writes scores as the one with the measured
    gyro_noise pasted, within 0.1 deg."""
    assert _heading_rms_deg("") <= _heading_rms_deg("gyro_noise = 0.003") + 0.1
