"""The doctor's NIS advice on a gated GPS: a fix the Mahalanobis gate rejected is not fused, so its NIS
says nothing about the stated noise.

A GPS with ``mahalanobis_threshold = 5`` whose receiver reports a few fixes at 0, 0 (thousands of km off,
a NIS of ~1e14 each): the gate keeps them out, but the whole-run mean NIS counts them, and a doctor judging
by it would advise "the stated noise is too small" for a GPS whose applied fixes agree with it. The summary
table prints the whole-run mean (every update, with its rejected count); the doctor judges the applied ones.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np

from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.doctor import ChannelStats
from fusiond.core.sensors import GpsSample
from fusiond.doctor.channels import GATED_FRACTION
from fusiond.doctor.checks.absolute import absolute_verdict
from fusiond.doctor.nis import NIS_HIGH

from tests.support import sim_gps
from tests.support.configs import robot_config
from tests.support.verdicts import one, verdicts_of

GATE = 5.0  # mahalanobis_threshold: a fix is rejected when sqrt(NIS) > 5, NIS > 25


def records(nis: np.ndarray, rejected: np.ndarray) -> list[DiagnosticsRecord]:
    """GPS position records (2 dof) with these NIS values and rejected flags, one a second."""
    return [DiagnosticsRecord(1000.0 + k, "gps", ["east", "north"], [0.0, 0.0], [1.0, 1.0], float(v), 2, bool(r),
                              channel="position") for k, (v, r) in enumerate(zip(nis, rejected))]


def test_a_few_gated_outliers_do_not_make_a_right_noise_read_too_small():
    """1000 fixes whose noise is stated right (NIS ~ chi-square(2): mean 1 per dof) and 3 fixes 7000 km off
    (NIS 1e14, rejected). Counting them, the mean is 3e11 per dof: "nis_high". The applied 1000: 1 per dof,
    inside [NIS_LOW, NIS_HIGH]; the gate rejected 0.3 % (below GATED_FRACTION). No noise advice."""
    rng = np.random.default_rng(3)
    nis = np.concatenate((rng.chisquare(2, 1000), [1e14] * 3))
    ch = ChannelStats(["east", "north"])
    ch.extend(records(nis, nis > GATE**2))
    assert ch.rejected == 3 and ch.verdict() == "nis_high" and ch.kept_verdict() == "ok"
    v = absolute_verdict("gps", "position", ch, 1000.0)
    assert v.level == "warn" and v.key == "", v  # said, nothing to change
    assert "only because of the 3 update(s) the gate rejected" in v.message, v
    assert "too small" not in v.message, v
    assert abs(v.evidence["applied_nis_per_dof"] - 1.0) < 0.15, v  # 1000 x 2 dof: se 1 / sqrt(1000) = 0.03


def test_a_noise_stated_too_small_is_still_named_through_the_gate():
    """The same GPS with its sigma stated half the truth: NIS = 4 chi-square(2) (2 per dof x 4). The gate
    rejects NIS > 25, chi-square(2) > 6.25: exp(-3.125) = 4.4 % of the fixes (below GATED_FRACTION, so the
    gated-fraction warning does not take over). The applied ones are truncated, E[chi2(2) | < 6.25] =
    2 - 6.25 exp(-3.125) / (1 - exp(-3.125)) = 1.71, so they read 4 x 1.71 / 2 = 3.4 per dof: still above
    NIS_HIGH (2): the advice stands."""
    rng = np.random.default_rng(4)
    nis = 4.0 * rng.chisquare(2, 1000)
    ch = ChannelStats(["east", "north"])
    ch.extend(records(nis, nis > GATE**2))
    frac = ch.rejected / ch.n
    assert 0.02 < frac < GATED_FRACTION  # 4.4 % expected; se sqrt(0.044 / 1000) = 0.0065
    assert ch.kept_nis_per_dof > 1.5 * NIS_HIGH  # 3.4 expected
    v = absolute_verdict("gps", "position", ch, 1000.0)
    assert v.level == "problem" and v.key == "sensors.gps.position_noise" and "too small" in v.message, v



def test_a_noise_stated_a_third_of_the_truth_is_named_though_a_quarter_is_gated():
    """Sigma stated a third of the truth (a receiver claiming an RTK fix it does not have): NIS = 9
    chi-square(2), rejected beyond 25: exp(-25 / 18) = 25 % gated, past GATED_FRACTION. Jumps among good fixes
    would leave the applied ones consistent; these read E[chi2(2) | < 2.78] = 2 - 2.78 exp(-1.39) / (1 -
    exp(-1.39)) = 1.08, x 9 / 2 = 4.9 per dof, above NIS_HIGH: the noise is named, not the gate. The same
    fraction gated as bursts of jumps (1e4 each) among fixes stated right keeps the gate's warning."""
    rng = np.random.default_rng(5)
    nis = 9.0 * rng.chisquare(2, 1000)
    ch = ChannelStats(["east", "north"])
    ch.extend(records(nis, nis > GATE**2))
    assert 0.2 < ch.rejected / ch.n < 0.3 and ch.kept_nis_per_dof > 2 * NIS_HIGH
    v = absolute_verdict("gps", "position", ch, 1000.0)
    assert v.level == "problem" and v.key == "sensors.gps.position_noise" and "too small" in v.message, v
    jumps = rng.chisquare(2, 1000)
    jumps[rng.random(1000) < 0.25] = 1e4
    ch = ChannelStats(["east", "north"])
    ch.extend(records(jumps, jumps > GATE**2))
    v = absolute_verdict("gps", "position", ch, 1000.0)
    assert v.level == "warn" and v.key == "sensors.gps.mahalanobis_threshold", v


