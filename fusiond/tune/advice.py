"""Advice proven before it is printed: each doctor paste line replayed on the recording it came from.

The doctor reads its figures off innovations and cross-checks, and a figure read that way can be a
bound rather than a value: pasted, it can make the estimate worse. So before a paste line is shown
as a fix, the recording is replayed with that one change (a fresh FusionCore over the same samples)
and scored by the innovations' likelihood on the terms of the replay as configured (``likelihood``:
the same terms for both, a gated-out or vanished update charged at its gate, so a change cannot win
by rejecting data). A change of what is measured (``orientation = "roll_pitch"`` turns a 3-dof
orientation update into a 2-dof one; ``orientation = "roll_pitch"`` on an IMU whose accelerometer
gave the tilt replaces its gravity updates by orientation ones) makes those updates' likelihoods
incomparable: the terms whose dof the change altered, and those of a channel the change removed,
are left out of both scores, and the change is judged by how well the filter
then predicts everything else. A line that makes a gyro drive the prediction, which the run left to the
wheels, changes what is fused, not how: a gain still advises it, but a loss is no verdict on it (the run's
own updates, read against the sharper prediction, score their own noise too: an IMU's orientation updates
whose noise is understated scored a gyro that took a car from 66 m to 2.8 m at -205,602), and it is then
printed as the doctor's. The line is advised only when -log L improves by more than the number of keys it
sets: Akaike's penalty of one per free parameter, the smallest improvement that a change fitted to
this recording has to beat to be expected to hold on the next one; and when it does not make the run's
last 30 % worse, held back as tune validates its own fit (``recording.FIT_FRACTION``): a sensor that errs
slowly rewards a larger white noise in the whole run's likelihood round after round (its own innovations
read consistent) while the filter, following it less, predicts the run's end worse. Otherwise it is
printed as tried, with what it did. A line that changes none of the updates cannot be judged by the likelihood (a heading
turned where nothing measures the heading; a key only the doctor's own check reads): it is printed as the
doctor's, with how far it moved the final pose, if at all, and why the replay cannot tell. A problem
whose line the replay judged and did not advise is shown as a warning: the replay does not bear it out (it
contradicts it when -log L is worse by more than the line's keys).
"""

from __future__ import annotations

import bisect
import math
import time
import tomllib
from collections.abc import Sequence

import msgspec

from ..estimator import rotation as rot
from ..estimator.backend import Backend
from ..collector import skips_the_caller
from ..core.sensors.registry import kind_of
from ..config import Config, ConfigError, convert, validate
from ..doctor import ChannelStats, Proof, Verdict
from ..logs import muted
from .forked import run_side_by_side
from .likelihood import Keyed, Plans, Reference, Score, TermKey, reference, replay_records, score
from .recording import split_stamp

__all__ = ["prove_advice", "split_key", "with_suggestion"]


def split_key(key: str) -> tuple[str, str, str] | None:
    """(section, sensor name, field) of a verdict's dotted key: "sensors.imu.gyro_noise" -> ("sensors",
    "imu", "gyro_noise") (a sensor's name may hold dots), "filter.gyro_bias_sigma" -> ("filter", "",
    "gyro_bias_sigma"); None for a key that names no table's field."""
    parts = key.split(".")
    if parts[0] == "sensors" and len(parts) >= 3:
        return "sensors", ".".join(parts[1:-1]), parts[-1]
    if len(parts) == 2:
        return parts[0], "", parts[1]
    return None


def with_suggestion(cfg: Config, verdict: Verdict) -> tuple[Config, int]:
    """``cfg`` with the verdict's paste line set in the table its key names, and the number of keys
    the line sets. ConfigError when the line does not parse or the result is not a valid config."""
    try:
        values = tomllib.loads(verdict.suggestion)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{verdict.suggestion!r}: not a TOML line: {err}") from None
    where = split_key(verdict.key)
    raw = msgspec.to_builtins(cfg)
    if where is not None and where[0] == "sensors":
        name = where[1]
        tables = [t for t in raw["sensors"] if t.get("name") == name]
        if not tables:
            raise ConfigError(f"{verdict.key}: no sensor named {name!r} in the config")
        table = tables[0]
    elif where is not None and isinstance(raw.get(where[0]), dict):
        table = raw[where[0]]
    else:
        raise ConfigError(f"{verdict.key}: not a key of a config table")
    table.update(values)
    try:
        return validate(convert(raw)), len(values)
    except (msgspec.ValidationError, ConfigError) as err:
        raise ConfigError(f"{verdict.suggestion!r} in {verdict.key}: {err}") from None


