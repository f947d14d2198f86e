"""The bounded, stamp-ordered history of applied samples and the state after each.

A sample older than the newest is inserted at its own stamp: the state just
before it is restored and the later samples re-applied, as robot_localization's
lagged-data smoothing does. The history keeps ``history_s`` seconds (and at most
``history_max`` samples); the state before its oldest sample is the ``base``, and a
sample older than that is too old to place.

Snapshots are recycled: the ones ``trim`` drops go to a free list, and the next
insert overwrites one of them in place (``FilterState.copy(into=...)``, x and P by
in-place writes) instead of allocating a state, an EKF and two arrays per message and
freeing as many. Once the history has filled, a steady stream allocates no
snapshots at all; the free list never holds more than one trim's worth.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from typing import Any

from .state import FilterState

Key = tuple[float, int]  # (stamp, sensor index): ties broken by sensor, never by arrival
SCAN = 8  # ``trim`` steps over this many keys before it bisects
COMPACT = 256  # dropped entries deleted from the lists' front at once


class History:
    """``keys[start:]``, ``events[start:]`` and ``after[start:]`` are the history, oldest first: ``trim``
    drops from the front by moving ``start`` (deleting one entry at the front of a list moves all the
    others: at 1 kHz, a second of history moved once a message), and the dropped entries are deleted
    in one block once COMPACT of them have gathered."""

    def __init__(self, base: FilterState | None) -> None:
        self.keys: list[Key] = []
        self.events: list[tuple[int, Any, float]] = []
        self.after: list[FilterState] = []
        self.start = 0  # entries before it are dropped (the snapshots among them are in _free or the base)
        self.base = base.copy() if base is not None else None
        self._free: list[FilterState] = []  # snapshots no longer referenced, to be overwritten

    def slot(self, key: Key) -> tuple[int, bool]:
        """(insert position, is a duplicate of an applied sample)."""
        keys = self.keys
        if keys and key > keys[-1]:  # the newest sample (nearly every one): after all, equal to none
            return len(keys), False
        pos = bisect.bisect_right(keys, key, self.start)
        return pos, pos > self.start and keys[pos - 1] == key

    def too_old(self, stamp: float) -> bool:
        return self.base is not None and self.base.t is not None and stamp < self.base.t

    def state_before(self, pos: int) -> FilterState:
        """A copy the caller owns (it becomes the live state)."""
        return (self.after[pos - 1] if pos > self.start else self.base).copy()

    def insert(self, pos: int, key: Key, event: tuple[int, Any, float], state: FilterState) -> None:
        self.keys.insert(pos, key)
        self.events.insert(pos, event)
        free = self._free
        self.after.insert(pos, state.copy(into=free.pop() if free else None))

    def reapply_after(self, pos: int, state: FilterState, apply: Callable[[FilterState, int, Any, float], None]) -> None:
        """Re-apply every event after ``pos`` on ``state`` (in place), refreshing their snapshots in place."""
        after = self.after
        for j in range(pos + 1, len(self.events)):
            idx, inp, stamp = self.events[j]
            apply(state, idx, inp, stamp)
            state.copy(into=after[j])

    def trim(self, history_s: float, history_max: int) -> None:
        """Drop the samples older than ``history_s`` before the newest, and beyond ``history_max``."""
        keys = self.keys
        start = self.start
        horizon = keys[-1][0] - history_s
        size = len(keys) - start
        if keys[start][0] >= horizon and size <= history_max:
            return
        # keys are sorted: the first one stamped at or after the horizon. A stream trims one or two a message:
        # found by stepping from the front (a bisection over a second of 1 kHz IMU cost more than the rest of
        # the trim); a longer run (after a pause) by bisection ((t,) sorts before any (t, i))
        n = 0
        while n < SCAN and n < size and keys[start + n][0] < horizon:
            n += 1
        if n == SCAN:
            n = bisect.bisect_left(keys, (horizon,), start) - start
        if size - history_max > n:
            n = size - history_max
        if n:
            after = self.after
            if self.base is not None:
                self._free.append(self.base)
            end = start + n
            self.base = after[end - 1]
            if n > 1:
                self._free.extend(after[start : end - 1])
            if end >= COMPACT:
                del keys[:end], self.events[:end], self.after[:end]
                end = 0
            self.start = end
