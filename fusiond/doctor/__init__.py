"""The tuning doctor: what the sources say about each other, turned into one verdict per channel.

It encodes the table a practitioner tunes an EKF with, but NIS alone points the
wrong way when one source is wrong and the filter follows it (a disturbed
magnetometer yaw makes the GPS look bad). So besides the innovation statistics the
doctor compares the sources on the quantities they share (heading, speed, the gyro
at rest; see ``checks/heading``, ``checks/speed``, ``gyro``, ``twist``) and names the one that
disagrees with the others, with what it measured and the config key to change. It
never advises trusting a sensor more while another source contradicts it.

How it is built: every check is one class with one interface in its own module (``checks/``), with
the thresholds it decides by beside it, each with where it comes from; it runs on the run's shared
``evidence.Evidence`` and returns its findings as :class:`Verdict` structs. The registry derives the
order they run in from what each needs (``registry.CHECKS``); who is to blame when findings meet is
decided by the rule table in ``blame``.

A floor above the fusion core: the core never imports it (its diagnostics records are all the
doctor reads of it), and only the commands that show verdicts do (replay, tune's advice, monitor).

Pure: no I/O. It is fed diagnostics records, samples and estimates (the replay has
them all; the live monitor only the diagnostics stream) and returns
:class:`Verdict` structs that the replay summary, the report and the monitor print.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from operator import attrgetter

import msgspec

from ..config import Config
from ..errors import DoctorError
from ..core.sensors.registry import kind_of
from ..core.sensors import OdomSample
from ..core.sensors.odom import PoseDifferences, body_twist
from .attitude import TiltStats
from .blame import Entry, apply_rules
from .clock import ClockOffsets
from .evidence import Evidence
from .lost import LostSamples
from .nis import ChannelStats, judge_nis, nis_bounds
from .pose_motion import PoseMotion
from .check import run_check
from .registry import CHECKS
from .series import Series, SeriesCollector
from .twist import TwistStats
from .verdict import LEVELS, Proof, Verdict, filter_key, format_verdicts, sensor_key

__all__ = ["Doctor", "Evidence", "Proof", "SampleSide", "Verdict", "Series", "SeriesCollector", "ChannelStats",
           "diagnose", "format_verdicts", "judge_nis", "nis_bounds", "sensor_key", "filter_key"]

# channels whose every update is kept (stamp, rejected, innovation): the standstill episodes, the GPS
# innovations whose autocorrelation tells a wandering receiver error from white noise, and the receiver's
# steps (each fix's innovation is the step it took)
KEPT_CHANNELS = ("gyro_bias", "position", "altitude", "position_step")
GATE_CHANNELS = ("yaw_jump",)  # every record is a reading its gate kept out: no NIS test (ChannelStats.judged)
_SENSOR, _STAMP = attrgetter("sensor"), attrgetter("stamp")
CHUNK = 4096  # records or samples noted before they are folded into the statistics (bounded memory)


@dataclass
class SampleSide:
    """What a doctor fed only a run's samples (``Doctor.add_sample``, every one in arrival order) made of them,
    settled at their end: the part of a doctor that reads no filter output. Another doctor, fed the same run's
    records and estimates but none of its samples, ``adopt``s it, and is then the doctor fed both: a replay's
    reading child, which has the samples first, does this part beside the filter (``replay.read_ahead``)."""

    t0: float | None  # the earliest sample stamp (the records' earliest is the other doctor's)
    repeats: dict[str, int]
    lost: LostSamples
    clocks: ClockOffsets
    collector: SeriesCollector | None  # its series' sample streams (the estimates are the other doctor's)
    pose_motion: PoseMotion | None


class Doctor:
    """Accumulates what a run showed. ``cfg`` may be None (a remote monitor that only sees the
    diagnostics stream): sensors are then known by name only, an orientation channel's mode is
    read from its components, and the cross-source checks have no series to work on."""

    def __init__(self, cfg: Config | None, window: int | None = None, confidence: float | None = None) -> None:
        self.known = cfg is not None
        self.cfg = cfg if cfg is not None else Config()
        self.window = window or self.cfg.filter.nis_window
        self.confidence = confidence or self.cfg.filter.nis_confidence
        self._channels: dict[tuple[str, str], ChannelStats] = {}
        self.twist = TwistStats()
        self.tilt = TiltStats()
        self.collector = SeriesCollector(self.cfg) if self.known else None
        self._clocks = ClockOffsets()
        self.t0: float | None = None
        # Fed for every message of a replay, the doctor only notes what it is given; the records and the
        # samples are folded into the statistics a chunk at a time, and before anything is read.
        self._records: list = []
        self._samples: list = []
        self.lost = LostSamples()  # lost samples left out of the series (``add_sample``)
        # per sensor, messages that came twice, stamp and content alike (``add_sample``), and the newest of each
        self.repeats: dict[str, int] = {}
        self._newest: dict[str, object] = {}
        self._stamp_offset = {s.name: s.stamp_offset_s for s in self.cfg.sensors if s.stamp_offset_s}
        self._world_twist = {s.name for s in self.cfg.sensors if kind_of(s).drives_prediction
                             and s.twist_frame == "world" and not s.twist_from_pose}
        # a twist taken from the poses (twist_from_pose): the series see it as the core takes it, from their own
        # differences of the same messages in the same order
        self._from_pose = {s.name: PoseDifferences(self.cfg.filter.gap_s) for s in self.cfg.sensors
                           if kind_of(s).drives_prediction and s.twist_from_pose}
        # a differential pose sensor's deltas against the direction the wheels move in (its mount: ``pose_motion``)
        motion = PoseMotion(self.cfg.sensors)
        self.pose_motion: PoseMotion | None = motion if motion.sensors else None

    # -- feeding ---------------------------------------------------------------
    def add(self, record) -> None:
        """A diagnostics record."""
        records = self._records
        records.append(record)
        if self.t0 is None or record.stamp < self.t0:
            self.t0 = record.stamp
        if len(records) >= CHUNK:
            self._settle_records()

    def add_twist(self, linear: tuple[float, float, float], angular: tuple[float, float, float],
                  orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
                  position: tuple[float, float, float] = (0.0, 0.0, 0.0), stamp: float = math.nan) -> None:
        """The twist of an accepted odometry message, as its driver wrote it (and the message's own pose, and its
        stamp: how far that pose travels)."""
        self.twist.add(linear, angular, orientation, position, stamp)

    def add_orientation(self, q: tuple[float, float, float, float]) -> None:
        """The estimate's attitude (x, y, z, w) at a published pose."""
        self.tilt.add_orientation(q)

    def add_sample(self, sample) -> None:
        """A raw sample, as the sensor sent it (for the cross-source series), in arrival order; a lost
        one (``lost.LostSamples``) is left out. Its stamp is shifted by the sensor's ``stamp_offset_s``, as
        the core shifts it: the sources are compared at the instants the filter takes them for."""
        prev = self._newest.get(sample.sensor)
        if prev is not None and prev.stamp == sample.stamp and prev == sample:  # the same message again
            self.repeats[sample.sensor] = self.repeats.get(sample.sensor, 0) + 1
        self._newest[sample.sensor] = sample
        offset = self._stamp_offset.get(sample.sensor)
        if offset:
            sample = msgspec.structs.replace(sample, stamp=sample.stamp + offset)
        differences = self._from_pose.get(sample.sensor)
        if differences is not None and type(sample) is OdomSample:
            sample = differences(sample)
        if sample.sensor in self._world_twist and type(sample) is OdomSample:
            body = body_twist(sample)  # the twist as the core takes it: turned into the body by the message's pose
            if body is not None:
                sample = msgspec.structs.replace(sample, linear=body[0], angular=body[1])
        for s in self.lost.admit(sample):
            self._note_sample(s)
        if self.pose_motion is not None:
            self.pose_motion.add(sample)

    def _note_sample(self, sample) -> None:
        samples = self._samples
        samples.append(sample)
        if self.collector is not None and (self.t0 is None or sample.stamp < self.t0):
            self.t0 = sample.stamp
        if len(samples) >= CHUNK:
            self._settle_samples()

    def sample_side(self) -> SampleSide:
        """This doctor's sample part (``SampleSide``), settled as the run's end settles it (the last waiting
        frame judged lost, every sample folded into the series): ask once every sample has been added."""
        self.lost.flush()
        self._settle_samples()
        if self.collector is not None:
            self.collector.finish()
        return SampleSide(self.t0, self.repeats, self.lost, self._clocks, self.collector, self.pose_motion)

    def adopt(self, side: SampleSide) -> None:
        """Take ``side`` (``sample_side`` of a doctor with this config, fed every sample of this run) as this
        doctor's sample part: this one is fed the run's records, twists and estimates, and none of its samples.
        The verdicts are then those of one doctor fed all of it (the two parts share no state but the earliest
        stamp, a minimum; the series' sample streams and its estimates are separate fields)."""
        if self._samples or self._newest:
            raise DoctorError("a doctor fed samples cannot adopt another's: the run's samples would count twice")
        self.repeats, self.lost, self._clocks, self.pose_motion = side.repeats, side.lost, side.clocks, side.pose_motion
        if side.t0 is not None and (self.t0 is None or side.t0 < self.t0):
            self.t0 = side.t0
        if self.collector is not None and side.collector is not None:
            side.collector.take_estimates(self.collector)
            self.collector = side.collector

    def add_rest(self, sample, since: float) -> None:
        """An odometry sample the filter took at rest, since ``since`` (filter time). The standstills the gyro
        is judged over are then the filter's own, not only the bins reading exactly zero."""
        if self.collector is not None:
            self.collector.add_rest(sample.stamp + self._stamp_offset.get(sample.sensor, 0.0), since)

    def add_estimate(self, t: float, q, pos_var: float, att_var: float, bias_z: float) -> None:
        if self.collector is not None:
            self.collector.add_estimate(t, q, pos_var, att_var, bias_z)

    def wants_estimate(self, t: float) -> bool:
        return self.collector is not None and self.collector.wants_estimate(t)

    @property
    def channels(self) -> dict[tuple[str, str], ChannelStats]:
        """Per (sensor, channel), the whole run's statistics (every record fed so far)."""
        self._settle_records()
        return self._channels

    @property
    def clocks(self) -> ClockOffsets:
        """The sensors' stamp offsets at arrival (every sample fed so far)."""
        self._settle_samples()
        return self._clocks

    def _settle_records(self) -> None:
        if not self._records:
            return
        by_channel: dict[tuple[str, str], list] = {}
        for r in self._records:
            by_channel.setdefault((r.sensor, r.channel), []).append(r)
        self._records = []
        for key, records in by_channel.items():
            ch = self._channels.get(key)
            if ch is None:
                first = records[0]
                ch = self._channels[key] = ChannelStats(list(first.components), self.window, self.confidence,
                                                        keep=first.channel in KEPT_CHANNELS,
                                                        judged=first.channel not in GATE_CHANNELS)
            ch.extend(records)

    def _settle_samples(self) -> None:
        samples = self._samples
        if not samples:
            return
        self._samples = []
        self._clocks.extend(list(map(_SENSOR, samples)), list(map(_STAMP, samples)))
        if self.collector is not None:
            self.collector.extend(samples)

    # -- results ------------------------------------------------------------------
    def series(self) -> Series:
        self.lost.flush()
        self._settle_samples()
        return self.collector.finish() if self.collector is not None else Series()

    def channel_summaries(self) -> dict[str, dict]:
        """Whole-run NIS figures per channel (the summary's and the report's table)."""
        return {f"{s}/{c}": ch.summary(self.t0) for (s, c), ch in sorted(self.channels.items())}

    def verdicts(self, stats: dict[str, dict] | None = None, at_cap: bool = False, covariance_resets: int = 0,
                 scales: dict[str, float] | None = None) -> list[Verdict]:
        """``stats``: per sensor {"received", "applied", "late", "dropped": {reason: n}}."""
        return diagnose(Evidence(self.cfg if self.known else None, self.series(), self.channels, self.twist,
                                 self.tilt, stats=stats, at_cap=at_cap, covariance_resets=covariance_resets,
                                 scales=scales, t0=self.t0, clocks=self.clocks, repeats=self.repeats,
                                 pose_motion=self.pose_motion))


