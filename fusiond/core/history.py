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

A snapshot is read only when a late sample is placed right after its entry (or its entry is the
base then). A caller that knows every sample to come (a replay of a recording in memory) can say
which entries no later sample lands right after (``snapshots_read``); those keep no snapshot
(``None`` in ``after``), and what the filter computes is the same to the bit, as nothing reads them.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable
from typing import Any

from ..errors import CoreError
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
        # the filter time of a base entry inserted without a snapshot (``too_old``)
        self.base_t: float | None = None
        self._free: list[FilterState] = []  # snapshots no longer referenced, to be overwritten

    def slot(self, key: Key) -> tuple[int, bool]:
        """(insert position, is a duplicate of an applied sample)."""
        keys = self.keys
        if keys and key > keys[-1]:  # the newest sample (nearly every one): after all, equal to none
            return len(keys), False
        pos = bisect.bisect_right(keys, key, self.start)
        return pos, pos > self.start and keys[pos - 1] == key

    def too_old(self, stamp: float) -> bool:
        base_t = self.base.t if self.base is not None else self.base_t
        return base_t is not None and stamp < base_t

    def state_before(self, pos: int) -> FilterState:
        """A copy the caller owns (it becomes the live state)."""
        s = self.after[pos - 1] if pos > self.start else self.base
        if s is None:  # the caller said no later sample lands here (``insert(keep=False)``)
            raise CoreError("a late sample landed after an entry inserted without its snapshot: the "
                            "samples were not the ones their snapshot plan was made for")
        return s.copy()

    def insert(self, pos: int, key: Key, event: tuple[int, Any, float], state: FilterState,
               keep: bool = True) -> None:
        """``keep``: False when no later sample is placed right after this entry (``snapshots_read``):
        its snapshot, never read, is not taken."""
        self.keys.insert(pos, key)
        self.events.insert(pos, event)
        if keep:
            free = self._free
            self.after.insert(pos, state.copy(into=free.pop() if free else None))
        else:
            self.after.insert(pos, None)

    def reapply_after(self, pos: int, state: FilterState, apply: Callable[[FilterState, int, Any, float], None]) -> None:
        """Re-apply every event after ``pos`` on ``state`` (in place), refreshing their snapshots in place."""
        after = self.after
        for j in range(pos + 1, len(self.events)):
            idx, inp, stamp = self.events[j]
            apply(state, idx, inp, stamp)
            if after[j] is not None:  # an entry without a snapshot stays without one: nothing reads it
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
            free = self._free
            if self.base is not None:
                free.append(self.base)
            end = start + n
            base = self.base = after[end - 1]
            if base is None:  # an entry's filter time is its stamp (keys in stamp order, each applied at its own)
                self.base_t = keys[end - 1][0]
            if n > 1:  # a loop, not a comprehension: its frame cost more than the one or two entries it reads
                for s in after[start : end - 1]:
                    if s is not None:
                        free.append(s)
            if end >= COMPACT:
                del keys[:end], self.events[:end], self.after[:end]
                end = 0
            self.start = end


def snapshots_read(keys: list[Key | None]) -> list[bool]:
    """For samples to be placed in this order (their keys; None: one the core drops whatever comes),
    whether a later one can be placed right after each (so its snapshot can be read: ``History``).

    A snapshot is read when a late sample lands right after its entry: a sample with a greater key (or
    the same one: a driver repeating a stamp with new values is placed after the entry it repeats),
    placed later, that is late then (older than the newest applied). Late in the core means older than
    the newest key applied, which is at most the newest key in the list before it: so a sample is
    taken as late when its key is below every earlier key's maximum, and an entry's snapshot as read
    when any such later sample has a greater key. Samples the core drops (duplicates, rejected ones,
    far stamps held for a time jump) only make more of them "read": the answer errs on the side of
    a snapshot. Samples held for a time jump are placed later than they come, in key order after
    everything placed meanwhile (a forward jump) or into a history started afresh (a backward one):
    neither lands late after an entry that came before it."""
    late_key: list[Key | None] = []
    newest: Key | None = None
    for k in keys:
        if k is None:
            late_key.append(None)
            continue
        if newest is not None and k < newest:
            late_key.append(k)
        else:
            late_key.append(None)
            newest = k
    read = [True] * len(keys)
    latest_late: Key | None = None  # the greatest key of a late sample after the current one
    for i in range(len(keys) - 1, -1, -1):
        k = keys[i]
        if k is not None:
            read[i] = latest_late is not None and k <= latest_late  # an equal key lands after it (bisect_right)
        lk = late_key[i]
        if lk is not None and (latest_late is None or lk > latest_late):
            latest_late = lk
    return read
