"""The daemon fuses each sample on the thread that receives it, one thread holding the core at a time, on a
real loopback Zenoh session: a sample that arrives while another thread holds the core waits in the inbox and
is fused when that thread lets go, never left there; the arrival order across sensors is kept (records and
the `late` counters are those of a core fed in that order)."""

from __future__ import annotations

import math
import threading
import time
from collections import Counter

import pytest
import zenoh

from fusiond.monitor import decode_diagnostics
from fusiond.core.sensors import ImuSample, encode_sample
from fusiond.transport.daemon import Daemon

from tests.support.configs import loopback_daemon_config
from tests.support.loopback import sessions, wait_answering, wait_until  # noqa: F401  (fixture)
from tests.support.batches import expected_records, identity, stream

COV3 = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)


def imu(k: int) -> bytes:
    return encode_sample(ImuSample("imu", 50.0 + 0.001 * k, (0.0, 0.0, 0.0, 1.0), COV3, (0.0, 0.0, 0.0), COV3),
                             "ros2-cdr")


def test_imu_samples_without_any_odometry_are_all_fused(sessions):  # noqa: F811
    """Samples that publish nothing (an IMU alone) are fused as they arrive all the same."""
    dsession, client = sessions
    daemon = Daemon(loopback_daemon_config(imu='orientation = "roll_pitch"'), dsession, monitor=False)
    daemon.start()
    try:
        pub = client.declare_publisher("t/imu", congestion_control=zenoh.CongestionControl.BLOCK)
        wait_answering(client)
        for k in range(200):
            pub.put(imu(k))
        rep = wait_until(lambda: (r := daemon.report()).sensors["imu"].applied == 200 and r, 10,
                         "all 200 IMU samples fused")
        assert rep.sensors["imu"].dropped == 0 and daemon.queued() == 0 and rep.published == 0
        # one pass or more fused them, each one sample or more
        assert 1 <= daemon.passes <= 200
    finally:
        daemon.stop()


def test_callbacks_on_a_thread_each_fuse_every_sample_one_thread_at_a_time(sessions):  # noqa: F811
    """With zenoh-python's default callbacks (a thread per subscriber) two threads append and try the core at
    once: one pass is under way at a time, and a burst on both keys is accounted for whole (every sample
    applied, or dropped and counted, none left in the inbox)."""
    dsession, client = sessions
    cfg = loopback_daemon_config(imu='orientation = "roll_pitch"\nangular_velocity = true')
    messages = stream()
    poses: list[bytes] = []
    sub = client.declare_subscriber("t/pose", lambda s: poses.append(s.payload.to_bytes()))
    daemon = Daemon(cfg, dsession, monitor=False, direct_callbacks=False)
    under_way: list[int] = []  # the threads of the passes under way
    overlaps: list[list[int]] = []  # any moment two passes were under way at once
    fused_on: set[int] = set()
    fuse = daemon._fuse_inbox

    def fuse_watched() -> None:
        under_way.append(threading.get_ident())
        fused_on.add(under_way[-1])
        if len(under_way) > 1:
            overlaps.append(list(under_way))
        try:
            fuse()
        finally:
            under_way.remove(threading.get_ident())

    daemon._fuse_inbox = fuse_watched
    daemon.start()
    try:
        block = zenoh.CongestionControl.BLOCK
        pubs = {k: client.declare_publisher(k, congestion_control=block) for k in ("t/imu", "t/odom")}
        wait_answering(client)
        for key, raw in messages:
            pubs[key].put(raw)
        sent = {"imu": sum(k == "t/imu" for k, _ in messages), "wheel": sum(k == "t/odom" for k, _ in messages)}

        def settled():
            rep = daemon.report()
            done = all(rep.sensors[n].received == c and rep.sensors[n].applied + rep.sensors[n].dropped
                       + rep.sensors[n].held == c for n, c in sent.items())
            return done and daemon.queued() == 0 and rep

        rep = wait_until(settled, 20, "every sample of the burst fused or counted")
        assert not overlaps  # one thread at a time
        assert fused_on - {daemon._worker.ident}  # the subscribers' threads fused
        # while one thread fuses, the other appends: a burst may fill the inbox, and one key's samples may reach
        # the core behind the other's by more than the history holds (no order across keys with a thread per
        # subscriber); both are counted
        for name in sent:
            assert set(rep.sensors[name].dropped_by_reason) <= {"queue_full", "too_old"}, rep.sensors[name]
        assert daemon.errors == 0 and 0 < len(poses) <= rep.sensors["wheel"].applied
    finally:
        daemon.stop()
        sub.undeclare()


