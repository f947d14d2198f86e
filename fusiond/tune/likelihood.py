"""The innovations' negative log-likelihood of one replay: what `fusiond tune` minimises.

The filter's own prediction-error decomposition: each update's innovation y with its predicted
covariance S = H P H^T + R is, for a filter whose model is right, a Gaussian independent of the
earlier ones, so the recording's negative log-likelihood is

    -log L = 1/2 sum over updates of (log det S + y^T S^-1 y)   (+ a constant: m log 2 pi)

and the noise that maximises L is the noise the innovations say the sensors and the process have.

What a diagnostics record carries. A record has the NIS, y^T S^-1 y computed from the full S
(the estimator's Cholesky solve), so that term is exact; of S it carries only the diagonal
(``innovation_var``). log det S is taken as sum(log S_ii), the log determinant of S's diagonal
approximation. That is exact for scalar updates (a GPS fix's up, each axis of a standstill's
gyro-bias window, which are separate scalar updates recorded together) and an upper bound otherwise (Hadamard: det S <= prod S_ii),
off by -log det of the correlation matrix of the innovation, small for roll/pitch (nearly
uncorrelated) and for a GPS fix once the heading is known. The exact value would need the log
det from the update itself (2 sum log L_ii of its Cholesky factor), which ``UpdateResult`` does
not return; adding it touches the compiled update kernel, which this module leaves alone.

Which records are terms. Updates only: a check that moves no state (the wheels' yaw rate against
the gyro, channel ``yaw_rate``) is not a prediction error of the filter. Learning updates (the
first standstill windows, the GPS heading search: their NIS tests a prior, not a noise) are left
out too. The set of terms must not depend on the parameters being compared, or a parameter that
makes the gate reject more updates, or a sensor model emit fewer records, would win by having
fewer (mostly negative: log of a small variance) terms. So one replay fixes the terms
(``reference``: keyed by sensor, channel, stamp), every other replay is scored on exactly
those, and:

- a rejected update (gated out) counts its log det S and its NIS capped at the gate (the
  sensor's ``mahalanobis_threshold``^2, or 5^2 = the standstill gate's per axis where the sensor
  has none): dropping an update costs at least as much as a 5-sigma innovation, not nothing;
- a term the replay does not produce at all counts as rejected with the reference's log det S;
- a record the reference does not have is not scored.

A term is found by its stamp, and where a channel's updates are windows of samples (the IMU's gravity tilt: 0.1 s
of accelerometer averaged, the window's start set by when the first one was quiet), a parameter that moves the
first window moves every later one, by a fraction of a window: at 0.01 m/s of wheel speed noise against 0.02,
8 of 475 gravity updates kept their stamp, and the other 467 counted as missing on both sides (the objective
jumped by 3,300 for a change the GPS's own terms scored 200 better), so tune could not leave a noise set ten times
too small. So the terms a replay leaves unfound are paired with its records of the same channel and dof that no
term found, in time order, the nearest within the channel's median interval in the reference
(``Reference.tolerance``): the same update, its window slid by less than one (there, up to 0.105 s of 0.115 s).
Where the windows moved farther (an IMU's clock shifted by 0.3 s, and the quiet stretches its gravity windows
open in with it: 16 of 489 updates a few tenths of a second from any of the other replay's), the terms still
unfound are paired, in time order, with the records of the same channel and dof left over: an update made
elsewhere stands in for one not made here. The count per channel stays the reference's, so a replay that makes
fewer updates still pays the gate for each one short; one that makes them at other moments does not (the
correct clock shift for that IMU counted 16 gate caps and read 94 worse where its updates scored 65 better).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from ..estimator.backend import Backend
from ..config import Config
from ..core.diagnostics import DiagnosticsRecord
from ..core.fusion import FusionCore
from ..core.sensors.imu.gyro_bias import ZERO_RATE_GATE
from ..errors import TuneError

CHECK_CHANNELS = frozenset({"yaw_rate"})  # records of consistency checks, not of updates
DEFAULT_GATE = ZERO_RATE_GATE  # sigma: the cap of a rejected update of a sensor without a gate

TermKey = tuple[str, str, float, int]  # sensor, channel, stamp, occurrence (records sharing the first three)
Channel = tuple[str, str]


class Plans:
    """The snapshot plans (``FusionCore.snapshot_plan``) of one recording held in memory, each made once.

    A plan depends on the samples and on each sensor's name, place in the config and ``stamp_offset_s``
    (``keys``), nothing else: tune's noise and most of the doctor's lines leave those alone, so the replays of
    one recording share a plan (making one takes ~0.6 us a sample: 7 ms of the highway car's recording, a
    thirtieth of a replay of its core). A plan made by the recording's own replay is handed in with ``add``.
    A plan made before replays are forked is shared by them; one made in a forked replay stays in its process."""

    def __init__(self, samples: Sequence[object]) -> None:
        self.samples = samples
        self._made: dict[tuple[tuple[str, float], ...], list[bool | None]] = {}

    @staticmethod
    def keys(cfg: Config) -> tuple[tuple[str, float], ...]:
        """What a plan of ``cfg``'s depends on besides the samples."""
        return tuple((s.name, s.stamp_offset_s) for s in cfg.sensors)

    def add(self, cfg: Config, plan: Sequence[bool | None]) -> None:
        """``plan``, made of these samples by a core with ``cfg`` (``FusionCore.snapshot_plan``)."""
        if len(plan) != len(self.samples):
            raise TuneError(f"a plan of {len(plan)} samples for a recording of {len(self.samples)}")
        self._made[self.keys(cfg)] = list(plan)

    def of(self, cfg: Config, core: FusionCore | None = None) -> list[bool | None]:
        """The plan of a replay with ``cfg`` (made by ``core``, a core with ``cfg``, the first time)."""
        key = self.keys(cfg)
        plan = self._made.get(key)
        if plan is None:
            plan = self._made[key] = (core if core is not None else FusionCore(cfg)).snapshot_plan(self.samples)
        return plan


