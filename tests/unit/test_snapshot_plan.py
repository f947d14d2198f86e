"""A replay that knows every sample to come takes no history snapshot where no later sample lands
(``FusionCore.snapshot_plan``): its estimates, records and counters must be the ones of the core that
keeps every snapshot, late samples, duplicates, dropped stamps and time jumps included."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond.core.fusion import FusionCore
from fusiond.core.history import snapshots_read, unrecorded_from
from fusiond.errors import CoreError

from tests.support.core_samples import imu, make_config, odom, plans_made

ROOT = Path(__file__).resolve().parents[2]


def _read_by_definition(keys: list) -> list[bool]:
    """Entry i's snapshot can be read when a later sample, late then (below the greatest key before
    it), has a greater key or the same (placed after the entry it repeats)."""
    out = []
    for i, k in enumerate(keys):
        if k is None:
            out.append(True)
            continue
        out.append(any(
            kj is not None and kj >= k and kj < max((kk for kk in keys[:j] if kk is not None), default=kj)
            for j, kj in enumerate(keys) if j > i))
    return out


@settings(max_examples=200, deadline=None)
@given(keys=st.lists(st.one_of(st.none(), st.tuples(st.integers(0, 30).map(float), st.integers(0, 2))),
                     max_size=40))
def test_snapshots_read_is_its_definition(keys):
    assert snapshots_read(keys) == _read_by_definition(keys)


def test_samples_in_order_read_no_snapshot_and_one_late_sample_its_predecessors():
    assert snapshots_read([(1.0, 0), (2.0, 0), (3.0, 1)]) == [False, False, False]
    # (2.0, 0) comes after (3.0, 0): it lands right after (1.0, 0), whose snapshot is read
    assert snapshots_read([(1.0, 0), (3.0, 0), (2.0, 0), (4.0, 0)]) == [True, False, False, False]


def _stream(draw_late, draw_jump) -> list:
    """100 Hz odometry and IMU, some IMU samples late (in blocks of 20 samples, so that runs in order
    lie between them), some duplicated, some with unusable stamps, and runs of far stamps (a forward
    jump that holds, a glitch the stream leaves, a backward jump)."""
    out = []
    t = 1.0
    for k in range(240):
        t += 0.01
        out.append(odom(t, v=0.5, w=0.2 * math.sin(0.05 * k)))
        late = draw_late[(k // 20) % len(draw_late)] if k % 3 == 0 else 0.0
        out.append(imu(t - late if late else t + 0.004, rpy=(0.01, -0.02, 0.1 * k * 0.01),
                       gyro=(0.0, 0.0, 0.2 * math.sin(0.05 * k))))
        if k % 37 == 5:
            out.append(out[-2])  # a duplicate of the odometry sample
        if k % 41 == 9 and late:  # a late IMU stamp repeated with new values (a driver's clock that stalls)
            again = out[-1]
            out.append(imu(again.stamp, rpy=(0.01, -0.02, 0.1 * k * 0.01), gyro=(0.0, 0.0, 0.3)))
        if k % 53 == 7:
            out.append(odom(math.nan, v=0.5))
        jump = draw_jump[(k // 60) % len(draw_jump)]
        if jump and k % 60 == 30:
            for n in range(4):  # far stamps: held, then confirmed (a new timeline) or dropped as the stream goes on
                out.append(odom(t + jump + 0.4 * n, v=0.5))
            if jump > 0:
                t += jump + 1.6
            elif jump < -10.0:
                t = max(t + jump + 1.6, 0.5)
    return out


def _run(cfg, samples, plan: bool):
    core = FusionCore(cfg)
    keeps = core.snapshot_plan(samples) if plan else [True] * len(samples)
    steps = []
    for s, keep in zip(samples, keeps):
        step = core.ingest(s, keep)
        steps.append((step.sensor, step.accepted, step.reason, step.late, step.publish,
                      [(r.channel, r.stamp, list(r.innovation), r.nis, r.rejected) for r in step.records],
                      None if not step.publish else (core.pose()[0], core.pose()[1].tolist())))
    stats = [(st.received, st.applied, st.late, st.rejected, dict(st.dropped)) for st in core.stats]
    return core, steps, stats


@settings(max_examples=15, deadline=None)
@given(late=st.lists(st.sampled_from([0.0, 0.0, 0.0, 0.013, 0.035, 0.2, 1.5]), min_size=1, max_size=12),
       jump=st.lists(st.sampled_from([0.0, 0.0, 20.0, -30.0, -3.0]), min_size=1, max_size=4),
       history_s=st.sampled_from([0.05, 0.3, 1.0]))
def test_a_planned_replay_is_the_replay_that_keeps_every_snapshot(late, jump, history_s):
    cfg = make_config(extra_filter=f"history_s = {history_s}")
    samples = _stream(late, jump)
    core_a, steps_a, stats_a = _run(cfg, samples, plan=False)
    core_b, steps_b, stats_b = _run(cfg, samples, plan=True)
    assert steps_b == steps_a
    assert stats_b == stats_a
    assert core_b.resets == core_a.resets
    assert np.array_equal(core_b.state.ekf.x, core_a.state.ekf.x)
    assert np.array_equal(core_b.state.ekf.P, core_a.state.ekf.P)


def test_a_late_stamp_repeated_with_new_values_reads_the_snapshot_of_the_entry_it_repeats():
    """An IMU whose clock stalls a second behind the others: each message repeats the stamp of the first, with
    new values, and is placed right after it (found by the replay of a recording whose IMU stamps froze)."""
    assert snapshots_read([(1.0, 1), (2.0, 0), (1.0, 1), (2.1, 0), (1.0, 1)]) == [True, False, True, False, False]
    cfg = make_config()
    samples = []
    for k in range(30):
        samples.append(odom(2.0 + 0.01 * k, v=0.3))
        samples.append(imu(1.5, gyro=(0.0, 0.0, 0.01 * k)))
    _, steps_a, stats_a = _run(cfg, samples, plan=False)
    _, steps_b, stats_b = _run(cfg, samples, plan=True)
    assert steps_b == steps_a and stats_b == stats_a


def test_samples_in_order_take_no_history_entry():
    cfg = make_config()
    samples = [s for k in range(50) for s in (odom(1.0 + 0.01 * k, v=0.3), imu(1.0 + 0.01 * k + 0.005))]
    core = FusionCore(cfg)
    plan = core.snapshot_plan(samples)
    assert plan == [None] * len(samples)
    for s, keep in zip(samples, plan):
        core.ingest(s, keep)
    h = core.history
    assert not h.keys and h.newest == (1.0 + 0.01 * 49 + 0.005, 1)


def test_after_the_last_late_sample_the_plan_records_nothing():
    """Snapshots where a late sample lands, entries up to the last one that comes late or repeats a key, none
    after it."""
    keys = [(1.0, 0), (3.0, 0), (2.0, 0), (4.0, 0), (4.0, 0), (5.0, 1), (6.0, 0)]
    assert unrecorded_from(keys) == 5  # after the repeated (4.0, 0)
    assert unrecorded_from([None, (1.0, 0), None, (2.0, 0)]) == 0
    assert unrecorded_from([]) == 0
    cfg = make_config()
    samples = [odom(1.0, v=0.3), odom(1.03, v=0.3), odom(1.02, v=0.3), odom(1.04, v=0.3), odom(1.05, v=0.3)]
    core = FusionCore(cfg)
    assert core.snapshot_plan(samples) == [True, False, False, None, None]


def test_a_sample_placed_before_one_that_took_no_entry_is_an_error_not_a_wrong_estimate():
    core = FusionCore(make_config())
    for k in range(10):
        core.ingest(odom(1.0 + 0.01 * k, v=0.3), keep=k < 5 or None)
    with pytest.raises(CoreError, match="snapshot plan"):
        core.ingest(imu(1.075))  # among the samples placed without an entry
    with pytest.raises(CoreError, match="snapshot plan"):
        core.ingest(imu(1.035))  # among the entries, with samples placed without one after them
    with pytest.raises(CoreError, match="snapshot plan"):
        core.ingest(odom(1.09, v=0.3), keep=None)  # a repeat of the newest, said to need no entry


def test_a_late_sample_the_plan_did_not_foresee_is_an_error_not_a_wrong_estimate():
    core = FusionCore(make_config())
    for k in range(10):
        core.ingest(odom(1.0 + 0.01 * k, v=0.3), keep=False)
    with pytest.raises(CoreError, match="snapshot plan"):
        core.ingest(imu(1.045))


@pytest.mark.skipif(not (ROOT / "data" / "jackal_test2.bag").exists(), reason="the Jackal bag is not here")
def test_the_jackal_bag_with_its_late_imu_samples_replays_the_same_planned():
    """One IMU message in five comes late in this recording."""
    from fusiond.config import load
    from fusiond.replay.bag import open_bag_samples

    cfg = load(ROOT / "examples" / "jackal.toml")
    with open_bag_samples([ROOT / "data" / "jackal_test2.bag"], cfg.sensors) as b:
        samples = list(b)[:3000]
    _, steps_a, stats_a = _run(cfg, samples, plan=False)
    _, steps_b, stats_b = _run(cfg, samples, plan=True)
    assert any(s[3] for s in steps_a)  # late samples were placed
    assert steps_b == steps_a and stats_b == stats_a


def _records(records) -> list:
    return [(r.sensor, r.channel, r.stamp, list(r.innovation), r.nis, r.rejected) for r in records]


def test_the_plans_of_a_recording_are_made_once_per_sensor_keys_and_replay_it_alike(monkeypatch):
    """``likelihood.Plans``: replays of one recording whose configs key its samples alike (sensor names, order,
    stamp offsets) share one plan, and replay exactly as each making its own; a shifted clock makes its own."""
    from fusiond.errors import TuneError
    from fusiond.tune.advice import with_suggestion
    from fusiond.doctor import Verdict
    from fusiond.tune.likelihood import Plans, replay_records

    cfg = make_config()
    samples = _stream([0.0, 0.035, 0.0], [0.0])
    noisier, _ = with_suggestion(cfg, Verdict("wheel", "twist", "problem", "", key="sensors.wheel.twist_noise",
                                              suggestion="twist_noise = [0.3, 0.1, 0.1, 0.1, 0.1, 0.05]"))
    shifted, _ = with_suggestion(cfg, Verdict("imu", "clock", "problem", "", key="sensors.imu.stamp_offset_s",
                                              suggestion="stamp_offset_s = 0.02"))
    alone = [_records(replay_records(c, samples)) for c in (cfg, noisier, shifted)]
    made = plans_made(monkeypatch)
    plans = Plans(samples)
    shared = [_records(replay_records(c, samples, plans=plans)) for c in (cfg, noisier, shifted, cfg)]
    assert shared == [*alone, alone[0]]
    assert len(made) == 2  # one for the configured clocks (cfg and the noisier one), one for the shifted IMU
    assert Plans.keys(noisier) == Plans.keys(cfg) != Plans.keys(shifted)
    with pytest.raises(TuneError):
        replay_records(cfg, list(samples), plans=plans)  # the plans of another list of samples
    with pytest.raises(TuneError):
        Plans(samples).add(cfg, [None])


def test_a_replay_holding_its_recording_hands_out_its_samples_and_their_plan():
    """``ReplayResult.samples`` and ``.plan`` (what the advice's replays take again), read ahead or not."""
    from fusiond.config import load
    from fusiond.replay.run import replay

    cfg = load(ROOT / "examples" / "jackal.toml")
    for read_ahead in (True, False):
        result = replay([ROOT / "data" / "jackal_test2.bag"], cfg, progress=False, doctor=False,
                        lookahead=True, read_ahead=read_ahead)
        assert result.samples is not None and len(result.samples) == result.messages
        assert result.plan is None or result.plan == FusionCore(cfg).snapshot_plan(result.samples)
        assert read_ahead or result.plan is not None
    assert replay([ROOT / "data" / "jackal_test2.bag"], cfg, progress=False, doctor=False).samples is None