def _comparable(ref: Reference, records: Keyed) -> tuple[Reference, int]:
    """``ref`` without the terms that ``records`` measure otherwise (module doc): with another dof, or
    of a channel ``records`` no longer have at all; and how many those are."""
    dof: dict[TermKey, int] = {}
    channels: set[tuple[str, str]] = set()
    for k, r, _ in records.items:
        dof[k] = r.dof
        channels.add((k[0], k[1]))
    keep = {k: t for k, t in ref.terms.items() if (k[0], k[1]) in channels and dof.get(k, t[2]) == t[2]}
    return Reference(keep, ref.tolerance), len(ref.terms) - len(keep)


# A record's stamp is its sample's stamp plus its sensor's stamp_offset_s: a line that shifts a sensor's clock
# shifts every one of its records, and a term is paired across two replays by its stamp. Shifted back, a
# record lands within rounding of its sample's stamp in the replay as configured (a few 1e-7 s at 1.7e9 s),
# far inside any sensor's period.
RESTAMP_TOLERANCE_S = 1e-6


def _shifts(cfg: Config, changed: Config) -> dict[str, float]:
    """Per sensor whose clock ``changed`` shifts: how much later it stamps its samples than ``cfg`` does."""
    before = {sc.name: sc.stamp_offset_s for sc in cfg.sensors}
    return {sc.name: sc.stamp_offset_s - before[sc.name] for sc in changed.sensors
            if sc.name in before and sc.stamp_offset_s != before[sc.name]}


def _restamped(records: Sequence[object], shifts: dict[str, float], base: Sequence[object]) -> list:
    """``records`` of a replay whose config shifts some sensors' clocks (``_shifts``), each record of those
    sensors at the stamp its sample has in ``base``, the replay as configured: the nearest of that sensor's
    and channel's stamps there within RESTAMP_TOLERANCE_S of its own less the shift (else its own less the
    shift: a sample the configured replay did not fuse). So the two replays' terms pair up sample by sample,
    and the likelihood judges a clock shift by what it does to the updates, not by every shifted one going
    missing."""
    stamps: dict[tuple[str, str], list[float]] = {}
    for r in base:
        if r.sensor in shifts:
            stamps.setdefault((r.sensor, r.channel), []).append(r.stamp)
    for v in stamps.values():
        v.sort()
    out = []
    for r in records:
        shift = shifts.get(r.sensor)
        if shift is None:
            out.append(r)
            continue
        t = r.stamp - shift
        near = stamps.get((r.sensor, r.channel), [])
        i = bisect.bisect_left(near, t)
        best = min((near[j] for j in (i - 1, i) if 0 <= j < len(near)), key=lambda b: abs(b - t), default=None)
        out.append(msgspec.structs.replace(r, stamp=best if best is not None and abs(best - t) <= RESTAMP_TOLERANCE_S
                                           else t))
    return out


def _gyros(cfg: Config) -> set[str]:
    """The sensors whose gyro drives the prediction in ``cfg``."""
    return {sc.name for sc in cfg.sensors if kind_of(sc).fuses_gyro(sc)}


def _brought_back(was: dict[str, int] | None, now: dict[str, int]) -> str:
    """The sensors whose samples a change makes the filter apply more than twice as often as the run as
    configured did (``was``: its applied counts; most of a sensor's samples dropped there, as far from filter
    time: a clock the line corrects), said with how many each; "" when there is none or ``was`` is unknown."""
    if was is None:
        return ""
    back = [f"{n - was.get(name, 0)} more samples of {name}" for name, n in sorted(now.items())
            if n > 2 * was.get(name, 0)]
    return ", ".join(back)


# A change that applies more than twice the updates of one of the run's channels, by at least this share of the
# terms the run is scored on, judges the lost run's gate charges and unscored updates, not the change.
UPDATES_BACK_SHARE = 0.1


def _applied(records: Sequence[object]) -> dict[tuple[str, str], int]:
    """Per channel, the updates applied: neither gated nor learning."""
    out: dict[tuple[str, str], int] = {}
    for r in records:
        if not r.rejected and not r.learning:
            key = (r.sensor, r.channel)
            out[key] = out.get(key, 0) + 1
    return out


