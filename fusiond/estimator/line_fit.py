"""The least-squares line through (t, v) pairs, as the odometry's forward acceleration takes it.

The reference of the backends' ``line_fit`` (``_kernels.c`` computes the same doubles): the sums run
over lists and maps (a generator costs a resume an item), in the order and with the operations of the
least-squares sums written over the pairs, so the compiled loop, adding in the same order with the same
``pow`` for the squares, gives the same bits.
"""

from __future__ import annotations

import math
from operator import mul


def line_fit(pairs: tuple[tuple[float, float], ...]) -> tuple[float, float]:
    """(slope, rms misfit with n - 2 degrees of freedom) of the least-squares line through ``pairs``
    (at least three, not all at one t)."""
    n = len(pairs)
    ts, vs = zip(*pairs)
    tm = sum(ts) / n
    vm = sum(vs) / n
    dts = [t - tm for t in ts]
    dvs = [v - vm for v in vs]
    stt = sum([d ** 2 for d in dts])
    slope = sum(map(mul, dts, dvs)) / stt
    misfit = math.sqrt(sum([(dv - slope * d) ** 2 for d, dv in zip(dts, dvs)]) / (n - 2))
    return slope, misfit


__all__ = ["line_fit"]
