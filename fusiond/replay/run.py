"""Offline replay: bag samples through the same FusionCore the daemon uses.

The TUM output has one line per odometry sample: the newest estimate at that
moment, exactly what the daemon publishes then (not a later, smoothed pose).
"""

from __future__ import annotations

import sys
import time
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Iterable, Iterator, Sequence
from typing import IO, TYPE_CHECKING, Callable

import msgspec
import numpy as np

from ..estimator.backend import Backend
from ..collector import skips_the_caller
from ..config import Config
from ..core.layout import absolute_sensor
from ..core.sensors.registry import kind_of
from ..errors import ReplayError
from ..core.fusion import FusionCore
from ..estimator import POSE
from ..estimator.rotation import to_rpy
from ..samples import Sample
from ..core.sensors import OdomSample
from .bag import BagError, BagSamples, did_you_mean, open_bag_samples
from .read_ahead import ReadAhead, reading_ahead

if TYPE_CHECKING:  # the doctor is imported only by a replay that runs it (not by --quiet)
    from ..doctor import Doctor, Verdict


@dataclass
class Trace:
    """What the plot and the summary need, gathered during the run."""

    fused: list[tuple[float, float, float, float]] = field(default_factory=list)  # t x y z
    raw_odom: list[tuple[float, float, float, float]] = field(default_factory=list)
    nis: dict[str, list[tuple[float, float, int, bool]]] = field(default_factory=dict)  # t nis dof rejected
    innovations: dict[str, tuple[list[str], list[tuple[float, list[float], list[float]]]]] = field(
        default_factory=dict)  # channel -> (components, [(t, innovation, innovation_var)])


@dataclass
class ReplayResult:
    core: FusionCore
    doctor: Doctor | None  # None: the replay was run without the doctor (nothing would read it)
    trace: Trace
    messages: int
    poses: int
    seconds: float  # wall time of the fusion loop (bag decoding included)
    missing: list[str]
    decode_errors: int
    trajectory: array = field(default_factory=lambda: array("d"))  # t x y z qx qy qz qw of every published pose
    # per published pose: 1 when its heading was known (a GPS-referenced heading waits for the first metres
    # of travel; until then the pose's yaw variance says "unknown" and its yaw is not an estimate)
    heading_known: array = field(default_factory=lambda: array("b"))
    # the verdicts with their paste lines replayed (fusiond.tune.advice), once that has run
    proven: list[Verdict] | None = None
    # with smoothing (replay(..., smooth=True)): t x y z qx qy qz qw of the smoothed pose at every publish
    # moment of the final timeline (``smoothed_trajectory``)
    smoothed: array | None = None
    # with lookahead (replay(..., lookahead=True)): the samples as fused, in order (the recording held in memory),
    # and the snapshot plan made of them (``FusionCore.snapshot_plan``; None where the reading child was done only
    # once every sample had been fused), which a replay of them with the same sensors' keys can take again
    samples: list[Sample] | None = None
    plan: list[bool | None] | None = None

    def verdicts(self) -> list[Verdict]:
        if self.proven is not None:
            return self.proven
        if self.doctor is None:
            raise ReplayError("this replay was run without the doctor (replay(..., doctor=False))")
        core = self.core
        periods = core.state.period if core.state is not None else [0.0] * len(core.sensors)
        stats = {s.name: {"received": st.received, "applied": st.applied, "late": st.late, "dropped": st.dropped,
                          "period": period, "lost": lost}
                 for s, st, period, lost in zip(core.sensors, core.stats, periods, core.lost_components())}
        at_cap = False
        if core.initialised:
            pos_var, att_var = _variances(core)
            cap = core.cfg.filter.covariance_cap
            at_cap = pos_var >= 0.999 * cap[0] or att_var >= 0.999 * cap[1]
        return self.doctor.verdicts(stats, at_cap=at_cap, covariance_resets=core.covariance_resets,
                                    scales=_learned(core))

    @property
    def applied(self) -> dict[str, int]:
        """Each sensor's count of samples the filter applied."""
        return {s.name: st.applied for s, st in zip(self.core.sensors, self.core.stats)}

    @property
    def final(self) -> tuple[float, ...] | None:
        if not self.core.initialised:
            return None
        t, x = self.core.pose()
        return (t, *x.tolist())


