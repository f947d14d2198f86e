"""The doctor folds what it is fed into its statistics in bulk, a chunk at a time: the replay feeds
it every message, and one-at-a-time bookkeeping would cost more than half of the fusion core's own time.

The bulk code claims the same floats as a one-at-a-time loop: running sums are continued
across chunks, bins and integrations carry over, the reorder buffer releases samples in the same order.
So the doctor's whole output must not depend on where the chunks end, and the pieces are held to direct
one-at-a-time references (a heap for the reorder buffer, a deque for the NIS window, plain sums).
"""

from __future__ import annotations

import heapq
import math
import random

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond import doctor as doctor_package
from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.doctor import ChannelStats, attitude, series, twist
from fusiond.doctor.attitude import TiltStats
from fusiond.doctor.nis import judge_nis
from fusiond.doctor.series import REORDER_S, release_order
from fusiond.doctor.twist import TwistStats
from fusiond.estimator.rotation import to_rpy
from fusiond.replay.run import run_samples

from tests.support import sim_gps
from tests.support.configs import robot_config
from tests.support.sim import arrival_order

CHUNKED_MODULES = (doctor_package, series, attitude, twist)


def heap_release(stamps: list[float]) -> list[int]:
    """The reorder buffer one sample at a time: a heap on (stamp, arrival), released once a sample
    stamped more than REORDER_S later has arrived, the rest at the end."""
    heap: list[tuple[float, int]] = []
    newest, out = -math.inf, []
    for i, t in enumerate(stamps):
        heapq.heappush(heap, (t, i))
        newest = max(newest, t)
        while heap and heap[0][0] < newest - REORDER_S:
            out.append(heapq.heappop(heap)[1])
    while heap:
        out.append(heapq.heappop(heap)[1])
    return out


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(0.0, 8.0, allow_nan=False).map(lambda t: round(t, 1)), max_size=120),
       st.integers(1, 40))
def test_release_order_is_the_reorder_heaps_in_any_chunking(stamps, chunk):
    # stamps rounded to 0.1 s: many ties (released by arrival) and many exactly REORDER_S apart
    got, held, newest = [], [], -math.inf
    for start in range(0, len(stamps), chunk):
        held += range(start, min(start + chunk, len(stamps)))
        order, still, newest = release_order(np.array([stamps[i] for i in held], dtype=float), newest, False)
        got += [held[i] for i in order]
        held = [p for p, h in zip(held, still) if h]
    order, still, _ = release_order(np.array([stamps[i] for i in held], dtype=float), newest, True)
    got += [held[i] for i in order]
    assert not still.any()
    assert got == heap_release(stamps)


def doctor_output(result) -> bytes:
    """Everything the doctor computed, encoded exactly (floats as their shortest round-trip text)."""
    doctor = result.doctor
    channels = {}
    for (sensor, channel), ch in sorted(doctor.channels.items()):
        channels[f"{sensor}/{channel}"] = {
            "summary": ch.summary(doctor.t0), "n_comp": ch.n_comp, "sums": ch.sums, "outer": ch.outer,
            "variances": ch.variances, "nis_sum": ch.nis_sum, "nis_sum_kept": ch.nis_sum_kept,
            "now": [ch.now_verdict, ch.now_since], "recent_sum": ch.recent_sum, "stamps": ch.stamps,
            "rejected_flags": ch.rejected_flags, "innovations": ch.innovations}
    names = sorted({s.name for s in doctor.cfg.sensors})
    return msgspec.json.encode({
        "series": doctor.series(), "channels": channels, "t0": doctor.t0,
        "tilt": [doctor.tilt.n, doctor.tilt.sums, doctor.tilt.squares],
        "twist": [doctor.twist.n, doctor.twist.abs_vx, doctor.twist.abs_vy, doctor.twist.abs_wz],
        "clocks": {n: doctor.clocks.offset(n) for n in names},
        "verdicts": result.verdicts()})


def late_block(samples: list, sensor: str, t0: float, t1: float, by: float) -> list:
    """The sensor's samples stamped t0..t1 s into the run arrive ``by`` seconds late (a stalled link)."""
    start = samples[0].stamp
    keyed = [(s.stamp + (by if s.sensor == sensor and t0 <= s.stamp - start < t1 else 0.0), i, s)
             for i, s in enumerate(samples)]
    return [s for _, _, s in sorted(keyed, key=lambda k: (k[0], k[1]))]


