"""The doctor on a vehicle that sets off at once: its gyro's z bias is learned only at the first standstill,
40 s in, and until then the heading turned with it (``doctor/checks/late_bias.py``).

A car weaving at 2 m/s (yaw rate W sin(2 pi s / P)) with a gyro z bias of 0.004 rad/s, no standstill until
REST_AT, its IMU publishing an AHRS yaw of its own (truth + a power-on offset + an optional drift + white
noise). Configured as the README's recommended start (roll_pitch, gyro fused) nothing holds the heading: the
filter integrates the bias with its prior (0) until the first standstill window closes, standstill_s after
REST_AT. The doctor must say so, with the drift, and advise ``orientation = "relative"`` when the IMU's yaw
is good enough (and not when it drifts more than the late bias costs); pasted, the heading must hold.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.doctor.checks.late_bias import LATE_DRIFT_RAD, RELATIVE_MARGIN
from fusiond.estimator import rotation as rot
from fusiond.replay.run import Runner, run_samples
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.verdicts import agree, one
from tests.support.core_samples import make_config

T0 = 1000.0
SPEED = 2.0  # m/s
W = 0.5  # rad/s: peak turn rate of the weave
PERIOD = 10.0  # s
GYRO_BIAS = 0.004  # rad/s (z)
GYRO_SIGMA = 0.004  # rad/s
WHEEL_SIGMA = 0.03
YAW_SIGMA = 0.005  # rad: the AHRS yaw's white noise
REST_AT, REST_S = 40.0, 3.0  # the first standstill
BRAKE_S = 1.0  # s of braking before it (2 m/s^2: a stop, not the drive dropping out, see core/sensors/odom/model.py)
DURATION = 70.0
STANDSTILL_S = 0.3  # the filter's default standstill_s (the first window closes this long after REST_AT)
LEARNED_AT = REST_AT + STANDSTILL_S
DRIFT = GYRO_BIAS * LEARNED_AT  # rad: the heading turned by the bias before it was learned (0.161)


def phase(rel: float, rest_at: float, rest_s: float) -> tuple[float, bool]:
    """(time spent driving so far, moving now): the weave pauses while the vehicle stands."""
    return phases(rel, ((rest_at, rest_s),))


def phases(rel: float, rests: tuple[tuple[float, float], ...]) -> tuple[float, bool]:
    """``phase`` with several standstills (start, duration), in time order."""
    stood = 0.0
    for at, length in rests:
        if rel < at:
            break
        if rel < at + length:
            return at - stood, False
        stood += length
    return rel - stood, True


def heading(s: float) -> float:
    """The exact integral of the weave's yaw rate over the driving time s."""
    return W * PERIOD / (2.0 * math.pi) * (1.0 - math.cos(2.0 * math.pi * s / PERIOD))


