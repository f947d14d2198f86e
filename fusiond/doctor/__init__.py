"""The tuning doctor: what the sources say about each other, turned into one verdict per channel.

It encodes the table a practitioner tunes an EKF with, but NIS alone points the
wrong way when one source is wrong and the filter follows it (a disturbed
magnetometer yaw makes the GPS look bad). So besides the innovation statistics the
doctor compares the sources on the quantities they share (heading, speed, the gyro
at rest; see ``heading``, ``speed``, ``gyro``, ``twist``) and names the one that
disagrees with the others, with what it measured and the config key to change. It
never advises trusting a sensor more while another source contradicts it.

A floor above the fusion core: the core never imports it (its diagnostics records are all the
doctor reads of it), and only the commands that show verdicts do (replay, tune's advice, monitor).

Pure: no I/O. It is fed diagnostics records, samples and estimates (the replay has
them all; the live monitor only the diagnostics stream) and returns
:class:`Verdict` structs that the replay summary, the report and the monitor print.
"""

from __future__ import annotations

import math
from collections import defaultdict

import msgspec

from ..config import Config, GpsSensor, ImuSensor, OdomSensor
from ..samples import OdomSample
from ..core.layout import state_layout
from ..core.sensors.odom import body_twist
from .attitude import TiltStats, lean_verdict, mount_verdict
from .grade import grade_fit, grade_verdict
from .channels import (absolute_verdict, applied_verdict, figures, frozen_verdict, nis_head, orientation_verdicts,
                       reacquired_verdict, unaligned_verdict, yaw_jump_verdict)
from .clock import ClockOffsets, clock_verdicts
from .coast import coast_verdict
from .covariance import cap_verdict
from .gap_heading import gap_heading_verdict
from .gps_wander import gps_wander_verdict
from .gyro import bias_check, quiet_episodes
from .heading import heading_check, wheel_heading_check, wheel_yaw_fit
from .late_bias import late_bias_verdict
from .lever import lever_verdict
from .lost import LostSamples
from .mounting import MountYaw, mount_yaw_fit
from .nis import ChannelStats, judge_nis, nis_bounds
from .series import Series, SeriesCollector
from .speed import speed_check
from .twist import TwistStats, slip_verdict, twist_frame_verdict, unmeasured_yaw_rate, yaw_rate_not_measured
from .verdict import LEVELS, Proof, Verdict, filter_key, format_verdicts, sensor_key
from .thresholds import MIN_UPDATES, TRACK_OFFSET_RAD, UNALIGNED_MIN_FIXES

__all__ = ["Doctor", "Proof", "Verdict", "Series", "SeriesCollector", "ChannelStats", "diagnose", "format_verdicts",
           "judge_nis", "nis_bounds", "sensor_key", "filter_key"]

ABSOLUTE_CHANNELS = ("position", "position_unaligned", "position_provisional", "altitude", "pose", "pose_delta")
# channels whose every update is kept (stamp, rejected, innovation): the standstill episodes, and the
# GPS innovations whose autocorrelation tells a wandering receiver error from white noise
KEPT_CHANNELS = ("gyro_bias", "position", "altitude")
GATE_CHANNELS = ("yaw_jump",)  # every record is a reading its gate kept out: no NIS test (ChannelStats.judged)
CHUNK = 4096  # records or samples noted before they are folded into the statistics (bounded memory)


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
        self._stamp_offset = {s.name: s.stamp_offset_s for s in self.cfg.sensors if s.stamp_offset_s}
        self._world_twist = {s.name for s in self.cfg.sensors if isinstance(s, OdomSensor) and s.twist_frame == "world"}

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
                  orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> None:
        """The twist of an accepted odometry message (and the message's own pose orientation)."""
        self.twist.add(linear, angular, orientation)

    def add_orientation(self, q: tuple[float, float, float, float]) -> None:
        """The estimate's attitude (x, y, z, w) at a published pose."""
        self.tilt.add_orientation(q)

    def add_sample(self, sample) -> None:
        """A raw sample, as the sensor sent it (for the cross-source series), in arrival order; a lost
        one (``lost.LostSamples``) is left out. Its stamp is shifted by the sensor's ``stamp_offset_s``, as
        the core shifts it: the sources are compared at the instants the filter takes them for."""
        offset = self._stamp_offset.get(sample.sensor)
        if offset:
            sample = msgspec.structs.replace(sample, stamp=sample.stamp + offset)
        if sample.sensor in self._world_twist and type(sample) is OdomSample:
            body = body_twist(sample)  # the twist as the core takes it: turned into the body by the message's pose
            if body is not None:
                sample = msgspec.structs.replace(sample, linear=body[0], angular=body[1])
        for s in self.lost.admit(sample):
            self._note_sample(s)

    def _note_sample(self, sample) -> None:
        samples = self._samples
        samples.append(sample)
        if self.collector is not None and (self.t0 is None or sample.stamp < self.t0):
            self.t0 = sample.stamp
        if len(samples) >= CHUNK:
            self._settle_samples()

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
        self._clocks.extend([s.sensor for s in samples], [s.stamp for s in samples])
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
        return diagnose(self.cfg if self.known else None, self.series(), self.channels, self.twist, self.tilt,
                        stats, at_cap, covariance_resets, scales, self.t0, self.clocks)


