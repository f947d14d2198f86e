"""The fit: noise parameters that maximise the innovations' likelihood, checked on held-back data.

1. Split the recording by stamp: the first ``fit_fraction`` (70 %) is fitted, the rest held back.
2. Probe: each parameter x2 (and, if that changes -log L by less than 1, /2) from its start on the
   fit part. One the likelihood does not notice either way (less than 1 over a factor of 2) is
   something the data cannot inform: it is left as the config has it, and the table says so.
3. Optimise the informed parameters' log-scales with Nelder-Mead (below), within ``budget_s``
   seconds (probes included) and ``maxfev`` evaluations, each one replay of the fit part through a
   fresh FusionCore. An optimum less than 1 below the start's -log L is no finding: nothing changes.
4. Validate on the held-back part, with the filter run over the whole recording (so the held-back
   part starts from the state the fit part left, as it would in use) and -log L counted only over
   the updates stamped after the split: each changed key is dropped back to its original in turn
   and stays dropped when that scores the held-back part no worse; if what is left does not beat
   the original config there, nothing is changed.
5. Validate by prediction (``prediction``), where an absolute GPS or pose gives positions: every 5th is
   held back from a replay of the whole recording and the filter's position at its stamp scored,
   horizontally and vertically apart. A key whose change makes either worse is dropped back, and the
   tuned config is kept only if it predicts no worse than the original on both: a coloured GPS error
   rewards a too-small white noise in likelihood while the positions get worse, and a user asked
   for better positions, not a better likelihood. (The fit saw those fixes; a handful of noise
   figures cannot fit individual fixes, and what the check catches is the filter drifting off.)
6. The doctor's measured value of each key (``doctor_values``) is tried in place of the fit's and
   judged the same way; it is taken when no worse, else the table says what it measured and why not.

Replays that do not depend on each other run side by side, each in a forked process (``forked``): the
probes of step 2, each of Nelder-Mead's reflections beside a guess of the point its step asks for next
(``simplex``: scipy's steps, held to scipy's points by a test), and in steps 4-6 each held-back check
beside its prediction of the held-back fixes. The original config's check is the doctor's replay (step 6's
values, the floors' standstills), made once, beside the original's prediction, before the fit.

No fitted white noise goes below what the recording shows at rest (``floors``): the scatter of each
sensor's readings over the filter's own standstills bounds the fit from below, beside the sensors'
``*_min_sigma`` constants.

Why derivative-free. The likelihood of this filter is not a smooth function of its noise: the
Mahalanobis gates switch updates between applied and rejected, the standstill detection and the
gyro-bias windows open and close on thresholds of the stated noise, the GPS heading search is
accepted at a threshold of its uncertainty. Each is a step in -log L; finite-difference gradients
across them are noise, and a quasi-Newton method fed those stalls or jumps. Nelder-Mead compares
values only, over a simplex whose steps (a factor of 2 to begin with) are wider than those
steps, and needs nothing but replays, which are what is available. In log-scale every parameter
stays positive and a factor is the same step at any magnitude.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

from ..estimator.backend import Backend
from ..config import Config, ConfigError
from ..errors import ReplayError
from ..logs import muted
from .advice import with_suggestion
from .doctor_values import diagnose, doctor_lines, untuned_problems
from .floors import measured_floors, with_floors
from .forked import beside, run_side_by_side
from .likelihood import Plans, Reference, Score, reference, replay_records, residuals, score
from .params import Param, apply, select, sensor_of, tunable_params, value
from .prediction import HOLD_EVERY, Prediction, predict
from .prediction import split as split_fixes
from .recording import FIT_FRACTION, split_stamp
from .simplex import nelder_mead

PROBE = math.log(2.0)  # the informedness probe and the first simplex step: a factor of 2
INFORMED = 1.0  # -log L must change by at least this over a factor of 2
BOUND = math.log(1000.0)  # no scale beyond x1000 or /1000 of the start
# Nelder-Mead stops when the simplex spans < 3 % in every scale and its values < 0.5 in -log L
# (a difference of 0.5 in log L is half a standard deviation of the likelihood-ratio statistic)
XATOL = 0.03
FATOL = 0.5


T = TypeVar("T")
_NOT_REPLAYED = object()  # ``_Objective.many``'s answer for a replay the budget did not start


class _OutOfBudget(Exception):
    pass


@dataclass
class Row:
    """One parameter's line of the table."""

    param: Param
    before: object  # value(original config): None = unset (the messages' covariances)
    after: object
    status: str  # tuned | unchanged | not informed | refused | skipped
    note: str = ""
    nis_before: float | None = None  # held-back mean NIS per dof of the updates it is judged by
    nis_after: float | None = None
    doctor: object = None  # the doctor's measured value for these components (None: it gave no paste line)


