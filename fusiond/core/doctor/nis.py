"""Whole-run NIS statistics per channel, and the one rule that judges them.

The summary, the report, the monitor and the doctor all call :func:`judge_nis`, so a
channel gets one verdict wherever it is printed. The rule uses the updates there
are: the mean NIS of n updates of d degrees of freedom is chi-square(n d) / n if the
stated noise is right, so 11 GPS fixes with a mean NIS of 51.6 for 3 dof are judged
(far above the bound for 33 dof), not set aside as "too few". For long runs those
bounds shrink to a few percent, tighter than any noise can be stated; a practical
band (R misstated by 2x high or 3x low) is kept around them so that a 10 % error in a
stated sigma is not called a fault.

The latest window is judged by the same rule. When it differs from the whole run the
channel says so, with the time since which it differs ("now: nis_high since 312 s").
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache

from ..diagnostics import DiagnosticsRecord, chi2_ppf

NIS_HIGH = 2.0  # mean NIS per dof above this (and above the chi-square bound): noise understated
NIS_LOW = 0.3  # ... below this (and below the bound): noise overstated


@lru_cache(maxsize=4096)
def nis_bounds(n: int, dof: float, confidence: float) -> tuple[float, float]:
    """Two-sided bounds on the mean NIS of n updates (chi-square on n*dof, divided by n),
    widened to the practical band [NIS_LOW, NIS_HIGH] per dof."""
    a = (1.0 - confidence) / 2.0
    lo = chi2_ppf(a, n * dof) / n
    hi = chi2_ppf(1.0 - a, n * dof) / n
    return min(lo, NIS_LOW * dof), max(hi, NIS_HIGH * dof)


def judge_nis(mean: float | None, n: int, dof: float, confidence: float) -> str:
    """ok | nis_high | nis_low | no_updates."""
    if mean is None or n <= 0 or dof <= 0 or not math.isfinite(mean):
        return "no_updates"
    lo, hi = nis_bounds(n, dof, confidence)
    return "nis_high" if mean > hi else "nis_low" if mean < lo else "ok"


@dataclass
class ChannelStats:
    """Whole-run innovation statistics of one sensor channel, plus its latest window."""

    components: list[str]
    window: int = 50
    confidence: float = 0.95
    n: int = 0
    n_nis: int = 0
    rejected: int = 0
    nis_sum: float = 0.0
    n_nis_kept: int = 0  # the same over the updates that were not rejected (gated, or flagged as slip)
    nis_sum_kept: float = 0.0
    dof_sum: int = 0
    dof: int = 0  # of the latest record
    n_comp: int = 0  # records of the channel's first shape (per-component figures)
    sums: list[float] = field(default_factory=list)
    outer: list[list[float]] = field(default_factory=list)  # sum of y y^T (second moment, for frame changes)
    variances: list[float] = field(default_factory=list)  # sum of predicted variances (diag S)
    first_stamp: float | None = None
    last_stamp: float | None = None
    recent: deque = field(default_factory=deque)
    recent_sum: float = 0.0
    recent_dof: int = 0
    now_verdict: str = "no_updates"
    now_since: float | None = None  # stamp at which the window's verdict became now_verdict
    keep: bool = False  # keep every update's stamp, rejected flag and innovation (standstill episodes)
    stamps: list[float] = field(default_factory=list)
    rejected_flags: list[bool] = field(default_factory=list)
    innovations: list[list[float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.recent = deque(maxlen=self.window)

    def add(self, r: DiagnosticsRecord) -> None:
        """Every record counts (and is judged: NIS over its own dof); the per-component figures keep the
        channel's first shape (a message without its yaw row, a per-axis update, do not mix columns)."""
        self.n += 1
        self.rejected += r.rejected
        if self.first_stamp is None:
            self.first_stamp = r.stamp
        self.last_stamp = r.stamp if self.last_stamp is None else max(self.last_stamp, r.stamp)
        if self.keep:
            self.stamps.append(r.stamp)
            self.rejected_flags.append(bool(r.rejected))
            self.innovations.append(list(r.innovation))
        if getattr(r, "learning", False):
            if not self.n_nis and r.dof > 0:
                self.dof = r.dof  # the summary's dof of a channel that has only learned so far
            return  # the prior's test, not the sensor's: counted, kept as an episode, not judged
        if math.isfinite(r.nis) and r.dof > 0 and not r.rejected:
            self.n_nis_kept += 1
            self.nis_sum_kept += r.nis
        if math.isfinite(r.nis) and r.dof > 0:
            self.n_nis += 1
            self.nis_sum += r.nis
            self.dof_sum += r.dof
            self.dof = r.dof
            if len(self.recent) == self.recent.maxlen:
                old_nis, old_dof = self.recent[0]
                self.recent_sum -= old_nis
                self.recent_dof -= old_dof
            self.recent.append((r.nis, r.dof))
            self.recent_sum += r.nis
            self.recent_dof += r.dof
            m = len(self.recent)
            verdict = judge_nis(self.recent_sum / m, m, self.recent_dof / m, self.confidence)
            if verdict != self.now_verdict:
                self.now_verdict, self.now_since = verdict, r.stamp
        if r.components != self.components:
            return
        k = len(self.components)
        if not self.sums:
            self.sums, self.variances = [0.0] * k, [0.0] * k
            self.outer = [[0.0] * k for _ in range(k)]
        self.n_comp += 1
        y, v = r.innovation, r.innovation_var
        for i in range(k):
            self.sums[i] += y[i]
            self.variances[i] += v[i]
            row = self.outer[i]
            for j in range(k):
                row[j] += y[i] * y[j]

    @property
    def mean_dof(self) -> float:
        return self.dof_sum / self.n_nis if self.n_nis else 0.0

    @property
    def nis_mean(self) -> float | None:
        return self.nis_sum / self.n_nis if self.n_nis else None

    @property
    def nis_per_dof(self) -> float:
        return self.nis_sum / self.dof_sum if self.dof_sum else math.nan

    def kept_verdict(self) -> str:
        """The whole-run NIS verdict of the updates that were not rejected."""
        mean = self.nis_sum_kept / self.n_nis_kept if self.n_nis_kept else None
        return judge_nis(mean, self.n_nis_kept, self.dof, self.confidence)

    def verdict(self) -> str:
        """The whole-run NIS verdict."""
        return judge_nis(self.nis_mean, self.n_nis, self.mean_dof, self.confidence)

    def bounds(self) -> tuple[float, float] | None:
        return nis_bounds(self.n_nis, self.mean_dof, self.confidence) if self.n_nis else None

    def component(self, i: int) -> tuple[float, float, float]:
        """(mean, rms, rms predicted by S) of component i over the run (NaN before any judged update)."""
        if not self.sums:
            return math.nan, math.nan, math.nan
        n = max(self.n_comp, 1)
        return self.sums[i] / n, math.sqrt(self.outer[i][i] / n), math.sqrt(self.variances[i] / n)

    def second_moment(self) -> list[list[float]]:
        n = max(self.n_comp, 1)
        return [[v / n for v in row] for row in self.outer]

    def now_note(self, t0: float | None) -> str:
        """' (now: nis_high since 312 s)' when the latest window differs from the whole run, else ''."""
        whole = self.verdict()
        if self.now_verdict in ("no_updates", whole) or self.now_since is None:
            return ""
        since = self.now_since - (t0 if t0 is not None else self.first_stamp or 0.0)
        return f"now: {self.now_verdict} since {since:.0f} s"

    @property
    def learning_only(self) -> bool:
        """Every update so far learned the state (e.g. the GPS heading search): none is judged."""
        return self.n > 0 and self.n_nis == 0

    def summary(self, t0: float | None = None) -> dict:
        """The channel's row of the summary table. A channel whose updates were all learning ones reads
        "learning ... not judged", never "no_updates" beside its update count."""
        b = self.bounds()
        if self.learning_only:
            return {"updates": self.n, "rejected": self.rejected, "dof": self.dof, "nis_mean": None,
                    "nis_bounds": None, "verdict": "learning", "now": "learning",
                    "now_note": "not judged: every update learned the state"}
        return {"updates": self.n, "rejected": self.rejected, "dof": self.dof, "nis_mean": self.nis_mean,
                "nis_bounds": list(b) if b else None, "verdict": self.verdict(),
                "now": self.now_verdict, "now_note": self.now_note(t0)}
