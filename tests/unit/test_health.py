"""Health logic with an injected wall clock: no Zenoh, no threads, no sleeping."""

from __future__ import annotations

import math

import pytest

from fusiond.config import loads
from fusiond.core.fusion import FusionCore
from fusiond.health import (
    FilterHealth,
    Health,
    core_counters,
    decode_report,
    encode_report,
)
from fusiond.core.sensors import ImuSample, OdomSample
from tests.support.configs import sensor_tables


class Clock:
    def __init__(self, t: float = 100.0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def feed(h: Health, clock: Clock, until: float, periods: dict[int, float]) -> None:
    """Both sensors arriving at their periods until wall time `until`."""
    nxt = {i: clock.t for i in periods}
    while True:
        i = min(nxt, key=nxt.get)
        if nxt[i] > until:
            break
        clock.t = nxt[i]
        h.on_received(i)
        h.on_accepted(i, clock.t)
        nxt[i] += periods[i]
    clock.t = until


def test_starting_then_ok_then_degraded_naming_the_sensor_then_failed():
    clock = Clock()
    h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock, queue_capacity=8)
    rep = h.report()
    assert rep.status == "starting"  # waiting for the first samples is not a failure
    assert rep.sensors["wheel"].age_s is None and rep.problems[:2] == ["wheel: no sample yet", "imu: no sample yet"]
    assert "no sensor alive" not in rep.problems and "starting: waiting for the first samples" in rep.problems
    h.on_received(0)  # received, still in the queue: still starting
    assert h.report().status == "starting"

    feed(h, clock, 102.0, {0: 0.02, 1: 0.01})
    rep = h.report()
    assert rep.status == "ok" and rep.problems == []
    assert rep.sensors["imu"].alive and rep.sensors["imu"].rate_hz == pytest.approx(100.0)
    assert rep.sensors["wheel"].rate_hz == pytest.approx(50.0)
    assert rep.sensors["wheel"].received == 102  # 101 fed + the one received while starting

    # the IMU stops; the wheel goes on
    feed(h, clock, 102.15, {0: 0.02})
    assert h.report().status == "ok"  # 0.15 s < timeout 0.2 s
    feed(h, clock, 102.25, {0: 0.02})
    rep = h.report()
    assert rep.status == "degraded"
    assert not rep.sensors["imu"].alive and rep.sensors["wheel"].alive
    assert rep.sensors["imu"].rate_hz == 0.0 and rep.sensors["imu"].age_s == pytest.approx(0.25, abs=0.02)
    assert len(rep.problems) == 1 and rep.problems[0].startswith("imu: silent for 0.2")

    clock.t += 1.0  # everything silent
    rep = h.report()
    assert rep.status == "failed"
    assert "no sensor alive" in rep.problems and any(p.startswith("wheel:") for p in rep.problems)

    feed(h, clock, clock.t + 0.5, {0: 0.02, 1: 0.01})  # back
    assert h.report().status == "ok"


def test_without_its_odometry_a_daemon_publishes_nothing_and_is_starting_then_failed_however_alive_its_imu():
    """Only the odometry's samples prompt a publish: an IMU alone keeps the daemon `starting` (nothing published
    yet, not an error) until the first odometry sample, and an odometry that dies later leaves nothing published:
    `failed`, naming it, though the IMU is alive. Every sensor counts when the flags are not given."""
    clock = Clock()
    h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock, publishing=[True, False])
    t0 = clock.t
    feed(h, clock, t0 + 1.0, {1: 0.01})  # the IMU first (its driver came up first, or the odometry's key is wrong)
    rep = h.report()
    assert rep.status == "starting" and rep.sensors["imu"].alive, rep
    assert "wheel: no sample yet" in rep.problems and "starting: waiting for the first samples" in rep.problems
    feed(h, clock, t0 + 2.0, {0: 0.02, 1: 0.01})
    assert h.report().status == "ok"
    feed(h, clock, t0 + 3.0, {1: 0.01})  # the odometry dies
    rep = h.report()
    assert rep.status == "failed" and rep.sensors["imu"].alive and not rep.sensors["wheel"].alive, rep
    assert "nothing is published: wheel, whose samples prompt every publish, not alive" in rep.problems
    feed(h, clock, t0 + 3.5, {0: 0.02, 1: 0.01})  # back
    assert h.report().status == "ok"

    every = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock)  # no flags: any sensor's samples count
    feed(every, clock, clock.t + 1.0, {1: 0.01})
    assert every.report().status == "degraded"
    with pytest.raises(ValueError, match="publishing"):
        Health([("wheel", 0.2), ("imu", 0.2)], clock=clock, publishing=[False, False])