@dataclass
class TuneResult:
    original: Config
    config: Config  # the tuned config (== original when nothing changed)
    rows: list[Row]
    split: float  # stamp between the fitted and the held-back part
    fit_before: float  # -log L of the fit part at the start ...
    fit_after: float  # ... and at the optimum
    heldback_before: Score | None  # the original config on the held-back part ...
    heldback_after: Score | None  # ... and the tuned one
    evaluations: int  # replays run (fit part and whole recording)
    seconds: float
    stopped: str  # converged | budget | maxfev | nothing to fit
    fit_residuals: int = 0  # scalar innovations in the fit part's terms
    prediction_before: Prediction | None = None  # the original config at the held-back fixes ...
    prediction_after: Prediction | None = None  # ... and the tuned one (None: no absolute GPS to hold back)
    comments: dict[tuple[str, str], str] = field(default_factory=dict)  # (table, key) -> its TOML comment
    # the doctor's problems on keys tune does not fit (``doctor_values.untuned_problems``): to fix first
    problems: list = field(default_factory=list)

    @property
    def changed(self) -> list[Row]:
        return [r for r in self.rows if r.status == "tuned"]


class _Progress:
    """rich's progress bar on stderr when it is a terminal (and asked for); silent otherwise."""

    def __init__(self, enabled: bool, total: int) -> None:
        self.bar = None
        if enabled and sys.stderr.isatty():
            from rich.console import Console
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

            self.bar = Progress(TextColumn("tune {task.description}"), BarColumn(), MofNCompleteColumn(),
                                TimeElapsedColumn(), console=Console(stderr=True), transient=True)
            self.bar.start()
            self.task = self.bar.add_task("", total=total)

    def step(self, description: str, total: int | None = None) -> None:
        if self.bar is not None:
            self.bar.update(self.task, advance=1, description=description, total=total)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()


class _Objective:
    """-log L of the fit part as a function of the active parameters' log-scales, memoised (the
    probes are the first simplex's vertices), counting replays against the budget."""

    def __init__(self, cfg: Config, params: Sequence[Param], samples: Sequence[object], deadline: float,
                 maxfev: int, bar: _Progress, backend: Backend | None = None) -> None:
        self.cfg, self.params, self.samples, self.backend = cfg, list(params), samples, backend
        # made here, before any replay is forked: the probes' configs key the samples alike (unless a clock is fitted)
        self.plans = Plans(samples)
        self.plans.of(cfg)
        self.deadline, self.maxfev, self.bar = deadline, maxfev, bar
        self.cache: dict[tuple[float, ...], float] = {}
        self.replays = 0
        self.ref: Reference | None = None
        self.best: tuple[float, tuple[float, ...]] = (math.inf, ())
        self.stopped = ""

    def config(self, theta: Sequence[float]) -> Config:
        return apply(self.cfg, self.params, list(theta))

    def __call__(self, theta: Sequence[float]) -> float:
        key = _key(theta)
        hit = self.cache.get(key)
        if hit is not None:
            return hit
        if self.ref is not None and self._spent(0):  # the reference replay is never refused
            raise _OutOfBudget
        records = self._replay(key)
        if self.ref is None:
            self.ref = reference(records, self.cfg)
        return self._note(key, score(records, self.ref).neg_loglik)

    def many(self, thetas: Sequence[Sequence[float]]) -> list[float]:
        """``[self(theta) for theta in thetas]`` with the replays not yet made side by side (``forked``): the
        same values, cached and counted alike; the budget is asked as each replay starts, and when it runs
        out, what was replayed is kept and ``_OutOfBudget`` raised, as in turn."""
        keys = [_key(theta) for theta in thetas]
        todo = [k for k in dict.fromkeys(keys) if k not in self.cache]
        if self.ref is None or len(todo) < 2:
            return [self(theta) for theta in thetas]
        started = 0

        def before(_key: tuple[float, ...]) -> object:
            nonlocal started
            if self._spent(started):
                return _NOT_REPLAYED
            started += 1
            return None

        def job(key: tuple[float, ...]) -> float:
            return score(self._replay(key), self.ref).neg_loglik

        for key, f in zip(todo, run_side_by_side(job, todo, before_each=before)):
            if f is not _NOT_REPLAYED:
                self._note(key, f)
        if started < len(todo):
            raise _OutOfBudget
        return [self.cache[k] for k in keys]

    def _replay(self, key: tuple[float, ...]) -> list:
        """The records of one replay of the fit part at ``key``."""
        with muted():  # the recording's warnings are said once, by the held-back check's first replay
            return replay_records(self.config(key), self.samples, self.backend, plans=self.plans)

    def _spent(self, started: int) -> bool:
        """Is the budget spent, with ``started`` replays under way besides those made? (``stopped`` says how)"""
        if time.perf_counter() > self.deadline:
            self.stopped = "budget"
            return True
        if self.replays + started >= self.maxfev:
            self.stopped = "maxfev"
            return True
        return False

    def _note(self, key: tuple[float, ...], f: float) -> float:
        self.replays += 1
        self.cache[key] = f
        if f < self.best[0]:
            self.best = (f, key)
        self.bar.step(f"fit: -log L {self.best[0]:.1f}")
        return f


