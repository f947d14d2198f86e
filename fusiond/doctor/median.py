"""The median the doctor's checks take: ``numpy.median``'s value, without its first call's cost.

``numpy.median`` imports ``numpy.ma`` on its first call (its NaN check asks for masked arrays), 7-15 ms
of a replay whose doctor takes one median. This is the same value: the middle element of the sorted
values, or the mean of the two middle ones ((a + b) / 2, as numpy's mean of two), NaN when any is NaN.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["median"]


def median(values) -> float:
    """The median of ``values`` (a sequence or an array of numbers) as numpy's, NaN for none."""
    a = np.sort(np.asarray(values, dtype=float), axis=None)
    n = a.size
    if n == 0 or math.isnan(a[-1]):  # numpy's sort puts NaN last
        return math.nan
    m = n // 2
    return float(a[m]) if n % 2 else float((a[m - 1] + a[m]) / 2)