def test_a_receiver_stating_a_third_of_its_noise_gets_the_noise_to_paste():
    """End to end: fixes of 0.3 m white noise stated as 0.1 m (10 Hz, 10 m/s, 90 s): about a quarter gated,
    the line pasteable and near the truth (the innovations include the filter's own uncertainty: an upper
    bound, asserted within 0.3 and 0.4 m)."""
    w = sim_gps.World(duration=90.0, speed=10.0, gps_rate=10.0, gps_sigma=0.3, arcs=((10.0, 90.0, 0.05),))
    v = one(verdicts_of(robot_config(gps="position_noise = [0.1, 0.1, 0.3]"), sim_gps.simulate(w)), "gps", "position")
    assert v.level == "problem" and v.key == "sensors.gps.position_noise", v
    assert GATED_FRACTION < v.evidence["gated_fraction"] < 0.5, v
    east, north, _ = (float(x) for x in v.suggestion.split("[")[1].rstrip("]").split(","))
    assert 0.3 <= east < 0.4 and 0.3 <= north < 0.4, v.suggestion


def test_a_receivers_noise_to_paste_is_not_its_multipath_bursts():
    """The receiver above (0.3 m stated as 0.1 m) with four multipath bursts of 2 s, 15 m off (8 % of the fixes):
    the line is the ordinary fixes' spread (the innovations' median magnitude, robust to a minority of bursts),
    within 0.3 and 0.45 m; their rms, ~4 m, pasted, would have let the next bursts in."""
    w = sim_gps.World(duration=90.0, speed=10.0, gps_rate=10.0, gps_sigma=0.3, arcs=((10.0, 90.0, 0.05),))
    samples = []
    for s in sim_gps.simulate(w):
        if isinstance(s, GpsSample) and any(t0 <= s.stamp - sim_gps.T0 < t0 + 2.0 for t0 in (20.0, 40.0, 60.0, 80.0)):
            s = msgspec.structs.replace(s, latitude=s.latitude + 15.0 / 111_320.0)
        samples.append(s)
    v = one(verdicts_of(robot_config(gps="position_noise = [0.1, 0.1, 0.3]"), samples), "gps", "position")
    assert v.key == "sensors.gps.position_noise" and v.suggestion, v
    east, north, _ = (float(x) for x in v.suggestion.split("[")[1].rstrip("]").split(","))
    assert 0.3 <= east < 0.45 and 0.3 <= north < 0.45, v.suggestion


