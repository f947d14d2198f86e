"""The doctor's median is numpy's, bit for bit (it exists to skip numpy.median's import of numpy.ma)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from fusiond.doctor.median import median


def test_the_median_is_numpys_to_the_bit():
    rng = np.random.default_rng(0)
    cases = [[1.0], [2.0, 1.0], [3, 1, 2], [1, 2, 3, 4], [0.1, 0.2, 0.3, 0.4], [math.inf, 1.0], [-math.inf, math.inf],
             np.arange(10.0).reshape(2, 5)]
    for n in range(1, 40):
        cases.append(rng.normal(size=n) * 10.0 ** rng.integers(-8, 8))
        cases.append(list(rng.integers(-5, 5, size=n)))
    for c in cases:
        expected = float(np.median(c))
        got = median(c)
        assert type(got) is float
        assert got == expected or (math.isnan(got) and math.isnan(expected)), (c, got, expected)
        assert math.copysign(1.0, got) == math.copysign(1.0, expected)


def test_nan_and_none():
    assert math.isnan(median([1.0, math.nan, 2.0]))
    assert math.isnan(median([]))


def test_it_does_not_import_numpy_ma():
    out = subprocess.run([sys.executable, "-c", "import sys; from fusiond.doctor.median import median; "
                          "median([1.0, 2.0]); print('numpy.ma' in sys.modules)"],
                         capture_output=True, text=True, check=True, timeout=60)
    assert out.stdout.split() == ["False"]


def test_a_gps_runs_verdicts_do_not_import_numpy_ma():
    """The noise line of a GPS stating far too much noise takes the median of its innovations (the absolute
    check's robust spread): through the doctor's median, so a replay's verdicts never pay numpy.ma's import."""
    script = (
        "import sys\n"
        "import fusiond.logs\n"
        "fusiond.logs.configure('warning')\n"
        "from tests.support import sim_gps\n"
        "from tests.support.configs import robot_config\n"
        "from tests.support.verdicts import one, verdicts_of\n"
        "world = sim_gps.World(duration=120.0, gps_rate=10.0, gps_sigma=0.6, speed=25.0)\n"
        "v = one(verdicts_of(robot_config(gps='position_noise = [10.0, 10.0, 20.0]'), sim_gps.simulate(world)),\n"
        "        'gps', 'position')\n"
        "print(v.suggestion.startswith('position_noise = ['), 'numpy.ma' in sys.modules)\n")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, timeout=120,
                         cwd=root)
    assert out.stdout.split() == ["True", "False"], out.stdout + out.stderr