def weaving_car(yaw_drift: float = 0.0, rest_at: float = REST_AT, rest_s: float = REST_S,
                seed: int = 5, gap: tuple[float, float] | None = None,
                duration: float = DURATION, rests: tuple[tuple[float, float, float, float], ...] | None = None,
                ) -> list[OdomSample | ImuSample]:
    """Odometry at 50 Hz, IMU at 100 Hz with its AHRS yaw, in stamp order; nothing logged within ``gap``.
    ``rests``: the standstills (start, duration, and what the gyro's z reads there beyond its bias and noise: an
    offset and a noise of its own), instead of the one at ``rest_at``."""
    rests = rests if rests is not None else ((rest_at, rest_s, 0.0, 0.0),)
    spans = tuple((at, length) for at, length, _, _ in rests)
    rng = np.random.default_rng(seed)
    out: list[OdomSample | ImuSample] = []
    wcov = tuple(WHEEL_SIGMA**2 if i % 7 == 0 else 0.0 for i in range(36))
    ocov = (YAW_SIGMA**2, 0.0, 0.0, 0.0, YAW_SIGMA**2, 0.0, 0.0, 0.0, YAW_SIGMA**2)
    gcov = (GYRO_SIGMA**2, 0.0, 0.0, 0.0, GYRO_SIGMA**2, 0.0, 0.0, 0.0, GYRO_SIGMA**2)
    for k in range(int(duration * 100)):
        rel = k / 100.0
        if gap is not None and gap[0] <= rel < gap[1]:
            continue
        s, moving = phases(rel, spans)
        w = W * math.sin(2.0 * math.pi * s / PERIOD) if moving else 0.0
        if not moving:
            offset, sigma = next((o, n) for at, length, o, n in rests if at <= rel < at + length)
            w = offset + (rng.normal(0, sigma) if sigma > 0.0 else 0.0)
        if k % 2 == 0:
            stop = next((at for at, _, _, _ in rests if at > rel), math.inf)  # braking into the next standstill
            speed = SPEED * min(1.0, max(0.0, (stop - rel) / BRAKE_S))
            v, wz = ((speed + rng.normal(0, WHEEL_SIGMA), w + rng.normal(0, WHEEL_SIGMA)) if moving else (0.0, 0.0))
            out.append(OdomSample("wheel", T0 + rel, (v, 0.0, 0.0), (0.0, 0.0, wz), wcov))
        yaw = heading(s) + 1.2 + yaw_drift * rel + rng.normal(0, YAW_SIGMA)
        gyro = (rng.normal(0, GYRO_SIGMA), rng.normal(0, GYRO_SIGMA), w + GYRO_BIAS + rng.normal(0, GYRO_SIGMA))
        out.append(ImuSample("imu", T0 + rel, rot.from_rpy(0.0, 0.0, yaw), ocov, gyro, gcov))
    return out


def replay(samples, orientation: str, extra_imu: str = ""):
    """(result, |heading error| at each published pose, their stamps relative to the start)."""
    runner = Runner(make_config(orientation=orientation, gyro=True, extra_imu=extra_imu))
    for sample in samples:
        runner.feed(sample)
    rows = np.asarray(runner.trajectory).reshape(-1, 8)
    rel = rows[:, 0] - T0
    truth = [heading(phase(r, REST_AT, REST_S)[0]) for r in rel]
    err = np.array([abs(rot.wrap(rot.yaw(tuple(q)) - h)) for q, h in zip(rows[:, 4:8].tolist(), truth)])
    return runner.result(), err, rel


def test_a_late_bias_is_named_and_a_good_imu_yaw_advised():
    """Thresholds. The first standstill's gyro mean is the bias to within its standard error,
    GYRO_SIGMA / sqrt(2.7 s x 100 Hz) = 0.00024 rad/s: asserted within 0.001. The drift the doctor states
    is that times the time to the first accepted update (LEARNED_AT, 0.161 rad), within 25 %. The trait: as
    configured (roll_pitch), the heading is off by b t until then, so by more than DRIFT / 2 just before
    REST_AT, and on average over the run by about b LEARNED_AT^2 / (2 T) = 0.046 rad (the update at the
    standstill turns it back: the stated gyro noise is honest); asserted above half that. The AHRS yaw drifts
    not at all: its fitted drift is the gyro's and the yaw's noise over a minute's windows (~1e-4 rad/s),
    asserted below 0.001, so relative costs ~0.035 rad on average at most, below RELATIVE_MARGIN x 0.046: the
    advice is given. Pasted, the relative yaw (noise 0.005 rad at 100 Hz) holds the heading from the start:
    its largest error is the yaw's noise after the filter's averaging, asserted below DRIFT / 4 (0.04 rad),
    and its mean below RELATIVE_MARGIN x the configured run's. Then nothing is left to say about the heading."""
    samples = weaving_car()
    result, err, rel = replay(samples, "roll_pitch")
    assert err[rel < REST_AT].max() > DRIFT / 2  # the simulation has the trait
    assert err.mean() > 0.5 * GYRO_BIAS * LEARNED_AT**2 / (2.0 * DURATION)
    verdicts = result.verdicts()
    agree(result.doctor, verdicts)
    v = one(verdicts, "imu", "heading")
    assert v.level == "warn" and "unknown for the first" in v.message, v
    assert abs(v.evidence["gyro_at_rest_rad_s"] - GYRO_BIAS) < 0.001, v
    assert abs(v.evidence["heading_drift_rad"] - DRIFT) < 0.25 * DRIFT, v
    assert abs(v.evidence["imu_yaw_drift_rad_s"]) < 0.001, v
    assert v.key == "sensors.imu.orientation" and v.suggestion == 'orientation = "relative"', v

    applied, err_relative, _ = replay(samples, "relative")
    assert err_relative.max() < DRIFT / 4
    assert err_relative.mean() < RELATIVE_MARGIN * err.mean()
    assert not [v for v in applied.verdicts() if v.channel == "heading"]