def _updates_back(base: Sequence[object], records: Sequence[object], scored: int) -> str:
    """The channels of the run as configured (``base``) whose applied updates a change more than doubles, by at
    least UPDATES_BACK_SHARE of the ``scored`` terms, said with how many more ("" when none): a run that lost a
    sensor (a twist in the wrong frame: of 576 fixes 59 gated, 517 only learned from) is scored on gate charges
    and on what it did not score, and read -2,388 for the line that takes the highway car from 42 m to 1.5 m."""
    seen = {(r.sensor, r.channel) for r in base}
    was, now = _applied(base), _applied(records)
    back = [f"{n - was.get(k, 0)} more {k[0]}/{k[1]} updates" for k, n in sorted(now.items())
            if k in seen and n > 2 * was.get(k, 0) and n - was.get(k, 0) >= UPDATES_BACK_SHARE * scored]
    return ", ".join(back)


def _channel(records: Sequence[object], v: Verdict) -> ChannelStats | None:
    """The verdict's own channel over ``records`` (the figures its message quotes), None where it has none (a
    check's channel that is no update's: the IMU's attitude, a heading)."""
    mine = [r for r in records if r.sensor == v.sensor and r.channel == v.channel]
    if not mine:
        return None
    ch = ChannelStats(list(mine[0].components))
    ch.extend(mine)
    return ch


def _effect(before: Score, after: Score, v: Verdict, dropped: int, base_records: Sequence[object],
            records: Sequence[object]) -> str:
    """The likelihood's gain, and the NIS per dof of the verdict's own channel before and after (the figure
    its message quotes), else of its sensor's scored updates, named so."""
    gain = before.neg_loglik - after.neg_loglik
    text = f"likelihood {gain:+.0f}"
    if dropped:
        text += f" over the {after.terms} updates it leaves measured as they were"
    was, now = _channel(base_records, v), _channel(records, v)
    if was is not None and now is not None and math.isfinite(was.nis_per_dof) and math.isfinite(now.nis_per_dof):
        text += f", {v.sensor}/{v.channel} NIS/dof {was.nis_per_dof:.2f} -> {now.nis_per_dof:.2f}"
    else:  # the sensor's own scored updates, else all of them, named for what they are
        b, a = before.nis_per_dof.get(v.sensor), after.nis_per_dof.get(v.sensor)
        whose = f"{v.sensor}'s"
        if b is None or a is None:
            b, a, whose = before.nis_per_dof.get(""), after.nis_per_dof.get(""), "the scored updates'"
        if b is not None and a is not None:
            text += f", {whose} NIS/dof {b:.2f} -> {a:.2f}"
    if after.rejected != before.rejected:
        text += f", {after.rejected} gated (was {before.rejected})"
    return text


def _still(v: Verdict, before: Sequence[object], after: Sequence[object]) -> str:
    """What the line leaves of a NIS verdict on its own channel: a noise fitted to the innovations of a filter
    that trusted the sensor more is not yet the noise of the filter that trusts it less (its own innovations
    grow as it follows the sensor less, where the sensor's error is slow), so a pasted value can still read
    high, and the next replay's innovations say the rest; or, no nearer 1, the line's gain is not its channel's.
    "" when the channel's whole-run verdict changed."""
    was, now = _channel(before, v), _channel(after, v)
    if was is None or now is None or was.verdict() not in ("nis_high", "nis_low") or now.verdict() != was.verdict():
        return ""
    name, side = f"{v.sensor}/{v.channel}", now.verdict().removeprefix("nis_")
    if abs(math.log(now.nis_per_dof)) >= abs(math.log(was.nis_per_dof)):  # no nearer 1 per dof
        return f"; {name} itself reads NIS {side}, no nearer 1 with it: what it gains is the other updates'"
    return f"; {name} still reads NIS {side} with it: paste it and replay, the next verdict's value goes on from there"