def _key(theta: Sequence[float]) -> tuple[float, ...]:
    """The cache's key of a point: its log-scales rounded (a simplex step lands on a probe exactly)."""
    return tuple(round(float(t), 9) for t in theta)


def _informed(obj: _Objective, n: int) -> list[bool]:
    """Step 2 of the module doc, per parameter: every x2 probe side by side, then the /2 probes of those
    the x2 left uninformed (``_Objective.many``)."""
    f0 = obj([0.0] * n)
    out = [abs(f - f0) >= INFORMED for f in obj.many([_probe(n, i, PROBE) for i in range(n)])]
    down = [i for i in range(n) if not out[i]]
    for i, f in zip(down, obj.many([_probe(n, i, -PROBE) for i in down])):
        out[i] = abs(f - f0) >= INFORMED
    return out


def _probe(n: int, i: int, step: float) -> list[float]:
    theta = [0.0] * n
    theta[i] = step
    return theta


def _minimise(obj: _Objective, n: int, informed: list[bool]) -> tuple[list[float], str]:
    """Nelder-Mead over the informed log-scales (the others held at their start), within budget: scipy's
    steps, each reflection replayed beside a guess of the next point (``simplex``)."""
    free = [i for i in range(n) if informed[i]]
    if not free:
        return [0.0] * n, "nothing to fit"

    def full(z) -> list[float]:
        theta = [0.0] * n
        for k, i in enumerate(free):
            theta[i] = float(z[k])
        return theta

    simplex = [[0.0] * len(free)]
    for k in range(len(free)):
        v = [0.0] * len(free)
        v[k] = PROBE  # the probes already replayed
        simplex.append(v)
    try:
        nelder_mead(lambda z: obj(full(z)), lambda points, _asked: obj.many([full(z) for z in points]), simplex,
                    [(max(-BOUND, obj.params[i].lowest()), BOUND) for i in free], XATOL, FATOL, len(free) > 3)
        stopped = "converged"
    except _OutOfBudget:
        stopped = obj.stopped
    best = obj.best[1]
    return (list(best) if best else [0.0] * n), stopped