def outliers(samples: list, every: int, offset_deg: float) -> list:
    """Every ``every``-th GPS fix moved by ``offset_deg`` of latitude (0.002 deg: 220 m)."""
    out, k = [], 0
    for s in samples:
        if isinstance(s, GpsSample) and s.status >= 0 and math.isfinite(s.latitude):
            k += 1
            if k % every == 0:
                s = msgspec.structs.replace(s, latitude=s.latitude + offset_deg)
        out.append(s)
    return out


def test_a_gps_with_gated_outlier_fixes_end_to_end():
    """A clean GPS robot (sigma 0.3 m stated and true, 1 Hz for 120 s) with every 40th fix 220 m off: three
    fixes, NIS ~ (220 / 0.3)^2 = 5e5 each, so the whole-run mean is ~1.3e4 per dof. With the gate at 5 they
    are rejected (sqrt(NIS) ~ 700 >> 5) and the other ~115 fixes are the clean run's (NIS ~1 per dof):
    no "noise too small". Without a gate (``inf``; 5 is the default) they are fused: the doctor's NIS verdict then has them as evidence
    and names the stated noise."""
    samples = outliers(sim_gps.simulate(sim_gps.World(duration=120.0, gps_rate=1.0)), 40, 0.002)
    gated = one(verdicts_of(robot_config(gps=f"mahalanobis_threshold = {GATE}"), samples), "gps", "position")
    assert "only because of the 3 update(s) the gate rejected" in gated.message, gated
    assert gated.key != "sensors.gps.position_noise" and "too small" not in gated.message, gated
    assert gated.evidence["applied_nis_per_dof"] < NIS_HIGH, gated
    fused = one(verdicts_of(robot_config(gps="mahalanobis_threshold = inf"), samples), "gps", "position")
    assert "gate rejected" not in fused.message and fused.level != "ok", fused


def test_a_wandering_gps_with_gated_outliers_gets_the_wander_verdict():
    """A real receiver's wander (white 0.6 m plus a Gauss-Markov wander of 1.2 m, tau 60 s,
    2 Hz for 400 s, stating 2.2 m: the filter follows the wander, NIS low; tests/doctor/test_doctor_faults.py) with
    every 100th fix 220 m off, gated at 5: 8 fixes of NIS ~(220 / 2.2)^2 = 1e4 among 800 make the whole-run
    mean ~50 per dof, "nis_high". The applied ones read low, as without the outliers, so the verdict is the
    wander's (error_tau_s), not "noise too small" and not "lower position_noise"."""
    from tests.support.gps_wander import STATED_HDOP, WANDER

    samples = outliers(sim_gps.simulate(sim_gps.World(gps_error_tau=60.0, gps_error_sigma=1.2, **WANDER)), 100, 0.002)
    result_verdicts = verdicts_of(robot_config(gps=f"{STATED_HDOP}\nmahalanobis_threshold = {GATE}"), samples)
    v = one(result_verdicts, "gps", "position")
    assert "only because of the 8 update(s) the gate rejected" in v.message, v
    assert v.key == "sensors.gps.error_tau_s" and "error_sigma = [" in v.suggestion, v
    assert "too small" not in v.message, v


