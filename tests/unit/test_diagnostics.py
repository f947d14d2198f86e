"""Windowed NIS consistency: chi-square bounds and verdicts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2

from fusiond.core.diagnostics import NisWindow, chi2_ppf


@pytest.mark.parametrize("dof", [20, 50, 100, 150, 300])
@pytest.mark.parametrize("p", [0.005, 0.025, 0.5, 0.975, 0.995])
def test_chi2_quantile_is_close_to_exact(dof, p):
    assert chi2_ppf(p, dof) == pytest.approx(chi2.ppf(p, dof), rel=1e-2 if dof < 50 else 3e-3)


@pytest.mark.parametrize("scale, verdict", [(1.0, "ok"), (10.0, "nis_high"), (0.1, "nis_low")])
def test_window_verdicts(scale, verdict):
    rng = np.random.default_rng(4)
    w = NisWindow(window=100, confidence=0.95)
    for _ in range(100):
        y = rng.normal(0, np.sqrt(scale), 2)
        w.add(float(y @ y), 2, False)
    assert w.verdict() == verdict
    assert w.summary()["nis_bounds"][0] < 2.0 < w.summary()["nis_bounds"][1]


def test_window_warms_up_and_restarts_on_dof_change():
    w = NisWindow(window=10, confidence=0.95)
    for _ in range(9):
        w.add(1.0, 1, False)
    assert w.verdict() == "warming_up"
    w.add(1e14, 1, True)  # rejected: counted, but not a value of the window
    assert w.verdict() == "warming_up" and w.rejected == 1 and w.mean == 1.0
    w.add(1.0, 1, False)
    assert w.verdict() == "ok"
    w.add(2.0, 2, False)
    assert w.verdict() == "warming_up"


def _consistent(rng, dof: int) -> float:
    y = rng.normal(0.0, 1.0, dof)
    return float(y @ y)


def test_a_rare_gated_outlier_does_not_read_as_understated_noise():
    """A consistent GPS (NIS ~ chi2(3)) with one fix in 50 thousands of km off, gated out. Below
    REJECTED_SHARE the outliers change nothing: every verdict is the one of a window fed the applied
    fixes alone. Counted as values, each outlier's NIS of 1e14 reads "nis_high" for a whole window."""
    rng = np.random.default_rng(7)
    w, applied_only, as_values = (NisWindow(window=50, confidence=0.95) for _ in range(3))
    high_after_outliers = 0
    for k in range(500):
        gated = k % 50 == 25
        nis = 1e14 if gated else _consistent(rng, 3)
        verdict = w.add(nis, 3, gated)
        if not gated:
            assert verdict == applied_only.add(nis, 3, False)
        if as_values.add(nis, 3, False) == "nis_high":
            high_after_outliers += 1
    assert w.rejected == 10 and w.recent_rejected == 1
    # the old window: full from the 50th update on (k = 49), and from then on always holding an outlier
    assert high_after_outliers == 500 - 49
@pytest.mark.parametrize("share, verdict", [(0.06, "ok"), (0.3, "nis_high"), (1.0, "nis_high")])
def test_a_sensor_the_gate_keeps_out_often_reads_high(share, verdict):
    """Applied updates consistent, a share of them gated out: up to REJECTED_SHARE it is the gate's
    work, beyond it the stated noise does not describe the sensor; all gated is not "warming_up"."""
    rng = np.random.default_rng(3)
    w = NisWindow(window=50, confidence=0.95)
    every = round(1.0 / share)
    for k in range(200):
        gated = k % every == 0
        w.add(1e3 if gated else _consistent(rng, 2), 2, gated)
    lo, hi = w.bounds(2)
    if share < 1.0:
        assert lo < w.mean < hi  # the applied ones are consistent either way
    assert w.verdict() == verdict
    # the summary says which: a mean within its bounds beside nis_high is the gate's share, not the mean
    summary = w.summary()
    assert summary["cause"] == ("rejected" if verdict == "nis_high" else "mean")
    assert summary["rejected_share"] == pytest.approx(w.recent_rejected / 50)


class _Reference:
    """The window as the definition says: the mean of the last `window` non-NaN values (same dof)."""

    def __init__(self, window: int) -> None:
        self.window, self.values, self.dof = window, [], 0

    def add(self, nis: float, dof: int) -> None:
        if dof != self.dof:
            self.values, self.dof = [], dof
        if nis == nis:
            self.values = (self.values + [nis])[-self.window:]


_nis = st.one_of(st.floats(min_value=0.0, max_value=1e6), st.just(math.inf), st.just(math.nan))


@settings(max_examples=200, deadline=None)
@given(window=st.integers(1, 12), steps=st.lists(st.tuples(_nis, st.sampled_from([1, 2, 3])), max_size=120))
def test_running_mean_is_the_window_mean(window, steps):
    w, ref = NisWindow(window=window, confidence=0.95), _Reference(window)
    for nis, dof in steps:
        verdict = w.add(nis, dof, rejected=False)
        ref.add(nis, dof)
        if not ref.values:
            assert w.mean is None
            continue
        want = math.inf if math.inf in ref.values else math.fsum(ref.values) / len(ref.values)
        if want == math.inf:
            assert w.mean == math.inf
        else:
            # the running sum's rounding: at most 2 windows of additions/subtractions (<= 24) since the
            # last exact re-sum, each off by <= eps * 1e6 = 2.2e-10: 5.3e-9 on the sum, less on the mean
            assert w.mean == pytest.approx(want, rel=1e-12, abs=1e-8)
        if len(ref.values) < window:
            assert verdict == "warming_up"
        else:
            lo, hi = w.bounds(dof)
            if min(abs(want - lo), abs(want - hi)) > 1e-8:
                assert verdict == ("nis_high" if want > hi else "nis_low" if want < lo else "ok")


def test_the_windows_bounds_are_the_doctors_so_health_and_the_monitor_agree():
    """The core's window (health, the diagnostics records' consistency) judges a mean NIS by the doctor's rule:
    chi-square's bounds widened to the practical band [NIS_LOW, NIS_HIGH] per dof. A window of 50 two-dof
    updates at 1.2 per dof (mean 2.4) is within it; by chi-square alone ([1.48, 2.59] on the mean) a mean of 1.4
    would read nis_low while the doctor's latest window read ok."""
    from fusiond.core.diagnostics import NIS_HIGH, NIS_LOW
    from fusiond.doctor.nis import judge_nis, nis_bounds

    w = NisWindow(window=50, confidence=0.95)
    assert w.bounds(2) == nis_bounds(50, 2, 0.95)
    assert w.bounds(2)[0] <= 2 * NIS_LOW and w.bounds(2)[1] >= 2 * NIS_HIGH
    for _ in range(50):
        w.add(1.4, 2, False)
    assert w.verdict() == judge_nis(1.4, 50, 2, 0.95) == "ok"