def _learned(core: FusionCore, keys: bool = False) -> dict[str, float]:
    """What the core estimated of its own configuration: its scales, (``keys``) the keys it estimates as the
    config states them (an IMU's yaw_offset: pasted, it holds), and the twist's pitch once it is estimated (not
    while ``pitch_estimation = "auto"`` holds it at the mount)."""
    learned = dict(core.scales)
    if keys:
        learned.update(core.estimated_keys())
    if core.twist_pitch is not None:
        learned["twist_pitch"] = core.twist_pitch
    return learned


def _variances(core: FusionCore) -> tuple[float, float]:
    """Largest position and attitude variance of the newest estimate (public Estimate only)."""
    v = core.pose_variances()
    return max(v[0], v[1], v[2]), max(v[3], v[4], v[5])


def missing_topics(bag: BagSamples | ReadAhead, cfg: Config) -> str:
    """Each configured sensor whose topic is not in the bag, with the bag topic its key may have meant, and
    the topics the bag has (the text of an error: ``check_topics``, and play's)."""
    have = ", ".join(f"{t} [{m}]" for t, m in sorted(bag.bag_topics.items())) or "none"
    absent = "; ".join(f"sensor {name!r}: topic /{cfg.sensor(name).key} is not in the bag"
                       f"{did_you_mean(cfg.sensor(name).key, bag.bag_topics)}" for name in bag.missing)
    return f"{absent}; the bag has: {have}"


def check_topics(bag: BagSamples | ReadAhead, cfg: Config, warn: Callable[[str], None] | None,
                 allow_missing: bool = True) -> None:
    """Before anything is fused: the odometry drives the prediction, and a GPS or absolute pose
    defines the world frame (nothing is published before it), so a config whose odometry topic,
    or every one of whose frame-defining topics, is not in the bag would only produce an empty
    run; that is an error naming them. Any other absent topic is an error too unless
    ``allow_missing`` (the CLI's --allow-missing): a misspelt IMU topic would otherwise give a run,
    a doctor's verdict or a "tuned" config that never saw the IMU; allowed, it is a warning."""
    have = ", ".join(f"{t} [{m}]" for t, m in sorted(bag.bag_topics.items())) or "none"
    for s in cfg.sensors:
        if s.name in bag.missing and kind_of(s).drives_prediction:
            raise BagError(f"the odometry topic /{s.key} (sensor {s.name!r}, which drives the prediction) is not "
                           f"in the bag{did_you_mean(s.key, bag.bag_topics)}; the bag has: {have}")
    # Nothing is published before a GPS or absolute pose has defined the world frame: without any
    # of them in the bag the run would fuse everything and publish nothing.
    frame = [s for s in cfg.sensors if absolute_sensor(s)]
    if frame and all(s.name in bag.missing for s in frame):
        names = " or ".join(f"/{s.key} (sensor {s.name!r}){did_you_mean(s.key, bag.bag_topics)}" for s in frame)
        raise BagError(f"the topic {names} that defines the world frame is not in the bag: nothing would be "
                       f"published; the bag has: {have}")
    if bag.missing and not allow_missing:
        raise BagError(f"{missing_topics(bag, cfg)}. Fix the key in the config, or pass --allow-missing to "
                       "replay without it")
    if bag.missing and warn is not None:
        for name in bag.missing:
            s = cfg.sensor(name)
            warn(f"sensor {name!r}: topic /{s.key} is not in the bag{did_you_mean(s.key, bag.bag_topics)}; "
                 f"replaying without it (the bag has: {have})")


_TUM = "%.9f %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n"


def tum_line(t: float, pose) -> str:
    """One TUM trajectory line: stamp x y z qx qy qz qw (``pose``: those seven)."""
    return _TUM % (t, *pose[:7])


def tum_text(trajectory: array) -> str:
    """The TUM file of a run's published poses (``trajectory``: 8 doubles a pose, t x y z qx qy qz qw),
    formatted in one pass at the end rather than a string per message."""
    fmt = _TUM
    return "".join([fmt % tuple(trajectory[i : i + 8]) for i in range(0, len(trajectory), 8)])