@pytest.mark.parametrize("arrival", ["jittered", "imu_block_late"])
def test_the_doctors_output_does_not_depend_on_where_the_chunks_end(monkeypatch, arrival):
    """A GPS robot whose samples arrive out of order: each sensor with its own lag and jitter, the GPS
    fixes 1.5 s late; or a 4 s block of IMU samples 1.5 s late. Both are later than the reorder window,
    so those samples are integrated as they arrive, out of stamp order (older samples joining the open
    bin). Chunks of 7 (records, samples, poses) cut through bins, integrations, the NIS window and the
    held samples hundreds of times; the output must be the same to the last bit."""
    samples = sim_gps.simulate(sim_gps.World(duration=60.0, gps_rate=1.0))
    if arrival == "jittered":
        samples = arrival_order(samples, lag={"gps": 1.5, "imu": 0.02, "wheel": 0.01}, jitter=0.03, seed=5)
    else:
        samples = late_block(samples, "imu", 10.0, 14.0, 1.5)
    cfg = robot_config(gps="")
    whole = doctor_output(run_samples(samples, cfg))
    for module in CHUNKED_MODULES:
        monkeypatch.setattr(module, "CHUNK", 7)
    chunked = doctor_output(run_samples(samples, cfg))
    assert b'"gps_t":[]' not in whole and b'"odom_t":[]' not in whole  # the streams were there to compare
    assert chunked == whole


def random_records(rng: random.Random, n: int) -> list[DiagnosticsRecord]:
    """Records of two shapes, some learning, some gated, some without a finite NIS. NIS values are
    multiples of 1/8 below 64, so every window sum is exact and a plain sum() is a valid reference."""
    out = []
    for k in range(n):
        comps = ["x", "y", "yaw"] if rng.random() < 0.8 else ["x", "y"]
        d = len(comps)
        nis = rng.choice([math.inf, math.nan]) if rng.random() < 0.03 else rng.randrange(0, 512) / 8.0
        out.append(DiagnosticsRecord(float(k) * 0.1, "gps", comps, [rng.gauss(0.0, 1.0) for _ in comps],
                                     [rng.uniform(0.5, 2.0) for _ in comps], nis, d, rng.random() < 0.1,
                                     channel="position", learning=k < 20 and rng.random() < 0.5))
    return out


def test_channel_stats_in_chunks_are_the_one_record_at_a_time_figures():
    rng = random.Random(11)
    records = random_records(rng, 700)
    one_by_one = ChannelStats(["x", "y", "yaw"], window=50, keep=True)
    for r in records:
        one_by_one.add(r)
    chunked = ChannelStats(["x", "y", "yaw"], window=50, keep=True)
    start = 0
    while start < len(records):
        step = rng.randint(1, 90)
        chunked.extend(records[start:start + step])
        start += step
    assert msgspec.json.encode(vars(chunked) | {"recent": list(chunked.recent)}) == \
        msgspec.json.encode(vars(one_by_one) | {"recent": list(one_by_one.recent)})

    # the references, one record at a time
    judged = [r for r in records if not r.learning and math.isfinite(r.nis) and r.dof > 0]
    same = [r for r in records if not r.learning and r.components == ["x", "y", "yaw"]]
    assert chunked.n == len(records) and chunked.n_nis == len(judged) and chunked.n_comp == len(same)
    assert chunked.dof_sum == sum(r.dof for r in judged) and chunked.dof == judged[-1].dof
    assert chunked.rejected == sum(r.rejected for r in records)
    total = 0.0
    for r in judged:
        total += r.nis
    assert chunked.nis_sum == total
    for i in range(3):
        s = 0.0
        for r in same:
            s += r.innovation[i]
        assert chunked.sums[i] == s
    verdict, since = "no_updates", None
    for k, r in enumerate(judged):
        window = judged[max(0, k - 49):k + 1]
        m = len(window)
        v = judge_nis(sum(w.nis for w in window) / m, m, sum(w.dof for w in window) / m, chunked.confidence)
        if v != verdict:
            verdict, since = v, r.stamp
    assert (chunked.now_verdict, chunked.now_since) == (verdict, since)


def test_tilt_and_twist_sums_are_the_one_at_a_time_sums(monkeypatch):
    monkeypatch.setattr(attitude, "CHUNK", 13)
    monkeypatch.setattr(twist, "CHUNK", 13)
    rng = np.random.default_rng(2)
    quats = rng.normal(size=(300, 4))
    quats /= np.linalg.norm(quats, axis=1)[:, None]
    tilt = TiltStats()
    sums, squares = [0.0, 0.0], [0.0, 0.0]
    for q in quats.tolist():
        tilt.add_orientation(tuple(q))
        roll, pitch, _ = to_rpy(tuple(q))
        for i, a in enumerate((roll, pitch)):
            sums[i] += a
            squares[i] += a * a
    assert (tilt.n, tilt.sums, tilt.squares) == (300, sums, squares)

    twists = rng.normal(size=(300, 6)).tolist()
    stats = TwistStats()
    vx = vy = wz = 0.0
    for row in twists:
        stats.add(tuple(row[:3]), tuple(row[3:]))
        vx += abs(row[0])
        vy += abs(row[1])
        wz += abs(row[5])
    assert (stats.n, stats.abs_vx, stats.abs_vy, stats.abs_wz) == (300, vx, vy, wz)
