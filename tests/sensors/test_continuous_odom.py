"""filter.continuous_odom (true by default): with nothing observing heading, a gyro bias learned at the first
standstill corrects the heading's rate from then on and never turns the published pose at once (REP-105's
odom frame); with the key false the correlated correction turns it.

The simulation: a robot drives 60 s on a gyro biased by b = 0.005 rad/s (unknown: the bias prior is
0.01 rad/s), then stops. Driving, the heading drifts by b t = 0.3 rad; the standstill measures the bias,
and the EKF's yaw-bias correlation (-t var_b) turns the heading back by about that. Between two published
poses at 50 Hz at rest, the gyro can turn the estimate by its noise only: 0.002 rad/s x 0.02 s = 4e-5 rad,
so a step above a hundredth of the drift (3e-3 rad) is a jump.
"""

from __future__ import annotations

import math

from fusiond.core.fusion import FusionCore
from fusiond.estimator.rotation import yaw
from tests.support.configs import robot_config
from tests.support.sim import SimConfig, simulate

BIAS = 0.005
DRIVE_S = 60.0
JUMP_RAD = 0.01 * BIAS * DRIVE_S
T0 = 1000.0  # the simulation's first stamp


def _largest_step_at_rest(filt: str) -> tuple[float, float]:
    """(largest heading step between published poses after the stop, the z bias learned)."""
    sim = SimConfig(duration=DRIVE_S + 10.0, gyro_bias=(0.0, 0.0, BIAS), stops=((DRIVE_S, DRIVE_S + 10.0),))
    core = FusionCore(robot_config(filt=filt))
    last, largest = None, 0.0
    for s in simulate(sim):
        if core.ingest(s).publish:
            t, x = core.pose()
            h = yaw(tuple(x[3:7]))
            if last is not None and t - T0 >= DRIVE_S + 0.1:  # the last turning step behind
                largest = max(largest, abs(math.remainder(h - last, math.tau)))
            last = h
    return largest, float(core.gyro_bias[2])


def test_a_bias_learned_at_rest_never_turns_the_default_odom_frame() -> None:
    step, bias = _largest_step_at_rest("")
    assert abs(bias - BIAS) < 0.2 * BIAS  # the standstill did learn the bias
    assert step < JUMP_RAD


def test_an_explicit_true_is_the_default() -> None:
    assert _largest_step_at_rest("continuous_odom = true") == _largest_step_at_rest("")


def test_with_it_false_the_correlated_correction_turns_the_heading() -> None:
    step, bias = _largest_step_at_rest("continuous_odom = false")
    assert abs(bias - BIAS) < 0.2 * BIAS
    assert step > JUMP_RAD  # the trait the key is for: the heading turned at once
