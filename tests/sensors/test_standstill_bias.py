"""Gyro bias learned at standstill: per axis, confirmed by a quiet gyro, not locked out by one bad update.

Noise budget of the simulations below (derives the 10 % thresholds): the gyro has
white noise sigma_g = 0.002 rad/s at 100 Hz, a standstill window averages
standstill_s = 0.3 s = 30 samples, so one window's mean has sigma 0.002 / sqrt(30) =
3.7e-4 rad/s; three real standstills of 3 s give ~27 windows, sigma ~7e-5 rad/s on the
combined estimate. 10 % of a 0.005 rad/s bias is 5e-4 rad/s: 7 sigma of margin.
"""

from __future__ import annotations

import pytest

from fusiond.core.fusion import FusionCore

from tests.support.sim_rest import RestWorld, Segment, simulate
from tests.support.core_samples import make_config

BIAS = (0.004, -0.003, 0.005)


def _core(orientation: str = "roll_pitch") -> FusionCore:
    return FusionCore(make_config(orientation))


def _run(world: RestWorld, core: FusionCore):
    records = []
    for s in simulate(world):
        records.extend(core.ingest(s).records)
    return [r for r in records if r.channel == "gyro_bias"]


def _drive_with_false_then_real_standstills(false_rate: float) -> list[Segment]:
    return [
        Segment(2.0, speed=1.0, yaw_rate=0.1),
        Segment(3.0, speed=0.3, yaw_rate=false_rate, odom_reads_zero=True),  # "at rest" while turning
        Segment(3.0, speed=1.0, yaw_rate=-0.2),
        Segment(3.0),  # real standstills
        Segment(3.0, speed=1.0, yaw_rate=0.2),
        Segment(3.0),
        Segment(3.0, speed=1.0, yaw_rate=-0.1),
        Segment(3.0),
    ]


@pytest.mark.parametrize("false_rate", [0.06, 0.02])
def test_bias_is_learned_after_a_false_standstill(false_rate):
    """0.06 rad/s: the gyro is not quiet, the false standstill is refused outright. 0.02 rad/s:
    within the quiet bound (3 x (noise + prior bias sigma 0.01) = 0.036), so it is accepted and
    locks in a wrong z bias; the real standstills after it agree with each other, re-open the
    bias and correct it."""
    world = RestWorld(_drive_with_false_then_real_standstills(false_rate), gyro_bias=BIAS)
    core = _core()
    bias_records = _run(world, core)
    b = core.gyro_bias
    assert b[2] == pytest.approx(BIAS[2], rel=0.10)
    assert b[0] == pytest.approx(BIAS[0], rel=0.10) and b[1] == pytest.approx(BIAS[1], rel=0.10)
    # and the updates of the real standstills are (once re-opened) accepted
    late = [r for r in bias_records if r.stamp > 1000.0 + 20.0]
    assert late and sum(not r.rejected for r in late) >= 0.8 * len(late)


def test_z_bias_is_learned_when_the_x_y_bias_is_confidently_wrong():
    """The IMU's own roll drifts at 0.02 rad/s: through roll/pitch updates the filter's x bias
    explains that drift, wrong by ~0.02 rad/s (> 50 sigma of a window) and confident. The x
    windows are rejected, but z is judged on its own and learned within 10 %."""
    segments = [Segment(3.0, speed=1.0, yaw_rate=0.1), Segment(4.0), Segment(3.0, speed=1.0, yaw_rate=-0.1),
                Segment(4.0), Segment(3.0, speed=1.0, yaw_rate=0.1), Segment(4.0)]
    world = RestWorld(segments, gyro_bias=BIAS, roll_drift=0.02)
    core = _core("roll_pitch")
    _run(world, core)
    assert core.gyro_bias[2] == pytest.approx(BIAS[2], rel=0.10)


def test_no_standstill_leaves_the_bias_at_its_prior():
    world = RestWorld([Segment(10.0, speed=1.0, yaw_rate=0.1)], gyro_bias=BIAS)
    core = _core()
    assert _run(world, core) == []
    assert core.gyro_bias[2] == pytest.approx(0.0, abs=1e-3)


def test_a_coasting_turn_is_not_taken_for_rest_when_the_driver_overstates_the_gyro_noise():
    """razor_imu_9dof states 0.02 rad^2/s^2 (sigma 0.141 rad/s) for a gyro of 0.002: by the stated
    noise the quiet bound is 3 x (0.141 + 0.01) = 0.45 rad/s, so a car coasting round a bend at
    0.06 rad/s with its drive at zero would pass for rest and teach a z bias of ~0.065 (truth
    0.005). By the readings' own scatter (0.002) the bound is 3 x (0.002 + 0.01) = 0.036: refused.
    The real standstills after it are learned with the noise each window shows, not the stated one
    (the stated 0.02 / 30 = 6.7e-4 per window would take the estimate only 68 % of the way): a window
    of 30 samples of 0.002 has variance 0.002^2 / 30 = 1.3e-7. Each stop is a physical one (0.5 s from
    1 m/s: an instant drop to zero would be a coast, see test_coast.py), so each segment of 3 s rests
    2.5 s, less the 0.3 s confirmation: ~7 windows a stop, together sigma ~1e-4 against the prior's
    0.01, so the estimate lands on the bias within 5e-4 (5 sigma). Never toward the coasting turn's 0.065."""
    segments = [Segment(3.0, speed=0.5, yaw_rate=0.06, odom_reads_zero=True),  # coasting at the start
                Segment(3.0, speed=1.0, yaw_rate=-0.1), Segment(3.0),
                Segment(3.0, speed=1.0, yaw_rate=0.1), Segment(3.0)]
    world = RestWorld(segments, gyro_bias=BIAS, gyro_stated_sigma=0.141, ramp_s=0.5)
    core = _core()
    records = _run(world, core)
    coasting = [r for r in records if r.stamp < 1000.0 + 3.0]
    assert coasting == []  # no bias update from the coasting turn
    assert core.gyro_bias[2] == pytest.approx(BIAS[2], abs=5e-4)
