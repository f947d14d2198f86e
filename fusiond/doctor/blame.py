"""Who is to blame: a small table of rules over the checks' findings.

When one source is wrong the filter follows it and the others look wrong too (a disturbed
magnetometer yaw makes the GPS look bad). A finding that is not ok only because another one is
wrong says so, points at that one's config key, and advises nothing of its own: pasting its own
line would write a second error into the config. Each rule names the checks whose findings it
may explain, how it finds the culprit for one of them (on typed fields: the check that found it,
the level, the sensor, the evidence), and what the explained finding becomes. They run in the
table's order, each over the findings as the rules before it left them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import msgspec

from ..config import ImuSensor
from .channels import applied_verdict, figures
from .evidence import Evidence
from .mounting import MountYaw
from .nis import ChannelStats
from .checks.heading import TRACK_OFFSET_RAD
from .verdict import Verdict, sensor_key

__all__ = ["ANY_CHECK", "Entry", "Rule", "RULES", "CULPRITS", "CANDIDATES", "apply_rules"]

Key = tuple[str, str]

# Whose wrong finding explains the other channels' (the first that applies): a gyro in the wrong unit; a body-frame twist read as
# a world one sends the dead reckoning sideways, and every check that compares against the wheels'
# motion reads it; else the first cross-source check that is not ok. (check, the levels that blame)
CULPRITS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("gyro_units", ("problem",)),  # a gyro in deg/s: every figure that reads the gyro is 57 times off
    ("twist_frame", ("problem",)),
    ("heading", ("warn", "problem")),
    ("wheel_heading", ("warn", "problem")),
    ("speed", ("warn", "problem")),
)

# checks whose findings are candidates only: a rule puts one in another's place, or it is not shown
CANDIDATES = frozenset({"gps_wander"})


@dataclass
class Entry:
    """A finding, the check that made it, and the slot it is filed under (its channel's for a channel
    check, else its own sensor/channel); ``verdict`` None: a rule dropped it."""

    check: str
    key: Key
    verdict: Verdict | None


class Blame:
    """The findings the rules work on, and the culprits they look up."""

    def __init__(self, ev: Evidence, entries: list[Entry]) -> None:
        self.ev = ev
        self.entries = entries

    def first(self, check: str) -> Verdict | None:
        return next((e.verdict for e in self.entries if e.check == check and e.verdict is not None), None)

    def filed(self, key: Key) -> list[Verdict]:
        return [e.verdict for e in self.entries if e.key == key and e.verdict is not None]

    def stats(self, v: Verdict, channel: str | None = None) -> ChannelStats:
        return self.ev.channels[(v.sensor, channel or v.channel)]

    @cached_property
    def culprit(self) -> Verdict | None:
        """The finding that explains the others (``CULPRITS``); looked up once, when a rule first asks."""
        for check, levels in CULPRITS:
            v = self.first(check)
            if v is not None and v.level in levels:
                return v
        return None

    def wrong_frame(self, v: Verdict) -> Verdict | None:
        frame = self.first("twist_frame")
        return frame if frame is not None and frame.level == "problem" else None

    def lever_for(self, v: Verdict) -> Verdict | None:
        """The lever-arm finding that explains ``v``, a GPS's position channel, when it is not ok."""
        lever = self.first("lever")
        if lever is not None and lever.level != "ok" and lever.sensor == v.sensor and v.channel == "position":
            return lever
        return None

    def culprit_explains(self, v: Verdict) -> bool:
        """An absolute channel's NIS finding that the culprit explains (a NIS low is the filter following a
        wrong source less, not more: the culprit does not explain it)."""
        return (self.culprit is not None and self.lever_for(v) is None and v.level != "ok"
                and applied_verdict(self.stats(v)) != "nis_low")

    @cached_property
    def bias_problem(self) -> Verdict | None:
        """The first gyro-bias finding that is a problem (by slot, in the order the slots were filled)."""
        slots: dict[Key, list[Verdict]] = {}
        for e in self.entries:
            slots.setdefault(e.key, [])
            if e.verdict is not None:
                slots[e.key].append(e.verdict)
        return next((v for (_, c), vs in slots.items() if c == "gyro_bias" for v in vs if v.level == "problem"),
                    None)


def blamed(v: Verdict, culprit: Verdict) -> Verdict:
    """A cross-source verdict that is not ok only because ``culprit`` is wrong: it says so, and names the
    culprit's key instead of its own (pasting its own would write a second error into the config)."""
    if v.level == "ok":
        return v
    return msgspec.structs.replace(v, level="warn", message=v.message + f"; explained by {culprit.sensor}/"
                                   f"{culprit.channel} (see it): fix that first", key=culprit.key, suggestion="")