def prove_advice(cfg: Config, samples: Sequence[object], verdicts: Sequence[Verdict],
                 budget_s: float = 60.0, base_records: Sequence[object] | None = None,
                 backend: Backend | None = None, workers: int | None = None,
                 base_final: Sequence[float] | None = None,
                 base_applied: dict[str, int] | None = None, plans: Plans | None = None) -> list[Verdict]:
    """``verdicts`` with a ``proof`` on each that has a paste line (module doc). ``samples``: the
    recording as the replay fused it, in its order; ``base_records``: that replay's diagnostics records,
    when the caller kept them (else the recording is replayed once more for them), and ``base_final`` its
    final pose (t, x y z, qx qy qz qw; else replayed for, where a line changes no update), and ``base_applied``
    each sensor's count of samples it applied (else a line that brings dropped samples back is judged as any
    other). Then one replay per
    distinct paste line, while ``budget_s`` lasts (the lines not replayed in time say so). The
    recording's warnings were logged by the replay the verdicts come from: these replays log nothing.
    ``backend``: the estimator's in these replays (``FusionCore``). ``workers``: how many lines are replayed
    at once, each in a forked process (``forked.run_side_by_side``; default: all at once, up to two per CPU).
    ``plans``: the snapshot plans of these very ``samples`` (``likelihood.Plans``), with the one the recording's own
    replay made when it made one (else made here, once for all the lines)."""
    pending = [v for v in verdicts if v.suggestion]
    if not pending:
        return list(verdicts)
    if plans is None:
        plans = Plans(samples)
    with skips_the_caller():  # the recording's own replay is alive (its records, the doctor): frozen
        return _proven(cfg, samples, verdicts, pending, time.perf_counter() + budget_s, budget_s, base_records,
                       backend, workers, base_final, base_applied, plans)


def _moved(before: Sequence[float] | None, after: Sequence[float] | None) -> str:
    """How far ``after``'s final pose is from ``before``'s ("" when the same, or either unknown)."""
    if before is None or after is None or tuple(before) == tuple(after):
        return ""
    shift = math.dist(before[1:4], after[1:4])
    turn = math.degrees(abs(rot.wrap(rot.yaw(tuple(after[4:8])) - rot.yaw(tuple(before[4:8])))))
    return f"{shift:.2f} m and {turn:.0f} deg of heading"