def replay_records(cfg: Config, samples: Iterable[object], backend: Backend | None = None,
                   ends: list | None = None, applied: dict[str, int] | None = None,
                   plans: Plans | None = None) -> list[DiagnosticsRecord]:
    """Every diagnostics record of one replay of ``samples`` (in the order given: a bag's) through a
    fresh FusionCore with ``cfg`` (and ``backend``, the estimator's: ``FusionCore``). ``ends``: the final
    pose (t, x y z, qx qy qz qw) is appended to it, when any sample was fused; ``applied``: each sensor's
    count of samples the filter applied is put in it. ``plans``: the recording's plans (``Plans`` of these
    very samples), where the caller replays it several times."""
    core = FusionCore(cfg, backend)
    core.judge_consistency = False  # a record's windowed verdict is not scored (nor is anything else read of it)
    ingest = core.ingest
    records: list[DiagnosticsRecord] = []
    samples = samples if isinstance(samples, Sequence) else list(samples)
    if plans is not None and plans.samples is not samples:
        raise TuneError("the plans given are of another recording than the samples replayed")
    # the recording is all here: no snapshot is taken where no later sample lands (FusionCore.snapshot_plan)
    plan = plans.of(cfg, core) if plans is not None else core.snapshot_plan(samples)
    for s, keep in zip(samples, plan):
        step = ingest(s, keep)
        if step.records:
            records.extend(step.records)
    if ends is not None and core.initialised:
        t, x = core.pose()
        ends.append((t, *x.tolist()))
    if applied is not None:
        applied.update({sc.name: st.applied for sc, st in zip(core.sensors, core.stats)})
    return records


def term_keys(records: Iterable[DiagnosticsRecord]) -> Iterable[tuple[TermKey, DiagnosticsRecord]]:
    """Each record with the key its term has (sensor, channel, stamp, occurrence)."""
    seen: dict[tuple[str, str, float], int] = {}
    for r in records:
        k = (r.sensor, r.channel, r.stamp)
        n = seen.get(k, 0)
        seen[k] = n + 1
        yield (r.sensor, r.channel, r.stamp, n), r