def test_timeout_follows_a_slow_sensor_so_it_does_not_flap():
    """5 Hz odometry with 0.4 s gaps: timeout max(0.2, 3 x period) ~ 0.6-1.2 s, never flagged."""
    clock = Clock()
    h = Health([("wheel", 0.2)], clock=clock)
    t = clock.t
    statuses = set()
    for k in range(60):
        t += 0.4 if k % 3 == 0 else 0.15
        while clock.t < t:  # the operator polls every 50 ms in between
            clock.t = min(clock.t + 0.05, t)
            statuses.add(h.report().status)
        h.on_received(0)
        h.on_accepted(0, t)
    statuses.discard("starting")  # before the first sample
    assert statuses == {"ok"}
    assert h.report().sensors["wheel"].timeout_s > 0.4


def test_drops_are_counted_per_reason_and_garbage_does_not_keep_a_sensor_alive():
    clock = Clock()
    h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock, queue_capacity=4, queue_depth=lambda: 3)
    for _ in range(5):
        h.on_received(1)
        h.on_dropped(1, "cdr_invalid")
    assert h.on_dropped(1, "queue_full") == 1
    h.on_received(0)
    h.on_accepted(0, clock.t)
    rep = h.report()
    imu = rep.sensors["imu"]
    assert not imu.alive and imu.received == 5 and imu.dropped == 6
    assert imu.dropped_by_reason == {"cdr_invalid": 5, "queue_full": 1}
    assert rep.problems[0] == "imu: no usable sample yet (5 received)"
    assert rep.queue.depth == 3 and rep.queue.capacity == 4 and rep.queue.dropped == 1
    assert rep.status == "degraded"


def test_core_counters_merge_and_non_finite_filter_fails():
    cfg = loads('[[sensors]]\nname="wheel"\nkind="odom"\nkey="odom"\n'
                '[[sensors]]\nname="imu"\nkind="imu"\nkey="imu"\nangular_velocity=true\n')
    core = FusionCore(cfg)
    cov36 = tuple(0.01 if i % 7 == 0 else 0.0 for i in range(36))
    cov9 = (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4)
    for k in range(20):
        t = 10.0 + 0.02 * k
        core.ingest(OdomSample("wheel", t, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), cov36))
        core.ingest(ImuSample("imu", t + 0.01, (0.0, 0.0, 0.0, 1.0), cov9, (0.0, 0.0, 0.0), cov9))
    core.ingest(OdomSample("wheel", 0.0, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), cov36))  # invalid stamp
    clock = Clock()
    h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock)
    h.on_accepted(0, clock.t)
    h.on_accepted(1, clock.t)
    h.set_core(core_counters(core, published=20))
    rep = h.report()
    assert rep.status == "ok" and rep.published == 20
    assert rep.sensors["wheel"].applied == 20 and rep.sensors["wheel"].dropped_by_reason == {"invalid_stamp": 1}
    assert rep.filter.initialised and rep.filter.finite and rep.filter.time == pytest.approx(10.39)
    assert set(rep.consistency) == {"imu/orientation", "wheel/yaw_rate"}
    assert decode_report(encode_report(rep)) == rep

    counters = core_counters(core)
    counters.filter = FilterHealth(initialised=True, time=math.nan, finite=False)
    h.set_core(counters)
    rep = h.report()
    assert rep.status == "failed" and "filter: non-finite state" in rep.problems
    h.set_core(core_counters(core))
    h.set_worker_alive(False)
    assert h.report().status == "failed" and "worker: stopped" in h.report().problems


def test_out_of_order_arrival_times_are_ignored():
    clock = Clock()
    h = Health([("imu", 0.2)], clock=clock)
    h.on_accepted(0, 100.0)
    h.on_accepted(0, 100.01)
    h.on_accepted(0, 99.0)  # an older arrival (another link) must not move the clock back
    clock.t = 100.1
    rep = h.report()
    assert rep.sensors["imu"].age_s == pytest.approx(0.09) and rep.sensors["imu"].rate_hz == pytest.approx(100.0)


# (sensor, arrival, floored) of one pass's accepted samples, one arriving out of order
ARRIVALS = [(0, 100.0, False), (1, 100.001, True), (1, 100.011, False), (0, 100.02, True),
            (1, 100.005, True), (0, 100.04, False), (1, 100.021, False)]


