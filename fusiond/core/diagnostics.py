"""Innovation diagnostics: the per-update record and the windowed NIS consistency test.

A remote operator reads these to tell at a glance whether R is too small (NIS
high), too large (NIS low) or a sensor is lying: the mean NIS over a window of N
updates is compared with chi-square bounds on N*dof degrees of freedom.
"""

from __future__ import annotations

import math
from collections import deque
from statistics import NormalDist

import msgspec


class DiagnosticsRecord(msgspec.Struct, gc=False):
    """One record per update (the documented diagnostics schema; ``channel`` and later fields are extensions)."""

    stamp: float
    sensor: str
    components: list[str]
    innovation: list[float]
    innovation_var: list[float]
    nis: float
    dof: int
    rejected: bool
    channel: str = ""
    late: bool = False  # applied at its own stamp from the history
    consistency: str = "warming_up"  # ok | nis_high | nis_low | warming_up (NisWindow.verdict)
    # The update is dominated by the state's prior (e.g. the first standstill window learning the
    # gyro bias from gyro_bias_sigma): its NIS tests the prior, not the sensor's noise, so the
    # consistency tests leave it out.
    learning: bool = False


def chi2_ppf(p: float, dof: float) -> float:
    """Chi-square quantile by Wilson-Hilferty: within 0.5% of the exact value for the
    window sizes used here (dof >= 20), and no scipy.special import (0.3 s) at start-up."""
    z = NormalDist().inv_cdf(p)
    h = 2.0 / (9.0 * dof)
    return dof * max(1.0 - h + z * h**0.5, 0.0) ** 3


def t_quantile(z: float, dof: float) -> float:
    """Student's t quantile matching the normal quantile z (Cornish-Fisher, two terms: 3.0 -> 3.75 at 12 dof,
    3.27 at 30, 3.0 for many). A standard error estimated from dof residuals is itself uncertain (by ~20 %
    with a dozen), which the wider quantile covers."""
    if dof <= 0:
        return math.inf
    z3, z5 = z**3, z**5
    return z + (z3 + z) / (4.0 * dof) + (5.0 * z5 + 16.0 * z3 + 3.0 * z) / (96.0 * dof * dof)


# More of a window's updates rejected (gated out, or flagged as slip) than this share: the stated noise
# does not describe the sensor, whatever the NIS of the applied ones. A consistent sensor behind a
# gate of g sigma is rejected with probability P(chi2_dof > g^2): 2.9 % for dof 3 at g = 3, far less
# at the 5-sigma defaults, so more than 5 of 50 (binomial tail 1.8 % at 2.9 %) is not chance.
REJECTED_SHARE = 0.1


# The practical band of a mean NIS per dof, beside its chi-square bounds: a window of 50 updates of 2 dof is
# "consistent" between 1.5 and 2.6 by chi-square alone, which real sensors' coloured errors leave at once while
# the filter is fine. A verdict needs the mean beyond both (the doctor's whole-run and latest-window verdicts
# and this window, which the health report and the monitor show, alike).
NIS_HIGH = 2.0  # mean NIS per dof above this (and above the chi-square bound): noise understated
NIS_LOW = 0.3  # ... below this (and below the bound): noise overstated


def nis_bounds(n: int, dof: float, confidence: float) -> tuple[float, float]:
    """Two-sided bounds on the mean NIS of n updates (chi-square on n*dof, divided by n),
    widened to the practical band [NIS_LOW, NIS_HIGH] per dof."""
    a = (1.0 - confidence) / 2.0
    lo = chi2_ppf(a, n * dof) / n
    hi = chi2_ppf(1.0 - a, n * dof) / n
    return min(lo, NIS_LOW * dof), max(hi, NIS_HIGH * dof)


