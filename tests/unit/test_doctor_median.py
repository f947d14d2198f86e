"""The doctor's median is numpy's, bit for bit (it exists to skip numpy.median's import of numpy.ma)."""

from __future__ import annotations

import math
import subprocess
import sys

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
