"""Fixed-width time bins over one stream, summed in bulk but rounded exactly as one sample at a time.

A bin opens at its first sample's stamp and takes every following sample until one stamped BIN_S or more
after that opening stamp arrives (a slightly older sample, out of the reorder buffer, still joins it). The
rule is sequential (a bin's start depends on the previous bin's), but in stamp order it is one binary
search per bin (one comparison per sample otherwise), and ``np.bincount`` sums the columns per bin.
bincount adds the weights in array order, so each sum is the same float as adding the samples one by one
(``np.add.reduceat`` sums pairwise and would round differently). The last bin may still be open at the
end of a chunk: it is carried to the next one, its partial sums added first, as the one-at-a-time loop
would have.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from dataclasses import dataclass

import numpy as np

BIN_S = 0.2  # series resolution: 5 Hz

__all__ = ["BIN_S", "OpenBin", "Binned", "bin_rows"]


@dataclass
class OpenBin:
    """A bin whose closing sample has not arrived yet: its opening stamp, count and column sums."""

    t0: float
    n: int
    sums: np.ndarray


@dataclass
class Binned:
    """Every bin the rows touched, in order (the carried one first); the last one is still open."""

    t0: np.ndarray
    n: np.ndarray
    sums: np.ndarray  # (bins, columns)
    opener: np.ndarray  # row index that opened each bin (-1: the bin carried in)

    def done(self, final: bool) -> int:
        """How many bins are complete: all of them at the end of the run, else all but the open last one."""
        return len(self.n) if final else max(len(self.n) - 1, 0)

    def mids(self, k: int) -> list[float]:
        """The time of the first k bins: their middle."""
        return (self.t0[:k] + BIN_S / 2).tolist()

    def last_open(self) -> OpenBin | None:
        if not len(self.n):
            return None
        return OpenBin(float(self.t0[-1]), int(self.n[-1]), self.sums[-1].copy())


def _openers(t: list[float], edge: float, ordered: bool) -> list[int]:
    """The rows that open a bin: the first one stamped at or after ``edge``, then each first one BIN_S or
    more after the previous opening. In stamp order (the usual case) a binary search per bin finds it;
    otherwise one comparison per row."""
    openers: list[int] = []
    if ordered:
        i = bisect_left(t, edge)
        while i < len(t):
            openers.append(i)
            i = bisect_left(t, t[i] + BIN_S, i + 1)
        return openers
    for i, ti in enumerate(t):
        if ti >= edge:
            openers.append(i)
            edge = ti + BIN_S
    return openers


def bin_rows(t: np.ndarray, cols: np.ndarray, carried: OpenBin | None) -> Binned:
    """Bins of rows with stamps ``t`` (processing order) and values ``cols`` (rows x columns)."""
    width = cols.shape[1]
    openers = _openers(t.tolist(), carried.t0 + BIN_S if carried is not None else -math.inf,
                       bool((t[1:] >= t[:-1]).all()))
    starts = t[openers].tolist()
    marks = np.zeros(len(t), dtype=np.intp)
    marks[openers] = 1
    ids = np.cumsum(marks) - (0 if carried is not None else 1)
    nb = len(openers) + (carried is not None)
    if carried is not None:  # its partial sums go first, so the additions happen in the same order
        ids = np.concatenate(([0], ids))
        cols = np.concatenate((carried.sums[None, :], cols))
        counts = np.bincount(ids[1:], minlength=nb) if len(t) else np.zeros(nb, dtype=np.intp)
        counts[0] += carried.n
        t0 = np.array([carried.t0, *starts])
        opener = np.array([-1, *openers], dtype=np.intp)
    else:
        counts = np.bincount(ids, minlength=nb)
        t0 = np.array(starts)
        opener = np.array(openers, dtype=np.intp)
    sums = np.empty((nb, width))
    for c in range(width):
        sums[:, c] = np.bincount(ids, weights=cols[:, c], minlength=nb)
    return Binned(t0, counts, sums, opener)