class Keyed:
    """A replay's records that can be terms, each with its term key (``term_keys``) and its log det S
    (``_log_det``; None: not usable), taken once for the several references one replay is scored on (the advice's
    proof scores each of its two replays on the whole run's terms and on the held-back end's). ``score``,
    ``reference`` and the proof take it wherever they take records. The checks' records (CHECK_CHANNELS) are
    left out: no reference has them as terms, nor does a score pair them, and their channels are their own, so
    the others' keys are the same without them (on the highway car, 4,974 wheel yaw-rate checks of 6,619 records)."""

    __slots__ = ("items", "keys")

    def __init__(self, records: Iterable[DiagnosticsRecord]) -> None:
        self.items: list[tuple[TermKey, DiagnosticsRecord, float | None]] = [
            (k, r, _log_det(r)) for k, r in term_keys(r for r in records if r.channel not in CHECK_CHANNELS)]
        self.keys: set[TermKey] = {k for k, _, _ in self.items}


def _keyed(records: Iterable[DiagnosticsRecord] | Keyed) -> Keyed:
    return records if isinstance(records, Keyed) else Keyed(records)


def _log_det(r: DiagnosticsRecord) -> float | None:
    """log det of S's diagonal approximation (module doc); None when S is not usable."""
    total = 0.0
    for v in r.innovation_var:
        if not (v > 0.0 and math.isfinite(v)):
            return None
        total += math.log(v)
    return total


def nis_cap(cfg: Config, sensor: str, channel: str, dof: int) -> float:
    """What a rejected update's NIS counts at most: the squared gate (per axis for the standstill
    bias windows, whose axes are gated one by one and recorded together)."""
    if channel == "gyro_bias":
        return ZERO_RATE_GATE**2 * max(dof, 1)
    try:
        gate = getattr(cfg.sensor(sensor), "mahalanobis_threshold", math.inf)
    except KeyError:
        gate = math.inf
    if not math.isfinite(gate):
        gate = DEFAULT_GATE
    return gate * gate


@dataclass(frozen=True)
class Reference:
    """The terms every replay is scored on: key -> (log det S in the reference replay, NIS cap, dof)."""

    terms: dict[TermKey, tuple[float, float, int]]
    # per channel, how far (s) an update may slide and still be the reference's term: its median interval
    tolerance: dict[Channel, float] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.terms)


def reference(records: Iterable[DiagnosticsRecord] | Keyed, cfg: Config, after: float = -math.inf,
              until: float = math.inf) -> Reference:
    """The terms of this replay (module doc) with stamp in (after, until]."""
    terms: dict[TermKey, tuple[float, float, int]] = {}
    caps: dict[tuple[str, str, int], float] = {}  # nis_cap of each (sensor, channel, dof): a config lookup each
    for key, r, ld in _keyed(records).items:
        if ld is None or r.channel in CHECK_CHANNELS or r.learning or not (after < r.stamp <= until):
            continue
        group = (r.sensor, r.channel, r.dof)
        cap = caps.get(group)
        if cap is None:
            cap = caps[group] = nis_cap(cfg, r.sensor, r.channel, r.dof)
        terms[key] = (ld, cap, r.dof)
    return Reference(terms, tolerances(terms))


