"""The daemon worker's wake-up plan (`DrainSchedule`): pure arithmetic, checked with numbers and with
a discrete-event simulation of the worker at 1 kHz IMU + 100 Hz odometry (simulated time, no clock)."""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fusiond.transport.drain_schedule import LEAD_S, MAX_INTERVAL, DrainSchedule

HOLD = 0.01
PERIOD = 0.01  # 100 Hz odometry


def learnt(period: float = PERIOD, n: int = 30, t0: float = 100.0) -> DrainSchedule:
    """A schedule that has seen `n` odometry arrivals `period` apart, the last at t0."""
    s = DrainSchedule(HOLD)
    for k in range(n):
        s.on_prompt(t0 - (n - 1 - k) * period)
    return s


def test_before_any_odometry_only_the_hold_bounds_a_wait():
    s = DrainSchedule(HOLD)
    assert s.next_wait(5.0) == (HOLD, False)
    s.on_prompt(5.0)  # one arrival is no period yet
    assert s.next_wait(5.001) == (HOLD, False)


def test_hold_zero_wakes_the_worker_for_every_arrival():
    s = learnt()
    s.hold_s = 0.0
    assert s.next_wait(100.003) == (math.inf, True)


def test_negative_durations_are_refused():
    with pytest.raises(ValueError, match="hold_s"):
        DrainSchedule(-0.001)
    with pytest.raises(ValueError, match="lead_s"):
        DrainSchedule(0.01, lead_s=-1.0)


def test_the_period_is_learnt_from_arrivals_and_pauses_or_repeats_do_not_stretch_it():
    s = learnt()
    assert s.period == pytest.approx(PERIOD, abs=1e-12)
    s.on_prompt(100.0)  # a repeated arrival time: ignored
    s.on_prompt(100.0 + 5 * MAX_INTERVAL)  # odometry paused: re-anchored, the period kept
    assert s.period == pytest.approx(PERIOD, abs=1e-12)
    assert s.last == 100.0 + 5 * MAX_INTERVAL


def test_between_odometry_samples_the_worker_batches_until_the_window_opens():
    s = learnt()  # last odometry at 100.000 s: the next is due at 100.010 s
    wait, any_arrival = s.next_wait(100.0005)
    assert not any_arrival
    # the window opens lead_s before the due time (no backlog timed yet)
    assert wait == pytest.approx(100.010 - LEAD_S - 100.0005, abs=1e-9)


def test_inside_the_window_every_arrival_wakes_the_worker_until_lead_s_after_the_due_time():
    s = learnt()
    wait, any_arrival = s.next_wait(100.0095)
    assert any_arrival
    assert wait == pytest.approx(100.010 + LEAD_S - 100.0095, abs=1e-9)


def test_a_late_odometry_sample_is_expected_a_period_later():
    s = learnt()
    now = 100.010 + LEAD_S + 0.0001  # past the window: it did not come
    wait, any_arrival = s.next_wait(now)
    assert not any_arrival
    assert wait == pytest.approx(100.020 - LEAD_S - now, abs=1e-9)


def test_a_long_backlog_opens_the_window_earlier_and_the_estimate_recovers_when_none_builds():
    s = learnt()
    s.on_backlog(0.003)
    wait, any_arrival = s.next_wait(100.001)
    assert not any_arrival and wait == pytest.approx(100.010 - LEAD_S - 0.003 - 100.001, abs=1e-9)
    s.on_prompt(100.010)  # a backlog was timed in this period: kept
    assert s.batch_s == 0.003
    s.on_prompt(100.020)  # none in this one: halved, so a stale long estimate cannot keep the window open
    assert s.batch_s == 0.0015


@given(st.floats(1e-4, 0.5), st.floats(0.0, 0.02), st.floats(0.0, 0.05), st.floats(-2.0, 2.0),
       st.floats(1e-4, 0.05))
def test_waits_are_never_negative_and_a_batching_wait_never_exceeds_the_hold(period, batch_s, lead, offset, hold):
    s = DrainSchedule(hold, lead_s=lead)
    s.on_prompt(10.0 - period)
    s.on_prompt(10.0)
    s.on_backlog(batch_s)
    wait, any_arrival = s.next_wait(10.0 + offset)
    assert wait >= 0.0
    if not any_arrival:
        assert wait <= hold


# --------------------------------------------------------------------------- simulated worker


