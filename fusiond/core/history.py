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

Where every sample from some point on comes after all before it (a recording without late samples from
there: ``unrecorded_from``), nothing is placed before any of them later, so they take no entry at all
(``pass_by``): only the newest key is kept, to know the next one is newer still.

A caller that cannot know (the daemon: a live stream) takes a snapshot at every ``stride``-th entry in
order only; the others are ``DERIVED``: the state after one is the nearest snapshot before it with the
events in between applied again, which is the state itself to the bit (applying an event is a function of
the state and the event alone: the re-application after a late sample already rests on that). The stride
trades the copies saved against the re-applications a late sample then pays: with a share p of the entries
placed late, a snapshot costing c_s and an event's re-application c_r, an entry costs c_s / k + p c_r (k - 1)
/ 2 on average at stride k (a late sample lands after an entry (k - 1) / 2 past the nearest snapshot), least
at k = sqrt(2 c_s / (p c_r)) (``stride_for``): every 8th entry for a stream in order (a late sample then
re-applies at most 7 events more), every 2nd with one sample in ten late, every entry beyond one in three.
``trim`` keeps the entries a derivation still starts from (``kept`` to ``start``: a few strides before the
horizon at most) but judges "too old" by the horizon itself, so what is placed and what is dropped does not
change.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from typing import Any

from ..errors import CoreError
from .state import FilterState

Key = tuple[float, int]  # (stamp, sensor index): ties broken by sensor, never by arrival
SCAN = 8  # ``trim`` steps over this many keys before it bisects
COMPACT = 256  # dropped entries deleted from the lists' front at once
# entries placed in order between two trims (``trimmed``): the history holds at most that many past its horizon
# until the next, and a trim costs about what an entry's insert does, so a sixteenth of one an entry. A sample
# placed late trims first (``slot``): what it finds is what a trim after every entry would have left.
TRIM_EVERY = 16
STRIDE_MAX = 8  # the longest stride (module doc): beyond, the copies saved are a few per cent of one
# an event's re-application against a snapshot's copy: ~70,000 against ~11,000 instructions on the daemon's
# traffic (1 kHz IMU, 100 Hz odometry; scripts/core_instructions.py with and without the stride)
REAPPLY_OVER_SNAPSHOT = 6.0
LATE_MEMORY = 256.0  # entries: the late share's exponential memory
DEFAULT_STRIDE: int | None = None  # None: the stride follows the late share (``stride_for``); an int: fixed


def stride_for(late_share: float) -> int:
    """The stride that costs least with ``late_share`` of the entries placed late (module doc)."""
    if late_share * REAPPLY_OVER_SNAPSHOT * STRIDE_MAX * STRIDE_MAX <= 2.0:
        return STRIDE_MAX
    return max(1, round(math.sqrt(2.0 / (REAPPLY_OVER_SNAPSHOT * late_share))))


_UNFORESEEN = ("a late sample landed after an entry inserted without its snapshot: the samples were not the ones "
               "their snapshot plan was made for")