def _blamed(v: Verdict | None, culprit: Verdict) -> Verdict | None:
    """A cross-source verdict that is not ok only because ``culprit`` is wrong: it says so, and names the
    culprit's key instead of its own (pasting its own would write a second error into the config)."""
    if v is None or v.level == "ok":
        return v
    return msgspec.structs.replace(v, level="warn", message=v.message + f"; explained by {culprit.sensor}/"
                                   f"{culprit.channel} (see it): fix that first", key=culprit.key, suggestion="")


def _explained(v: Verdict, culprit: Verdict, ch: ChannelStats, t0: float | None) -> Verdict:
    """A channel whose NIS is high because another source is wrong: point there, advise nothing here."""
    head = f"NIS {ch.verdict().removeprefix('nis_')} ({figures(ch, t0)})"
    if ch.rejected:
        head += f", {ch.rejected} gated"
    return Verdict(v.sensor, v.channel, "warn",
                   f"{head}: explained by {culprit.sensor}/{culprit.channel} (see it), not by this sensor's noise; "
                   "fix that first", culprit.key, evidence=v.evidence)


def _mount_explains_offset(heading: Verdict, mount: MountYaw, imu: ImuSensor | None) -> Verdict:
    """An IMU yaw off the GPS track by the mounting yaw the accelerometer measures is that mounting, not a
    declination: one fix (extrinsic_rpy), never both (a yaw_offset on top of the corrected mount would
    turn the yaw back by as much). Beyond the mounting, what remains is the yaw_offset to state."""
    off = heading.evidence.get("imu_vs_gps_track_offset_rad")
    if not mount.named or off is None or not heading.key.endswith(".yaw_offset"):
        return heading
    se = math.hypot(heading.evidence.get("imu_vs_gps_track_offset_se_rad", 0.0), mount.se)
    rest = math.remainder(off - mount.delta, 2.0 * math.pi)
    mounting = f"the mounting yaw the accelerometer measures ({mount.delta:+.3f} rad, see {heading.sensor}/attitude)"
    if abs(rest) <= max(TRACK_OFFSET_RAD, 3.0 * se):
        return Verdict(heading.sensor, heading.channel, "warn",
                       f"the IMU's absolute yaw sits {off:+.3f} rad off the GPS track: that is {mounting}, not a "
                       "declination; set extrinsic_rpy there, not yaw_offset",
                       heading.key.rsplit(".", 1)[0] + ".extrinsic_rpy", evidence=heading.evidence)
    configured = getattr(imu, "yaw_offset", 0.0) if imu is not None else 0.0
    return Verdict(heading.sensor, heading.channel, heading.level,
                   heading.message + f"; {mounting} accounts for part of it, {rest:+.3f} rad remain: with "
                   "extrinsic_rpy corrected, the yaw_offset below", heading.key,
                   f"yaw_offset = {configured - rest:.4f}", heading.evidence | {"offset_beyond_mount_rad": rest})


def _merge(candidates: list[Verdict]) -> Verdict:
    """One verdict per channel: the most severe finding leads, the others are appended."""
    ranked = sorted(candidates, key=lambda v: -LEVELS.index(v.level))
    top = ranked[0]
    extra = [v.message for v in ranked[1:] if v.level != "ok" and v.message != top.message]
    if extra:
        top = Verdict(top.sensor, top.channel, top.level, top.message + "; also: " + "; ".join(extra), top.key,
                      top.suggestion, top.evidence)
    return top