def tolerances(terms: Iterable[TermKey]) -> dict[Channel, float]:
    """Per channel of ``terms``, the median interval between its terms' stamps (0 for a single term)."""
    stamps: dict[Channel, list[float]] = {}
    for k in terms:
        stamps.setdefault((k[0], k[1]), []).append(k[2])
    out = {}
    for ch, ts in stamps.items():
        ts.sort()
        gaps = sorted(b - a for a, b in zip(ts, ts[1:]) if b > a)
        out[ch] = gaps[len(gaps) // 2] if gaps else 0.0
    return out


def _paired(terms: dict[TermKey, tuple[float, float, int]], unfound: Iterable[TermKey],
            spare: list[DiagnosticsRecord], tolerance: dict[Channel, float]) -> list[tuple[TermKey, DiagnosticsRecord]]:
    """The unfound terms paired with the spare records (``spare``: in time order), per channel and dof (module
    doc). First each term, in time order, with the nearest spare record not yet taken within the channel's
    tolerance: the same update, its window slid. Then the terms still unfound, in time order, with the records
    left, in time order: an update made elsewhere stands in for one not made here, up to the channel's count."""
    by: dict[tuple[str, str, int], list[DiagnosticsRecord]] = {}
    for r in spare:
        by.setdefault((r.sensor, r.channel, r.dof), []).append(r)
    behind: dict[tuple[str, str, int], list[DiagnosticsRecord]] = {}  # records passed over, before any window
    pairs, still = [], []
    for k in sorted(unfound, key=lambda k: k[2]):
        group = (k[0], k[1], terms[k][2])
        rs = by.get(group)
        tol = tolerance.get((k[0], k[1]), 0.0)
        if not rs or tol <= 0.0:
            still.append(k)
            continue
        # rs is in time order and consumed from the front: records before the term's window are passed over
        while rs and rs[0].stamp < k[2] - tol:
            behind.setdefault(group, []).append(rs.pop(0))
        best = min(range(min(len(rs), 2)), key=lambda i: abs(rs[i].stamp - k[2]), default=None)
        if best is not None and abs(rs[best].stamp - k[2]) <= tol:
            pairs.append((k, rs.pop(best)))
        else:
            still.append(k)
    left = {g: behind.get(g, []) + rs for g, rs in by.items()}  # each group's records not taken, in time order
    for k in sorted(still, key=lambda k: k[2]):
        rs = left.get((k[0], k[1], terms[k][2]))
        if rs:
            pairs.append((k, rs.pop(0)))
    return pairs


@dataclass
class Score:
    """A replay scored on a reference's terms."""

    neg_loglik: float  # 1/2 sum (log det S + NIS), over the reference's terms
    terms: int
    applied: int  # of them, applied (not rejected) in this replay
    rejected: int
    missing: int  # reference terms this replay did not produce
    # mean NIS per dof over the applied terms, per sensor ("" = all): near 1 for a consistent filter
    nis_per_dof: dict[str, float] = field(default_factory=dict)


def score(records: Iterable[DiagnosticsRecord] | Keyed, ref: Reference) -> Score:
    """-log L of a replay's records on ``ref``'s terms (module doc)."""
    terms = ref.terms
    total = 0.0
    applied = rejected = 0
    found: set[TermKey] = set()
    nis_sum: dict[str, float] = {}
    nis_n: dict[str, int] = {}
    keyed = _keyed(records)
    spare = [r for key, r, _ in keyed.items
             if key not in terms and r.channel not in CHECK_CHANNELS and not r.learning]
    unfound = terms.keys() - keyed.keys
    slid = _paired(terms, unfound, sorted(spare, key=lambda r: r.stamp), ref.tolerance) if unfound and spare else []
    # the keys are distinct: a paired term is one no record found
    for key, r, ld in [*keyed.items, *((k, r, _log_det(r)) for k, r in slid)]:
        t = terms.get(key)
        if t is None:
            continue
        found.add(key)
        cap = t[1]
        if ld is None:
            total += t[0] + cap
            rejected += 1
            continue
        nis = r.nis
        if r.rejected or nis != nis:
            total += ld + (min(nis, cap) if nis == nis else cap)
            rejected += 1
            continue
        total += ld + nis
        applied += 1
        per = nis / max(r.dof, 1)
        nis_sum[r.sensor] = nis_sum.get(r.sensor, 0.0) + per
        nis_n[r.sensor] = nis_n.get(r.sensor, 0) + 1
    missing = [k for k in terms if k not in found]
    for k in missing:
        total += terms[k][0] + terms[k][1]
    means = {s: nis_sum[s] / nis_n[s] for s in nis_sum}
    if nis_n:
        means[""] = sum(nis_sum.values()) / sum(nis_n.values())
    return Score(0.5 * total, len(terms), applied, rejected, len(missing), means)


def residuals(ref: Reference, sensors: Sequence[str] | None = None, channel: str | None = None) -> int:
    """How many scalar innovations the reference's terms hold (of these sensors, this channel): the
    n of a noise estimate's spread, ~1/sqrt(2n) relative for a standard deviation."""
    return sum(t[2] for k, t in ref.terms.items() if (sensors is None or k[0] in sensors) and (channel is None or k[1] == channel))


__all__ = ["CHECK_CHANNELS", "Keyed", "Plans", "Reference", "Score", "TermKey", "nis_cap", "reference",
           "replay_records", "residuals", "score", "term_keys", "tolerances"]