def test_paced_samples_fuse_in_arrival_order_and_answer_every_odometry_sample(sessions):  # noqa: F811
    """1 kHz IMU + 100 Hz odometry in real time: each odometry sample gets its pose, and the records
    (with their `late` flags) are exactly those of a core fed the samples in send order, so fusing where they
    arrive (with the worker's timers taking the core between them) neither reorders samples across sensors
    nor loses any."""
    dsession, client = sessions
    cfg = loopback_daemon_config(imu='orientation = "roll_pitch"\nangular_velocity = true')
    messages = stream()[:330]  # 0.3 s of traffic
    expected = expected_records(cfg, messages)
    poses: list[bytes] = []
    payloads: list[bytes] = []
    subs = [client.declare_subscriber("t/pose", lambda s: poses.append(s.payload.to_bytes())),
            client.declare_subscriber("t/diagnostics", lambda s: payloads.append(s.payload.to_bytes()))]
    daemon = Daemon(cfg, dsession, monitor=False)
    daemon.start()
    try:
        block = zenoh.CongestionControl.BLOCK
        pubs = {k: client.declare_publisher(k, congestion_control=block) for k in ("t/imu", "t/odom")}
        wait_answering(client)
        start = time.perf_counter()
        for i, (key, raw) in enumerate(messages):  # paced like the sensors: 1 ms between IMU samples
            delay = start + 0.001 * math.floor(i * 1000 / 1100) - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            pubs[key].put(raw)
        n_odom = sum(1 for key, _ in messages if key == "t/odom")
        wait_until(lambda: len(poses) == n_odom, 10, "a pose for every odometry sample")
        wait_until(lambda: sum(s.received for s in daemon.report().sensors.values()) == len(messages), 10,
                   "every sample in the daemon's callbacks (the last IMU samples follow the last odometry)")
    finally:
        daemon.stop()
    rep = daemon.report()
    assert sum(s.applied for s in rep.sensors.values()) == len(messages) and daemon.errors == 0
    wait_until(lambda: len(payloads) >= daemon.diagnostics_puts, 10, "every diagnostics put")
    for sub in subs:
        sub.undeclare()
    records = [r for p in payloads for r in decode_diagnostics(p)]
    assert Counter(identity(r) for r in records) == expected


def test_samples_arriving_while_the_worker_holds_the_core_are_fused_when_it_lets_go(sessions):  # noqa: F811
    """A sample is fused on the thread that receives it. The worker holds the core to copy its counters for
    health; the samples that arrive meanwhile wait in the inbox (their callbacks do not wait for the core) and
    the worker fuses them as soon as it lets go, with no further arrival to prompt it."""
    dsession, client = sessions
    daemon = Daemon(loopback_daemon_config(imu='orientation = "roll_pitch"'), dsession, monitor=False)
    fused_on: list[int] = []  # the thread each sample is fused on
    ingest = daemon.core.ingest

    def ingest_noting_the_thread(sample, keep=True):
        fused_on.append(threading.get_ident())
        return ingest(sample, keep)

    daemon.core.ingest = ingest_noting_the_thread
    daemon.start()
    # the worker's next copy of the core's counters (after a pass) holds the core until the test says
    inside, go_on, holder = threading.Event(), threading.Event(), []
    refresh = daemon._refresh

    def held_refresh() -> None:
        if not go_on.is_set():
            holder.append(threading.get_ident())
            inside.set()
            go_on.wait(10.0)
        refresh()

    daemon._refresh = held_refresh
    try:
        pub = client.declare_publisher("t/imu", congestion_control=zenoh.CongestionControl.BLOCK)
        wait_answering(client)
        pub.put(imu(0))  # fused: the worker copies the counters next, and holds the core there
        assert inside.wait(10.0), "the worker never copied the core's counters"
        for k in range(1, 51):
            pub.put(imu(k))
        wait_until(lambda: daemon.report().sensors["imu"].received == 51, 10, "the 50 samples in the callbacks")
        assert daemon.queued() == 50  # the core is held: they wait, none is dropped or fused
        go_on.set()
        wait_until(lambda: daemon.queued() == 0 and daemon.report().sensors["imu"].applied == 51, 10,
                   "the 50 samples fused once the worker let go")
        assert daemon.report().sensors["imu"].dropped == 0 and daemon.errors == 0
        worker = daemon._worker.ident
        assert holder == [worker]
        assert len(fused_on) == 51 and fused_on[0] != worker  # the first: where it arrived, the core free
        assert fused_on[1:] == [worker] * 50  # the rest: by the worker, once it let go
    finally:
        go_on.set()
        daemon.stop()
