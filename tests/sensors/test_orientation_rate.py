"""``orientation_rate_hz``: an IMU's orientation is fused at most at that rate, its gyro at every sample.

The grid is phase-locked (``ImuModel._orientation_due``): an IMU at or below the cap loses no
sample, jittered stamps included; a faster one is fused at the cap on average; a late sample
re-applied from the history thins as it did the first time. The reason for the cap is the
filter's confidence: an AHRS's orientation errors are alike from sample to sample, so the
roll/pitch variance must not shrink with the message rate beyond the cap.
"""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from fusiond.config import ConfigError
from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.imu import ORIENTATION_BURST
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config

ORI_SIGMA = 0.01  # rad, the AHRS's stated roll/pitch noise
GYRO_SIGMA = 0.002  # rad/s


def _imu(stamp: float, roll: float = 0.0, yaw: float = 0.0) -> ImuSample:
    ov = ORI_SIGMA**2
    gv = GYRO_SIGMA**2
    return ImuSample("imu", stamp, rot.from_rpy(roll, 0.0, yaw), (ov, 0, 0, 0, ov, 0, 0, 0, ov), (0.0, 0.0, 0.0),
                     (gv, 0, 0, 0, gv, 0, 0, 0, gv))


def _odom(stamp: float) -> OdomSample:
    return OdomSample("wheel", stamp, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), tuple(1e-4 if i % 7 == 0 else 0.0
                                                                         for i in range(36)))


def _run(stamps: list[float], rate: str = "", odom_hz: float = 50.0, order: list[int] | None = None):
    """Feed IMU samples at ``stamps`` (in ``order`` of arrival when given) between odometry at
    ``odom_hz``; returns (core, number of orientation updates made on first arrival)."""
    core = FusionCore(robot_config(imu=rate))
    end = stamps[-1]
    odom = [k / odom_hz for k in range(1, int(end * odom_hz) + 1)]
    events = sorted([(t, "odom") for t in odom] + [(t, "imu") for t in stamps])
    if order is not None:
        imu_events = [e for e in events if e[1] == "imu"]
        shuffled = [imu_events[i] for i in order]
        it = iter(shuffled)
        events = [next(it) if e[1] == "imu" else e for e in events]
    fused = 0
    for t, kind in events:
        step = core.ingest(_imu(t) if kind == "imu" else _odom(t))
        assert step.accepted, step.reason
        fused += sum(1 for r in step.records if r.channel == "orientation" and not r.late)
    return core, fused


def test_a_1khz_imu_is_fused_at_the_cap_and_its_gyro_at_every_sample() -> None:
    stamps = [0.001 * k for k in range(1, 2001)]  # 2 s at 1 kHz
    core, fused = _run(stamps)
    imu = core.models[core.index["imu"]]
    assert fused == pytest.approx(200 + ORIENTATION_BURST, abs=1)  # 100 Hz over 2 s, after the first burst
    assert imu.thinned == 2000 - fused
    assert core.stats[core.index["imu"]].applied == 2000  # the gyro of every sample is taken


def test_every_sample_of_an_imu_at_the_cap_is_fused_also_with_jittered_stamps() -> None:
    rng = random.Random(4)
    stamps = [0.01 * k + rng.uniform(-0.003, 0.003) for k in range(1, 301)]  # 100 Hz, +-30 % jitter
    _, fused = _run(stamps)
    assert fused == 300


def test_an_imu_between_one_and_two_times_the_cap_is_fused_at_the_cap() -> None:
    stamps = [k / 150.0 for k in range(1, 451)]  # 3 s at 150 Hz
    _, fused = _run(stamps)
    assert fused == pytest.approx(300 + ORIENTATION_BURST, abs=1)


def test_rate_zero_fuses_every_sample() -> None:
    stamps = [0.001 * k for k in range(1, 501)]
    core, fused = _run(stamps, rate="orientation_rate_hz = 0")
    assert fused == 500 and core.models[core.index["imu"]].thinned == 0


def test_late_samples_thin_as_in_order() -> None:
    """Arrival order within the history does not change the estimate: the grid is part of the state."""
    stamps = [0.001 * k for k in range(1, 801)]
    in_order, _ = _run(stamps)
    rng = random.Random(7)
    order = list(range(len(stamps)))
    for k in range(0, len(order) - 5, 5):  # each block of five arrives shuffled (up to 4 ms late)
        block = order[k:k + 5]
        rng.shuffle(block)
        order[k:k + 5] = block
    shuffled, _ = _run(stamps, order=order)
    np.testing.assert_allclose(shuffled.state.ekf.x, in_order.state.ekf.x, atol=1e-12)
    np.testing.assert_allclose(shuffled.state.ekf.P, in_order.state.ekf.P, atol=1e-15)


def test_the_roll_variance_stops_shrinking_with_the_rate_at_the_cap() -> None:
    """Between updates the roll variance grows by q per second (gyro noise and the attitude's process
    noise); an update of variance r every 1/f s settles it where growth and shrinkage balance,
    P+ ~ sqrt(q r / f) while q / f << r. So fusing every sample of a 1 kHz IMU makes the filter
    sqrt(10) times surer of the roll than fusing it at 100 Hz, though the AHRS knows no more: the
    cap keeps that variance at its 100 Hz value whatever the IMU's rate."""
    stamps = [0.001 * k for k in range(1, 5001)]  # 5 s: settled
    capped, _ = _run(stamps)
    every, _ = _run(stamps, rate="orientation_rate_hz = 0")
    at_100hz, _ = _run([0.01 * k for k in range(1, 501)])
    p_capped, p_every, p_100 = (c.state.ekf.P[3, 3] for c in (capped, every, at_100hz))
    assert p_capped == pytest.approx(p_100, rel=0.1)
    assert p_capped / p_every == pytest.approx(math.sqrt(10.0), rel=0.2)


@pytest.mark.parametrize("value", ["-1.0", "inf", "nan"])
def test_a_bad_rate_is_refused_naming_the_key(value: str) -> None:
    with pytest.raises(ConfigError, match="orientation_rate_hz"):
        robot_config(imu=f"orientation_rate_hz = {value}")


def test_the_replay_summary_says_how_many_orientations_were_thinned() -> None:
    from fusiond.replay.run import Runner, summary

    runner = Runner(robot_config(), keep_trace=False)
    for k in range(1, 501):  # 0.5 s at 1 kHz, odometry at 50 Hz
        t = 0.001 * k
        runner.feed(_imu(t))
        if k % 20 == 0:
            runner.feed(_odom(t + 0.0005))
    thinned = runner.core.models[runner.core.index["imu"]].thinned
    assert thinned > 400
    assert f"orientation of {thinned} sample(s) not fused: above orientation_rate_hz = 100" in summary(
        runner.result(1.0, [], 0))
