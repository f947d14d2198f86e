"""The late-data history recycles its snapshots: a steady stream allocates none once the history is
full, and a recycled snapshot never shares an array with the live state or another snapshot."""

from __future__ import annotations

import bisect

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fusiond.core.history as history
from fusiond.core.fusion import FusionCore
from fusiond.core.history import DERIVED

from tests.support.core_samples import imu, make_config, odom


def _snapshots(core: FusionCore) -> list:
    """Every state the history holds: the base, the snapshots from ``kept`` on, the free list."""
    h = core.history
    return [s for s in (h.base, *h.after[h.kept:], *h._free) if s is not None and s is not DERIVED]


@pytest.mark.parametrize("stride", [1, history.STRIDE_MAX])
def test_steady_stream_reuses_the_same_snapshots(stride, monkeypatch):
    # history_s = 0.2 s at 100 + 100 Hz: about 40 entries; the 2 s of stream after the first second only
    # ever overwrites the snapshots the first second created (at a steady stride: one that follows the
    # late share takes more of them as it learns it)
    monkeypatch.setattr(history, "DEFAULT_STRIDE", stride)
    core = FusionCore(make_config(extra_filter="history_s = 0.2"))

    def second(k0: int) -> None:  # one second of stream, with a late IMU sample every 0.1 s
        for k in range(k0, k0 + 100):
            core.ingest(odom(1.0 + 0.01 * k, v=0.5))
            core.ingest(imu(1.0 + 0.01 * k + 0.005))
            if k % 10 == 0 and k:  # re-application refreshes the later snapshots in place
                assert core.ingest(imu(1.0 + 0.01 * k - 0.0525)).late

    second(0)
    kept = _snapshots(core)  # held here, so that no id can be reused by a new object
    kept_arrays = [s.ekf.P for s in kept]
    pool, arrays = {id(s) for s in kept}, {id(a) for a in kept_arrays}
    second(100)
    second(200)
    assert {id(s) for s in _snapshots(core)} <= pool
    assert {id(s.ekf.P) for s in _snapshots(core)} <= arrays


def test_no_snapshot_shares_an_array_with_the_live_state_or_another():
    core = FusionCore(make_config(extra_filter="history_s = 0.1"))
    for k in range(200):
        core.ingest(odom(1.0 + 0.01 * k, v=0.5, w=0.1))
        core.ingest(imu(1.0 + 0.01 * k + 0.005))
        if k % 7 == 0 and k:
            core.ingest(imu(1.0 + 0.01 * k - 0.0125))
    live = core.state.ekf
    arrays = [a for s in _snapshots(core) for a in (s.ekf.x, s.ekf.P)]
    arrays += [live.x, live.P]
    for i, a in enumerate(arrays):
        for b in arrays[i + 1:]:
            assert not np.shares_memory(a, b)
    assert live._spare is None or not np.shares_memory(live._spare, live.P)


@settings(max_examples=200, deadline=None)
@given(stamps=st.lists(st.floats(0.0, 10.0), min_size=1, max_size=60), history_s=st.floats(0.0, 5.0),
       history_max=st.integers(1, 80))
def test_trim_keeps_exactly_the_samples_within_the_window_and_the_count(stamps, history_s, history_max):
    """What trim keeps, against its definition: the newest ``history_max`` samples, none stamped
    more than ``history_s`` before the newest; the last one dropped becomes the base."""
    from fusiond.core.history import History
    from fusiond.core.state import FilterState

    h = History(None)
    keys = sorted((t, i % 3) for i, t in enumerate(stamps))
    states = []
    for pos, key in enumerate(keys):
        s = FilterState.__new__(FilterState)
        s.t = key[0]  # an entry's filter time is its stamp
        states.append(s)
        h.keys.insert(pos, key)
        h.events.insert(pos, (key[1], None, key[0]))
        h.after.insert(pos, s)
    h.trim(history_s, history_max)
    newest = keys[-1][0]
    expected = [k for k in keys[-history_max:] if k[0] >= newest - history_s]
    assert h.keys[h.start:] == expected and len(h.after) - h.start == len(expected) == len(h.events) - h.start
    dropped = len(keys) - len(expected)
    assert h.base is (states[dropped - 1] if dropped else None)


@settings(max_examples=30, deadline=None)
@given(steps=st.lists(st.tuples(st.floats(-0.3, 0.05), st.integers(0, 2)), min_size=300, max_size=1200),
       history_s=st.floats(0.05, 0.5), history_max=st.integers(20, 400))
def test_a_long_stream_keeps_what_plain_lists_would_keep(steps, history_s, history_max):
    """Across many trims (the dropped front deleted in blocks of COMPACT), the history holds exactly
    what lists trimmed one entry at a time would hold: the same keys, events, snapshots and base,
    and a new key finds the same place and the same duplicate."""
    from fusiond.core.history import History
    from fusiond.core.state import FilterState

    h = History(None)
    keys: list = []  # the model: plain lists, entries deleted from the front as they are dropped
    after: list = []
    base = None
    newest = 0.0
    for k, (back, sensor) in enumerate(steps):
        newest += 0.01
        key = (round(newest + back, 3) if back < 0.0 else newest, sensor)  # some late, some duplicates
        pos = bisect.bisect_right(keys, key)
        duplicate = pos > 0 and keys[pos - 1] == key
        got_pos, got_duplicate = h.slot(key)
        assert (got_pos - h.start, got_duplicate) == (pos, duplicate)
        if duplicate or (base is not None and key[0] < base.t):
            continue
        s = FilterState.__new__(FilterState)
        s.t = key[0]
        h.keys.insert(got_pos, key)
        h.events.insert(got_pos, (sensor, k, key[0]))
        h.after.insert(got_pos, s)
        if h.newest is None or key > h.newest:  # as ``History.insert`` keeps it
            h.newest = key
        keys.insert(pos, key)
        after.insert(pos, s)
        h.trim(history_s, history_max)
        horizon = keys[-1][0] - history_s
        drop = max(sum(1 for kk in keys if kk[0] < horizon), len(keys) - history_max)
        if drop:
            base = after[drop - 1]
            del keys[:drop], after[:drop]
        assert h.keys[h.start:] == keys and h.after[h.start:] == after and h.base is base
        assert [e[2] for e in h.events[h.start:]] == [kk[0] for kk in keys]
