"""Chords of the GPS track against the wheels' travel: what the speed and grade checks share.

A chord between two fixes, chosen on the wheels' travel (``chord_ends``), compares the GPS displacement
with the dead-reckoned one; consecutive short chords follow the path, and the fixes' slow wander then
telescopes (``checks/speed.py``'s docstring derives it). ``newey_west`` is the residuals' standard
error of a fit over such chords, which neighbouring chords correlate.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import Config
from .gyro import coasts
from .series import Series

__all__ = ["ASSUMED_TAU_S", "CHORD_M", "MIN_CHORDS", "SCALE_Z_SIGMAS", "chord_ends", "cumulative", "newey_west",
           "wheel_chords"]

CHORD_M = 10.0  # chords at least this long (or 20 sigma_w): short and consecutive (checks/speed.py's docstring)
CHORD_MAX_S = 60.0  # a chord spans at most this long (slower: the robot is standing or creeping)
MIN_CHORDS = 3  # the fewest for a residual standard error (2 dof) next to the model's
ASSUMED_TAU_S = 100.0  # the fast end of receivers' wander times (checks/speed.py's docstring)
SCALE_Z_SIGMAS = 3.0  # a scale is named beyond this many standard errors (as a normal quantile: 0.27 % two-sided)


def cumulative(t: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.zeros(len(t))
    if len(t) > 1:
        dt = np.diff(t)
        out[1:] = np.cumsum(np.where(dt < 1.0, 0.5 * (v[1:] + v[:-1]) * dt, 0.0))
    return out


def chord_ends(series: Series, to: np.ndarray, travelled: np.ndarray, length: float,
               usable: np.ndarray | None = None) -> list[tuple[int, int]]:
    """Consecutive chords (indices into the fixes) each spanning ``length`` metres of WHEEL travel;
    ``usable`` (a flag per fix, in the series' order): the fixes a chord may end on (None: all).

    Chosen on the wheels, not on the fixes' own distance: a chord that ends where the GPS distance
    first exceeds a threshold ends preferably on a fix whose error points forward, and is biased
    long by it (measured: +3 % with 0.3 m noise at 1 m/s, 1 Hz fixes, 10 m chords). The wheels'
    travel is independent of the GPS error, so the GPS chord stays unbiased."""
    t = np.asarray(series.gps_t)
    if len(t) < 2 or np.any(np.diff(t) < 0.0):
        order = np.argsort(t, kind="stable")
    else:
        order = np.arange(len(t))
    ts = t[order]
    inside = (ts >= to[0]) & (ts <= to[-1])
    # a fix repeating the one before it to the bit (a frozen receiver republishing its last fix with new stamps,
    # which the core refuses while the wheels move) measured nothing: no chord ends on it
    e, n = np.asarray(series.gps_e)[order], np.asarray(series.gps_n)[order]
    inside[1:] &= (e[1:] != e[:-1]) | (n[1:] != n[:-1])
    if usable is not None:
        inside &= np.asarray(usable, dtype=bool)[order]
    s = np.where(inside, np.interp(ts, to, travelled), np.nan)
    out = []
    i = 0
    while i < len(ts) - 1:
        if not inside[i]:
            i += 1
            continue
        end = int(np.searchsorted(ts, ts[i] + CHORD_MAX_S, side="right"))
        far = np.nonzero(s[i + 1:end] - s[i] >= length)[0]
        if not len(far):
            i += 1  # standing, or too slow from here: try the next fix
            continue
        j = i + 1 + int(far[0])
        out.append((int(order[i]), int(order[j])))
        i = j
    return out


def wheel_chords(series: Series, cfg: Config, to: np.ndarray, travelled: np.ndarray,
                 length: float, usable: np.ndarray | None = None) -> list[tuple[int, int]]:
    """``chord_ends``, less the chords whose wheels' travel is not all there: across a logging gap (the wheels'
    travel and the gyro's turn in the gap are missing from the dead reckoning, not from the GPS) or across a
    coast (``gyro.coasts``: the drive read zero while the vehicle rolled on)."""
    breaks = np.array(sorted([*series.odom_breaks, *series.gyro_breaks]))
    dropped = coasts(series, cfg)
    out = []
    for i, j in chord_ends(series, to, travelled, length, usable):
        t0, t1 = series.gps_t[i], series.gps_t[j]
        if len(breaks) and np.searchsorted(breaks, t0, side="right") != np.searchsorted(breaks, t1, side="right"):
            continue
        if any(a <= t1 and t0 <= b for a, b in dropped):
            continue
        out.append((i, j))
    return out


def newey_west(score: np.ndarray) -> float:
    """Variance of sum(score) from the scores' autocovariances up to NW_LAGS(n) apart, Bartlett weights
    (never negative). Longer-range terms of an OU wander are negative (see the module docstring), so
    leaving them out errs on the large side."""
    n = len(score)
    lags = min(n - 1, int(math.ceil(n ** (1.0 / 3.0))))
    total = float(score @ score)
    for lag in range(1, lags + 1):
        total += 2.0 * (1.0 - lag / (lags + 1.0)) * float(score[lag:] @ score[:-lag])
    return max(total, 0.0)