def test_samples_noted_by_the_worker_read_as_the_same_samples_one_by_one():
    """The worker notes the samples it fused in `Health.noted` (a deque's append, no lock) and health counts
    them on `count_noted` or when a report is taken: the report is the one the same arrivals, floored flags
    and an out-of-order arrival give through `on_accepted` and `on_floored` one call at a time."""
    healths = []
    for noted in (False, True):
        clock = Clock(100.0)
        h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock)
        if noted:
            h.noted.extend(ARRIVALS[:3])
            h.count_noted()
            h.noted.extend(ARRIVALS[3:])  # counted by the report
        else:
            for idx, arrival, floored in ARRIVALS:
                h.on_accepted(idx, arrival)
                if floored:
                    h.on_floored(idx)
        clock.t = 100.05
        healths.append(h)
    one_by_one, noted = (encode_report(h.report()) for h in healths)
    assert one_by_one == noted
    rep = healths[1].report()
    assert rep.sensors["imu"].zero_covariance_floored == 2 and rep.sensors["wheel"].zero_covariance_floored == 1
    assert rep.sensors["wheel"].rate_hz == pytest.approx(1 / 0.02)  # 20 ms apart, twice (100.0, 100.02, 100.04)


def test_samples_noted_without_the_lock_are_counted_in_order_by_the_next_report_or_core_counters():
    """The worker notes each accepted sample with a deque's append (`Health.noted`), no lock and no call:
    the next report counts them, in the order noted, as the same arrivals one call at a time; the core's
    counters count them too, so they do not pile up while nobody asks for a report."""
    reports = []
    for noted in (False, True):
        clock = Clock(100.0)
        h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock)
        for idx, arrival, floored in ARRIVALS:
            if noted:
                h.noted.append((idx, arrival, floored))
            else:
                h.on_accepted(idx, arrival)
                if floored:
                    h.on_floored(idx)
        clock.t = 100.05
        reports.append(encode_report(h.report()))
    assert reports[0] == reports[1]
    h.noted.append((0, 100.06, True))
    h.set_core(core_counters(FusionCore(loads(sensor_tables()))))
    assert not h.noted
    assert h.report().sensors["wheel"].zero_covariance_floored == 2


def test_health_says_when_the_world_frame_is_not_defined_yet():
    """A GPS-referenced core publishes nothing before its first fix: health names the reason."""
    from fusiond.config import loads
    from fusiond.core.fusion import FusionCore
    from fusiond.health import core_counters
    from fusiond.core.sensors import ImuSample

    cfg = loads(sensor_tables("angular_velocity = true", gps="", gps_key="gps/fix"))
    core = FusionCore(cfg)
    f = core_counters(core).filter
    assert not f.initialised and not f.ready and f.not_ready_reason == "no sample fused yet"  # no pose to publish
    core.ingest(ImuSample("imu", 10.0, (0.0, 0.0, 0.0, 1.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4), (0.0, 0.0, 0.0),
                          (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)))
    f = core_counters(core).filter
    assert f.initialised and not f.ready and "first GPS fix" in f.not_ready_reason
    assert not f.heading_known


def test_a_fast_drive_whose_logger_pauses_does_not_flap_after_the_first_pause():
    """83 Hz odometry (period 12 ms: 3 periods is under the 0.2 s timeout) that pauses 0.4 s every 2 s. The
    first pause is longer than anything seen: the sensor reads silent in it. From then on the timeout holds
    1.5 x the longest recent interval (core/inputs.py), 0.6 s: every later pause stays ok. A pause longer than
    gap_s (a logging gap) is not learned."""
    clock = Clock()
    h = Health([("wheel", 0.2)], clock=clock, gap_s=0.5)
    t = clock.t
    statuses = []
    for k in range(800):
        t += 0.4 if k % 166 == 165 else 1.0 / 83.0
        while clock.t < t:
            clock.t = min(clock.t + 0.05, t)
            statuses.append((k, h.report().status))
        h.on_received(0)
        h.on_accepted(0, t)
    bad = [k for k, st in statuses if st not in ("ok", "starting")]
    assert bad and max(bad) <= 166, bad  # the first pause only
    assert h.report().sensors["wheel"].timeout_s == pytest.approx(1.5 * 0.4, rel=0.01)  # its pauses, recurring
    long = Health([("wheel", 0.2)], clock=clock, gap_s=0.5)
    for dt in (0.012, 0.012, 0.8, 0.012):
        clock.t += dt
        long.on_accepted(0, clock.t)
    assert long.report().sensors["wheel"].timeout_s < 0.3  # 3 periods of the EMA the gap moved, not 1.5 x 0.8 s


