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
from itertools import chain
from operator import attrgetter
from typing import Sequence

import numpy as np

from ..core.diagnostics import NIS_HIGH, NIS_LOW, DiagnosticsRecord, nis_bounds  # noqa: F401 - NIS_* read from here too

# a record's fields, read off a chunk of records by map (no Python frame per record, as a generator has)
_STAMP, _NIS, _DOF = attrgetter("stamp"), attrgetter("nis"), attrgetter("dof")
_REJECTED, _LEARNING = attrgetter("rejected"), attrgetter("learning")
_INNOVATION, _INNOVATION_VAR = attrgetter("innovation"), attrgetter("innovation_var")

VERDICTS = ("ok", "nis_high", "nis_low", "no_updates")  # what judge_nis returns


@lru_cache(maxsize=4096)
def judge_nis(mean: float | None, n: int, dof: float, confidence: float) -> str:
    """ok | nis_high | nis_low | no_updates."""
    if mean is None or n <= 0 or dof <= 0 or not math.isfinite(mean):
        return "no_updates"
    lo, hi = nis_bounds(n, dof, confidence)
    return "nis_high" if mean > hi else "nis_low" if mean < lo else "ok"


def _running_sum(start, values: np.ndarray):
    """start + values[0] + values[1] + ..., added in that order (np.cumsum does; np.sum would pair them)."""
    return np.cumsum(np.concatenate((np.asarray(start, dtype=float)[None], values)), axis=0)[-1]