def test_a_drifting_imu_yaw_is_not_advised():
    """The AHRS yaw drifts 0.005 rad/s: fused as relative, ~0.005 x 70 / 2 = 0.175 rad off on average, against
    ~0.046 + 0.004 x 40.3 x 29.7 / 70 = 0.114 as configured (the continuous odom frame keeps the drift
    after the bias is learned): not worth it. The verdict still names the late bias, says the IMU's yaw would
    not do better, and suggests nothing to paste; the drift it measured is 0.005 within the fit's ~1e-4 rad/s
    (0.0005 allowed), the cost it states for the configuration within 20 % of the replay's. And the doctor is
    right: replayed as relative, the mean heading error is the larger."""
    samples = weaving_car(yaw_drift=0.005)
    result, err, _ = replay(samples, "roll_pitch")
    v = one(result.verdicts(), "imu", "heading")
    assert "would not do better" in v.message and not v.suggestion, v
    assert abs(v.evidence["imu_yaw_drift_rad_s"] - 0.005) < 0.0005, v
    assert abs(v.evidence["mean_heading_error_rad"] - err.mean()) < 0.2 * err.mean(), (v, err.mean())
    _, err_relative, _ = replay(samples, "relative")
    assert err_relative.mean() > err.mean()


def test_a_vehicle_that_starts_at_rest_learns_its_bias_in_time():
    """At rest for 3 s first: the bias is learned after standstill_s, the heading having turned by
    0.004 x 0.3 = 0.0012 rad, far below LATE_DRIFT_RAD: no heading verdict."""
    assert GYRO_BIAS * STANDSTILL_S < LATE_DRIFT_RAD / 10
    result = run_samples(weaving_car(rest_at=0.0), make_config(orientation="roll_pitch", gyro=True))
    assert not [v for v in result.verdicts() if v.channel == "heading"]


def test_across_logging_gaps_the_imu_yaw_decides():
    """The drifting AHRS of the test above, and a 6 s logging gap at 20 s in which the car turns (the weave's
    half period is 10 s: up to ~1 rad), with yaw_across_gaps turned off. The gap verdict advises it (the IMU's
    yaw alone says how far the car turned); the late bias verdict, whose drift alone would not advise the
    relative yaw, points there instead of leaving the user two contradicting answers."""
    samples = weaving_car(yaw_drift=0.003, gap=(20.0, 26.0))
    verdicts = run_samples(samples, make_config(orientation="roll_pitch", gyro=True,
                                                extra_imu="yaw_across_gaps = false")).verdicts()
    gaps = one(verdicts, "imu", "heading_across_gaps")
    assert gaps.suggestion == "yaw_across_gaps = true", gaps
    v = one(verdicts, "imu", "heading")
    assert not v.suggestion and v.message.endswith("see imu/heading_across_gaps"), v


