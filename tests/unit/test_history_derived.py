"""A history that keeps a snapshot at every ``stride``-th entry only (``core/history.py``) fuses exactly what one
keeping every snapshot fuses: a DERIVED entry's state, rebuilt from the nearest snapshot before it by applying
the events between again, is that state to the bit. Held to a history of stride 1 on streams with late samples,
duplicates, samples too old to place, and samples a snapshot plan says nothing lands after."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fusiond.core.history as history
from fusiond.core.fusion import FusionCore
from fusiond.core.history import DERIVED
from fusiond.replay.run import run_samples

from tests.support.core_samples import imu, make_config, odom


def _stream(steps: list[tuple[int, float, float]]) -> list:
    """Odometry and IMU samples 10 ms apart, each ``(kind, lateness s, rate)`` late by that much against the
    stream's newest stamp (0: in order; beyond history_s: too old; a repeated stamp now and then)."""
    out, t = [], 1.0
    for k, (kind, back, rate) in enumerate(steps):
        t += 0.005
        stamp = round(t - back, 4)
        if kind == 0:
            out.append(odom(stamp, v=0.5 + rate, w=rate))
        else:
            out.append(imu(stamp, rpy=(0.01 * rate, -0.02 * rate, 0.0), gyro=(0.0, 0.0, rate)))
    return out


def _fused(samples: list, stride: int | None, plan: bool, trim_every: int = history.TRIM_EVERY) -> tuple[list, FusionCore]:
    """What a core makes of ``samples`` with its histories striding by ``stride`` and trimmed every ``trim_every``
    entries: each step's outcome, its records' NIS and innovations, the pose after it, and the core (its final
    state)."""
    with pytest.MonkeyPatch.context() as m:
        m.setattr(history, "DEFAULT_STRIDE", stride)
        m.setattr(history, "TRIM_EVERY", trim_every)
        core = FusionCore(make_config(extra_filter="history_s = 0.08"))
        keeps = core.snapshot_plan(samples) if plan else [True] * len(samples)
        seen = []
        for s, keep in zip(samples, keeps):
            step = core.ingest(s, keep)
            pose = core.pose()[1].tobytes() if core.initialised else None
            seen.append((step.accepted, step.reason, step.late, pose,
                         [(r.channel, r.nis, tuple(r.innovation)) for r in step.records]))
        assert stride is None or core.history.stride == stride
    return seen, core


@settings(max_examples=60, deadline=None)
@given(steps=st.lists(st.tuples(st.integers(0, 1),
                                st.one_of(st.just(0.0), st.just(0.0), st.floats(0.0, 0.12), st.just(0.005)),
                                st.floats(-0.3, 0.3)), min_size=20, max_size=160),
       plan=st.booleans(), stride=st.sampled_from([None, 2, history.STRIDE_MAX]))
def test_a_history_of_derived_states_fuses_what_one_of_snapshots_fuses(steps, plan, stride):
    """... and trimmed now and then, what one trimmed after every entry fuses."""
    samples = _stream(steps)
    every, core_every = _fused(samples, 1, plan, trim_every=1)
    strided, core_strided = _fused(samples, stride, plan)
    assert strided == every
    a, b = core_every.state, core_strided.state
    assert a.ekf.x.tobytes() == b.ekf.x.tobytes() and a.ekf.P.tobytes() == b.ekf.P.tobytes()
    assert [(s.applied, s.late, s.dropped) for s in core_every.stats] == \
           [(s.applied, s.late, s.dropped) for s in core_strided.stats]


