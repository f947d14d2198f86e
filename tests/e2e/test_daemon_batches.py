"""The daemon's worker fuses per batch (`DrainSchedule`), on a real loopback Zenoh session: samples that
publish nothing wait in the inbox for the next batch but are never left there, and the batches keep the
arrival order across sensors (records and the `late` counters are those of a core fed in that order)."""

from __future__ import annotations

import math
import time
from collections import Counter

import pytest
import zenoh

from fusiond.monitor import decode_diagnostics
from fusiond.core.sensors import ImuSample, encode_sample
from fusiond.transport.daemon import HOLD_S, Daemon

from tests.support.configs import loopback_daemon_config
from tests.support.loopback import sessions, wait_until  # noqa: F401  (fixture)
from tests.support.batches import expected_records, identity, stream

COV3 = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)


def imu(k: int) -> bytes:
    return encode_sample(ImuSample("imu", 50.0 + 0.001 * k, (0.0, 0.0, 0.0, 1.0), COV3, (0.0, 0.0, 0.0), COV3),
                             "ros2-cdr")


def test_hold_must_not_be_negative(sessions):  # noqa: F811
    with pytest.raises(ValueError, match="hold_s"):
        Daemon(loopback_daemon_config(), sessions[0], hold_s=-0.01, monitor=False)


def test_imu_samples_without_any_odometry_are_all_fused(sessions):  # noqa: F811
    """Nothing but an odometry sample wakes a busy worker; an IMU alone still gets fused (the hold)."""
    dsession, client = sessions
    daemon = Daemon(loopback_daemon_config(imu='orientation = "roll_pitch"'), dsession, monitor=False)
    daemon.start()
    try:
        pub = client.declare_publisher("t/imu", congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: [r for r in client.get("t/health", timeout=1.0) if r.ok is not None], 10, "the daemon")
        for k in range(200):
            pub.put(imu(k))
        rep = wait_until(lambda: (r := daemon.report()).sensors["imu"].applied == 200 and r, 10,
                         "all 200 IMU samples fused")
        assert rep.sensors["imu"].dropped == 0 and daemon.queued() == 0 and rep.published == 0
        # they came as a burst, faster than a sample is fused: far fewer batches than samples
        assert 1 <= daemon.wakeups <= 200
    finally:
        daemon.stop()


def test_paced_batches_fuse_in_arrival_order_and_answer_every_odometry_sample(sessions):  # noqa: F811
    """1 kHz IMU + 100 Hz odometry in real time: each odometry sample gets its pose, and the records
    (with their `late` flags) are exactly those of a core fed the samples in send order, so batching
    neither reorders samples across sensors nor loses any."""
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
        wait_until(lambda: [r for r in client.get("t/health", timeout=1.0) if r.ok is not None], 10, "the daemon")
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


def test_the_hold_is_at_most_a_quarter_of_the_shortest_sensor_timeout(sessions):  # noqa: F811
    """Health ages a sensor from its samples' arrival but learns of them when they are fused: a hold
    of a quarter of the timeout keeps a sensor that sends on time alive however the batches fall."""
    dsession = sessions[0]
    assert Daemon(loopback_daemon_config(), dsession, monitor=False).hold_s == HOLD_S  # default timeouts 0.2 s
    fast = Daemon(loopback_daemon_config(imu="timeout_s = 0.02"), dsession, monitor=False)
    assert fast.hold_s == pytest.approx(0.005)
    assert Daemon(loopback_daemon_config(), dsession, hold_s=0.0, monitor=False).hold_s == 0.0
