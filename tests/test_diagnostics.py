"""Windowed NIS consistency: chi-square bounds and verdicts."""

from __future__ import annotations

import numpy as np
import pytest
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
    w.add(1.0, 1, True)
    assert w.verdict() == "ok" and w.rejected == 1
    w.add(2.0, 2, False)
    assert w.verdict() == "warming_up"