class _Derived:
    """The ``after`` of an entry whose state is derived from the nearest snapshot before it (module doc)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "DERIVED"


DERIVED = _Derived()


class History:
    """``keys[start:]``, ``events[start:]`` and ``after[start:]`` are the history, oldest first: ``trim``
    drops from the front by moving ``start`` (deleting one entry at the front of a list moves all the
    others: at 1 kHz, a second of history moved once a message), and the dropped entries are deleted
    in one block once COMPACT of them have gathered. ``kept`` <= ``start``: the dropped entries a derived
    state after the horizon still starts from (module doc); ``base`` is the state before ``kept``.
    ``stride``: every how many entries in order keep a snapshot (1: each; None: ``stride_for`` the late share)."""

    def __init__(self, base: FilterState | None, stride: int | None = None, history_s: float = math.inf,
                 history_max: int = 1 << 62) -> None:
        stride = DEFAULT_STRIDE if stride is None else stride
        self.keys: list[Key] = []
        self.events: list[tuple[int, Any, float]] = []
        self.after: list[FilterState | None | _Derived] = []
        self.start = 0  # entries before it are dropped (the snapshots among them are in _free or the base)
        self.kept = 0  # entries from here to start are dropped but still start a derivation
        self.base = base.copy() if base is not None else None
        # the filter time of the newest entry dropped: a sample older than it is too old to place
        self.horizon: float | None = base.t if base is not None else None
        self.adaptive = stride is None
        self.stride = STRIDE_MAX if stride is None else stride
        self._run = -1  # entries DERIVED at the end since its newest snapshot (-1: none there to derive from)
        self.late_share = 0.0  # of the entries inserted, over the last ~LATE_MEMORY
        self._free: list[FilterState] = []  # snapshots no longer referenced, to be overwritten
        self.newest: Key | None = None  # the greatest key placed (an entry's, or one ``pass_by`` took)
        self.history_s, self.history_max = history_s, history_max  # what ``trimmed`` keeps
        self._untrimmed = 0  # entries placed since the last trim

    def slot(self, key: Key) -> tuple[int, bool]:
        """(insert position, is a duplicate of an applied sample)."""
        keys = self.keys
        newest = self.newest
        if newest is None or key > newest:  # the newest sample (nearly every one): after all, equal to none
            return len(keys), False
        if not keys or keys[-1] != newest:  # samples placed without an entry (``pass_by``) would be skipped
            raise CoreError(_UNFORESEEN)
        if self._untrimmed:  # placed before the newest: against the history a trim after every entry leaves
            self._untrimmed = 0
            self.trim(self.history_s, self.history_max)
        pos = bisect.bisect_right(keys, key, self.start)
        return pos, pos > self.start and keys[pos - 1] == key

    def pass_by(self, key: Key) -> None:
        """Place a sample after all others without an entry: the caller knows no later one is placed before or
        on it (``unrecorded_from``). A key not after the newest is a CoreError."""
        newest = self.newest
        if newest is not None and key <= newest:
            raise CoreError(_UNFORESEEN)
        self.newest = key

    def too_old(self, stamp: float) -> bool:
        return self.horizon is not None and stamp < self.horizon

    def state_before(self, pos: int, reapply: Callable[[FilterState, int, Any, float], None]) -> FilterState:
        """A copy the caller owns (it becomes the live state): the snapshot before ``pos``, or, where that
        entry's state is DERIVED, the nearest snapshot before it with the events between applied again
        (``reapply``, as ``reapply_after`` applies them)."""
        after = self.after
        j = pos - 1
        kept = self.kept
        while j >= kept and after[j] is DERIVED:
            j -= 1
        s = after[j] if j >= kept else self.base
        if s is None:  # the caller said no later sample lands here (``insert(keep=False)``)
            raise CoreError(_UNFORESEEN)
        c = s.copy()
        events = self.events
        for i in range(j + 1, pos):
            idx, inp, stamp = events[i]
            reapply(c, idx, inp, stamp)
        return c

    def insert(self, pos: int, key: Key, event: tuple[int, Any, float], state: FilterState,
               keep: bool = True) -> None:
        """``keep``: False when no later sample is placed right after this entry (``snapshots_read``):
        its snapshot, never read, is not taken (unless entries after it derive their state through it).
        Otherwise an entry placed at the end is DERIVED where fewer than ``stride`` - 1 entries before it
        are, and a late one keeps its snapshot."""
        after = self.after
        at_end = pos == len(after)
        self.keys.insert(pos, key)
        self.events.insert(pos, event)
        share = self.late_share
        if at_end:
            self.newest = key
            self.late_share = share - share / LATE_MEMORY
            if not keep:
                after.append(None)
                self._run = -1  # nothing after it can derive through it
                return
            run = self._run
            if 0 <= run < self.stride - 1:
                after.append(DERIVED)
                self._run = run + 1
                return
            self._run = 0
            if self.adaptive:
                self.stride = stride_for(share)
        else:
            self.late_share = share + (1.0 - share) / LATE_MEMORY
            if not keep and after[pos] is not DERIVED:
                after.insert(pos, None)
                return
        free = self._free
        snapshot = state.copy(into=free.pop() if free else None)
        if at_end:
            after.append(snapshot)
        else:
            after.insert(pos, snapshot)

    def reapply_after(self, pos: int, state: FilterState, apply: Callable[[FilterState, int, Any, float], None]) -> None:
        """Re-apply every event after ``pos`` on ``state`` (in place), refreshing their snapshots in place."""
        after = self.after
        for j in range(pos + 1, len(self.events)):
            idx, inp, stamp = self.events[j]
            apply(state, idx, inp, stamp)
            a = after[j]
            if a is not None and a is not DERIVED:  # an entry without a snapshot stays without one
                state.copy(into=a)

    def trimmed(self) -> None:
        """After an entry is placed: ``trim`` to ``history_s`` and ``history_max`` every TRIM_EVERY entries
        (and before the next late one, ``slot``). Trims are the same whenever they run between two late
        samples: each drops what is older than the newest less ``history_s``, and beyond the count."""
        n = self._untrimmed + 1
        if n < TRIM_EVERY:
            self._untrimmed = n
            return
        self._untrimmed = 0
        self.trim(self.history_s, self.history_max)

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
            end = start + n
            last = self.after[end - 1]
            if last is DERIVED:
                # what stays derives its state from this entry's chain: kept from the chain's snapshot on. Looked
                # for only once the entries kept so have grown past two strides (a stream in order drops them
                # through its next snapshot a few trims later, without looking)
                after, kept = self.after, self.kept
                if end - kept > 2 * STRIDE_MAX:
                    head = end - 2
                    while head >= kept and after[head] is DERIVED:
                        head -= 1
                    if head >= kept:  # a chain starts at a snapshot
                        self._drop_through(head)
                self.horizon = keys[end - 1][0]  # an entry's filter time is its stamp
            else:
                self._drop_through(end - 1)
                # (no snapshot: an entry's filter time is its stamp, keys in stamp order, each applied at its own)
                self.horizon = last.t if last is not None else keys[end - 1][0]
            self.start = end
            kept = self.kept
            if kept >= COMPACT:
                del keys[:kept], self.events[:kept], self.after[:kept]
                self.start = end - kept
                self.kept = 0

    def _drop_through(self, j: int) -> None:
        """Entries ``kept`` to ``j`` leave the history: their snapshots (and the old base) to the free list,
        the state after ``j`` the new base."""
        after = self.after
        free = self._free
        if self.base is not None:
            free.append(self.base)
        if j > self.kept:  # a loop, not a comprehension: its frame cost more than the one or two entries it reads
            for s in after[self.kept : j]:
                if s is not None and s is not DERIVED:
                    free.append(s)
        self.base = after[j]
        self.kept = j + 1


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


def unrecorded_from(keys: list[Key | None]) -> int:
    """For samples to be placed in this order (their keys, as ``snapshots_read`` takes them), the first from
    which each comes after every one before it: the one after the last that comes late or repeats a key
    (at or below the greatest key before it). From there no sample is placed before or on another, so none
    needs an entry (``History.pass_by``). A sample the core drops (a far stamp held for a time jump, a
    reading it refuses) only moves that point later: the answer errs on the side of an entry."""
    newest: Key | None = None
    last = -1
    for i, k in enumerate(keys):
        if k is None:
            continue
        if newest is not None and k <= newest:
            last = i
        else:
            newest = k
    return last + 1
