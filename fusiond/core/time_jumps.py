"""Samples stamped far from filter time, held until their timeline is confirmed or left.

A stamp more than ``jump_s`` from filter time is either a clock glitch (a driver's
clock stepping for a few messages, an NTP step undone) or a new timeline (a bag
restarted, a clock reset, a long logging gap). Which one only the following
samples can tell: the far ones are held together as one cluster; the cluster is a
new timeline once it has ``confirm`` samples spanning ``persist_s`` of its own
stamps, and a glitch when the stream goes on along the old timeline first. The core
decides what each outcome does to the filter (reset, carry on, drop and count).

One sensor's clock is the filter's: the ``anchor``'s, the odometry's (it drives the prediction and
every published pose is stamped by it). A cluster that holds its samples is a glitch only when the
anchor itself goes on along the old timeline, and another sensor's far samples on yet another
timeline are dropped beside it rather than replacing it: an IMU stamped by its boot clock (46,000 s
behind, its first sample 10 ms before the odometry's) kept the old timeline going and every odometry
message and fix was dropped, nothing published; with the odometry first, its real 26 s logging gap was
never taken, the IMU's far samples replacing its cluster one by one. A sensor on a wrong clock is
dropped alone, and its doctor's verdict names the offset.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

Held = tuple[float, int, Any]  # (stamp, sensor index, converted input)


@dataclass(slots=True)
class Cluster:
    first: float  # the stamp that opened it
    lo: float = math.inf
    hi: float = -math.inf
    samples: list[Held] = field(default_factory=list)
    anchored: bool = False  # it holds samples of the anchor (the sensor whose clock the filter follows)

    def in_order(self) -> list[Held]:
        """The held samples in (stamp, sensor) order, as the history orders events."""
        return sorted(self.samples, key=lambda e: (e[0], e[1]))


class HeldTimeline:
    def __init__(self, jump_s: float, confirm: int, persist_s: float, capacity: int, anchor: int = -1) -> None:
        self.jump_s = jump_s
        self.anchor = anchor  # the sensor index whose clock the filter follows (-1: none, every sensor alike)
        self.confirm = confirm
        self.persist_s = persist_s
        self.capacity = capacity
        self.cluster: Cluster | None = None

    def far(self, stamp: float, t: float | None) -> bool:
        """Is this stamp too far from filter time t to be applied now?"""
        return t is not None and (stamp < t - self.jump_s or stamp > t + self.jump_s)

    def full(self, stamp: float) -> bool:
        """Would this sample join a cluster that already holds ``capacity`` samples?"""
        c = self.cluster
        return c is not None and abs(stamp - c.first) <= self.jump_s and len(c.samples) >= self.capacity

    def hold(self, stamp: float, idx: int, inp: Any) -> tuple[list[Held], bool]:
        """Hold a far sample (the caller checks ``full`` first). Returns the samples of a previous
        cluster this one replaces (they did not persist: glitches to drop) and whether the cluster
        is now a confirmed timeline."""
        dropped: list[Held] = []
        c = self.cluster
        if c is not None and abs(stamp - c.first) > self.jump_s:
            if c.anchored and idx != self.anchor:  # another sensor's far clock: this sample goes, not the anchor's
                return [(stamp, idx, inp)], False
            dropped = self.abandon()  # a different far timeline: the held one did not persist
            c = None
        if c is None:
            c = self.cluster = Cluster(first=stamp)
        c.samples.append((stamp, idx, inp))
        c.anchored = c.anchored or idx == self.anchor
        c.lo, c.hi = min(c.lo, stamp), max(c.hi, stamp)
        return dropped, len(c.samples) >= self.confirm and c.hi - c.lo >= self.persist_s

    def left_by(self, idx: int) -> bool:
        """Does a sample of sensor ``idx`` going on along the old timeline show the held cluster a glitch?
        Any sensor's does, but for a cluster that holds the anchor's samples: only the anchor's."""
        c = self.cluster
        return c is not None and (idx == self.anchor or not c.anchored)

    def take(self) -> Cluster:
        """The confirmed cluster, no longer held."""
        c = self.cluster
        assert c is not None
        self.cluster = None
        return c

    def abandon(self) -> list[Held]:
        """Give up the held cluster (a glitch, or a reset): its samples, to be dropped."""
        c, self.cluster = self.cluster, None
        return [] if c is None else c.samples

    def counts(self, n_sensors: int) -> list[int]:
        """Held samples per sensor."""
        n = [0] * n_sensors
        if self.cluster is not None:
            for _, idx, _ in self.cluster.samples:
                n[idx] += 1
        return n
