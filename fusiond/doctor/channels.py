"""What the per-channel checks share: which check judges a channel, how they run, and the NIS figures.

Every channel with updates is judged by exactly one check, picked by ``channel_kind`` (an IMU's
orientation, the wheels' yaw rate, the gyro at rest, the GPS's special channels, an absolute position or
pose; any other by its NIS alone); each such check is a :class:`PerChannel`, in ``checks/``. What they
find may later be explained by a cross-source finding (``blame``): a channel's NIS is high because
another source is wrong.
"""

from __future__ import annotations

import math
from abc import abstractmethod
from collections.abc import Callable

from ..core.sensors.registry import kind_of
from .check import BaseCheck
from .evidence import Evidence
from .nis import ChannelStats
from .verdict import Verdict

__all__ = ["ABSOLUTE_CHANNELS", "GATED_FRACTION", "PerChannel", "applied_verdict", "channel_kind", "figures",
           "gated_out", "geodetic", "gps_up", "innovations_below", "nis_head", "process_overstated"]

# gated beyond this: the sensor jumps, or its noise is understated (checks/absolute.py MOST_GATED tells which)
GATED_FRACTION = 0.1
UNALIGNED_MIN_FIXES = 50  # fixes before a heading never found is worth a verdict


ABSOLUTE_CHANNELS = ("position", "position_unaligned", "position_provisional", "altitude", "pose", "pose_delta")


def figures(ch: ChannelStats, t0: float | None) -> str:
    if ch.n and not ch.n_nis:  # every update was a learning one (e.g. the GPS heading search)
        return f"{ch.n} updates while the state was being learned, not judged against the stated noise"
    now = ch.now_note(t0)
    return f"{ch.nis_per_dof:.2f} per dof over {ch.n} updates" + (f"; {now}" if now else "")


def applied_verdict(ch: ChannelStats) -> str:
    """The channel's whole-run NIS verdict, judged on the applied updates when it is high only through the
    ones the gate rejected. Those were not fused, so they say nothing of the stated noise: a receiver that
    reported three fixes at 0, 0 (a NIS of 1e14 each) among thousands of good ones would otherwise read as
    noise stated too small, and advising a larger one would only blunt the gate. The applied ones are
    truncated by the gate, which lowers their mean only where the gate cuts into the distribution, where
    the gated fraction (GATED_FRACTION, judged first) speaks instead."""
    verdict = ch.verdict()
    if verdict == "nis_high" and ch.rejected and ch.kept_verdict() != "nis_high":
        return ch.kept_verdict()
    return verdict


def nis_head(ch: ChannelStats, t0: float | None) -> str:
    """'NIS high (figures)', and when the applied updates are judged apart, what the gate took out."""
    head = f"NIS {ch.verdict().removeprefix('nis_')} ({figures(ch, t0)})"
    if applied_verdict(ch) == ch.verdict():
        return head
    frac = ch.rejected / ch.n if ch.n else 0.0
    return (f"{head} only because of the {ch.rejected} update(s) the gate rejected ({100 * frac:.1f}%, not fused): "
            f"the {ch.n_nis_kept} applied ones read {ch.kept_nis_per_dof:.2f} per dof")


def gated_out(ch: ChannelStats) -> bool:
    """Whether the gate rejected more of the channel's judged updates than jumps explain (GATED_FRACTION):
    its verdict (``absolute_verdict``) is then about the gate, not the innovations of what was fused."""
    return bool(ch.n and ch.n_nis) and ch.rejected / ch.n > GATED_FRACTION


def geodetic(s: object | None) -> bool:
    """Is ``s`` a configured sensor whose fixes are geodetic (a GPS: its re-acquisitions, its heading search)?"""
    return s is not None and kind_of(s).geodetic


# the channels of a GPS's fixes fused once its heading was found (or a step or a loss was taken from them)
JUDGED_FIX_CHANNELS = ("position", "position_provisional", "position_reacquired", "position_step")


