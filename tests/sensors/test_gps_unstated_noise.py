"""A receiver that states no accuracy (covariance type UNKNOWN): its horizontal white noise is measured
from consecutive fixes against the dead-reckoned distance between them (``GpsModel._measured_noise``).

Thresholds from the simulation's physics: with white fix noise sigma per axis and a robot driving
straight, the difference d of two consecutive fixes' distances and the wheels' has E d^2 = 2 sigma^2
(the wheels' own noise over one 0.1 s interval adds (0.02 m/s * 0.1 s)^2, nothing at this scale). A
variance estimated from n such d has a relative standard deviation sqrt(2/n) (chi-square, n dof, up to
the mild correlation of consecutive d, which share a fix: var of the mean of d^2 is at most doubled), so
the estimated sigma is held within 4 * sqrt(1/n) of the truth (> 3 standard deviations of sigma-hat)."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.gps import GpsOwn
from fusiond.core.sensors import GpsSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at


def _unstated(samples: list) -> list:
    """The same fixes as a receiver that says nothing of its accuracy."""
    return [msgspec.structs.replace(s, covariance_type=0, position_covariance=(0.0,) * 9)
            if isinstance(s, GpsSample) else s for s in samples]


def _run(w: World, gps: str) -> tuple[FusionCore, float, list[float]]:
    core = FusionCore(robot_config(gps=gps))
    errors, nis = [], []
    for s in _unstated(simulate(w)):
        step = core.ingest(s)
        for r in step.records:
            if r.sensor == "gps" and r.channel == "position" and not r.rejected:
                nis.append(r.nis / r.dof)
        if isinstance(s, GpsSample) and core.ready:
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            errors.append(math.hypot(x[0] - tx, x[1] - ty))
    return core, float(np.sqrt(np.mean(np.square(errors)))), nis


def _gps_own(core: FusionCore) -> GpsOwn:
    return next(o for o in core.state.own if isinstance(o, GpsOwn))


@pytest.mark.parametrize("sigma", [0.05, 0.3])
def test_the_unstated_noise_is_measured_within_what_its_sample_count_allows(sigma: float) -> None:
    w = World(duration=60.0, speed=5.0, standstill=0.0, gps_rate=10.0, gps_sigma=sigma, seed=11)
    core, _, nis = _run(w, "")
    n, sq = _gps_own(core).increments
    assert n > 500
    estimate = math.sqrt(sq / (2.0 * n))
    assert abs(estimate / sigma - 1.0) < 4.0 * math.sqrt(1.0 / n), (estimate, sigma, n)
    # used at its upper bound, so the fixes' NIS per dof sits at or a little below 1, never far above:
    # the mean of ~500 NIS/dof (2 dof) has a standard deviation ~0.045
    assert np.mean(nis[-300:]) < 1.0 + 3.0 * math.sqrt(2.0 / 300), np.mean(nis[-300:])


def test_measuring_the_unstated_noise_follows_good_fixes_closer_than_the_default() -> None:
    """Fixes of 0.1 m stated as nothing, a car starting 90 deg off the heading the filter assumes: with the
    default (2.5 m) the position dead-reckoned the wrong way while the heading is searched for is pulled
    back weakly, and the search waits for 4 default sigmas of travel; measured, the fixes hold it."""
    w = World(duration=30.0, speed=5.0, start=(0.0, 0.0, math.pi / 2), standstill=0.0, gps_rate=10.0,
              gps_sigma=0.1, wheel_scale=1.02, seed=3)
    _, measured, _ = _run(w, "")
    _, default, _ = _run(w, "estimate_unknown_noise = false")
    assert measured < 0.5 * default, (measured, default)
    assert measured < 3.0 * 0.1, measured  # a few fix sigmas at most


def test_a_stated_covariance_is_left_alone() -> None:
    w = World(duration=20.0, speed=5.0, standstill=0.0, gps_rate=10.0, gps_sigma=0.3, seed=4)
    core = FusionCore(robot_config(gps=""))
    for s in simulate(w):  # covariance type DIAGONAL_KNOWN, as the receiver states it
        core.ingest(s)
    assert _gps_own(core).increments == (0, 0.0)


@pytest.mark.parametrize("n", [3, 5, 10, 30, 100, 1000])
def test_the_upper_bound_is_the_chi_square_quantiles_on_the_safe_side(n: int) -> None:
    """Wilson-Hilferty's approximation against scipy's exact quantile: never below it (a bound that is
    not safe would trust a lucky few increments), within 5 % of it from 5 increments on."""
    from scipy.stats import chi2, norm

    from fusiond.core.sensors.gps.model import NOISE_UPPER_Z, _upper_variance

    exact = 2.0 * n / (2.0 * chi2.ppf(norm.cdf(-NOISE_UPPER_Z), n))  # sigma^2 bound for sum d^2 = 2 n
    approx = _upper_variance(2.0 * n, n)
    assert approx >= exact
    if n >= 5:
        assert approx <= 1.05 * exact


def test_no_bound_from_too_few_increments() -> None:
    from fusiond.core.sensors.gps.model import _upper_variance

    assert _upper_variance(1.0, 0) is None and _upper_variance(1.0, 1) is None


def test_an_unstated_altitude_whose_nis_is_low_names_unknown_position_sigma():
    """Fixes 0.3 m noisy on every axis stating no accuracy: their altitude is taken at unknown_position_sigma's
    5 m, so its NIS per dof is about (0.3 / 5)^2, far below its bounds. Without the slow vertical error state
    (vertical_error_sigma = 0) that noise is all of the spread: the verdict names the key that set it
    (position_noise would replace the horizontal noise the filter measures from the fixes too). With the state
    (5 m over 300 s, a 60 s run) its wander alone keeps the NIS below the bound whatever the fixes' noise: the
    verdict says so, at level ok. Stated, the same fixes are consistent."""
    from fusiond.replay.run import run_samples

    w = World(duration=60.0, gps_rate=10.0, gps_sigma=0.3)
    samples = simulate(w)
    cfg = robot_config(gps="vertical_error_sigma = 0.0")
    (v,) = [v for v in run_samples(_unstated(samples), cfg).verdicts() if v.channel == "altitude"]
    assert v.level == "warn" and "NIS low" in v.message and v.key == "sensors.gps.unknown_position_sigma", v
    assert "which state none" in v.message, v.message
    (slow,) = [v for v in run_samples(_unstated(samples), robot_config(gps="")).verdicts() if v.channel == "altitude"]
    assert slow.level == "ok" and slow.message.startswith("NIS low") and "expects" in slow.message, slow
    cfg = robot_config(gps="")
    (stated,) = [v for v in run_samples(samples, cfg).verdicts() if v.channel == "altitude"]
    assert stated.level == "ok" and stated.key == "", stated  # stated, the same fixes' noise is their own


def test_an_unstated_receivers_horizontal_verdict_names_the_measured_noise_and_position_noise():
    """Fixes stating no accuracy: the filter measures their horizontal noise from the wheels and takes their
    altitude's from unknown_position_sigma. A NIS-low verdict on the horizontal says the noise taken for them
    was measured (not "stated": they state none) and names position_noise, which states it instead; on the
    altitude, without a paste line, it names unknown_position_sigma. 300 updates of NIS 0.05 per dof."""
    from fusiond.core.diagnostics import DiagnosticsRecord
    from fusiond.doctor.checks.absolute import absolute_verdict
    from fusiond.doctor.nis import ChannelStats

    def stats(channel: str, comps: list[str]) -> ChannelStats:
        k = len(comps)
        ch = ChannelStats(comps)
        ch.extend([DiagnosticsRecord(100.0 + 0.1 * i, "gps", comps, [0.1] * k, [0.2] * k, 0.05 * k, k, False,
                                     channel=channel) for i in range(300)])
        return ch

    horizontal = absolute_verdict("gps", "position", stats("position", ["x", "y"]), 100.0, unstated=True)
    assert "NIS low" in horizontal.message and "measured from the wheels" in horizontal.message, horizontal
    assert "the stated noise" not in horizontal.message and horizontal.key == "sensors.gps.position_noise"
    altitude = absolute_verdict("gps", "altitude", stats("altitude", ["up"]), 100.0, unstated=True)
    assert altitude.key == "sensors.gps.unknown_position_sigma" and "which state none" in altitude.message
    stated = absolute_verdict("gps", "position", stats("position", ["x", "y"]), 100.0)
    assert "the stated noise" in stated.message and stated.key == "sensors.gps.position_noise"


def test_the_measured_noise_outlives_the_heading_fits() -> None:
    """Every pair of consecutive fixes is one increment of the noise's measurement, the heading search's fits
    (applied again at each fix until the heading is known, each turning the track) included: a car driving
    from its first fix, 90 deg off the placeholder heading, fixes of 0.1 m stating nothing. Dropped at each
    fit, the fixes of the whole search went in at the unknown default (2.5 m)."""
    w = World(duration=10.0, speed=15.0, start=(0.0, 0.0, math.pi / 2), standstill=0.0, gps_rate=10.0,
              gps_sigma=0.1, seed=6)
    core = FusionCore(robot_config(gps=""))
    fixes, searched = 0, 0
    for s in _unstated(simulate(w)):
        core.ingest(s)
        if isinstance(s, GpsSample):
            fixes += 1
            searched += not core.heading_known
    assert core.heading_known and searched >= 5, searched  # the search took several fits
    n, _ = _gps_own(core).increments
    assert n == fixes - 1, (n, fixes)