def test_a_receiver_that_lost_its_fix_and_republishes_it_is_named_as_the_fault():
    """A receiver repeating its last fix with 3 mm of noise for 10 s while the robot drives on at 1 m/s
    (10 m): the repeats are recognised as frozen and not fused (their NIS is 0: they say nothing of the
    stated noise). The doctor names the receiver's fault, with no config key to change, instead of a bare
    "NIS low"; the fixes that were fused read as consistent as the clean run's."""
    w = sim_gps.World(duration=120.0, gps_rate=5.0, gps_freeze=((60.0, 70.0),), gps_freeze_jitter=0.003)
    verdicts = verdicts_of(robot_config(gps=""), sim_gps.simulate(w))
    frozen = one(verdicts, "gps", "position_frozen")
    assert frozen.level == "warn" and "lost its fix" in frozen.message and not frozen.key, frozen
    assert frozen.evidence["frozen_fixes"] >= 45, frozen  # ~50 repeats at 5 Hz, the first ones inside 0.5 m
    assert one(verdicts, "gps", "position").level == "ok"


def test_a_short_correlation_time_is_pasted_as_itself_never_as_zero():
    """error_tau_s = 0 turns the error state off: a wander of ~0.5 s (the highway car's fixes with a 7 m step,
    20 % persisting at 10 Hz) is pasted as 0.5, not rounded to 0 (a line that changed nothing, beside a verdict
    that said the error wanders); whole seconds from 10 s on."""
    from fusiond.doctor.checks.gps_wander import _secs

    assert _secs(0.49913788) == "0.5" and _secs(3.14159) == "3.1" and _secs(60.2) == "60" and _secs(9.96) == "10"
    assert float(_secs(0.11)) > 0.0


def test_an_altitude_low_as_its_slow_error_expects_stays_so_beside_gated_outliers():
    """The altitude beside a slow vertical error state (5 m over 300 s, a 60 s run): the applied fixes read NIS
    low, as that model expects over a slice of its time constant (nothing to change). 49 fixes 30 m off (a
    receiver's height reference switched for 5 s), rejected by the gate, make the whole run's mean high: the
    verdict on the applied ones is still the model's, not "the noise is larger than they show"."""
    rng = np.random.default_rng(6)
    nis = 0.01 * rng.chisquare(1, 600)
    nis[300:349] = 1e4
    ch = ChannelStats(["up"])
    ch.extend([DiagnosticsRecord(1000.0 + 0.1 * k, "gps", ["up"], [0.0], [1.0], float(v), 1, bool(v > GATE**2),
                                 channel="altitude") for k, v in enumerate(nis)])
    v = absolute_verdict("gps", "altitude", ch, 1000.0, slow_vertical=(5.0, 300.0, 60.0))
    assert v.level == "ok" and "as the altitude's error model expects" in v.message, v
    assert "only because of the 49 update(s) the gate rejected" in v.message, v


def test_an_rtk_altitude_that_does_not_wander_names_the_wander_model_with_the_most_it_allows():
    """An RTK receiver's altitude (1.5 cm, no wander) beside the default wander model (5 m over 300 s): between two
    fixes 0.1 s apart the model alone moves the altitude by 0.13 m, and the innovations are a tenth of that. No
    noise of the fixes explains it: the doctor names vertical_error_sigma with the most the innovations allow
    (not "as the model expects"). A receiver whose altitude does wander by that much is left as the model's."""
    w = sim_gps.World(duration=60.0, gps_rate=10.0, gps_sigma=0.015)
    v = one(verdicts_of(robot_config(gps=""), sim_gps.simulate(w)), "gps", "altitude")
    assert v.level == "warn" and v.key == "sensors.gps.vertical_error_sigma", v
    most = float(v.suggestion.split("=")[1])
    assert 0.0 < most < 5.0 and v.evidence["innovation_rms_m"] < v.evidence["wander_alone_rms_m"], v
    wandering = sim_gps.World(duration=60.0, gps_rate=10.0, gps_sigma=0.015, gps_alt_error_sigma=5.0,
                              gps_alt_error_tau=300.0)
    v = one(verdicts_of(robot_config(gps=""), sim_gps.simulate(wandering)), "gps", "altitude")
    assert v.key != "sensors.gps.vertical_error_sigma", v