def explained(v: Verdict, culprit: Verdict, ch: ChannelStats, t0: float | None) -> Verdict:
    """A channel whose NIS is high because another source is wrong: point there, advise nothing here."""
    head = f"NIS {ch.verdict().removeprefix('nis_')} ({figures(ch, t0)})"
    if ch.rejected:
        head += f", {ch.rejected} gated"
    return Verdict(v.sensor, v.channel, "warn",
                   f"{head}: explained by {culprit.sensor}/{culprit.channel} (see it), not by this sensor's noise; "
                   "fix that first", culprit.key, evidence=v.evidence)


def mount_explains_offset(heading: Verdict, mount: MountYaw, imu: ImuSensor | None) -> Verdict:
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


def _is_mount_fix(v: Verdict) -> bool:
    """The orientation finding of a roll/pitch offset in the innovations: its fix is the mounting."""
    return v.key.endswith("extrinsic_rpy")


def _contradicted(b: Blame, v: Verdict) -> Verdict | None:
    heading = b.first("heading")
    return heading if heading is not None and heading.sensor == v.sensor and heading.level != "ok" else None


def _own_nis(b: Blame, v: Verdict) -> ChannelStats | None:
    ch = b.ev.channels.get((v.sensor, "orientation"))
    return ch if v.level != "ok" and ch is not None and ch.n else None


def _orientation_culprit(b: Blame, v: Verdict) -> Verdict | None:
    if v.level == "ok" or _is_mount_fix(v) or b.stats(v).verdict() != "nis_high":
        return None
    return b.culprit


def _wander_in_place(b: Blame, v: Verdict) -> Verdict | None:
    """The wander candidate filed under ``v``'s channel, when the lever and the culprit explain nothing there
    and the NIS is low (or consistent, with no culprit whose errors the innovations may carry)."""
    if b.lever_for(v) is not None or b.culprit_explains(v):
        return None
    if applied_verdict(b.stats(v)) != "nis_low" and b.culprit is not None:
        return None
    return next((e.verdict for e in b.entries if e.check == "gps_wander" and e.key == (v.sensor, v.channel)
                 and e.verdict is not None), None)


def _with_caveat(b: Blame, v: Verdict, wander: Verdict) -> Verdict:
    c = b.culprit
    if c is None:
        return wander
    return msgspec.structs.replace(wander, message=wander.message + f"; {c.sensor}/{c.channel} is wrong too (see it) "
                                   "and may carry part of this: fix it first, then replay to confirm")


def _inverted_imu(b: Blame, v: Verdict) -> Verdict | None:
    imu, odom = b.ev.run_imu, b.ev.odom
    if not b.ev.known or imu is None or odom is None or v.level == "ok" or (v.sensor, v.channel) != (odom.name,
                                                                                                    "yaw_rate"):
        return None
    return next((a for a in b.filed((imu.name, "attitude")) if a.evidence.get("inverted")), None)


def _climb(b: Blame, v: Verdict) -> Verdict | None:
    """The IMU's attitude verdict whose climb the GPS's vertical error state could not hold (``checks/lean``):
    what a GPS altitude channel that is not ok shows (its fixes gated as the height leaves them)."""
    if v.channel != "altitude" or v.level == "ok":
        return None
    return next((a for e in b.entries if e.verdict is not None and (a := e.verdict).channel == "attitude"
                 and "unmodelled_climb_m" in a.evidence), None)


def _gaps_advice(b: Blame, v: Verdict) -> Verdict | None:
    if v.suggestion:
        return None
    return next((g for g in b.filed((v.sensor, "heading_across_gaps")) if g.suggestion), None)


ANY_CHECK = ("*",)  # a rule's ``explains`` for the findings of every check


@dataclass(frozen=True)
class Rule:
    """``culprit(blame, finding)``: what explains the finding (None: the rule does not apply to it);
    ``effect(blame, finding, culprit)``: the finding explained (None: dropped, it is evidence of nothing)."""

    explains: tuple[str, ...]  # the checks whose findings the rule may rewrite
    culprit: Callable[[Blame, Verdict], Any]
    effect: Callable[[Blame, Verdict, Any], Verdict | None]
    why: str


def _units(b: Blame, v: Verdict) -> Verdict | None:
    """The gyro-units problem (``checks/gyro_units``) for any other finding that is not ok."""
    if v.level == "ok" or v.channel == "units":
        return None
    return b.first("gyro_units")


def _explained_by_units(v: Verdict, units: Verdict) -> Verdict:
    return Verdict(v.sensor, v.channel, "warn", v.message + f": explained by {units.sensor}/units (see it): a gyro "
                   "in deg/s puts everything that reads it 57 times off; fix that first", evidence=v.evidence)


def _pose_only(b: Blame, v: Verdict) -> Verdict | None:
    """The pose-only odometry problem (``checks/pose_only``) for any other finding that is not ok."""
    if v.level == "ok":
        return None
    culprit = b.first("pose_only")
    return culprit if culprit is not None and culprit is not v else None


def _explained_by_pose_only(v: Verdict, culprit: Verdict) -> Verdict:
    return Verdict(v.sensor, v.channel, "warn", v.message + f": explained by {culprit.sensor}/{culprit.channel} (see "
                   "it): the filter took the robot as standing all run, so nothing compared with its motion reads "
                   "right; fix that first", culprit.key, evidence=v.evidence)