def _fmt(v: object) -> str:
    if v is None:
        return "unset"
    if isinstance(v, tuple):
        return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def tune(samples: Sequence[object], cfg: Config, keys: Sequence[str] | None = None, budget_s: float = 120.0,
         maxfev: int | None = None, progress: bool = False, fit_fraction: float = FIT_FRACTION,
         backend: Backend | None = None) -> TuneResult:
    """Fit ``cfg``'s noise to ``samples`` (a recording's configured-sensor samples in bag order; the
    module doc says how). ``keys``: the parameters to fit (``params.select``; ConfigError for an
    unknown one). ``maxfev`` (default 60 per parameter) and ``budget_s`` bound the fit's replays;
    validation adds 1 + one per changed key replays of the whole recording (the original's is the doctor's).
    ``backend``: the estimator's in every replay (``FusionCore``)."""
    t_start = time.perf_counter()
    samples = list(samples)
    if not samples:
        raise ReplayError("nothing to tune: the recording has no sample of a configured sensor")
    params = select(tunable_params(cfg, samples), keys)
    # One replay of the whole recording with the original config and the doctor: its paste lines (step 6),
    # the standstills the floors are measured over, and the records step 4 scores the original on (its
    # warnings are the recording's, said once); beside it, the original's prediction of the held-back fixes.
    held_back = split_fixes(samples, cfg)
    original: list = []
    plans = Plans(samples)  # the whole recording's: this replay's plan, and the held-back checks' (``_validate``)

    def diagnosed() -> tuple[list, list]:
        return diagnose(cfg, samples, backend, records=original, quiet=False, plan=plans.of(cfg))

    if held_back[1]:
        (verdicts, spans), pred_before = beside(diagnosed, lambda: _predicted(cfg, held_back, backend))
    else:
        (verdicts, spans), pred_before = diagnosed(), None
    first_replays = 1 if pred_before is None else 2
    params = with_floors(params, measured_floors(cfg, samples, params, spans))
    active = [p for p in params if not p.skipped]
    n = len(active)
    if maxfev is None:
        maxfev = 60 * max(n, 1)
    split = split_stamp(samples, fit_fraction)
    fit_part = [s for s in samples if s.stamp <= split]
    bar = _Progress(progress, total=2 * n + maxfev + 2 * (1 + n))
    try:
        obj = _Objective(cfg, active, fit_part, t_start + budget_s, maxfev, bar, backend)
        informed = [False] * n
        stopped = "nothing to fit"
        theta = [0.0] * n
        f_start = f_best = math.nan
        if n:
            try:
                informed = _informed(obj, n)
            except _OutOfBudget:
                informed = [False] * n  # not even probed in time: nothing is claimed about them
                stopped = "budget"
            else:
                theta, stopped = _minimise(obj, n, informed)
            f_start = obj.cache[tuple([0.0] * n)]
            f_best = obj.cache.get(tuple(round(t, 9) for t in theta), f_start)
            if not f_start - f_best >= INFORMED:  # the fit found nothing the data tell apart from the start
                theta = [0.0] * n
                f_best = f_start
        floored = [informed[i] and theta[i] <= active[i].lowest() + 1e-9 for i in range(n)]
        # at the search's own limit, x1000 or /1000 of the start (not a floor): the recording asks for more
        limited = [informed[i] and not floored[i] and abs(theta[i]) >= BOUND - 1e-9 for i in range(n)]
        result = _validate(cfg, samples, active, theta, informed, split, bar, floored, verdicts, original,
                           pred_before, held_back, backend, limited, plans)
    finally:
        bar.close()
    rows, config, before, after, comments, replays, predicted = result
    skipped = [Row(p, value(cfg, p), value(cfg, p), "skipped", p.skipped) for p in params if p.skipped]
    rows = rows + skipped
    order = {p.name: i for i, p in enumerate(params)}
    rows.sort(key=lambda r: order[r.param.name])
    return TuneResult(cfg, config, rows, split, f_start, f_best, before, after,
                      obj.replays + replays + first_replays, time.perf_counter() - t_start, stopped,
                      residuals(obj.ref) if n and obj.ref is not None else 0, comments=comments,
                      prediction_before=predicted[0], prediction_after=predicted[1],
                      problems=untuned_problems(verdicts, params))


def _predicted(c: Config, held_back: tuple[list, list], backend: Backend | None) -> Prediction:
    """``c``'s prediction of the held-back fixes (step 5; ``held_back``: ``prediction.split``'s)."""
    with muted():
        return predict(c, held_back[0], held_back[1], backend)


