"""The doctor on a noise the driver states honestly but below a floor the filter applies instead.

``twist_min_sigma`` (0.01 rad/s by default) floors the odometry's stated yaw-rate noise against drivers
that publish zeros. A good driver stating its true 0.004 rad/s is floored too, and the wheel-vs-gyro check
then reads NIS low: S holds 0.01^2 + the gyro's 0.002^2 (+ the bias estimate's variance, small once a
standstill has taught it) where the residuals show 0.004^2 + 0.002^2, a NIS of ~(16 + 4) / (100 + 4) = 0.19
per dof, below the window's bounds. "State less twist_noise" (six values,
none of them known to the doctor) is the wrong answer (a highway car); the floor is what to change,
with the wheels' own noise from the residuals less the rest of S.
"""

from __future__ import annotations

import re

import pytest

from tests.support.configs import robot_config
from tests.support.sim import SimConfig, simulate
from tests.support.verdicts import one, verdicts_of

WHEEL_SIGMA = 0.004  # rad/s, true and stated: below the default floor of 0.01
GYRO_SIGMA = 0.002


def _samples():
    # 5 s at rest first: the gyro's bias is learned, so its prior (gyro_bias_sigma 0.01) leaves S
    return simulate(SimConfig(duration=60.0, standstill=5.0, wheel_sigma=WHEEL_SIGMA, gyro_sigma=GYRO_SIGMA, seed=11))


def test_an_honest_noise_below_the_floor_names_the_floor_with_its_value():
    v = one(verdicts_of(robot_config(), _samples()), "wheel", "yaw_rate")
    assert v.level == "warn" and v.key == "sensors.wheel.twist_min_sigma", v
    assert "below the twist_min_sigma floor" in v.message, v
    assert v.evidence["stated_sigma_rad_s"] == pytest.approx(WHEEL_SIGMA, rel=1e-6)
    # the wheels' noise from the residuals: their rms^2 less the gyro's share, over ~3000 samples (a relative
    # sampling error of ~1/sqrt(1500) on the sigma), never below what the driver states
    value = float(re.search(r"twist_min_sigma = \[0.01, ([0-9.]+)\]", v.suggestion).group(1))
    assert WHEEL_SIGMA <= value < 1.25 * WHEEL_SIGMA, v.suggestion
    # pasted, the check is consistent
    pasted = one(verdicts_of(robot_config(odom=v.suggestion), _samples()), "wheel", "yaw_rate")
    assert pasted.level == "ok", pasted


def test_a_noise_above_the_floor_is_not_put_down_to_it():
    """Stated 0.02 rad/s for wheels of 0.004: NIS low as well, but nothing was floored: the stated
    twist noise is what is too large, and the floor is not named."""
    samples = _samples()
    overstated = [s if type(s).__name__ != "OdomSample" else type(s)(
        s.sensor, s.stamp, s.linear, s.angular, tuple(0.02**2 if i % 7 == 0 else 0.0 for i in range(36)))
        for s in samples]
    v = one(verdicts_of(robot_config(), overstated), "wheel", "yaw_rate")
    assert v.level == "warn" and v.key == "sensors.wheel.twist_noise", v
    assert "floor" not in v.message, v


def test_a_floor_that_is_not_most_of_s_is_not_blamed():
    """No standstill: the gyro's bias keeps its prior (gyro_bias_sigma 0.01 rad/s), as large a part of S as
    the floor. Lowering the floor alone would leave the NIS low: the floor is not named."""
    samples = simulate(SimConfig(duration=60.0, wheel_sigma=WHEEL_SIGMA, gyro_sigma=GYRO_SIGMA, seed=11))
    v = one(verdicts_of(robot_config(), samples), "wheel", "yaw_rate")
    assert v.key != "sensors.wheel.twist_min_sigma" and "floor" not in v.message, v


def test_an_empty_covariance_on_noisier_wheels_names_the_floor_to_raise():
    """A driver leaving the twist covariance at 0 (a race car): the core floors it to twist_min_sigma
    (0.01 rad/s) while its wheels' yaw rate scatters by 0.03: NIS ~(0.03^2 + 0.002^2) / (0.01^2 + 0.002^2)
    = 8.7 per dof, high. Its value to paste is the wheels' noise from the residuals, 0.03 within the
    sampling error of ~3000 samples (asserted within 15 %); pasted, the check is consistent."""
    noisy = 0.03
    samples = simulate(SimConfig(duration=60.0, standstill=5.0, wheel_sigma=noisy, gyro_sigma=GYRO_SIGMA, seed=11))
    empty = [s if type(s).__name__ != "OdomSample" else type(s)(s.sensor, s.stamp, s.linear, s.angular, (0.0,) * 36)
             for s in samples]
    v = one(verdicts_of(robot_config(), empty), "wheel", "yaw_rate")
    assert v.level == "warn" and v.key == "sensors.wheel.twist_min_sigma" and "raise the floor" in v.message, v
    value = float(re.search(r"twist_min_sigma = \[0.01, ([0-9.]+)\]", v.suggestion).group(1))
    assert value == pytest.approx(noisy, rel=0.15), v.suggestion
    pasted = one(verdicts_of(robot_config(odom=v.suggestion), empty), "wheel", "yaw_rate")
    assert pasted.level == "ok", pasted