RULES: tuple[Rule, ...] = (
    Rule(ANY_CHECK, _units, lambda b, v, units: _explained_by_units(v, units),
         "a gyro in deg/s explains every other finding: nothing it drives or is compared with reads right"),
    Rule(ANY_CHECK, _pose_only, lambda b, v, culprit: _explained_by_pose_only(v, culprit),
         "an odometry whose driver fills the pose only keeps the filter's robot standing: every finding that "
         "reads its motion is that"),
    Rule(("heading",), lambda b, v: b.ev.mount, lambda b, v, mount: mount_explains_offset(v, mount, b.ev.imu),
         "an IMU yaw off the GPS track by the accelerometer's mounting yaw is that mounting, not a declination"),
    Rule(("speed", "mounting"), Blame.wrong_frame, lambda b, v, frame: blamed(v, frame),
         "a body-frame twist read as a world one sends the wheels' motion sideways: not the wheel scale, not "
         "the IMU's mounting"),
    Rule(("heading",), _own_nis,
         lambda b, v, ch: msgspec.structs.replace(v, message=v.message + f" (its own NIS: {figures(ch, b.ev.t0)})"),
         "an IMU yaw the other sources contradict quotes its own NIS beside the verdict"),
    Rule(("orientation",), _contradicted, lambda b, v, heading: v if _is_mount_fix(v) else None,
         "an IMU yaw the other sources contradict: no advice to trust it more, and its NIS (the filter follows "
         "it) is evidence of nothing"),
    Rule(("orientation",), _orientation_culprit, lambda b, v, c: explained(v, c, b.stats(v), b.ev.t0),
         "a wrong source explains the IMU orientation's high NIS"),
    Rule(("gyro_bias",), lambda b, v: b.culprit if v.evidence.get("bias_moved") else None,
         lambda b, v, c: Verdict(v.sensor, v.channel, v.level, v.message + f": explained by {c.sensor}/"
                                 f"{c.channel} (see it)", c.key, evidence=v.evidence),
         "a wrong source explains a gyro bias that moved"),
    Rule(("absolute",), Blame.lever_for,
         lambda b, v, lever: explained(v, lever, b.stats(v), b.ev.t0) if v.level != "ok" else v,
         "an unstated lever swings the fixes as the vehicle turns: what the GPS position's NIS shows"),
    Rule(("absolute",), lambda b, v: b.culprit if b.culprit_explains(v) else None,
         lambda b, v, c: explained(v, c, b.stats(v), b.ev.t0),
         "a wrong source explains an absolute channel's NIS"),
    Rule(("absolute",), _climb, lambda b, v, c: explained(v, c, b.stats(v), b.ev.t0),
         "a mount's climb the vertical error state could not hold puts the altitude's fixes out of its gate: "
         "not their noise, not the gate"),
    Rule(("absolute",), _wander_in_place, _with_caveat,
         "a wandering receiver error reads as NIS low (the filter follows it): not \"lower position_noise\""),
    Rule(("unmeasured_yaw_rate", "slip"), _inverted_imu,
         lambda b, v, a: msgspec.structs.replace(
             v, message=v.message + f"; explained by {a.sensor}/attitude: the IMU is mounted upside down, so its z "
             "rate reads against the wheels' (see it)", key=sensor_key(a.sensor, "extrinsic_rpy"), suggestion=""),
         "an upside-down IMU's z rate reads against the wheels' yaw rate: not slip"),
    Rule(("late_bias",), _gaps_advice,
         lambda b, v, g: msgspec.structs.replace(
             v, message=v.message + "; but across the logging gaps the IMU's yaw is what holds the heading: see "
             f"{v.sensor}/heading_across_gaps"),
         "a late bias's drift alone not worth the IMU's yaw: across the logging gaps it is"),
    Rule(("unmeasured_yaw_rate", "slip"), lambda b, v: b.bias_problem if "mean_rad_s" in v.evidence else None,
         lambda b, v, c: Verdict(v.sensor, v.channel, "warn", v.message + f": explained by {c.sensor}/gyro_bias "
                                 "(see it)", c.key, evidence=v.evidence),
         "a wrong gyro bias (a false standstill it learned from) shows as a wheel-vs-gyro offset too"),
)


def apply_rules(ev: Evidence, entries: list[Entry]) -> list[Entry]:
    """The findings as the rules leave them: explained, dropped, candidates put in place or left out."""
    b = Blame(ev, entries)
    for rule in RULES:
        for e in entries:
            if e.verdict is None or (rule.explains != ANY_CHECK and e.check not in rule.explains):
                continue
            culprit = rule.culprit(b, e.verdict)
            if culprit is not None:
                e.verdict = rule.effect(b, e.verdict, culprit)
    return [e for e in entries if e.verdict is not None and e.check not in CANDIDATES]