def test_across_logging_gaps_a_drifting_imu_yaw_carries_the_heading_at_its_drift_over_the_gap():
    """A race car: a 6-axis IMU whose yaw integrates its own uncorrected gyro bias (the gyro's 0.004
    rad/s), over 300 s, with a 1.2 s logging gap at 100.4 s in which the weave turns the car by
    heading(97.4) - heading(98.6) = 0.56 rad (driving time: the 3 s rest comes first). Fused as relative,
    the yaw's drift runs for the whole run: ~0.004 x 300 / 2 = 0.6 rad off on average, worse than the miss
    (~0.56 x 198 / 300 = 0.37 rad held from the gap on). Across the gap only (yaw_across_gaps, the default)
    it costs 0.004 x 1.2 = 0.005 rad, once (less the drift it measured): with yaw_across_gaps on, after the gap
    the heading error is what it was before it (the drift the bias learned at 40 s left in the continuous odom
    frame), within a tenth of the miss, and no gap verdict is given.
    Turned off, the miss, beyond the yaw's drift over the gap, is named with yaw_across_gaps = true to paste; with roll/pitch
    not fused (orientation = "off"), with roll_pitch and it, quoting the drift it measured (the IMU's within
    the fit's ~1e-4 rad/s, 0.0005 allowed); relative is the worst of the three."""
    gap = (100.4, 101.6)
    missed = heading(gap[0] - REST_S) - heading(gap[1] - REST_S)
    assert abs(missed) > 0.5  # the simulation has the trait: a turn hidden by the gap
    samples = weaving_car(yaw_drift=GYRO_BIAS, gap=gap, duration=300.0)
    result, err, rel = replay(samples, "roll_pitch", "yaw_across_gaps = true")
    assert not [v for v in result.verdicts() if v.channel == "heading_across_gaps"]
    before = err[(rel > gap[0] - 5.5) & (rel < gap[0] - 0.5)].mean()
    assert abs(err[rel > gap[1] + 0.5].mean() - before) < 0.1 * abs(missed)
    v = one(replay(samples, "roll_pitch", "yaw_across_gaps = false")[0].verdicts(), "imu", "heading_across_gaps")
    assert v.suggestion == "yaw_across_gaps = true", v
    result_off, err_off, _ = replay(samples, "off")
    assert err_off[rel > gap[1] + 0.5].mean() > 0.5 * abs(missed)  # held along the old heading
    v = one(result_off.verdicts(), "imu", "heading_across_gaps")
    assert v.level == "warn" and v.suggestion == 'orientation = "roll_pitch"\nyaw_across_gaps = true', v
    assert abs(v.evidence["imu_yaw_drift_rad_s"] - GYRO_BIAS) < 0.0005, v
    # what the filter missed: the gap's turn less what the held inputs turned (the gyro's rate for its 0.2 s
    # timeout, then the wheels' yaw rate with the twist held through filter.gap_s: the rate at the gap, 0.5 s)
    held = 0.5 * (heading(gap[0] - REST_S) - heading(gap[0] - REST_S - 0.01)) / 0.01
    assert abs(abs(v.evidence["largest_missed_turn_rad"]) - abs(missed + held)) < 0.1, (v, missed, held)
    _, err_relative, _ = replay(samples, "relative")
    assert err_relative.mean() > err_off.mean() > err.mean()


def test_a_bias_moved_by_a_drifting_fused_yaw_is_not_put_down_to_the_gyro_noise():
    """The drifting AHRS fused as relative (the race car above): its yaw, 0.004 rad/s off the bias-corrected
    gyro, pulls the bias estimate towards 0 while the car drives, and the first standstill's windows (2 s
    at 30 s) find the gyro reading 0.004 at rest: NIS high. The gyro's noise at rest measures what is
    stated (GYRO_SIGMA, within its sampling error over ~200 samples a window: well inside 1.5x), so
    "gyro_noise = <the same value>" would be no advice: the verdict names the bias being moved, and the yaw."""
    samples = weaving_car(yaw_drift=GYRO_BIAS, rest_at=30.0, rest_s=2.0, duration=52.0)
    result, _, _ = replay(samples, "relative")
    assert result.doctor.channels[("imu", "gyro_bias")].verdict() == "nis_high"  # the simulation has the trait
    v = one(result.verdicts(), "imu", "gyro_bias")
    assert v.level == "warn" and v.key != "sensors.imu.gyro_noise" and not v.suggestion, v
    assert "as stated" in v.message and 'orientation = "relative"' in v.message, v
    assert abs(v.evidence["gyro_sigma_at_rest_rad_s"] - GYRO_SIGMA) < 0.5 * GYRO_SIGMA, v