class NisWindow:
    """Sliding window of NIS values for one sensor channel.

    The window holds the NIS of the updates the filter applied. A rejected update's NIS is the
    gate's business, not evidence about the stated noise: one GPS fix 7000 km off has a NIS of
    1e14 and would read as "nis_high" for the next ``window`` updates of thousands of good ones (the
    doctor judges its whole-run verdicts the same way, ``ChannelStats.kept_verdict``). Rejections
    are judged by their share instead: more than ``REJECTED_SHARE`` of the last ``window`` updates
    rejected reads "nis_high" (a sensor the gate keeps out that often is lying or its noise is
    stated too small), so a sensor whose every update is gated out does not stay "warming_up".

    The window's mean is read on every update (the verdict), so it keeps a running sum of
    the finite values (plus a count of infinite ones, which would poison a running sum:
    inf - inf is NaN) instead of summing the window each time. Rounding drift is bounded by
    re-summing exactly (math.fsum) once per window length of additions.
    """

    def __init__(self, window: int, confidence: float) -> None:
        self.window = window
        self.confidence = confidence
        self.values: deque[float] = deque(maxlen=window)
        self.flags: deque[bool] = deque(maxlen=window)  # rejected or not, of the last ``window`` updates
        self.recent_rejected = 0  # True in ``flags``
        self.dof = 0
        self._bounds: dict[int, tuple[float, float]] = {}
        self.total = 0
        self.rejected = 0
        self._sum = 0.0  # of the finite values in the window
        self._infinite = 0  # +inf values in the window
        self._since_exact = 0  # additions since the sum was last recomputed exactly
        # the whole run's applied updates (since the dof last changed): a windowed verdict alone flaps with
        # each window of a coloured error, the whole run's says whether it persists (``run_verdict``)
        self._run_sum = 0.0
        self._run_n = 0
        self._run_updates = 0  # ... and every update, rejected ones too (the run's share rejected)
        self._run_rejected = 0

    def bounds(self, dof: int) -> tuple[float, float]:
        """Two-sided bounds on the window's mean NIS: chi-square's, widened to the practical band."""
        b = self._bounds.get(dof)
        if b is None:
            b = self._bounds[dof] = nis_bounds(self.window, dof, self.confidence)
        return b

    def add(self, nis: float, dof: int, rejected: bool) -> str:
        self.total += 1
        values, flags = self.values, self.flags
        if dof != self.dof:
            values.clear()
            flags.clear()
            self.dof = dof
            self._sum, self._infinite, self._since_exact = 0.0, 0, 0
            self._run_sum, self._run_n = 0.0, 0
            self._run_updates = self._run_rejected = 0
            self.recent_rejected = 0
        self._run_updates += 1
        if len(flags) == self.window and flags[0]:
            self.recent_rejected -= 1
        flags.append(rejected)
        if rejected:
            self.rejected += 1
            self._run_rejected += 1
            self.recent_rejected += 1
            return self.verdict()
        if nis == nis:  # NaN from a singular S is not evidence either way
            if len(values) == self.window:
                old = values[0]
                if old == math.inf:
                    self._infinite -= 1
                else:
                    self._sum -= old
            values.append(nis)
            if nis == math.inf:
                self._infinite += 1
            else:
                self._sum += nis
                self._run_sum += nis
                self._run_n += 1
            self._since_exact += 1
            if self._since_exact >= self.window:
                self._sum = math.fsum(v for v in values if v != math.inf)
                self._since_exact = 0
        return self.verdict()

    @property
    def mean(self) -> float | None:
        n = len(self.values)
        if not n:
            return None
        return math.inf if self._infinite else self._sum / n

    @property
    def gated_out(self) -> bool:
        """Is the verdict nis_high by the share of rejected updates (not by the applied ones' mean)?"""
        return len(self.flags) == self.window and self.recent_rejected > REJECTED_SHARE * self.window

    def verdict(self) -> str:
        if self.gated_out:
            return "nis_high"
        n = len(self.values)
        if n < self.window:
            return "warming_up"
        lo, hi = self.bounds(self.dof)
        m = math.inf if self._infinite else self._sum / n
        return "nis_high" if m > hi else "nis_low" if m < lo else "ok"

    def run_verdict(self) -> str:
        """The verdict of every finite NIS applied since the dof last changed, against the chi-square bounds of
        that many (widened to the practical band, as the window's): "warming_up" before a window's worth. As the
        window's, "nis_high" by the share the gate kept out over the run, beyond REJECTED_SHARE, whatever the
        applied ones' mean (a channel gated three times in four read "ok" here while the replay's read nis_high)."""
        if self._run_updates >= self.window and self._run_rejected > REJECTED_SHARE * self._run_updates:
            return "nis_high"
        n = self._run_n
        if n < self.window or not self.dof:
            return "warming_up"
        lo, hi = nis_bounds(n, self.dof, self.confidence)
        m = self._run_sum / n
        return "nis_high" if m > hi else "nis_low" if m < lo else "ok"

    def summary(self) -> dict:
        lo_hi = self.bounds(self.dof) if self.dof else None
        return {
            "updates": self.total,
            "rejected": self.rejected,
            "recent_rejected": self.recent_rejected,  # of the last ``window`` updates
            "dof": self.dof,
            "nis_mean": self.mean,  # of the applied updates: a rejected one's NIS is the gate's
            "nis_bounds": list(lo_hi) if lo_hi else None,
            "verdict": self.verdict(),
            # "rejected": nis_high by the share of the last ``window`` updates the gate kept out (beyond
            # REJECTED_SHARE), whatever the applied ones' mean; "mean": by the mean against its bounds
            "cause": "rejected" if self.gated_out else "mean",
            "rejected_share": self.recent_rejected / len(self.flags) if self.flags else 0.0,
            # the whole run's mean and verdict (``run_verdict``): a window's verdict that the run's shares persists
            "run_nis_mean": self._run_sum / self._run_n if self._run_n else None,
            "run_verdict": self.run_verdict(),
        }