@dataclass
class ChannelStats:
    """Whole-run innovation statistics of one sensor channel, plus its latest window.

    Fed in bulk (:meth:`extend`; the replay's doctor hands it a chunk of records at a time), with the
    figures a one-record-at-a-time loop would give, to the last bit."""

    components: list[str]
    window: int = 50
    confidence: float = 0.95
    n: int = 0
    n_nis: int = 0
    rejected: int = 0
    nis_sum: float = 0.0
    n_nis_kept: int = 0  # the same over the updates that were not rejected (gated, or flagged as slip)
    nis_sum_kept: float = 0.0
    dof_sum_kept: int = 0
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
    judged: bool = True  # False: a gate's channel (yaw_jump), every record beyond the gate: its NIS is no test
    stamps: list[float] = field(default_factory=list)
    rejected_flags: list[bool] = field(default_factory=list)
    innovations: list[list[float]] = field(default_factory=list)
    # the learning updates' own per-component sums of y^2 and of S's diagonal (``learning_component``)
    n_learning_comp: int = 0
    learning_squares: list[float] = field(default_factory=list)
    learning_variances: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.recent = deque(maxlen=self.window)

    def add(self, r: DiagnosticsRecord) -> None:
        self.extend((r,))

    def extend(self, records: Sequence[DiagnosticsRecord]) -> None:
        """Every record counts (and is judged: NIS over its own dof); the per-component figures keep the
        channel's first shape (a message without its yaw row, a per-axis update, do not mix columns).

        In bulk (the doctor hands a chunk at a time): the running sums are ``np.cumsum`` continued from
        the sums so far, which adds in record order, so every figure is the float a one-record-at-a-time
        loop would give."""
        if not records:
            return
        stamps = list(map(_STAMP, records))
        self.n += len(records)
        rejected = list(map(bool, map(_REJECTED, records)))
        self.rejected += sum(rejected)
        if self.first_stamp is None:
            self.first_stamp = stamps[0]
        self.last_stamp = max(stamps) if self.last_stamp is None else max([self.last_stamp, *stamps])
        if self.keep:
            self.stamps.extend(stamps)
            self.rejected_flags.extend(rejected)
            self.innovations.extend(list(r.innovation) for r in records)
        # a learning update tests the prior, not the sensor: counted, kept as an episode, not judged
        learning_flags = list(map(bool, map(_LEARNING, records)))
        learning = np.array(learning_flags, dtype=bool)
        nis = np.fromiter(map(_NIS, records), dtype=float, count=len(records))
        dof = np.fromiter(map(_DOF, records), dtype=np.int64, count=len(records))
        judged = ~learning & np.isfinite(nis) & (dof > 0)
        self._count_dof(learning, judged, dof)
        kept = judged & ~np.array(rejected, dtype=bool)
        if kept.any():
            self.n_nis_kept += int(kept.sum())
            self.nis_sum_kept = float(_running_sum(self.nis_sum_kept, nis[kept]))
            self.dof_sum_kept += int(dof[kept].sum())
        if judged.any():
            self.n_nis += int(judged.sum())
            self.nis_sum = float(_running_sum(self.nis_sum, nis[judged]))
            self.dof_sum += int(dof[judged].sum())
            self._window(nis[judged].tolist(), dof[judged].tolist(), np.array(stamps)[judged])
        components = self.components
        same = [r for r, lf in zip(records, learning_flags) if not lf and r.components == components]
        if same:
            self._component_sums(same)
        learned = [r for r, lf in zip(records, learning_flags) if lf and r.components == components]
        if learned:
            self._learning_sums(learned)

    def _count_dof(self, learning: np.ndarray, judged: np.ndarray, dof: np.ndarray) -> None:
        """The channel's dof: the latest judged record's, or a learning one's while none was judged yet."""
        before = np.cumsum(judged) - judged + self.n_nis  # judged records before each one
        sets = judged | (learning & (dof > 0) & (before == 0))
        if sets.any():
            self.dof = int(dof[np.flatnonzero(sets)[-1]])

    def _window(self, nis: list[float], dof: list[int], stamps: np.ndarray) -> None:
        """The latest window's verdict after each judged record, and the stamp at which it last changed.

        The window's NIS sum is a running one (the oldest value subtracted, the newest added), so that a
        long run's sum does not grow into the window's rounding; the loop below is that recurrence and
        nothing else (the dof sums are integers: numpy)."""
        recent, size = self.recent, self.recent.maxlen
        history = [v for v, _ in recent] + nis
        dof_history = np.array([d for _, d in recent] + dof, dtype=np.int64)
        first = len(recent)  # history index of the first new record
        index = np.arange(first, len(history))
        # the value that leaves the window as each new record enters (0.0 while the window fills)
        leaving = [history[i] if i >= 0 else 0.0 for i in (index - size).tolist()]
        total, sums = self.recent_sum, []
        append = sums.append
        for old, new in zip(leaving, nis):
            total = total - old + new
            append(total)
        dof_cum = np.concatenate(([0], np.cumsum(dof_history)))
        dof_sums = dof_cum[index + 1] - dof_cum[np.maximum(index + 1 - size, 0)]
        counts = np.minimum(index + 1, size)
        self.recent.extend(zip(nis, dof))
        self.recent_sum, self.recent_dof = total, int(dof_sums[-1])
        verdicts = self._judge_windows(np.array(sums), dof_sums, counts)
        changed = np.flatnonzero(verdicts != np.concatenate(([VERDICTS.index(self.now_verdict)], verdicts[:-1])))
        if len(changed):
            self.now_verdict, self.now_since = VERDICTS[verdicts[-1]], float(stamps[changed[-1]])

    def _judge_windows(self, sums: np.ndarray, dof_sums: np.ndarray, counts: np.ndarray) -> np.ndarray:
        """judge_nis of each window state, as indices into VERDICTS: the bounds once per distinct
        (count, dof sum), the comparisons in bulk."""
        base = int(counts.max()) + 1  # (count, dof sum) packed into one integer key
        keys, inverse = np.unique(dof_sums * base + counts, return_inverse=True)
        bounds = np.array([nis_bounds(m, d / m, self.confidence) for d, m in (divmod(int(k), base) for k in keys)])
        lo, hi = bounds[inverse.ravel()].T
        mean = sums / counts
        out = np.where(mean > hi, VERDICTS.index("nis_high"), np.where(mean < lo, VERDICTS.index("nis_low"),
                                                                       VERDICTS.index("ok")))
        return np.where(np.isfinite(mean), out, VERDICTS.index("no_updates"))

    def _learning_sums(self, records: list[DiagnosticsRecord]) -> None:
        k = len(self.components)
        if not self.learning_squares:
            self.learning_squares, self.learning_variances = [0.0] * k, [0.0] * k
        n = len(records)
        self.n_learning_comp += n
        y = np.fromiter(chain.from_iterable(map(_INNOVATION, records)), dtype=float, count=n * k).reshape(n, k)
        v = np.fromiter(chain.from_iterable(map(_INNOVATION_VAR, records)), dtype=float, count=n * k).reshape(n, k)
        self.learning_squares = _running_sum(np.array(self.learning_squares), y * y).tolist()
        self.learning_variances = _running_sum(np.array(self.learning_variances), v).tolist()

    def learning_component(self, i: int) -> tuple[float, float]:
        """(rms, rms predicted by S) of component i over the learning updates (NaN before any): what a
        search that never ended (the GPS heading) saw of the sensor, though no update was judged."""
        if not self.learning_squares:
            return math.nan, math.nan
        n = self.n_learning_comp
        return math.sqrt(self.learning_squares[i] / n), math.sqrt(self.learning_variances[i] / n)

    def _component_sums(self, records: list[DiagnosticsRecord]) -> None:
        k = len(self.components)
        if not self.sums:
            self.sums, self.variances = [0.0] * k, [0.0] * k
            self.outer = [[0.0] * k for _ in range(k)]
        self.n_comp += len(records)
        n = len(records)
        y = np.fromiter(chain.from_iterable(map(_INNOVATION, records)), dtype=float, count=n * k).reshape(n, k)
        v = np.fromiter(chain.from_iterable(map(_INNOVATION_VAR, records)), dtype=float, count=n * k).reshape(n, k)
        self.sums = _running_sum(np.array(self.sums), y).tolist()
        self.variances = _running_sum(np.array(self.variances), v).tolist()
        self.outer = _running_sum(np.array(self.outer), y[:, :, None] * y[:, None, :]).tolist()

    @property
    def mean_dof(self) -> float:
        return self.dof_sum / self.n_nis if self.n_nis else 0.0

    @property
    def nis_mean(self) -> float | None:
        return self.nis_sum / self.n_nis if self.n_nis else None

    @property
    def nis_per_dof(self) -> float:
        return self.nis_sum / self.dof_sum if self.dof_sum else math.nan

    @property
    def kept_nis_per_dof(self) -> float:
        """NIS per dof of the updates that were not rejected (NaN before any)."""
        return self.nis_sum_kept / self.dof_sum_kept if self.dof_sum_kept else math.nan

    def kept_verdict(self) -> str:
        """The whole-run NIS verdict of the updates that were not rejected (gated out, or flagged as slip):
        what the filter fused, so what says whether the stated noise is right. A rejected update's NIS is
        the gate's business: one fix 7000 km off (a receiver reporting 0, 0) has a NIS of 1e14 and would
        make the mean of thousands of good ones read as noise stated too small."""
        mean = self.nis_sum_kept / self.n_nis_kept if self.n_nis_kept else None
        dof = self.dof_sum_kept / self.n_nis_kept if self.n_nis_kept else 0.0
        return judge_nis(mean, self.n_nis_kept, dof, self.confidence)

    def verdict(self) -> str:
        """The whole-run NIS verdict."""
        if not self.judged:
            return "not_judged"
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
        """' (now: nis_high since 312 s into the run)' when the latest window differs from the whole run, else ''."""
        whole = self.verdict()
        if self.now_verdict in ("no_updates", whole) or self.now_since is None:
            return ""
        since = self.now_since - (t0 if t0 is not None else self.first_stamp or 0.0)
        return f"now: {self.now_verdict} since {since:.0f} s into the run"

    @property
    def learning_only(self) -> bool:
        """Every update so far learned the state (e.g. the GPS heading search): none is judged."""
        return self.n > 0 and self.n_nis == 0

    def summary(self, t0: float | None = None) -> dict:
        """The channel's row of the summary table. A channel whose updates were all learning ones reads
        "learning ... not judged", never "no_updates" beside its update count."""
        b = self.bounds()
        if not self.judged:
            return {"updates": self.n, "rejected": self.rejected, "dof": self.dof, "nis_mean": None,
                    "nis_bounds": None, "verdict": "not_judged", "now": "not_judged",
                    "now_note": "not judged: every record is a reading the gate kept out"}
        if self.learning_only:
            return {"updates": self.n, "rejected": self.rejected, "dof": self.dof, "nis_mean": None,
                    "nis_bounds": None, "verdict": "learning", "now": "learning",
                    "now_note": "not judged: every update learned the state"}
        return {"updates": self.n, "rejected": self.rejected, "dof": self.dof, "nis_mean": self.nis_mean,
                "nis_per_dof": self.nis_per_dof if self.nis_mean is not None else None,
                "nis_bounds": list(b) if b else None, "verdict": self.verdict(),
                "now": self.now_verdict, "now_note": self.now_note(t0)}