def _validate(cfg: Config, samples: Sequence[object], active: list[Param], theta: list[float],
              informed: list[bool], split: float, bar: _Progress, floored: list[bool], verdicts: Sequence[object],
              original: list, pred_before: Prediction | None, held_back: tuple[list, list],
              backend: Backend | None = None, limited: list[bool] | None = None, plans: Plans | None = None):
    """Step 4 of the module doc: (rows, tuned config, held-back scores before/after, comments, replays).
    ``verdicts``: the doctor's on the original config (``doctor_values.diagnose``), for step 6; ``original``:
    the records of that replay, and ``pred_before`` its prediction of ``held_back``'s fixes (None: none held);
    ``plans``: the whole recording's snapshot plans (``likelihood.Plans`` of ``samples``)."""
    replays = 0
    if plans is None:
        plans = Plans(samples)
    plans.of(cfg)  # the whole recording's plan made before the checks fork their predictions

    def run(c: Config) -> list:
        nonlocal replays
        replays += 1
        bar.step("held-back check")
        with muted():
            return replay_records(c, samples, backend, plans=plans)

    def and_predicted(here: Callable[[], T], c: Config) -> tuple[T, Prediction | None]:
        """``here()`` and, where fixes are held back, ``c``'s prediction of them beside it (a replay of its
        own, independent of ``here``'s: in a forked process, ``forked.beside``)."""
        nonlocal replays
        if not held_back[1]:
            return here(), None
        replays += 1
        bar.step("held-back fixes")
        return beside(here, lambda: _predicted(c, held_back, backend))

    ref = reference(original, cfg, after=split)
    before = score(original, ref)
    pred_after = pred_before
    start = apply(cfg, active, [0.0] * len(active))
    kept: list[float | None] = [None] * len(active)
    for i, p in enumerate(active):
        if informed[i] and value(apply(cfg, active, theta), p) != value(start, p):
            kept[i] = theta[i]
    status = ["not informed" if not informed[i] else "unchanged" for i in range(len(active))]
    notes = [""] * len(active)
    after, config = before, cfg
    if any(t is not None for t in kept):
        config = apply(cfg, active, kept)
        after, pred_after = and_predicted(lambda: score(run(config), ref), config)
        for i in range(len(active)):
            if kept[i] is None:
                continue
            trial = list(kept)
            trial[i] = None
            trial_cfg = apply(cfg, active, trial)
            trial_score, trial_pred = and_predicted(lambda: score(run(trial_cfg), ref), trial_cfg)
            fitted = _fmt(value(apply(cfg, active, kept), active[i]))
            if trial_score.neg_loglik <= after.neg_loglik:
                notes[i] = (f"fitted {fitted}; held-back -log L {trial_score.neg_loglik:.1f} without it, "
                            f"{after.neg_loglik:.1f} with it")
            elif pred_after is not None and trial_pred is not None and pred_after.worse_than(trial_pred):
                notes[i] = (f"fitted {fitted}; the held-back fixes are predicted worse with it "
                            f"({pred_after.describe()}) than without ({trial_pred.describe()})")
            else:
                continue
            status[i] = "refused"
            kept, config, after, pred_after = trial, trial_cfg, trial_score, trial_pred
        worse_fit = after.neg_loglik >= before.neg_loglik
        worse_pred = pred_after is not None and pred_before is not None and pred_after.worse_than(pred_before)
        if (worse_fit or worse_pred) and any(t is not None for t in kept):
            for i in range(len(active)):
                if kept[i] is not None:
                    status[i] = "refused"
                    notes[i] = (f"fitted {_fmt(value(config, active[i]))}; " + (
                        f"the tuned config's held-back -log L {after.neg_loglik:.1f} is not below the original's "
                        f"{before.neg_loglik:.1f}" if worse_fit else
                        f"the tuned config predicts the held-back fixes worse ({pred_after.describe()}) than the "
                        f"original ({pred_before.describe()})"))
            kept, config, after, pred_after = [None] * len(active), cfg, before, pred_before
    for i, p in enumerate(active):
        if kept[i] is not None:
            status[i] = "tuned"
    # the doctor's measured values, each a candidate in place of tune's (doctor_values.py)
    doctor = doctor_lines(cfg, verdicts, active)  # type: ignore[arg-type]
    measured: list[object] = [None] * len(active)

    def effective(c: Config, i: int) -> object:
        """The components of ``active[i]`` as the filter takes them in ``c``: unset, the messages' (the start's),
        each floored by the sensor (a line stating the floor the messages are held at changes nothing)."""
        v = value(c, active[i])
        v = value(start, active[i]) if v is None else v
        floor = active[i].floor
        return tuple(max(x, floor) for x in v) if isinstance(v, tuple) else max(v, floor)

    for group, line in doctor.items():
        idx = [i for i, p in enumerate(active) if p.group == group]
        for i in idx:
            measured[i] = value(line.config, active[i])
        if all(effective(line.config, i) == effective(config, i) for i in idx):
            continue
        try:
            trial_cfg, _ = with_suggestion(config, line.verdict)
        except ConfigError:
            continue
        trial_score, trial_pred = and_predicted(lambda: score(run(trial_cfg), ref), trial_cfg)
        loses = trial_score.neg_loglik > after.neg_loglik + INFORMED
        mispredicts = trial_pred is not None and pred_after is not None and trial_pred.worse_than(pred_after)
        if not loses and not mispredicts:
            for i in idx:
                changed = effective(trial_cfg, i) != effective(cfg, i)
                status[i] = "tuned" if changed else "unchanged"
                notes[i] = f"the doctor's measured value (held-back -log L {trial_score.neg_loglik:.1f} against " \
                           f"the fit's {after.neg_loglik:.1f})"
            config, after, pred_after = trial_cfg, trial_score, trial_pred
        else:
            why = (f"held-back -log L {trial_score.neg_loglik:.1f} with it, {after.neg_loglik:.1f} without" if loses
                   else f"it predicts the held-back fixes worse ({trial_pred.describe()} against "
                        f"{pred_after.describe()})")
            for i in idx:
                notes[i] = (notes[i] + "; " if notes[i] else "") + f"the doctor measured {_fmt(measured[i])}: {why}"
    comments: dict[tuple[str, str], str] = {}
    for i, p in enumerate(active):
        if status[i] == "tuned":
            was = getattr(cfg.filter if p.table == "filter" else cfg.sensor(p.table), p.key)
            was_text = _fmt(was) if was is not None else "unset (the messages' covariances)"
            comments[p.group] = (f"tuned: was {was_text}; held-back -log L {before.neg_loglik:.1f} -> "
                                 f"{after.neg_loglik:.1f}")
            if pred_before is not None and pred_after is not None and pred_before.fixes:
                comments[p.group] += f"; held-back fixes {pred_before.describe()} -> {pred_after.describe()}"
            for name, _ in p.companions:
                comments[(p.table, name)] = f"tuned: set with {p.key} (the components the messages state as not measured)"
    rows = []
    for i, p in enumerate(active):
        s = sensor_of(p) or ""
        note = notes[i] or ("the likelihood changes by less than 1 over a factor of 2" if status[i] == "not informed"
                            else "")
        below = _below_measured(p, value(config, p))
        if floored[i] and status[i] in ("tuned", "unchanged"):
            if below and p.held_by_measured():  # not held there: it started below it, and the fit does not lift it
                note, below = (f"the fit would go lower still; {below}, where it started (lifting it is the "
                               "user's call)"), ""
            else:
                note = (f"held at the noise the recording shows at rest, {p.measured_note}: the fit would go lower"
                        if p.held_by_measured() else
                        f"held at its floor {p.floor:g} (the sensor's *_min_sigma): the fit would go lower")
        if limited is not None and limited[i] and status[i] == "tuned" and value(config, p) == value(
                apply(cfg, active, theta), p):  # the fit's own value is the one kept (not the doctor's)
            edge = ("at the fit's limit, 1/1000 of where it started: the recording asks for less still (a start "
                    "far above it, such as another filter's process noise; tune the tuned config again to go on)"
                    if theta[i] < 0.0 else
                    "at the fit's limit, 1000 x where it started: the recording asks for more still (tune the tuned "
                    "config again to go on)")
            note = f"{note}; {edge}" if note else edge
        if below:
            note = f"{note}; {below}" if note else below
        rows.append(Row(p, value(cfg, p), value(config, p), status[i], note, before.nis_per_dof.get(s),
                        after.nis_per_dof.get(s), measured[i]))
    return rows, config, before, after, comments, replays, (pred_before, pred_after)


