"""The per-channel checks: each channel judged on its own innovations.

Every channel with updates is judged by exactly one check, picked by ``channel_kind`` (an IMU's
orientation, the wheels' yaw rate, the gyro at rest, the GPS's special channels, an absolute
position or pose; any other by its NIS alone). What they find may later be explained by a
cross-source finding (``blame``): a channel's NIS is high because another source is wrong.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

from ..config import Config, OdomSensor
from ..core.sensors.registry import kind_of
from .channels import (absolute_verdict, applied_verdict, figures, frozen_verdict, gated_out, nis_head,
                       orientation_verdicts, reacquired_verdict, unaligned_verdict, yaw_jump_verdict)
from .evidence import Evidence
from .gps_wander import gps_wander_verdict
from .gyro import bias_check
from .nis import ChannelStats
from .series import Series
from .thresholds import UNALIGNED_MIN_FIXES
from .twist import slip_verdict
from .verdict import Verdict

__all__ = ["ABSOLUTE_CHANNELS", "channel_kind", "OrientationNis", "YawRateSlip", "GyroBiasAtRest", "YawJumps",
           "Reacquired", "Frozen", "Unaligned", "AbsoluteNis", "GpsWander", "ChannelNis"]

ABSOLUTE_CHANNELS = ("position", "position_unaligned", "position_provisional", "altitude", "pose", "pose_delta")


def _geodetic(s: object | None) -> bool:
    """Is ``s`` a configured sensor whose fixes are geodetic (a GPS: its re-acquisitions, its heading search)?"""
    return s is not None and kind_of(s).geodetic


def channel_kind(ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> str:
    """Which check judges channel ``key``: the ``kind`` of one of the checks below."""
    name, channel = key
    s = ev.sensors.get(name)
    if channel in ("orientation", "yaw_rate", "gyro_bias", "yaw_jump"):
        return channel
    if channel == "position_reacquired" and _geodetic(s):
        return "reacquired"
    if channel == "position_frozen":
        return "frozen"
    if (channel == "position_unaligned" and _geodetic(s) and ch.n >= UNALIGNED_MIN_FIXES
            and not any(n == name and c in ("position", "position_provisional", "position_reacquired") and c_.n
                        for (n, c), c_ in ev.channels.items())):
        # a heading never found is worth a verdict of its own only when no fix was ever judged
        return "unaligned"
    if channel in ABSOLUTE_CHANNELS:
        return "absolute"
    return "nis"


class _PerChannel(ABC):
    """A check run once per channel of its ``kind`` (sorted by sensor and channel); what it finds is filed
    under that channel."""

    name = ""
    kind = ""
    group = "channel"
    needs: tuple[str, ...] = ()
    listed_after: tuple[str, ...] = ()
    needs_config = False  # a channel's innovations are judged without the config (a remote monitor)

    def run(self, ev: Evidence) -> list[Verdict]:
        out: list[Verdict] = []
        for key, ch in ev.active():
            if channel_kind(ev, key, ch) == self.kind:
                for v in self.judge(ev, key, ch):
                    ev.findings.file(v, key)
                    out.append(v)
        return out

    @abstractmethod
    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The findings on channel ``key`` (its statistics ``ch``)."""


class OrientationNis(_PerChannel):
    """An IMU's orientation innovations. A yaw the heading cross-check found following the gyro is not a
    disturbed one, whatever its NIS: that check's wander figure is passed on."""

    name = kind = "orientation"
    needs = ("heading",)

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        heading = ev.findings.first("heading")
        agrees = (heading.evidence.get("imu_vs_gyro_wander_rad")
                  if heading is not None and heading.sensor == key[0] and heading.level == "ok" else None)
        return orientation_verdicts(ev.channel_imu(key), ch, ev.t0,
                                    agrees if agrees is not None and math.isfinite(agrees) else None)


class YawRateSlip(_PerChannel):
    """The wheels' yaw rate against the gyro (slip); not judged when the driver does not measure it."""

    name = "slip"
    kind = "yaw_rate"
    needs = ("unmeasured_yaw_rate",)

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        if ev.findings.first("unmeasured_yaw_rate") is not None:
            return []
        s = ev.sensors.get(key[0])
        odom = s if s is not None and kind_of(s).drives_prediction else OdomSensor(name=key[0], key=key[0])
        return [slip_verdict(odom, ch, ev.wheel_yaw, ev.odom_floored)]


class GyroBiasAtRest(_PerChannel):
    """The gyro at the standstills: the cross-source verdict when there is one, else the channel's own."""

    name = kind = "gyro_bias"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        v = ev.bias_verdict(key)
        if v is None:
            v = bias_check(Series(), Config(sensors=[ev.channel_imu(key)]), ch, True) or Verdict(
                key[0], key[1], "ok", f"consistent ({figures(ch, ev.t0)})")
        return [v]


class YawJumps(_PerChannel):
    """Absolute yaw readings the jump gate kept out, against the orientation samples."""

    name = kind = "yaw_jump"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        return [yaw_jump_verdict(key[0], ch, ev.channels.get((key[0], "orientation")))]


class Reacquired(_PerChannel):
    """A GPS the filter lost and found again."""

    name = kind = "reacquired"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        return [reacquired_verdict(key[0], ch, ev.series.odom_gaps if ev.known else None)]


class Frozen(_PerChannel):
    """Fixes repeated unchanged (a receiver holding its last position)."""

    name = kind = "frozen"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        return [frozen_verdict(key[0], ch, sum(c.n for (n, _), c in ev.channels.items() if n == key[0]))]


class Unaligned(_PerChannel):
    """A GPS whose heading was never found: every fix fused as position only."""

    name = kind = "unaligned"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        return [unaligned_verdict(ev.sensors[key[0]], ch, ev.channels.get((key[0], "altitude")))]


def _up(ev: Evidence, key: tuple[str, str]) -> ChannelStats | None:
    """A GPS fix's horizontal and vertical are two blocks (two channels): a paste line of position_noise
    takes its up from the altitude channel."""
    return ev.channels.get((key[0], "altitude")) if key[1] != "altitude" else None


class AbsoluteNis(_PerChannel):
    """GPS and pose channels: NIS against the stated noise."""

    name = kind = "absolute"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        return [absolute_verdict(key[0], key[1], ch, ev.t0, _up(ev, key))]


class GpsWander(_PerChannel):
    """A wandering receiver error, which reads as NIS low (the filter follows it): a candidate finding for
    a GPS position channel whose applied updates are not too many gated and read low or consistent. It
    replaces the channel's NIS finding only where the blame rules say so."""

    name = "gps_wander"
    kind = "absolute"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        s = ev.sensors.get(key[0])
        if key[1] != "position" or not _geodetic(s) or gated_out(ch):
            return []
        if applied_verdict(ch) not in ("nis_low", "ok"):
            return []
        wander = gps_wander_verdict(s, ch, f"{nis_head(ch, ev.t0)}: ", _up(ev, key))
        return [] if wander is None else [wander]


class ChannelNis(_PerChannel):
    """Any other channel: its NIS verdict, a warning unless consistent."""

    name = kind = "nis"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        verdict = ch.verdict()
        return [Verdict(key[0], key[1], "ok" if verdict == "ok" else "warn", f"{verdict} ({figures(ch, ev.t0)})")]