def test_an_in_order_stream_snapshots_one_entry_in_stride_and_a_late_sample_lands_among_the_derived():
    """The point of it: in order, seven entries in eight keep no snapshot; a late sample landing after one of
    those is placed from the state derived for it, the same as with every snapshot kept."""
    samples = [odom(1.0 + 0.01 * k, v=0.5, w=0.1) if k % 2 else imu(1.0 + 0.01 * k, gyro=(0.0, 0.0, 0.1))
               for k in range(40)]
    _, core = _fused(samples, history.STRIDE_MAX, False)
    h = core.history
    live = h.after[h.kept:]
    assert sum(a is DERIVED for a in live) >= (history.STRIDE_MAX - 1) * (len(live) // history.STRIDE_MAX)
    j = max(i for i in range(h.start, len(h.after) - 1) if h.after[i] is DERIVED and h.after[i - 1] is DERIVED)
    late = imu(0.5 * (h.keys[j][0] + h.keys[j + 1][0]), gyro=(0.0, 0.0, 0.12))  # lands right after entry j
    every, _ = _fused([*samples, late], 1, False)
    strided, _ = _fused([*samples, late], history.STRIDE_MAX, False)
    assert strided[-1][2] and strided == every


def test_a_smoothed_replay_with_late_samples_is_the_same_with_derived_states(monkeypatch):
    """The smoother's recording rides in the EKF a snapshot copies: derived, it is the same recording."""
    samples = []
    for k in range(300):
        samples.append(odom(1.0 + 0.01 * k, v=0.5, w=0.2))
        samples.append(imu(1.0 + 0.01 * k + 0.003, rpy=(0.0, 0.0, 0.0), gyro=(0.0, 0.0, 0.2)))
        if k % 9 == 4:  # an IMU sample 17 ms late, landing among entries that keep no snapshot
            samples.append(imu(1.0 + 0.01 * k - 0.017 + 0.0001, gyro=(0.0, 0.0, 0.21)))
    cfg = make_config(extra_filter="history_s = 0.1")
    with monkeypatch.context() as m:
        m.setattr(history, "DEFAULT_STRIDE", 1)
        every = run_samples(samples, cfg, smooth=True)
    strided = run_samples(samples, cfg, smooth=True)
    assert every.core.stats[1].late > 20
    assert np.array_equal(np.asarray(every.smoothed), np.asarray(strided.smoothed))
    assert every.trajectory == strided.trajectory


def test_the_stride_is_the_cheapest_one_for_the_share_of_late_samples():
    """``stride_for`` minimises c_s / k + p c_r (k - 1) / 2 over the strides up to STRIDE_MAX (module doc)."""
    r = history.REAPPLY_OVER_SNAPSHOT
    for p in (0.0, 1e-4, 0.003, 0.01, 0.03, 0.1, 0.2, 0.34, 0.6, 1.0):
        costs = {k: 1.0 / k + p * r * (k - 1) / 2.0 for k in range(1, history.STRIDE_MAX + 1)}
        best = min(costs.values())
        assert costs[history.stride_for(p)] <= best * 1.02, p
    assert history.stride_for(0.0) == history.STRIDE_MAX and history.stride_for(0.1) == 2
    assert history.stride_for(0.34) == 1


def test_a_live_stream_strides_by_how_many_of_its_samples_come_late():
    """In order, every eighth entry keeps a snapshot; with one odometry sample in ten landing behind the
    IMU samples the stride follows the late share down, and back up once the stream is in order again."""
    core = FusionCore(make_config())
    t = 1.0
    for k in range(3000):
        t += 0.001
        core.ingest(imu(t, gyro=(0.0, 0.0, 0.1)))
        if k % 10 == 9 and 1000 <= k < 2000:
            core.ingest(odom(t - 0.004, v=0.5, w=0.1))  # arrives after four newer IMU samples
        elif k % 10 == 9:
            core.ingest(odom(t + 0.0005, v=0.5, w=0.1))
        if k == 999:
            assert core.history.stride == history.STRIDE_MAX
        if k == 1999:
            assert core.history.stride == history.stride_for(core.history.late_share) == 2
    assert core.history.stride == history.STRIDE_MAX


@pytest.mark.parametrize("pattern", ["alone", "pairs", "triples"])
def test_the_entries_kept_for_derivations_stay_within_a_few_strides(pattern):
    """``trim`` drops the entries before the horizon through the newest snapshot among them only now and then:
    however a stream's trims fall against its snapshots (one entry a trim, or two and three at once), what it
    keeps before the horizon stays within two strides and a trim's worth."""
    per = {"alone": 1, "pairs": 2, "triples": 3}[pattern]
    core = FusionCore(make_config(extra_filter="history_s = 0.05"))
    h_max = 0
    for k in range(3000):
        t = 1.0 + 0.01 * k
        for j in range(per):  # samples at one instant trim together at the next
            core.ingest(imu(t + 1e-5 * j, gyro=(0.0, 0.0, 0.1)) if j != 1 else odom(t + 1e-5, v=0.5, w=0.1))
        h = core.history
        h_max = max(h_max, h.start - h.kept)
    assert h_max <= 2 * history.STRIDE_MAX + per
    assert len(core.history.keys) < 2 * history.COMPACT + 20  # compacted as it goes