class _JsonLines:
    """The --diagnostics file: each record encoded as it comes (records are not kept), the lines
    gathered in one buffer and written in blocks of ~1 MiB rather than two writes a record."""

    BLOCK = 1 << 20

    def __init__(self, path: Path) -> None:
        self._file = open(path, "wb")
        self._buf = bytearray()
        self._encode_into = msgspec.json.Encoder().encode_into

    def add(self, record: object) -> None:
        buf = self._buf
        self._encode_into(record, buf, -1)  # appended at the end of the buffer
        buf += b"\n"
        if len(buf) >= self.BLOCK:
            self._file.write(buf)
            buf.clear()

    def close(self) -> None:
        try:
            self._file.write(self._buf)
        finally:
            self._buf.clear()
            self._file.close()


class _Progress:
    """A one-line progress bar on a terminal; silent otherwise (CI logs, pipes)."""

    def __init__(self, total: int, stream: IO[str] | None = None) -> None:
        self.total = max(total, 1)
        stream = sys.stderr if stream is None else stream  # at call time: sys.stderr may have been replaced
        self.stream = stream
        self.enabled = stream.isatty() and total > 0
        self.next = 0

    def update(self, n: int) -> None:
        if self.enabled and n >= self.next:
            frac = n / self.total
            bar = "#" * int(30 * frac)
            self.stream.write(f"\rreplay [{bar:<30}] {100 * frac:5.1f}% {n}/{self.total}")
            self.stream.flush()
            self.next = n + max(self.total // 200, 1)

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")


def replay(
    paths: list[Path],
    cfg: Config,
    tum: Path | None = None,
    diagnostics: Path | None = None,
    keep_trace: bool = True,
    progress: bool = True,
    warn: Callable[[str], None] | None = None,
    doctor: bool = True,
    through: Callable[[Iterator[Sample]], Iterator[Sample]] | None = None,
    records: list | None = None,
    allow_missing: bool = True,
    smooth: bool = False,
    backend: Backend | None = None,
    lookahead: bool = False,
    read_ahead: bool = True,
    reading: ReadAhead | None = None,
) -> ReplayResult:
    """Fuse the bags' samples in bag order, as the daemon would have received them. ``doctor``:
    also feed the tuning doctor (its verdicts are the summary, the report and the plots read
    its series); a replay whose only output is files (``--quiet`` without plot or report) skips it.
    ``through``: the bag's samples pass through it on their way to the core (the evaluation's
    recorder sees every one and holds back the fixes it scores on). ``records``: every diagnostics
    record of the replay is appended to it (the advice's proof scores them as its reference run).
    ``allow_missing``: a configured topic absent from the bags is a warning, not an error (``check_topics``).
    ``smooth``: the forward pass records what the smoother needs and the result carries the smoothed
    trajectory (``ReplayResult.smoothed``), which the TUM file then holds instead of the causal one.
    ``backend``: the estimator's (``FusionCore``'s; None: compiled when built). ``lookahead``: the samples
    are read in full before the first is fused, so that the core takes a history snapshot only where a later
    sample can land (``FusionCore.snapshot_plan``): the same estimates, for the recording held in memory
    (as a caller that keeps it for the advice's proof does anyway). ``read_ahead``: on a machine with two
    cores or more, a forked child opens and decodes the bags while this process fuses (``replay.read_ahead``);
    with ``lookahead``, the samples are then fused as they come, each keeping its snapshot, until the child
    is done, and the plan covers the rest (the same estimates). ``reading``: that child, started by the
    caller (``reading_ahead``) before it imported the filter, so that the two overlap too; closed here."""
    diag_out = _JsonLines(diagnostics) if diagnostics else None
    if reading is None and read_ahead:
        reading = reading_ahead(paths, cfg.sensors)
    t0 = time.perf_counter()
    try:
        runner = Runner(cfg, keep_trace, doctor, smooth, backend)  # built while a reading child opens the bags
        opened = reading.opened() if reading is not None else open_bag_samples(paths, cfg.sensors)
        with skips_the_caller(), opened as bag:
            check_topics(bag, cfg, warn, allow_missing)
            if diag_out is not None and records is not None:
                def keep(r, add=diag_out.add, append=records.append) -> None:
                    add(r)
                    append(r)
                runner.on_record = keep
            elif diag_out is not None:
                runner.on_record = diag_out.add
            elif records is not None:
                runner.on_record = records.append
            bar = _Progress(bag.total if progress else 0)
            samples = bag if through is None else through(iter(bag))
            fed: list[Sample] | None = None
            plan: list[bool | None] | None = None
            if lookahead and reading is None:
                fed = list(samples)
                plan = runner.core.snapshot_plan(fed)
                _feed(runner, zip(fed, plan), bar)
            elif lookahead:
                # the child makes the doctor's sample part (the caller asked it: every sample it reads is fed)
                runner.samples_to_doctor = runner.doctor is None or not reading.feeds_doctor
                fed, plan = _feed_until_read(runner, iter(samples), reading, bar)
                if not runner.samples_to_doctor:
                    _doctor_samples(runner.doctor, reading, fed)
            else:
                _feed(runner, ((sample, True) for sample in samples), bar)
            bar.update(runner.messages)
            bar.close()
            missing, decode_errors = list(bag.missing), bag.decode_errors
    finally:
        if reading is not None:
            reading.close()
        if diag_out is not None:
            diag_out.close()
    seconds = time.perf_counter() - t0
    result = runner.result(seconds, missing, decode_errors)
    result.samples, result.plan = fed, plan
    if tum is not None:
        tum.parent.mkdir(parents=True, exist_ok=True)
        tum.write_text(tum_text(result.smoothed if smooth else runner.trajectory))
    return result


def _feed(runner: Runner, planned: Iterable[tuple[Sample, bool]], bar: _Progress) -> None:
    """Each sample through the runner with its ``keep`` (``FusionCore.snapshot_plan``)."""
    for sample, keep in planned:
        runner.feed(sample, keep)
        if runner.messages % 256 == 0:
            bar.update(runner.messages)


def _feed_until_read(runner: Runner, samples: Iterator[Sample], ahead: ReadAhead, bar: _Progress
                     ) -> tuple[list[Sample], list[bool | None] | None]:
    """``samples`` as they come from ``ahead``, each keeping its snapshot (a plan needs every later sample),
    until the child has read the whole recording; then the rest as ``snapshot_plan`` says, planned over the
    whole recording as fed (so what the rest keeps is what a plan made before the first sample would say).
    Returns every sample fed, in order, and that plan (None when the child was done only after the last)."""
    fed: list[Sample] = []
    for sample in samples:
        fed.append(sample)
        runner.feed(sample)
        if runner.messages % 256 == 0:
            bar.update(runner.messages)
        if ahead.complete:
            first = len(fed)
            rest = list(samples)
            fed += rest
            plan = runner.core.snapshot_plan(fed)
            _feed(runner, zip(rest, plan[first:]), bar)
            return fed, plan
    return fed, None


def _doctor_samples(doctor, ahead: ReadAhead, fed: list[Sample]) -> None:
    """The doctor's sample part of a replay whose reading child was asked for it (``read_ahead``): adopted from
    the child, else (it sent none) made here from the samples ``fed``, in their order."""
    side = ahead.doctor_side()
    if side is not None:
        doctor.adopt(side)
        return
    for sample in fed:
        doctor.add_sample(sample)


class Runner:
    """One sample at a time through the core, the doctor and the trace: the loop of `replay`, also
    used on simulated samples by the tests (so they judge exactly what a replay would)."""

    def __init__(self, cfg: Config, keep_trace: bool = True, doctor: bool = True, smooth: bool = False,
                 backend: Backend | None = None) -> None:
        self.core = FusionCore(cfg, backend)
        self.smooth = smooth
        if smooth:
            self.core.record_for_smoothing()
        if doctor:
            from ..doctor import Doctor

            self.doctor: Doctor | None = Doctor(cfg)
        else:
            self.doctor = None
        self.trace = Trace()
        self.keep_trace = keep_trace
        self.trajectory = array("d")  # t x y z qx qy qz qw of every published pose (64 bytes each)
        self.heading_known = array("b")  # per published pose (ReplayResult.heading_known)
        self.messages = 0
        self.on_record: Callable | None = None
        # False: the doctor's sample part is made elsewhere from the same samples and adopted (``replay``)
        self.samples_to_doctor = True

    def feed(self, sample, keep: bool | None = True) -> None:
        """``keep``: the core's (``FusionCore.ingest``, ``snapshot_plan``)."""
        core, doctor, keep_trace = self.core, self.doctor, self.keep_trace
        self.messages += 1
        step = core.ingest(sample, keep)
        if doctor is not None and self.samples_to_doctor:
            doctor.add_sample(sample)
        if step.poses:  # samples held for a time jump, applied at once: one pose per odometry message
            known = step.poses_heading_known or [core.heading_known] * len(step.poses)
            for (t_held, x_held), k in zip(step.poses, known):
                self.trajectory.append(t_held)
                self.trajectory.extend(x_held.tolist())
                self.heading_known.append(k)
        if step.publish:
            t, x = core.pose()
            p = x.tolist()  # one conversion for the trajectory, the doctor and the trace
            if not step.poses:
                self.trajectory.append(t)
                self.trajectory.extend(p)
                self.heading_known.append(core.heading_known)
            if doctor is not None:
                q = (p[3], p[4], p[5], p[6])
                doctor.add_orientation(q)
                if doctor.wants_estimate(t):
                    pos_var, att_var = _variances(core)
                    bias = core.gyro_bias
                    doctor.add_estimate(t, q, pos_var, att_var, float(bias[2]) if bias is not None else 0.0)
            if keep_trace:
                self.trace.fused.append((t, p[0], p[1], p[2]))
        if type(sample) is OdomSample:
            if doctor is not None:
                since = core.still_since
                if since is not None:
                    doctor.add_rest(sample, since)
                if step.accepted:
                    doctor.add_twist(sample.linear, sample.angular, sample.orientation, sample.position,
                                     sample.stamp)
            if keep_trace and step.accepted:
                self.trace.raw_odom.append((sample.stamp, *sample.position))
        records = step.records
        if records:
            on_record, trace = self.on_record, self.trace
            for r in records:
                if doctor is not None:
                    doctor.add(r)
                if on_record is not None:
                    on_record(r)
                if keep_trace:
                    name = f"{r.sensor}/{r.channel}"
                    trace.nis.setdefault(name, []).append((r.stamp, r.nis, r.dof, r.rejected))
                    comps, rows = trace.innovations.setdefault(name, (list(r.components), []))
                    if r.components == comps:
                        rows.append((r.stamp, r.innovation, r.innovation_var))

    def result(self, seconds: float = 0.0, missing: list[str] | None = None, decode_errors: int = 0) -> ReplayResult:
        return ReplayResult(self.core, self.doctor, self.trace, self.messages, len(self.trajectory) // 8, seconds,
                            missing or [], decode_errors, self.trajectory, self.heading_known,
                            smoothed=smoothed_trajectory(self.core) if self.smooth else None)


def smoothed_trajectory(core: FusionCore) -> array:
    """The smoothed poses at the core's publish moments, 8 doubles a pose (t x y z qx qy qz qw), as
    ``ReplayResult.trajectory`` holds the causal ones."""
    out = array("d")
    if core.state is None:
        return out
    sm = core.smoothed()
    rows = np.column_stack((sm.t, sm.x[:, POSE])) if sm.t.size else np.zeros((0, 8))
    out.frombytes(np.ascontiguousarray(rows, dtype=float).tobytes())
    return out


def run_samples(samples, cfg: Config, keep_trace: bool = False, smooth: bool = False,
                backend: Backend | None = None, records: list | None = None,
                plan: Sequence[bool | None] | None = None) -> ReplayResult:
    """Replay samples already in memory (a simulation) exactly as a bag would be replayed (``backend``: the
    estimator's, ``FusionCore``; ``records``: every diagnostics record is appended to it, as ``replay``'s;
    ``plan``: ``FusionCore.snapshot_plan`` of these samples with ``cfg``'s sensors, when the caller made it)."""
    runner = Runner(cfg, keep_trace, smooth=smooth, backend=backend)
    if records is not None:
        runner.on_record = records.append
    samples = samples if isinstance(samples, Sequence) else list(samples)
    if plan is None:
        plan = runner.core.snapshot_plan(samples)  # all here: FusionCore.snapshot_plan
    elif len(plan) != len(samples):
        raise ReplayError(f"a plan of {len(plan)} samples for {len(samples)} samples")
    for s, keep in zip(samples, plan):
        runner.feed(s, keep)
    return runner.result()


def summary(result: ReplayResult) -> str:
    """The human summary printed at the end of a replay."""
    core = result.core
    out = []
    final = result.final
    if final is None:
        out.append("no sample was fused: check the sensor keys against the bag's topics")
    elif result.poses == 0:
        out.append(f"no pose published: {core.not_ready_reason or 'no odometry message was fused'}")
    else:
        t, x, y, z, qx, qy, qz, qw = final
        r, p, yaw = to_rpy((qx, qy, qz, qw))
        out.append(f"final pose  t={t:.3f}  x={x:.4f} y={y:.4f} z={z:.4f}  roll={r:.4f} pitch={p:.4f} yaw={yaw:.4f}")
    rate = result.messages / result.seconds if result.seconds > 0 else float("nan")
    out.append(f"messages    {result.messages} in {result.seconds:.3f} s ({rate:,.0f} msg/s), {result.poses} poses")
    if result.missing:
        out.append(f"missing     no bag topic for sensor(s): {', '.join(result.missing)}")
    if result.decode_errors:
        out.append(f"undecodable {result.decode_errors} message(s) skipped")
    for s, st in zip(core.sensors, core.stats):
        dropped = ", ".join(f"{k}={v}" for k, v in sorted(st.dropped.items())) or "none"
        out.append(
            f"sensor {s.name:<10} received={st.received} applied={st.applied} late={st.late} "
            f"rejected={st.rejected} dropped: {dropped}"
        )
    for s, model in zip(core.sensors, core.models):
        thinned = getattr(model, "thinned", 0)
        if thinned:
            out.append(f"sensor {s.name:<10} orientation of {thinned} sample(s) not fused: above "
                       f"orientation_rate_hz = {s.orientation_rate_hz:g} (their gyro was)")
    bias = core.gyro_bias
    if bias is not None:
        out.append("gyro bias   [" + ", ".join(f"{b:+.5f}" for b in bias) + "] rad/s")
    learned = _learned(core, keys=True)
    if learned:
        out.append("estimated   " + "  ".join(f"{k}={v:.4f}" for k, v in learned.items()))
    for sensor, key, why in core.idle_keys:
        out.append(f"no effect   {sensor}.{key}: {why}")
    for name, c in result.doctor.channel_summaries().items():
        mean = "n/a" if c["nis_mean"] is None else f"{c['nis_mean']:.3f}"
        if c.get("nis_per_dof") is not None and c["nis_mean"] is not None:  # the figure the verdicts quote
            mean += f" ({c['nis_per_dof']:.2f} per dof)"
        bounds = "" if not c["nis_bounds"] else f" bounds [{c['nis_bounds'][0]:.2f}, {c['nis_bounds'][1]:.2f}]"
        now = f"; {c['now_note']}" if c["now_note"] else ""
        out.append(f"NIS {name:<22} whole run mean={mean} dof={c['dof']}{bounds} -> {c['verdict']} "
                   f"({c['updates']} updates, {c['rejected']} rejected{now})")
    if not core.tilt_reference:
        out.append("tilt        no tilt reference (no IMU roll/pitch, no accelerometer, no absolute pose): "
                   "taken as planar, roll/pitch rates not integrated")
    held_dropped = sum(st.dropped.get("future_stamp", 0) + st.dropped.get("stale_stamp", 0) for st in core.stats)
    if held_dropped:
        out.append(f"time jumps  {held_dropped} sample(s) far from filter time dropped as a clock glitch")
    if core.resets:
        out.append(f"time jumps  {core.resets} filter reset(s) on a backwards time jump")
    if core.covariance_resets:
        out.append(f"covariance  {core.covariance_resets} reset(s) after a non-finite value")
    from ..doctor import format_verdicts

    out.append(format_verdicts(result.verdicts()))
    return "\n".join(out)