def _merge(candidates: list[Verdict]) -> Verdict:
    """One verdict per channel: the most severe finding leads, the others are appended."""
    ranked = sorted(candidates, key=lambda v: -LEVELS.index(v.level))
    top = ranked[0]
    extra = [v.message for v in ranked[1:] if v.level != "ok" and v.message != top.message]
    if extra:
        top = Verdict(top.sensor, top.channel, top.level, top.message + "; also: " + "; ".join(extra), top.key,
                      top.suggestion, top.evidence)
    return top


def diagnose(ev: Evidence) -> list[Verdict]:
    """Every check (``registry.CHECKS``, in order) on the run's evidence, the blame rules over what they
    found (``blame.RULES``), merged into one verdict per (sensor, channel)."""
    entries: list[Entry] = []
    for check in CHECKS:
        verdicts = run_check(check, ev)
        ev.findings.add(check.name, verdicts)
        entries.extend(Entry(check.name, ev.findings.slot(v), v) for v in verdicts)
    found: dict[tuple[str, str], list[Verdict]] = {}
    for e in apply_rules(ev, entries):
        found.setdefault(e.key, []).append(e.verdict)
    order = ev.order
    keys = sorted(found, key=lambda k: (order.get(k[0], len(order)), k[0], k[1]))
    return [_merge(found[k]) for k in keys]