def _proven(cfg: Config, samples: Sequence[object], verdicts: Sequence[Verdict], pending: list[Verdict],
            deadline: float, budget_s: float, base_records: Sequence[object] | None,
            backend: Backend | None, workers: int | None, base_final: Sequence[float] | None,
            base_applied: dict[str, int] | None, plans: Plans) -> list[Verdict]:
    """``prove_advice`` once its pending lines are known."""
    if base_records is None:
        with muted():
            base_records = replay_records(cfg, samples, backend, plans=plans)
    base = Keyed(base_records)  # each term's key and log det, for every reference and score below
    full = reference(base, cfg)
    held = reference(base, cfg, after=split_stamp(samples))  # the run's last 30 %, as tune holds it back
    proofs: dict[tuple[str, str], Proof] = {}
    to_replay: list[tuple[tuple[str, str], Verdict, Config, int]] = []
    # problems first: if the budget runs out, the lines left unproven are the least urgent ones
    for v in sorted(pending, key=lambda v: v.level != "problem"):
        line = (v.key, v.suggestion)
        if line in proofs or any(line == queued[0] for queued in to_replay):
            continue
        try:
            changed, n_keys = with_suggestion(cfg, v)
        except ConfigError as err:
            proofs[line] = Proof(False, f"it does not apply to this config ({err})", tried=False)
            continue
        to_replay.append((line, v, changed, n_keys))

    def out_of_time(_job) -> Proof | None:
        if time.perf_counter() > deadline:
            return Proof(True, f"the {budget_s:g} s budget for replaying advice ran out", tried=False)
        return None

    def prove(job: tuple[tuple[str, str], Verdict, Config, int]) -> Proof:
        _, v, changed, n_keys = job
        ends: list = []
        applied: dict[str, int] = {}
        with muted():
            records = replay_records(changed, samples, backend, ends, applied, plans)
        shifts = _shifts(cfg, changed)
        if shifts:  # a clock shifted: its records paired with the configured replay's by their samples' stamps
            records = _restamped(records, shifts, base_records)
        back = _brought_back(base_applied, applied)
        if back:  # the run as configured dropped most of a sensor: its likelihood has nothing to compare
            return Proof(False, f"it fuses {back} the run as configured dropped: the likelihood over the run's own "
                                "updates cannot judge a change of what is fused; the evidence above is the case for it",
                         judged=False)
        back = _updates_back(base_records, records, len(full))
        if back:  # ... or gated most of a channel's updates, or only learned from them
            return Proof(False, f"it applies {back} the run as configured gated or only learned from: the likelihood "
                                "over the run's own updates cannot judge a run it no longer loses; the evidence above "
                                "is the case for it", judged=False)
        keyed = Keyed(records)
        ref, dropped = _comparable(full, keyed)
        if dropped and not ref.terms:  # every update it leaves is measured otherwise (a yaw no longer fused)
            return Proof(False, f"it changes how each of the run's {dropped} updates is measured, so none is left "
                                "to compare: the likelihood over the run's own updates cannot judge it; the "
                                "evidence above is the case for it", judged=False)
        before, after = score(base, ref), score(keyed, ref)
        gain = before.neg_loglik - after.neg_loglik
        if gain == 0.0 and not dropped and after.rejected == before.rejected:
            start = base_final
            if start is None:
                start_ends: list = []
                with muted():
                    replay_records(cfg, samples, backend, start_ends, plans=plans)
                start = start_ends[0] if start_ends else None
            moved = _moved(start, ends[0] if ends else None)
            if moved:  # the estimate moved where no update looks (a heading with nothing measuring it)
                return Proof(False, f"it moves the final pose by {moved} but changes none of the filter's "
                                    "updates: nothing on this recording measures what it changes, so the replay "
                                    "cannot judge it; the evidence above is the case for it", judged=False)
            # a key the filter does not use here (a floor of a channel only the doctor's check reads; a channel
            # the filter already leaves out): nothing against it, and its case is the doctor's
            return Proof(False, "it changes none of the filter's updates on this recording, only the "
                                "doctor's own check: the replay cannot judge it", judged=False)
        effect = _effect(before, after, v, dropped, base_records, records)
        if gain > n_keys:
            held_ref, _ = _comparable(held, keyed)
            held_gain = score(base, held_ref).neg_loglik - score(keyed, held_ref).neg_loglik
            if held_gain < 0.0:  # better over the run, worse over its end: fitted to the run, not predicting it
                return Proof(False, effect + f"; but over the run's last 30 % (held back, as tune validates) "
                                             f"likelihood {held_gain:+.0f}: it does not predict the run's end better")
        advised = gain > n_keys
        added = sorted(_gyros(changed) - _gyros(cfg))
        if added and not advised:  # a new input to the prediction: a loss is no verdict on it (module doc)
            return Proof(False, effect + f"; it makes the gyro of {', '.join(added)} drive the prediction, which the "
                                         "run as configured left to the wheels: the run's own updates, read against a "
                                         "sharper prediction, score their own noise as much as the gyro, so the "
                                         "replay cannot judge it; the evidence above is the case for it", judged=False)
        still = _still(v, base_records, records) if advised else ""  # what the next round would say of an advised one
        return Proof(advised, effect + still, refuted=gain < -n_keys)

    if len(to_replay) > 1:  # the configured keys' plan made once here, before the lines' replays are forked
        plans.of(cfg)
    # each line's replay is independent of the others': side by side on the machine's cores (``forked``)
    for job, proof in zip(to_replay, run_side_by_side(prove, to_replay, workers, out_of_time)):
        proofs[job[0]] = proof
    return [_with_proof(v, proofs[(v.key, v.suggestion)]) if v.suggestion else v for v in verdicts]


def _with_proof(v: Verdict, proof: Proof) -> Verdict:
    """``v`` with its line's proof; a problem whose line the replay judged and did not advise is a warning that
    says so: the problem's claim is its line's fix, the replay is the test of a fix, and the doctor does not call
    a problem what that test does not bear out (one the replay refutes, worse by more than its keys, says that;
    one it cannot judge stands on its check's evidence)."""
    if v.level == "problem" and proof.tried and proof.judged and not proof.advised:
        said = ("makes the filter's predictions worse" if proof.refuted else
                "does not make the filter's predictions better by more than it adds")
        return msgspec.structs.replace(
            v, level="warn", proof=proof,
            message=v.message + f". Replayed, its line {said} (below): the replay does not bear this check out on "
                                "this recording, so it is a warning, not a problem")
    return msgspec.structs.replace(v, proof=proof)