def _below_measured(p: Param, v: object) -> str:
    """What the table says of a value that ends below the noise the recording shows at rest (a start the user
    or the messages put there, which the fit does not lift: whether to is the user's call)."""
    if not p.measured:
        return ""
    if v is None:
        start = p.start()
        components = start if isinstance(start, tuple) else (start,)
    elif isinstance(v, tuple):
        components = tuple(v[i] for i in p.indices) if p.indices is not None else v  # type: ignore[index]
    else:
        components = (v,)  # type: ignore[assignment]
    if any(f > c for f, c in zip(p.measured, components) if f > 0.0):
        return f"below the noise the recording shows at rest, {p.measured_note}"
    return ""


# why the fit ended, as the table's "fit part" line says it
STOPPED = {"converged": "the fit converged", "budget": "the fit stopped at --budget-s",
           "maxfev": "the fit stopped at its replay limit", "nothing to fit": "nothing to fit"}


def format_table(result: TuneResult) -> str:
    """The table `fusiond tune` prints: key | before | after | the doctor's value | held-back NIS per dof | status."""
    head = ("key", "before", "after", "doctor", "held-back NIS/dof", "status")
    lines = []
    for r in result.rows:
        said = "messages ~" if r.param.source == "messages (median)" else r.param.source + " "
        before = _fmt(r.before) if r.before is not None else f"unset ({said}{_fmt(r.param.start())})" \
            if r.param.source != "config" and not r.param.skipped else "unset"
        nis = "" if r.nis_before is None else f"{r.nis_before:.3g} -> {r.nis_after:.3g}" \
            if r.nis_after is not None else f"{r.nis_before:.3g} -> n/a"
        status = r.status + (f": {r.note}" if r.note else "")
        doctor = "-" if r.doctor is None else _fmt(r.doctor)
        lines.append((r.param.name, before, _fmt(r.after), doctor, nis, status))
    widths = [max(len(x[k]) for x in [head, *lines]) for k in range(5)]
    out = ["  ".join(h.ljust(w) for h, w in zip(head[:5], widths)) + "  " + head[5]]
    out += ["  ".join(c.ljust(w) for c, w in zip(line[:5], widths)) + "  " + line[5] for line in lines]
    if result.problems:  # said first: what the table fitted, it fitted around them
        said = [f"the doctor finds {len(result.problems)} problem(s) on keys tune does not fit; the noise below is "
                "fitted around them. Fix them first (`fusiond doctor` says why), then tune again:"]
        for v in result.problems:
            said.append(f"  {v.sensor}/{v.channel} [{v.key}]" + (f" -> {v.suggestion}" if v.suggestion else ""))
        out = said + out
    b, a = result.heldback_before, result.heldback_after
    if b is not None and a is not None:
        out.append(f"held-back   -log L {b.neg_loglik:.1f} -> {a.neg_loglik:.1f} over {b.terms} updates after stamp "
                   f"{result.split:.3f} (mean NIS/dof {_fmt(b.nis_per_dof.get(''))} -> "
                   f"{_fmt(a.nis_per_dof.get(''))})")
    pb, pa = result.prediction_before, result.prediction_after
    if pb is not None and pa is not None and pb.fixes:
        out.append(f"held-back fixes (every {HOLD_EVERY}th, not fused): {pb.describe()} -> {pa.describe()} RMS over "
                   f"{pb.fixes} fixes")
    if result.fit_before == result.fit_before:
        out.append(f"fit part    -log L {result.fit_before:.1f} -> {result.fit_after:.1f} over "
                   f"{result.fit_residuals} residuals; {STOPPED.get(result.stopped, result.stopped)}")
    out.append(f"replays     {result.evaluations} in {result.seconds:.1f} s")
    return "\n".join(out)


__all__ = ["Row", "TuneResult", "format_table", "tune"]