def diagnose(cfg: Config | None, series: Series, channels: dict[tuple[str, str], ChannelStats],
             twist: TwistStats, tilt: TiltStats, stats: dict[str, dict] | None = None, at_cap: bool = False,
             covariance_resets: int = 0, scales: dict[str, float] | None = None,
             t0: float | None = None, clocks: ClockOffsets | None = None) -> list[Verdict]:
    """Every check, merged into one verdict per (sensor, channel). ``clocks``: the sensors' stamp offsets
    measured at arrival (the replay has them), to explain samples dropped as far from filter time."""
    known = cfg is not None
    cfg = cfg if cfg is not None else Config()
    sensors = {s.name: s for s in cfg.sensors}
    order = {s.name: i for i, s in enumerate(cfg.sensors)}
    found: dict[tuple[str, str], list[Verdict]] = defaultdict(list)
    odom = next((s for s in cfg.sensors if isinstance(s, OdomSensor)), None)
    gyro_fused = any(isinstance(s, ImuSensor) and s.angular_velocity for s in cfg.sensors)

    # cross-source checks first: they decide who is to blame
    imu = next((s for s in cfg.sensors if isinstance(s, ImuSensor)), None)
    mount = mount_yaw_fit(series, imu) if known else None
    heading = heading_check(series, cfg) if known else None
    if heading is not None and mount is not None:
        heading = _mount_explains_offset(heading, mount, imu)
    speed = speed_check(series, cfg, scales) if known else None
    unmeasured = unmeasured_yaw_rate(series, odom) if known and odom is not None else None
    no_yaw_rate = yaw_rate_not_measured(series, odom, imu, gyro_fused) if known and odom is not None else None
    wheel_heading = (wheel_heading_check(series, cfg) if known and unmeasured is None and no_yaw_rate is None
                     else None)
    culprit = next((v for v in (heading, wheel_heading, speed) if v is not None and v.level != "ok"), None)
    frame = twist_frame_verdict(odom, twist, MIN_UPDATES) if known and odom is not None else None
    # a body-frame twist read as a world one sends the dead reckoning sideways: every check that compares
    # against the wheels' motion (their speed along the GPS track, the IMU's mounting yaw) reads it, and
    # would otherwise blame the wheel scale or the IMU's mounting
    wrong_frame = frame if frame is not None and frame.level == "problem" else None
    if wrong_frame is not None:
        culprit = wrong_frame
        speed = _blamed(speed, wrong_frame)
    lever = lever_verdict(series, cfg) if known else None
    if lever is not None:
        found[(lever.sensor, lever.channel)].append(lever)
    if wheel_heading is not None:
        found[(wheel_heading.sensor, wheel_heading.channel)].append(wheel_heading)
    if no_yaw_rate is not None:
        found[(no_yaw_rate.sensor, no_yaw_rate.channel)].append(no_yaw_rate)
    if heading is not None:
        found[(heading.sensor, heading.channel)].append(heading)
    if speed is not None:
        found[(speed.sensor, speed.channel)].append(speed)
    if unmeasured is not None:
        found[(unmeasured.sensor, unmeasured.channel)].append(unmeasured)

    for (name, channel), ch in sorted(channels.items()):
        if ch.n == 0:
            continue
        s = sensors.get(name)
        if channel == "orientation":
            imu = s if isinstance(s, ImuSensor) else ImuSensor(
                name=name, key=name, orientation="absolute" if "yaw" in ch.components else "roll_pitch")
            # the heading cross-check found this IMU's yaw following the gyro: its NIS is not a disturbance
            agrees = (heading.evidence.get("imu_vs_gyro_wander_rad")
                      if heading is not None and heading.sensor == name and heading.level == "ok" else None)
            vs = orientation_verdicts(imu, ch, t0, agrees if agrees is not None and math.isfinite(agrees) else None)
            if heading is not None and heading.sensor == name and heading.level != "ok":
                # the IMU yaw is contradicted by the other sources: no advice to trust it more, and its
                # NIS (the filter follows it) is evidence of nothing
                vs = [v for v in vs if v.key.endswith("extrinsic_rpy")]
                heading.message += f" (its own NIS: {figures(ch, t0)})"
            elif culprit is not None and ch.verdict() == "nis_high":
                vs = [_explained(v, culprit, ch, t0) if v.level != "ok" and not v.key.endswith("extrinsic_rpy") else v
                      for v in vs]
            found[(name, channel)].extend(vs)
        elif channel == "yaw_rate":
            if unmeasured is None:
                o = s if isinstance(s, OdomSensor) else OdomSensor(name=name, key=name)
                floored = (series.odom_wz_floored, series.odom_wz_floored_sigma_sum / series.odom_wz_floored
                           if series.odom_wz_floored else math.nan)
                found[(name, channel)].append(slip_verdict(o, ch, wheel_yaw_fit(series) if known else None, floored))
        elif channel == "gyro_bias":
            v = bias_check(series, cfg, ch, gyro_fused) if known else None
            if v is None:
                imu = s if isinstance(s, ImuSensor) else ImuSensor(name=name, key=name, angular_velocity=True)
                v = bias_check(Series(), Config(sensors=[imu]), ch, True) or Verdict(
                    name, channel, "ok", f"consistent ({figures(ch, t0)})")
            if v.evidence.get("bias_moved") and culprit is not None:
                v = Verdict(v.sensor, v.channel, v.level, v.message + f": explained by {culprit.sensor}/"
                            f"{culprit.channel} (see it)", culprit.key, evidence=v.evidence)
            found[(name, channel)].append(v)
        elif channel == "yaw_jump":
            found[(name, channel)].append(yaw_jump_verdict(name, ch, channels.get((name, "orientation"))))
        elif channel == "position_reacquired" and isinstance(s, GpsSensor):
            found[(name, channel)].append(reacquired_verdict(name, ch))
        elif channel == "position_frozen":
            found[(name, channel)].append(frozen_verdict(name, ch, sum(c.n for (n, _), c in channels.items()
                                                                       if n == name)))
        elif (channel == "position_unaligned" and isinstance(s, GpsSensor) and ch.n >= UNALIGNED_MIN_FIXES
              and not any(n == name and c in ("position", "position_provisional", "position_reacquired") and c_.n
                          for (n, c), c_ in channels.items())):
            found[(name, channel)].append(unaligned_verdict(s, ch, channels.get((name, "altitude"))))
        elif channel in ABSOLUTE_CHANNELS:
            # a GPS fix's horizontal and vertical are two blocks (two channels): a paste line of
            # position_noise takes its up from the altitude channel
            up = channels.get((name, "altitude")) if channel != "altitude" else None
            v = absolute_verdict(name, channel, ch, t0, up)
            judged = applied_verdict(ch)  # the whole run's, or the applied updates' (module channels)
            if lever is not None and lever.level != "ok" and lever.sensor == name and channel == "position":
                # an unstated lever swings the fixes as the vehicle turns: what the NIS (or a wander) shows
                if v.level != "ok":
                    v = _explained(v, lever, ch, t0)
            elif culprit is not None and v.level != "ok" and judged != "nis_low":
                v = _explained(v, culprit, ch, t0)
            elif channel == "position" and isinstance(s, GpsSensor) and "gated" not in v.message and (
                    judged == "nis_low" or (culprit is None and judged == "ok")):
                # a wandering receiver error reads as NIS low (the filter follows it): not "lower position_noise".
                # With another source wrong (a culprit) its errors may be what the innovations carry: an ok
                # channel is then left alone, a NIS-low one gets the wander verdict with that caveat
                head = f"{nis_head(ch, t0)}: "
                wander = gps_wander_verdict(s, ch, head, up)
                if wander is not None and culprit is not None:
                    wander.message += (f"; {culprit.sensor}/{culprit.channel} is wrong too (see it) and may carry "
                                       "part of this: fix it first, then replay to confirm")
                v = wander or v
            found[(name, channel)].append(v)
        else:
            verdict = ch.verdict()
            level = "ok" if verdict == "ok" else "warn"
            found[(name, channel)].append(Verdict(name, channel, level, f"{verdict} ({figures(ch, t0)})"))

    if known:
        gb = channels.get(next(((n, c) for n, c in channels if c == "gyro_bias"), ("", "")))
        if gb is None:
            v = bias_check(series, cfg, None, gyro_fused)
            if v is not None:
                found[(v.sensor, v.channel)].append(v)
        mounted = mount_verdict(imu, mount, tilt, MIN_UPDATES)
        if wrong_frame is not None:
            mounted = _blamed(mounted, wrong_frame)
        # With a GPS altitude the grade is measured, so the lean against it replaces the lean check's
        # "on level ground"; without enough driving to tell, the lean check still speaks.
        grade = grade_fit(series, cfg)
        graded = grade_verdict(grade, imu, mount, state_layout(cfg).has("twist_pitch"))
        lean = graded if graded is not None else lean_verdict(tilt, imu, MIN_UPDATES, mount)
        for v in (lean, mounted):
            if v is not None:
                found[(v.sensor, v.channel)].append(v)
        if (imu is not None and odom is not None and (odom.name, "yaw_rate") in found
                and any(v.evidence.get("inverted") for v in found.get((imu.name, "attitude"), []))):
            # an upside-down IMU's z rate reads against the wheels' yaw rate: not slip
            found[(odom.name, "yaw_rate")] = [
                msgspec.structs.replace(v, message=v.message + f"; explained by {imu.name}/attitude: the IMU is mounted "
                                        "upside down, so its z rate reads against the wheels' (see it)",
                                        key=sensor_key(imu.name, "extrinsic_rpy"), suggestion="")
                if v.level != "ok" else v for v in found[(odom.name, "yaw_rate")]]
        v = gap_heading_verdict(series, cfg, imu, t0)
        if v is not None:
            found[(v.sensor, v.channel)].append(v)
        v = late_bias_verdict(series, cfg, gyro_fused, gb)
        if v is not None:
            gap = next((g for g in found.get((v.sensor, "heading_across_gaps"), []) if g.suggestion), None)
            if gap is not None and not v.suggestion:  # its drift alone was not worth it; the gaps decide
                v = msgspec.structs.replace(v, message=v.message + f"; but across the logging gaps the IMU's yaw is "
                                            f"what holds the heading: see {v.sensor}/heading_across_gaps")
            found[(v.sensor, v.channel)].append(v)
        if imu is not None:
            standstills, turning = quiet_episodes(series, cfg, imu)
            v = coast_verdict(series, cfg, mount, turning, standstills)
            if v is not None:
                found[(v.sensor, v.channel)].append(v)
        if frame is not None:
            found[(frame.sensor, frame.channel)].append(frame)
        standstill_updates = sum(ch.n for (n, c), ch in channels.items() if c == "gyro_bias")
        v = cap_verdict(series, cfg, at_cap, gyro_fused, standstill_updates)
        if v is not None:
            found[("filter", "covariance")].append(v)
    if stats:
        for v in _drops(stats, clocks) + (clock_verdicts(stats, clocks, sensors) if clocks is not None else []):
            found[(v.sensor, v.channel)].append(v)
    if covariance_resets:
        found[("filter", "covariance")].append(
            Verdict("filter", "covariance", "problem",
                    f"covariance went non-finite {covariance_resets} time(s) and was reset: Q too large, a time jump, "
                    "or a bad Jacobian; check the stamps and filter.process_noise", filter_key("process_noise")))
    # a wrong gyro bias (a false standstill it learned from) shows as a wheel-vs-gyro offset too
    bias_problem = next((v for (n, c), vs in found.items() if c == "gyro_bias" for v in vs if v.level == "problem"),
                        None)
    if bias_problem is not None:
        for (n, c), vs in found.items():
            if c == "yaw_rate":
                found[(n, c)] = [Verdict(v.sensor, c, "warn", v.message + f": explained by {bias_problem.sensor}/"
                                         "gyro_bias (see it)", bias_problem.key, evidence=v.evidence)
                                 if "mean_rad_s" in v.evidence else v for v in vs]
    keys = sorted(found, key=lambda k: (order.get(k[0], len(order)), k[0], k[1]))
    return [_merge(found[k]) for k in keys]


