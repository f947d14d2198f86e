"""Tune validated by prediction (tune/prediction.py): every 5th fix held back and the filter's position at
its stamp scored, horizontally and vertically apart, with a paired test for "worse"."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import GpsSample
from fusiond.tune import tune
from fusiond.tune.fit import format_table
from fusiond.tune.prediction import HOLD_EVERY, Prediction, predict, split

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at


def _prediction(h2, v2=None) -> Prediction:
    v2 = h2 if v2 is None else v2
    return Prediction(math.sqrt(float(np.mean(h2))), math.sqrt(float(np.mean(v2))), len(h2),
                      {k: (float(a), float(b)) for k, (a, b) in enumerate(zip(h2, v2))})


def test_worse_is_a_paired_test_of_a_relevant_size():
    rng = np.random.default_rng(1)
    base = rng.chisquare(2, 200) * 0.25  # squared errors of ~0.5 m
    same = _prediction(base)
    assert not same.worse_than(_prediction(base))
    assert _prediction(base * 1.10).worse_than(same)  # 5 % worse RMS at every fix: real and relevant
    assert not _prediction(base * 1.01).worse_than(same)  # 0.5 % worse everywhere: real, not relevant
    assert not same.worse_than(_prediction(base * 1.10))
    # a config whose errors differ from fix to fix by chance alone (another draw of the same spread,
    # 2 % higher on average): not told apart from the first
    other = rng.chisquare(2, 200) * 0.25
    other *= 1.02 * base.mean() / other.mean()
    assert not _prediction(other).worse_than(same)
    # the vertical is judged on its own: a worse vertical alone is worse
    assert _prediction(base, base * 1.2).worse_than(_prediction(base, base))


@pytest.fixture(scope="module")
def wander():
    """A GPS whose error is coloured (Gauss-Markov 1.5 m, 20 s) on 0.2 m of white noise, 5 Hz, 200 s."""
    w = World(duration=200.0, gps_rate=5.0, gps_sigma=0.2, gps_error_tau=20.0, gps_error_sigma=1.5)
    return w, simulate(w)


def test_split_holds_back_every_fifth_fix(wander):
    _, samples = wander
    cfg = robot_config(gps="position_noise = [1.5, 1.5, 3.0]")
    kept, held = split(samples, cfg)
    fixes = [s for s in samples if type(s) is GpsSample]
    assert len(held) == len(fixes) // HOLD_EVERY
    assert not set(map(id, held)) & set(map(id, kept)) and len(kept) + len(held) == len(samples)


def test_prediction_finds_a_noise_that_lets_the_filter_drift(wander):
    """Fixes stated at 2 cm when their error wanders by 1.5 m: the gate turns the wander away and the
    filter dead-reckons off; the held-back fixes say so where the likelihood of the fused ones cannot."""
    _, samples = wander
    kept, held = split(samples, robot_config(gps="position_noise = [1.5, 1.5, 3.0]"))
    honest = predict(robot_config(gps="position_noise = [1.5, 1.5, 3.0]"), kept, held)
    tiny = predict(robot_config(gps="position_noise = [0.02, 0.02, 0.04]"), kept, held)
    assert honest.fixes >= 0.9 * len(held)
    assert tiny.worse_than(honest) and not honest.worse_than(tiny)


def _truth_rms(world, samples, cfg) -> float:
    core, err = FusionCore(cfg), []
    for s in samples:
        if core.ingest(s).publish and core.initialised:
            t, p = core.pose()
            tx, ty, _ = truth_at(world, t)
            err.append((p[0] - tx) ** 2 + (p[1] - ty) ** 2)
    return math.sqrt(float(np.mean(err[len(err) // 5:])))


def test_tune_shows_and_keeps_to_the_held_back_prediction(wander):
    world, samples = wander
    cfg = robot_config(gps="position_noise = [1.5, 1.5, 3.0]")
    result = tune(samples, cfg, keys=["gps.position_noise"], budget_s=300.0)
    before, after = result.prediction_before, result.prediction_after
    assert before is not None and after is not None and before.fixes >= 30
    assert not after.worse_than(before)
    assert "held-back fixes (every 5th, not fused)" in format_table(result)
    # and against the truth, which tune never sees: no worse than the config it started from (within 2 %)
    assert _truth_rms(world, samples, result.config) <= 1.02 * _truth_rms(world, samples, cfg)


def test_tune_and_the_doctor_give_one_number_or_say_why_not():
    """An IMU stating 0.14 rad/s for a 0.003 rad/s gyro: the doctor measures the noise at rest and prints
    gyro_noise = ~0.003; tune takes that value when it scores no worse than its own fit, and otherwise
    says what the doctor measured and why it was not taken."""
    from tests.support.sim_rest import RestWorld, Segment
    from tests.support.sim_rest import simulate as simulate_rest

    segments = [Segment(5.0), Segment(20.0, speed=0.5, yaw_rate=0.2), Segment(3.0),
                Segment(20.0, speed=0.5, yaw_rate=-0.2), Segment(3.0)]
    world = RestWorld(segments, gyro_bias=(0.002, -0.001, 0.006), gyro_sigma=0.003, gyro_stated_sigma=0.14,
                      ramp_s=0.5)
    result = tune(simulate_rest(world), robot_config(), keys=["imu.gyro_noise"], budget_s=300.0)
    r = next(r for r in result.rows if r.param.name == "imu.gyro_noise")
    assert r.doctor is not None and 0.002 < r.doctor < 0.004  # the doctor measured it at rest
    assert r.after == r.doctor or "the doctor measured" in r.note, (r.after, r.doctor, r.note)
    assert "doctor" in format_table(result).splitlines()[0]


@pytest.mark.parametrize("minutes, skipped", [(1.0, True), (20.0, False)])
def test_a_gps_error_slower_than_the_recording_is_not_fitted(minutes, skipped):
    """The altitude's Gauss-Markov error (tau 300 s by default) is identified by its innovations only over
    several time constants: a minute of fixes shares one slow offset, which tune would take for the truth."""
    from fusiond.tune.params import tunable_params

    cfg = robot_config(gps="")
    n = int(minutes * 60)
    fixes = [GpsSample("gps", 100.0 + k, 48.0, 11.0, 500.0, 0, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 4.0), 2)
             for k in range(n)]
    by_name = {p.name: p for p in tunable_params(cfg, fixes)}
    vertical = [by_name[k] for k in ("gps.position_noise.vertical", "gps.vertical_error_sigma",
                                     "gps.vertical_error_tau_s")]
    assert all(bool(p.skipped) == skipped for p in vertical), [(p.name, p.skipped) for p in vertical]
    assert not by_name["gps.position_noise.horizontal"].skipped  # no horizontal error model: its white noise fits


def test_an_axis_whose_error_is_slower_than_the_recording_is_not_scored(wander):
    """The held fixes share a slow error with their fused neighbours: scored, a config that follows it would
    look better. 200 s of fixes: the altitude's default error (tau 300 s) leaves the vertical unscored, none
    (vertical_error_sigma = 0) scores it; a horizontal error of tau 100 s leaves both unscored."""
    _, samples = wander
    default = robot_config(gps="position_noise = [1.5, 1.5, 3.0]")
    kept, held = split(samples, default)
    slow_up = predict(default, kept, held)
    assert slow_up.horizontal is not None and slow_up.vertical is None
    white = predict(robot_config(gps="position_noise = [1.5, 1.5, 3.0]\nvertical_error_sigma = 0.0"), kept, held)
    assert white.horizontal is not None and white.vertical is not None
    slow_all = predict(robot_config(gps="position_noise = [1.5, 1.5, 3.0]\nerror_tau_s = 100.0\nerror_sigma = [1.5, 1.5, 3.0]"),
                       kept, held)
    assert slow_all.horizontal is None and slow_all.vertical is None
    assert not slow_all.worse_than(white) and not white.worse_than(slow_all)  # nothing scored both ways


def test_an_absolute_pose_is_held_back_and_scored_through_its_lever_arm():
    """A ceiling camera 0.36 m ahead of and 1 m above base_link, 10 Hz, 1 cm: every 5th pose held back, the
    filter's marker position at its stamp is within a few cm of it; a config that forgets the lever arm
    predicts the held poses worse, horizontally (the marker swings round the body as it turns) and all."""
    from tests.support.sim_gps import World
    from tests.support.sim_gps import simulate as simulate_gps

    world = World(duration=60.0, start=(1.0, 2.0, 0.5), pose_rate=10.0, gyro_bias=0.003, pose_lever=(0.36, 0.0, 1.0))
    samples = simulate_gps(world)
    right = robot_config(pose="extrinsic_xyz = [0.36, 0.0, 1.0]")
    kept, held = split(samples, right)
    assert len(held) >= 100 and all(s.sensor == "pose" for s in held)
    good = predict(right, kept, held)
    assert good.fixes >= 0.9 * len(held) and good.horizontal < 0.05 and good.vertical is not None, good
    wrong = predict(robot_config(pose=""), kept, held)
    assert wrong.worse_than(good) and not good.worse_than(wrong), (good, wrong)