@dataclass
class Sim:
    """The daemon's worker loop on simulated time: samples arrive, wait in the inbox, and are fused
    one after another at a fixed cost each; odometry (and any arrival in a wake-on-any wait) ends a
    wait at once. What it records is what the schedule is for: wake-ups, how long each IMU sample
    waited for its batch, and how long each odometry sample waited before its own fusing began."""

    imu_cost: float
    odom_cost: float
    wakeups: int = 0
    imu_waits: list[float] = field(default_factory=list)
    odom_waits: list[float] = field(default_factory=list)

    def run(self, arrivals: list[tuple[float, str]], hold: float = HOLD) -> None:
        s = DrainSchedule(hold)
        now, i, idle = 0.0, 0, True
        while i < len(arrivals):
            # wait: until the wait's end, an odometry arrival, or (wake on any) any arrival
            if idle:
                limit, any_arrival = math.inf, True
            else:
                wait, any_arrival = s.next_wait(now)
                limit = now + wait
            nxt = next((t for t, kind in arrivals[i:] if any_arrival or kind == "odom"), math.inf)
            woke = min(limit, nxt)
            pending = arrivals[i][0] <= woke
            timed_out = woke == limit and limit < nxt
            if not pending:
                now = woke
                idle = timed_out and not any_arrival
                continue
            now, idle = woke, False
            backlog = timed_out and not any_arrival
            self.wakeups += 1
            started = now
            while i < len(arrivals) and arrivals[i][0] <= now:  # drain, including arrivals while fusing
                t, kind = arrivals[i]
                i += 1
                if kind == "odom":
                    s.on_prompt(t)
                    self.odom_waits.append(now - t)
                    now += self.odom_cost
                else:
                    self.imu_waits.append(now - t)
                    now += self.imu_cost
            if backlog:
                s.on_backlog(now - started)


def traffic(seconds: float, jitter: float = 0.0, seed: int = 1) -> list[tuple[float, str]]:
    """1 kHz IMU at k ms; 100 Hz odometry half a millisecond after every tenth IMU (as
    `fusiond bench-latency` sends it), optionally with uniform arrival jitter of +-`jitter` s."""
    rng = random.Random(seed)
    out = [(k * 1e-3, "imu") for k in range(int(seconds * 1000))]
    out += [(k * PERIOD + 0.0005 + rng.uniform(-jitter, jitter), "odom") for k in range(int(seconds / PERIOD))]
    return sorted(out)


def test_simulated_worker_wakes_a_few_times_per_odometry_period_and_odometry_never_waits():
    # Costs as measured on this machine's worker (about 150 us an IMU sample, 300 us an odometry
    # sample with its publishing); the schedule takes the backlog's duration from what it observes.
    sim = Sim(imu_cost=150e-6, odom_cost=300e-6)
    sim.run(traffic(5.0))
    steady = sim.odom_waits[10:]  # the period is known after the first few
    # Every odometry sample finds the worker idle and the inbox empty: its fusing starts on arrival.
    assert max(steady) == 0.0
    # Wake-ups per 10 ms period: the odometry sample, the backlog when the window opens, and the IMU
    # samples arriving inside the window (lead_s + the backlog's ~1 ms before the due time, lead_s
    # after: 3 ms at 1 kHz), against 11 with a wake-up per message.
    periods = 5.0 / PERIOD
    assert sim.wakeups / periods <= 1 + 1 + 3
    # No IMU sample waits longer than the hold plus the fusing of the batch ahead of it.
    assert max(sim.imu_waits) <= HOLD + 10 * 150e-6


def test_simulated_odometry_jitter_inside_the_lead_still_finds_an_empty_inbox():
    sim = Sim(imu_cost=150e-6, odom_cost=300e-6)
    sim.run(traffic(5.0, jitter=0.4 * LEAD_S, seed=7))
    # an odometry sample can still meet one IMU sample being fused when it arrives (the window wakes
    # the worker for each), never a backlog: at most one IMU sample's cost
    assert max(sim.odom_waits[10:]) <= 150e-6 + 1e-12


def test_simulated_imu_without_odometry_is_fused_within_the_hold():
    sim = Sim(imu_cost=150e-6, odom_cost=300e-6)
    sim.run([(k * 1e-3, "imu") for k in range(2000)])
    assert len(sim.imu_waits) == 2000
    assert max(sim.imu_waits) <= HOLD + 1e-3  # the hold, plus the arrival that woke an idle worker
    # batches of about hold_s of samples: roughly one wake-up per 10 IMU samples, not one each
    assert sim.wakeups <= 2000 / 5


def test_simulated_hold_zero_is_one_wake_up_per_message():
    sim = Sim(imu_cost=150e-6, odom_cost=300e-6)
    arrivals = traffic(1.0)
    sim.run(arrivals, hold=0.0)
    assert sim.wakeups == len(arrivals)