def _drops(stats: dict[str, dict], clocks: ClockOffsets | None = None) -> list[Verdict]:
    out = []
    for name, st in stats.items():
        received = max(st.get("received", 0), 1)
        dropped = st.get("dropped", {})
        old = dropped.get("too_old", 0)
        if old / received > 0.01:
            msg = (f"{old} samples ({100 * old / received:.1f}%) arrived older than the history: "
                   "their sensor's stamps lag more than filter.history_s")
            line = ""
            lag = clocks.lag(name) if clocks is not None else None
            if lag is not None and lag > 0.0:
                # the history must reach back over the lag of 99 % of the samples, with a fifth to spare
                line = f"history_s = {math.ceil(12.0 * lag) / 10.0:g}"
                msg += (f" (99% of them arrive within {lag:.2f} s of the other sensors' newest stamp). Each such "
                        "sample re-applies that much history; a lag this steady may be the sensor's clock (a stamp "
                        "set late or early), which a longer history only hides: check its driver's stamping")
            out.append(Verdict(name, "time", "warn", msg, filter_key("history_s"), line))
        bad = {k: v for k, v in dropped.items() if k != "too_old"}
        if bad:
            reasons = ", ".join(f"{k}={v}" for k, v in sorted(bad.items()))
            out.append(Verdict(name, "input", "warn", f"dropped samples: {reasons}"))
    return out