def test_a_car_parked_through_a_gap_is_not_told_its_drifting_imu_turned():
    """A 6-axis AHRS whose yaw drifts 0.03 rad/s, the car parked from 100 s to 130 s with a 25 s logging
    gap inside the stop: the IMU's yaw moved 0.75 rad across the gap, beyond the allowance (GAP_TURN_RAD +
    GAP_DRIFT_RATE x 25 = 0.45 rad), though the car never turned. Its drift, measured against the bias-corrected
    gyro over the run, explains it all: no turn is named, and yaw_across_gaps is not advised. Nor does the
    core (yaw_across_gaps on, the default) turn the heading: the car stood still before and after the gap.
    Turned anyway, the heading would be off by the 0.75 rad from the gap on; asserted: the run is exactly
    the one with the feature off."""
    from fusiond.doctor.checks.gap_heading import GAP_DRIFT_RATE, GAP_TURN_RAD

    assert 0.03 * 25.0 > GAP_TURN_RAD + GAP_DRIFT_RATE * 25.0  # the simulation has the trait
    samples = weaving_car(yaw_drift=0.03, rest_at=100.0, rest_s=30.0, gap=(103.0, 128.0), duration=200.0)
    result, err, rel = replay(samples, "roll_pitch")
    assert not [v for v in result.verdicts() if v.channel == "heading_across_gaps"]
    assert result.core.models[result.core.index["imu"]].gap_turns == 0
    _, err_off, rel_off = replay(samples, "roll_pitch", "yaw_across_gaps = false")
    np.testing.assert_array_equal(rel, rel_off)
    np.testing.assert_array_equal(err, err_off)


@pytest.mark.parametrize("orientation", ["relative", "absolute"])
def test_a_drifting_ahrs_yaw_fused_is_named_with_roll_pitch(orientation):
    """The same drifting AHRS (0.003 rad/s, 10 deg a minute), its yaw fused (on a race car: heading error
    26 deg instead of 1.5, where a smaller yaw noise would be the NIS's only advice). Its drift against the gyro less the bias the
    gyro reads at rest (REST_AT) is the yaw's own: 0.003 within the fit's ~1e-4 rad/s (0.0005 allowed),
    beyond DRIFT_RAD_S: no heading, take roll/pitch only. The fused yaw dragged the filter's bias estimate
    to b - r (0.001), which is why the bias at rest, not the estimate, is what is subtracted. The AHRS
    that does not drift gets no such verdict."""
    from fusiond.doctor.checks.heading import DRIFT_RAD_S

    assert 0.003 - 0.0005 > DRIFT_RAD_S  # the whole tolerance band is beyond the threshold
    result, _, _ = replay(weaving_car(yaw_drift=0.003), orientation)
    v = one(result.verdicts(), "imu", "orientation")
    assert v.level == "problem" and v.key == "sensors.imu.orientation" and "roll_pitch" in v.suggestion, v
    assert abs(v.evidence["imu_yaw_drift_rad_s"] - 0.003) < 0.0005, v
    steady, _, _ = replay(weaving_car(), orientation)
    v = one(steady.verdicts(), "imu", "orientation")
    assert "drifts" not in v.message and abs(v.evidence["imu_yaw_drift_rad_s"]) < 0.0005, v


def test_the_bias_at_rest_is_the_standstills_median_not_the_first_one_alone():
    """Three standstills: a short first one at 20 s (1 s) where the gyro's z reads 0.006 rad/s beyond its bias
    with 0.015 rad/s of noise of its own (an engine idling: the first standstill of the F1/10 car read 0.0146
    rad/s over 7 samples scattered by 0.011, against 0.007 at its later ones), then 3 s at 40 s and at 55 s.
    The gyro at rest is the median of the three means, the bias within the long ones' standard error
    (GYRO_SIGMA / sqrt(270) = 0.00024 rad/s; 0.001 asserted), not the first's ~0.010: the figure the
    late-bias verdict prices its drift with is the one the gyro-bias and heading checks name."""
    rests = ((20.0, 1.0, 0.006, 0.015), (40.0, 3.0, 0.0, 0.0), (55.0, 3.0, 0.0, 0.0))
    result, _, _ = replay(weaving_car(rests=rests), "roll_pitch")
    v = one(result.verdicts(), "imu", "heading")
    assert v.evidence["first_standstill_s"] == pytest.approx(20.0, abs=0.5), v
    assert abs(v.evidence["gyro_at_rest_rad_s"] - GYRO_BIAS) < 0.001, v
    assert "median of its 3 standstills" in v.message, v