def test_the_ros_status_of_the_wheels_yaw_rate_check_says_slip_not_a_noise():
    """The wheels' yaw rate is a consistency check against the fused gyro, not an update: its NIS high is slip,
    only reported. A ROS status reading "R too small" of it sent a user to raise the wheels' yaw-rate noise, the
    doctor's opposite; its NIS low (a stated wheel noise nothing uses) is no warning. An update's NIS keeps the
    noise wording."""
    from fusiond.health import FilterHealth, HealthReport, QueueHealth, SensorHealth, ros_statuses

    def status(verdicts: dict[str, str]):
        sensor = SensorHealth(alive=True, age_s=0.01, rate_hz=50.0, received=100, dropped=0, rejected=0)
        report = HealthReport(status="ok", sensors={"wheel": sensor}, problems=[], filter=FilterHealth(),
                              queue=QueueHealth(), consistency={f"wheel/{ch}": {"nis_mean": 1.0, "verdict": v}
                                                                for ch, v in verdicts.items()})
        (s,) = [s for s in ros_statuses(report, "fusiond", {}) if s.name == "fusiond: wheel"]
        return int(s.level), s.message

    level, message = status({"yaw_rate": "nis_high"})
    assert level == 1 and "slip" in message and "R too small" not in message, message
    assert status({"yaw_rate": "nis_low"}) == (0, "alive")
    level, message = status({"twist": "nis_high"})
    assert level == 1 and "R too small" in message, message


def test_the_whole_run_reads_nis_high_when_the_gate_kept_out_more_than_its_share():
    """A channel whose updates the gate rejected three times in four over the run, the applied ones consistent:
    the whole run's verdict is nis_high by that share, as the window's and the replay's are (it read "ok", so
    the ROS status, which warns only where the two agree, never warned)."""
    from fusiond.core.diagnostics import REJECTED_SHARE, NisWindow

    w = NisWindow(50, 0.95)
    for k in range(400):
        w.add(1.0, 1, k % 4 != 0)
    assert w.summary()["run_verdict"] == "nis_high"
    few = NisWindow(50, 0.95)
    for k in range(400):  # a share within REJECTED_SHARE: the applied ones' mean decides
        few.add(1.0, 1, k % 20 == 0 and REJECTED_SHARE > 0.05)
    assert few.summary()["run_verdict"] == "ok"


def test_a_window_out_of_its_bounds_warns_on_ros_only_while_the_whole_run_is_too():
    """One window of an AHRS's coloured error reads NIS low and the next ok: the ROS status followed each window
    and flapped between OK and WARN twenty times a minute while the doctor read the channel consistent. The
    window's verdict warns only when the whole run's (``NisWindow.run_verdict``) is the same."""
    from fusiond.core.diagnostics import NisWindow
    from fusiond.health import FilterHealth, HealthReport, QueueHealth, SensorHealth, ros_statuses

    w = NisWindow(50, 0.95)
    for _ in range(500):
        w.add(2.0, 2, False)  # consistent for the dof
    for _ in range(50):
        w.add(0.1, 2, False)  # one low window
    summary = w.summary()
    assert summary["verdict"] == "nis_low" and summary["run_verdict"] == "ok", summary
    for _ in range(5000):
        w.add(0.1, 2, False)  # low for good: the run says so too
    assert w.summary()["run_verdict"] == "nis_low"

    def level(window: str, run: str) -> int:
        sensor = SensorHealth(alive=True, age_s=0.01, rate_hz=50.0, received=100, dropped=0, rejected=0)
        report = HealthReport(status="ok", sensors={"imu": sensor}, problems=[], filter=FilterHealth(),
                              queue=QueueHealth(),
                              consistency={"imu/orientation": {"nis_mean": 0.1, "verdict": window, "run_verdict": run}})
        (s,) = [s for s in ros_statuses(report, "fusiond", {}) if s.name == "fusiond: imu"]
        return int(s.level)

    assert level("nis_low", "ok") == 0 and level("nis_low", "nis_low") == 1 and level("nis_low", "warming_up") == 1


def test_a_sensor_whose_samples_are_held_for_a_clock_jump_is_said_held_not_silent():
    """The wheels' samples arrive, stamped far from the filter's time, and are held until the jump persists: the
    problem says so (it read "silent" while their messages flowed)."""
    from fusiond.health import CoreCounters, FilterHealth

    clock = Clock()
    h = Health([("wheel", 0.2), ("imu", 0.2)], clock=clock, queue_capacity=8)
    feed(h, clock, 100.0, {0: 0.02, 1: 0.01})
    clock.t += 0.5
    h.set_core(CoreCounters(applied=[1, 1], late=[0, 0], held=[25, 0], rejected=[0, 0], dropped=[{}, {}],
                            filter=FilterHealth(), consistency={}))
    problems = h.report().problems
    assert any(p.startswith("wheel: 25 samples held for a clock jump") for p in problems), problems
    assert any(p.startswith("imu: silent for") for p in problems), problems
