"""When the daemon's worker next fuses what waits in its inbox.

Waking the worker for every message costs more than the hand-off: at 1 kHz IMU a
worker woken per message runs the fusion core with cold caches each time, and the
GIL and futex traffic lands on Zenoh's receive thread too. Fusing several samples
per wake-up is cheaper, but the order of fusing is fixed (arrival order: an
odometry sample is fused after everything that arrived before it), so a backlog
still waiting when an odometry sample arrives delays the pose that answers it.

So the worker alternates two ways of waiting, planned from the odometry's arrival
period (`next_wait`):

- Batching: samples wait in the inbox, the worker sleeps until `hold_s` has
  passed (no sample waits longer for its batch: a robot without odometry, or with
  odometry stopped, still has its IMU fused) or until the window before the next
  odometry sample opens, whichever comes first; an odometry sample always wakes
  it at once (`Daemon._callback`).
- The window: from `lead_s` plus the time the backlog takes to fuse before the
  odometry sample is due until `lead_s` after: the backlog is fused when it opens,
  then every arrival wakes the worker, so the odometry sample finds the inbox empty
  and its pose goes out as fast as with a wake-up per message. An odometry sample
  that has not come by the window's end is expected a period later.

Until the period is known, and with `hold_s` = 0, every arrival wakes the worker
(`hold_s` alone bounds the batching). Pure arithmetic on the caller's clock: no
thread, no I/O, testable with numbers.
"""

from __future__ import annotations

import math

from ..core.inputs import smoothed_period

__all__ = ["LEAD_S", "DrainSchedule"]

LEAD_S = 0.001  # the window before (and after) an expected odometry sample in which every arrival wakes the worker
MAX_INTERVAL = 1.0  # a longer gap between odometry samples is a pause, not a period: not averaged in


class DrainSchedule:
    """How long the worker waits next, and whether any arrival ends that wait."""

    __slots__ = ("hold_s", "lead_s", "last", "period", "batch_s", "_measured")

    def __init__(self, hold_s: float, lead_s: float = LEAD_S) -> None:
        if not (hold_s >= 0.0 and lead_s >= 0.0):
            raise ValueError(f"hold_s and lead_s must be >= 0 s, got {hold_s} and {lead_s}")
        self.hold_s = hold_s
        self.lead_s = lead_s
        self.last: float | None = None  # arrival of the newest odometry sample fused
        self.period = 0.0  # EMA of the intervals between odometry arrivals (0: not known yet)
        self.batch_s = 0.0  # how long the last backlog fused when a window opened took
        self._measured = False  # a backlog was timed since the last odometry sample

    def on_prompt(self, arrival: float) -> None:
        """An odometry sample (one that publishes) that arrived at `arrival` is being fused."""
        if not self._measured:  # no backlog timed in that period: the window opened before any could build
            self.batch_s *= 0.5
        self._measured = False
        last = self.last
        if last is not None:
            if arrival <= last:
                return
            d = arrival - last
            if d <= MAX_INTERVAL:
                self.period = smoothed_period(self.period, d)  # the sensors' own average (core/inputs.py)
        self.last = arrival

    def on_backlog(self, seconds: float) -> None:
        """The backlog fused when the window opened took `seconds`: the next window opens that much earlier."""
        self.batch_s = seconds
        self._measured = True

    def next_wait(self, now: float) -> tuple[float, bool]:
        """(longest wait in seconds, whether any arrival ends it) for a worker with an empty inbox at `now`."""
        if self.hold_s <= 0.0:
            return math.inf, True
        if self.period <= 0.0 or self.last is None:
            return self.hold_s, False
        period, lead = self.period, self.lead_s
        due = self.last + period  # the next odometry arrival expected
        if now > due + lead:  # it has not come: expect it a whole number of periods later
            due += (math.floor((now - due - lead) / period) + 1) * period
        opens = due - lead - self.batch_s
        if now >= opens:
            return due + lead - now, True
        return min(opens - now, self.hold_s), False