def channel_kind(ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> str:
    """Which check judges channel ``key``: the ``kind`` of one of the checks below."""
    name, channel = key
    s = ev.sensors.get(name)
    if channel in ("orientation", "yaw_rate", "gyro_bias", "yaw_jump"):
        return channel
    if channel == "position_reacquired" and geodetic(s):
        return "reacquired"
    if channel == "position_step" and geodetic(s):
        return "step"
    if channel == "position_frozen":
        return "frozen"
    if (channel == "position_unaligned" and geodetic(s) and ch.n >= UNALIGNED_MIN_FIXES
            and not any(n == name and c in JUDGED_FIX_CHANNELS and c_.n for (n, c), c_ in ev.channels.items())):
        # a heading never found is worth a verdict of its own only when no fix was ever judged
        return "unaligned"
    if channel in ABSOLUTE_CHANNELS:
        return "absolute"
    return "nis"


class PerChannel(BaseCheck):
    """A check run once per channel of its ``kind`` (sorted by sensor and channel); what it finds is filed
    under that channel."""

    kind = ""
    group = "channel"
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


def innovations_below(ch: ChannelStats, added: Callable[[float], float], axes: tuple[str, ...],
                      period: float = 0.0) -> tuple[str, float, float] | None:
    """(component, its innovation rms, the interval dt) where one of ``axes``' innovations is smaller than what one
    term of the model alone adds to the prediction's variance between two updates, ``added(dt)``: the prediction's
    variance at an update is at least that, before any sensor's noise or the state's own, so innovations below it
    cannot be explained by any R. Judged with the sample variance's own spread: below added(dt) (1 - 3 sqrt(2 / n))
    over n updates, a 3-sigma margin for a chi-square's mean. The interval is the median between the channel's
    updates where it keeps their stamps, else ``period``, the sensor's typical one (an update per sample at most:
    no longer than the updates' own interval, so the bound stays a bound); the component, of those below, the
    smallest rms. None otherwise."""
    if not ch.n_comp:
        return None
    ts = sorted(ch.stamps)
    gaps = sorted(b - a for a, b in zip(ts, ts[1:]) if b > a)
    dt = gaps[len(gaps) // 2] if gaps else period
    if not (0.0 < dt < math.inf):
        return None
    floor = added(dt) * (1.0 - 3.0 * math.sqrt(2.0 / ch.n_comp))
    below = [(c, ch.component(i)[1]) for i, c in enumerate(ch.components) if c in axes]
    below = [(c, r) for c, r in below if math.isfinite(r) and r * r < floor]
    if not below:
        return None
    c, rms = min(below, key=lambda cr: cr[1])
    return c, rms, dt


def process_overstated(ch: ChannelStats, q: float, axes: tuple[str, ...],
                       period: float = 0.0) -> tuple[str, float, float, float, float] | None:
    """(component, its innovation rms, the process noise's own rms over an update interval, that interval, the
    largest process noise the innovations allow) where one of ``axes``' innovations is smaller than the process
    noise ``q`` (per sqrt(s): filter.process_noise's position part for positions, attitude part for angles) alone
    adds to the prediction between two updates, q^2 dt on each axis (Q's block, isotropic, over the interval dt
    since the last update: ``innovations_below``). None otherwise."""
    if not (q > 0.0):
        return None
    found = innovations_below(ch, lambda dt: q * q * dt, axes, period)
    if found is None:
        return None
    c, rms, dt = found
    return c, rms, q * math.sqrt(dt), dt, rms / math.sqrt(dt)


def gps_up(ev: Evidence, key: tuple[str, str]) -> ChannelStats | None:
    """A GPS fix's horizontal and vertical are two blocks (two channels): a paste line of position_noise
    takes its up from the altitude channel."""
    return ev.channels.get((key[0], "altitude")) if key[1] != "altitude" else None
