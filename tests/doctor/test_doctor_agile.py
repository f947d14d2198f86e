"""The doctor on an agile vehicle: a race car turning at ~1 rad/s whose IMU reports its own
AHRS yaw, relative to power-on, with small white noise and a slow drift.

Pairing each bin's mean IMU yaw (it holds at the bin's middle) with the integrated gyro heading reached
when the bin closes (its end) is a skew of BIN_S / 2 = 0.1 s, which a vehicle turning at w reads as
w x 0.1 s of yaw "wander" (0.06 rad on an F1/10 car's bag, over WANDER_RAD): a correct yaw would be
called magnetometer-disturbed and ``orientation = "roll_pitch"`` advised, against the doctor's own
advice of ``"relative"`` for the heading lost across logging gaps. So the comparisons are made at the
instants each value holds at (``Series.*_heading_at``, ``imu_yaw_at``). The simulation has the trait
(the bin-paired figure exceeds WANDER_RAD), the doctor does not call the yaw disturbed, and a yaw
with tens of degrees of real disturbance is still named.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.doctor.bins import BIN_S
from fusiond.doctor.checks.heading import heading_check
from fusiond.doctor.heading import WANDER_RAD, detrended_rms
from fusiond.estimator import rotation as rot
from fusiond.replay.run import run_samples
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.verdicts import agree, one
from tests.support.core_samples import make_config

T0 = 1000.0
STANDSTILL_S = 3.0  # at rest first: the gyro bias is learned
SPEED = 3.0  # m/s
W = 1.2  # rad/s: peak turn rate (rms W / sqrt(2) = 0.85 rad/s)
PERIOD = 8.0  # s: one left-right weave
YAW_SIGMA = 0.005  # rad: the AHRS yaw's white noise
YAW_DRIFT = 0.0005  # rad/s: the AHRS yaw's drift against the truth
GYRO_SIGMA = 0.004  # rad/s
GYRO_BIAS = 0.004  # rad/s (z)
WHEEL_SIGMA = 0.03
DISTURBANCE = (0.4, 20.0)  # rad (23 deg), s: a magnetometer disturbance, for the disturbed twin


def yaw_rate(rel: float) -> float:
    return 0.0 if rel < STANDSTILL_S else W * math.sin(2.0 * math.pi * (rel - STANDSTILL_S) / PERIOD)


def heading(rel: float) -> float:
    """The exact integral of yaw_rate."""
    if rel < STANDSTILL_S:
        return 0.0
    return W * PERIOD / (2.0 * math.pi) * (1.0 - math.cos(2.0 * math.pi * (rel - STANDSTILL_S) / PERIOD))


def race_car(duration: float = 90.0, stated_yaw_sigma: float = YAW_SIGMA, disturbed: bool = False,
             seed: int = 7) -> list[OdomSample | ImuSample]:
    """Odometry at 50 Hz, IMU at 100 Hz (AHRS yaw = truth + power-on offset + drift + noise, and a slow
    sinusoidal disturbance when ``disturbed``), in stamp order. ``stated_yaw_sigma``: the orientation
    covariance the IMU reports (0: an AHRS stating none, read as the orientation_min_sigma floor)."""
    rng = np.random.default_rng(seed)
    out: list[OdomSample | ImuSample] = []
    wcov = [0.0] * 36
    for i in range(6):
        wcov[7 * i] = WHEEL_SIGMA**2
    ocov = (stated_yaw_sigma**2, 0.0, 0.0, 0.0, stated_yaw_sigma**2, 0.0, 0.0, 0.0, stated_yaw_sigma**2)
    gcov = (GYRO_SIGMA**2, 0.0, 0.0, 0.0, GYRO_SIGMA**2, 0.0, 0.0, 0.0, GYRO_SIGMA**2)
    for k in range(int(duration * 100)):
        rel = k / 100.0
        t = T0 + rel
        w = yaw_rate(rel)
        moving = rel >= STANDSTILL_S
        if k % 2 == 0:
            v = SPEED if moving else 0.0
            out.append(OdomSample("wheel", t, (v + moving * rng.normal(0, WHEEL_SIGMA), 0.0, 0.0),
                                  (0.0, 0.0, w + moving * rng.normal(0, WHEEL_SIGMA)), tuple(wcov)))
        yaw = heading(rel) + 1.2 + YAW_DRIFT * rel + rng.normal(0, YAW_SIGMA)
        if disturbed:
            yaw += DISTURBANCE[0] * math.sin(2.0 * math.pi * rel / DISTURBANCE[1])
        out.append(ImuSample("imu", t, rot.from_rpy(0.0, 0.0, yaw), ocov,
                             (rng.normal(0, GYRO_SIGMA), rng.normal(0, GYRO_SIGMA), w + GYRO_BIAS + rng.normal(0, GYRO_SIGMA)),
                             gcov))
    return out


def bin_paired_wander(series) -> float:
    """The wander a bin-paired comparison measures: each bin's closing gyro heading paired with the IMU's mean yaw
    of the bin at the same index time (both stamped at their bins' middles)."""
    ti, yi = np.array(series.imu_t), np.array(series.imu_yaw)
    tg, hg = np.array(series.gyro_t), np.array(series.gyro_heading)
    m = (ti >= tg[0]) & (ti <= tg[-1])
    g = np.interp(ti[m], tg, hg)
    return detrended_rms(ti[m], yi[m] - g, g, [*series.gyro_breaks, *series.imu_breaks])[0]


@pytest.mark.parametrize("stated", ["honest", "none"])
def test_an_agile_vehicles_correct_imu_yaw_is_not_called_disturbed(stated):
    """Derivation of the thresholds (W = 1.2 rad/s peak, rms turn rate W / sqrt(2) = 0.85 rad/s).

    The trait: the closing gyro heading holds about BIN_S (less half a 100 Hz step) after its bin opens,
    the mean yaw at BIN_S / 2 - 0.005 s: a skew of tau = 0.1 s, a difference tau w(t). Over a weave it is
    90 degrees out of phase with the heading (the derivative of a sinusoid), so the detrending
    (a + b t + c heading, a minute at a time) removes none of it: rms tau W / sqrt(2) = 0.085 rad, 1.7 x
    WANDER_RAD. Asserted above 1.3 x WANDER_RAD (the 20 % margin covers the windowing).

    At the same instants what is left: the yaw's white noise averaged over a bin's 20 samples
    (0.005 / sqrt(20) = 0.0011 rad), the integrated gyro noise over a detrended minute (0.004 rad/s x
    sqrt(0.01 s) = 0.0004 rad/sqrt(s), ~0.001 rad rms after the fit), and the error of interpolating the
    gyro heading linearly between bins 0.2 s apart (at most wdot h^2 / 8 with wdot = W 2 pi / PERIOD =
    0.94 rad/s^2: 0.005 rad, ~0.002 rms); the drift (0.0005 rad/s) is the fitted slope. Together ~0.003 rad:
    asserted below WANDER_RAD / 4 = 0.0125 (4x margin), far from the disturbance threshold.

    With no covariance stated ("none": the IMU's zeros read as the orientation_min_sigma floor, 0.001 rad,
    against 0.005 of noise) the yaw's NIS is high, ~25 per dof: that is the stated noise, not a disturbance
    (the gyro says the yaw follows it), so the doctor must advise orientation_noise, not roll_pitch. The
    innovation is the yaw's noise (0.005) plus the filter's own yaw error, which it draws from the same noisy
    yaws through a gyro good to 0.0004 rad per step: the measured yaw sigma lies within [0.8, 2] x 0.005."""
    samples = race_car(stated_yaw_sigma=YAW_SIGMA if stated == "honest" else 0.0)
    cfg = make_config(orientation="relative", gyro=True)
    result = run_samples(samples, cfg)
    series = result.doctor.series()
    assert bin_paired_wander(series) > 1.3 * WANDER_RAD  # the simulation has the trait
    checked = heading_check(series, result.doctor.cfg)
    assert checked is not None and checked.level == "ok", checked
    assert checked.evidence["imu_vs_gyro_wander_rad"] < WANDER_RAD / 4, checked
    verdicts = result.verdicts()
    agree(result.doctor, verdicts)
    for v in verdicts:
        assert "roll_pitch" not in v.suggestion and "magnetometer" not in v.message, v
    orientation = one(verdicts, "imu", "orientation")
    if stated == "honest":
        assert orientation.level == "ok", orientation
    else:
        assert orientation.key == "sensors.imu.orientation_noise", orientation
        assert "not a disturbed yaw" in orientation.message, orientation
        yaw_sigma = float(orientation.suggestion.split("[")[1].rstrip("]").split(",")[2])
        assert 0.8 * YAW_SIGMA <= yaw_sigma <= 2.0 * YAW_SIGMA, orientation


def test_a_disturbed_yaw_on_the_same_vehicle_is_still_named():
    """The same race car, its IMU yaw disturbed by 0.4 rad (23 deg) over a 20 s period (motors, steel). The
    detrending fits a + b t + c heading per minute; the disturbance (20 s) is neither a line nor the heading
    (an 8 s weave), so it stays: rms ~0.4 / sqrt(2) = 0.28 rad, over 5 x WANDER_RAD; asserted above
    4 x WANDER_RAD. The doctor names it and takes heading from the gyro."""
    samples = race_car(disturbed=True)
    result = run_samples(samples, make_config(orientation="relative", gyro=True))
    verdicts = result.verdicts()
    agree(result.doctor, verdicts)
    v = one(verdicts, "imu", "orientation")
    assert v.level == "problem" and "magnetometer" in v.message, v
    assert v.key == "sensors.imu.orientation" and 'orientation = "roll_pitch"' in v.suggestion, v
    assert v.evidence["imu_vs_gyro_wander_rad"] > 4 * WANDER_RAD, v


def test_heading_instants_lie_where_the_values_hold():
    """What the series says about its own instants: each closing gyro heading holds about its bin's end
    (within a 100 Hz step of BIN_S / 2 after the bin's middle: half a step earlier than the closing stamp,
    the integration holding each rate over the step after it), each mean yaw within a step of its bin's
    middle (the last bin, flushed part-full at the end, excepted). Paired at the middles, these are the
    tau = 0.1 s of skew the test above measures."""
    series = run_samples(race_car(duration=20.0), make_config(orientation="relative", gyro=True)).doctor.series()
    mids, at = np.array(series.gyro_t), np.array(series.gyro_heading_at)
    assert len(at) == len(mids) == len(series.gyro_heading)
    assert np.all(at[:-1] - mids[:-1] >= BIN_S / 2 - 0.01), (at - mids)[:10]
    assert np.all(at[:-1] - mids[:-1] <= BIN_S / 2 + 0.01), (at - mids)[:10]
    yaw_at, yaw_mid = np.array(series.imu_yaw_at), np.array(series.imu_t)
    assert len(yaw_at) == len(series.imu_yaw) and np.all(np.abs(yaw_at[:-1] - yaw_mid[:-1]) <= 0.01)
