"""A gyro bias that drifts with temperature, told from one false standstill (a skid-steer and a race car).

Both show as standstills that disagree and updates rejected. One odd standstill (the vehicle coasting while its
wheels read zero) sits off the line through the others; a drifting bias puts every standstill on one line. A
doctor that takes the first standstill for a false one would advise ``standstill_s``; a drift needs
``gyro_bias_walk``.
"""

from __future__ import annotations

from fusiond.doctor.gyro import Episode, bias_drift
from fusiond.doctor.gyro import DISAGREE_RAD_S

from tests.support import sim
from tests.support.configs import robot_config
from tests.support.core_samples import make_config
from tests.support.sim_rest import RestWorld, Segment, simulate
from tests.support.verdicts import one, verdicts_of

DRIFT = 3e-5  # rad/s per s: 0.009 rad/s over the 300 s run


def _episode(t0: float, mean: float) -> Episode:
    return Episode(t0, t0 + 3.0, gyro_mean=mean, gyro_sigma=0.003, samples=300)  # standard error 1.7e-4


def test_a_trend_is_a_drift_and_one_odd_standstill_is_not():
    """Five standstills on a line from 0.003 to -0.002 rad/s: a drift, whose walk is the change over the root of
    the span (0.005 / sqrt(400) = 2.5e-4). The same five with only the first odd (0.003, the rest at 0): no line
    leaves them within max(5 x 1.7e-4, DISAGREE_RAD_S / 3) = 1e-3: no drift. Nor two standstills (no trend)."""
    times = [0.0, 100.0, 200.0, 300.0, 400.0]
    drifting = [_episode(t, 0.003 - 0.005 * t / 400.0) for t in times]
    found = bias_drift(drifting, 2e-5)
    assert found is not None and abs(found[2] - 0.005 / 400.0**0.5) < 1e-6
    assert bias_drift(drifting, 2e-4) is None  # a walk that already allows it
    odd = [_episode(t, 0.003 if t == 0.0 else 0.0) for t in times]
    assert bias_drift(odd, 2e-5) is None
    assert bias_drift(drifting[:2], 2e-5) is None
    assert 0.005 > DISAGREE_RAD_S


def _world(drift: float) -> RestWorld:
    """Standstills of 4 s between 56 s drives, for 300 s; the z bias starts at 0.002 and drifts."""
    segs = []
    for _ in range(5):
        segs += [Segment(4.0), Segment(56.0, speed=1.0, yaw_rate=0.1)]
    return RestWorld(segs, gyro_bias=(0.0, 0.0, 0.002), gyro_bias_drift=drift, gyro_sigma=0.002, ramp_s=0.5)


def test_the_doctor_names_the_drift_and_its_walk_settles_the_standstills():
    """0.009 rad/s of drift over 240 s between the first and last standstill: the walk it shows is 0.0072 /
    sqrt(240) ~ 4.6e-4 against the default 2e-5, so standstill updates are rejected against the old bias.
    The verdict names gyro_bias_walk with that value (within 30 %), not standstill_s; pasted, the standstills
    are followed: the verdict is no longer the drift and fewer than 10 % of the updates are rejected."""
    from fusiond.replay.run import run_samples

    samples = simulate(_world(DRIFT))
    v = one(verdicts_of(robot_config(), samples), "imu", "gyro_bias")
    assert v.key == "filter.gyro_bias_walk" and "drifts" in v.message, v
    walk = float(v.suggestion.split("=")[1])
    expected = DRIFT * 240.0 / 240.0**0.5
    assert abs(walk - expected) < 0.3 * expected, v
    applied = run_samples(samples, robot_config(filt=f"gyro_bias_walk = {walk}"))
    after = one(applied.verdicts(), "imu", "gyro_bias")
    assert "drifts" not in after.message, after
    ch = applied.doctor.channels[("imu", "gyro_bias")]
    assert ch.rejected < 0.1 * ch.n


def test_a_steady_bias_is_not_a_drift():
    """No drift: every standstill reads 0.002 within its noise: nothing about a walk."""
    v = one(verdicts_of(robot_config(), simulate(_world(0.0))), "imu", "gyro_bias")
    assert v.key != "filter.gyro_bias_walk" and "drifts" not in v.message, v


def test_standstills_that_disagree_on_x_alone_are_not_put_down_to_the_heading():
    """The IMU's own roll drifts at 0.01 rad/s (roll_pitch fused): through the roll/pitch updates the filter's x
    bias takes that drift, and the standstill windows' x axis reads far beyond its bounds (NIS ~30 per dof)
    while z agrees and the noise at rest is as stated. The verdict names the x/y axes, that heading is not
    affected, and nothing to paste; it does not say something moved the heading's bias."""
    from tests.support.core_samples import make_config

    segments = [Segment(3.0, speed=1.0, yaw_rate=0.1), Segment(4.0), Segment(3.0, speed=1.0, yaw_rate=-0.1),
                Segment(4.0), Segment(3.0, speed=1.0, yaw_rate=0.1), Segment(4.0),
                Segment(3.0, speed=1.0, yaw_rate=-0.1), Segment(4.0)]
    world = RestWorld(segments, gyro_bias=(0.01, -0.005, 0.02), roll_drift=0.01, ramp_s=0.5)
    v = one(verdicts_of(make_config("roll_pitch"), simulate(world)), "imu", "gyro_bias")
    assert v.level == "warn" and "x/y axes only" in v.message and "heading is not affected" in v.message, v
    assert not v.suggestion and "bias_moved" not in v.evidence and v.evidence["nis_gyro_x"] > 10.0, v
    assert "nis_gyro_z" not in v.evidence


def test_standstill_updates_that_all_learned_are_said_so_not_given_a_nan_nis():
    """A bias walk so large (0.005 rad/s/sqrt(s)) that the prior never narrows: every standstill bias update
    learns the state and none is judged. The verdict says so instead of 'consistent (nan per dof ...)'."""
    samples = sim.simulate(sim.SimConfig(duration=20.0, standstill=3.0, stops=((10.0, 13.0),)))
    v = one(verdicts_of(make_config(extra_filter="gyro_bias_walk = 0.005"), samples), "imu", "gyro_bias")
    assert v.level == "ok" and "nan" not in v.message and "being learned" in v.message, v
