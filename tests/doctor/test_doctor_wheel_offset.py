"""The wheels' yaw-rate offset on a road that hardly turns, with the gyro not fused (``wheel_yaw_offset``).

Without turns a scale cannot be parted from an offset, but the offset alone is what bends a heading the
wheels drive: 0.02 rad/s is 1.2 rad over a minute. The difference wheel - gyro carries the gyro's own bias
too, so the test takes off the bias read at a standstill (then only its random walk over the run is left
unknown) or, without one, allows what the filter's prior ``gyro_bias_sigma`` allows. Wheel noise 0.01 rad/s
at 50 Hz over 57 s of driving: the offset's standard error is about 2e-4 rad/s, so with a standstill the
test's bound (3.29 sigma, with the walk's 1.5e-4 over the run) is under 1e-3 rad/s.
"""

from __future__ import annotations

import pytest

from tests.support.core_samples import make_config
from tests.support.sim import SimConfig, simulate
from tests.support.verdicts import one, verdicts_of

STRAIGHT = dict(duration=60.0, turn_amplitude=0.0, speed=5.0)


def heading_verdict(**kw):
    samples = simulate(SimConfig(**{**STRAIGHT, **kw}))
    return one(verdicts_of(make_config(gyro=False), samples), "wheel", "heading")


def test_a_wheel_offset_on_a_straight_road_names_the_gyro():
    v = heading_verdict(standstill=3.0, gyro_bias=(0.0, 0.0, 0.004), wheel_yaw_offset=0.02)
    assert (v.level, v.key, v.suggestion) == ("problem", "sensors.imu.angular_velocity", "angular_velocity = true"), v
    off = v.evidence["wheel_vs_gyro_yaw_offset_rad_s"]
    # the gyro's bias at rest taken off: the wheels' own 0.02, not 0.02 - 0.004
    assert off == pytest.approx(0.02, abs=3 * v.evidence["wheel_vs_gyro_yaw_offset_se"] + 2e-4), v
    assert "+0.0200 rad/s" in v.message or f"{off:+.4f}" in v.message


def test_a_gyro_bias_alone_is_not_called_a_wheel_offset():
    """The wheels read the turn exactly; the gyro is biased by 0.004 rad/s, seen at the standstill: without
    taking that bias off, the difference (-0.004) would be twenty standard errors from zero."""
    v = heading_verdict(standstill=3.0, gyro_bias=(0.0, 0.0, 0.004))
    assert v.level == "ok" and not v.key and not v.suggestion, v
    assert abs(v.evidence["wheel_vs_gyro_yaw_offset_rad_s"]) < v.evidence["offset_bound_rad_s"], v


@pytest.mark.parametrize("offset, level", [(0.02, "ok"), (0.05, "problem")])
def test_without_a_standstill_the_gyro_bias_prior_bounds_what_can_be_told(offset, level):
    """No standstill: the gyro's bias may be anything its prior allows (gyro_bias_sigma 0.01 rad/s), so the
    bound is 3.29 x 0.01: 0.02 rad/s cannot be told from the gyro's bias, 0.05 can."""
    v = heading_verdict(wheel_yaw_offset=offset)
    assert v.level == level, v
    assert v.evidence["offset_bound_rad_s"] == pytest.approx(0.0329, rel=0.05)
    assert ("cannot" in v.message or "can be told" in v.message) if level == "ok" else v.suggestion, v
