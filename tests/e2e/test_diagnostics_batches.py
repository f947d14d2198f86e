"""Diagnostics on the wire in batches: a real daemon (the `Daemon` of `fusiond run`) on loopback Zenoh.

Every update's record must reach a subscriber exactly once, including the records of the
samples still queued when a clean stop begins (here the test holds the core while the burst
arrives: the worker fuses them at the stop, then flushes the last batch before the outputs are
undeclared). The reference is a second FusionCore fed the same
payloads in the same order: the records it emits are the updates the daemon must report.
"""

from __future__ import annotations

import threading
from collections import Counter

import msgspec
import pytest
import zenoh

from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.monitor import Monitor, decode_diagnostics
from fusiond.transport.daemon import Daemon

from tests.support.configs import loopback_daemon_config
from tests.support.loopback import sessions, wait_answering, wait_until  # noqa: F401  (fixture)
from tests.support.batches import N_IMU, expected_records, identity, stream


@pytest.mark.parametrize("batch", [0.05, 0.0])
def test_every_record_arrives_exactly_once_including_those_flushed_at_stop(sessions, batch):  # noqa: F811
    dsession, client = sessions
    cfg = loopback_daemon_config(output=f"diagnostics_batch_s = {batch}",
                                 imu='orientation = "roll_pitch"\nangular_velocity = true\n'
                                     'orientation_rate_hz = 0')  # a record per sample: many to batch
    messages = stream()
    expected = expected_records(cfg, messages)
    assert sum(expected.values()) >= N_IMU  # every IMU sample updates at least its roll/pitch channel

    payloads: list[bytes] = []
    sub = client.declare_subscriber("t/diagnostics", lambda s: payloads.append(s.payload.to_bytes()))
    # a queue that holds the whole burst: this test is about records, not the drop policy
    daemon = Daemon(cfg, dsession, queue_size=len(messages) + 1, monitor=False)
    daemon.start()
    stopping = threading.Thread(target=daemon.stop, kwargs={"drain_s": 30.0})  # a clean stop
    held = daemon._core.acquire(timeout=10.0)  # another thread holds the core: the burst waits in the inbox
    try:
        block = zenoh.CongestionControl.BLOCK
        pubs = {k: client.declare_publisher(k, congestion_control=block) for k in ("t/imu", "t/odom")}
        wait_answering(client)
        for key, raw in messages:
            pubs[key].put(raw)
        wait_until(lambda: sum(s.received for s in daemon.report().sensors.values()) == len(messages), 10,
                   "every sample in the daemon's callbacks")
        assert daemon.queued() == len(messages)
        stopping.start()
        wait_until(lambda: not daemon._subscribers, 10, "the stop to begin (its subscribers undeclared)")
    finally:
        if held:
            daemon._core.release()  # the worker fuses the queue, then flushes the last batch
        if stopping.is_alive():
            stopping.join(40.0)
        else:
            daemon.stop(drain_s=30.0)

    rep = daemon.report()
    assert rep.queue.dropped == 0 and daemon.errors == 0
    assert sum(s.applied for s in rep.sensors.values()) == len(messages)
    # every put the daemon made reaches the subscriber (reliable, loopback); then nothing more can come
    wait_until(lambda: len(payloads) >= daemon.diagnostics_puts, 10, "every diagnostics put")
    sub.undeclare()
    assert len(payloads) == daemon.diagnostics_puts

    decoded = [msgspec.json.decode(p) for p in payloads]
    records = [r for p in payloads for r in decode_diagnostics(p)]
    assert Counter(identity(r) for r in records) == expected  # each update once: none lost, none twice
    if batch:
        assert all(isinstance(d, list) and d for d in decoded)  # arrays, never an empty one
        # Batches, not one put per record: the worker fuses the queued burst in one pass, a batch put
        # every MAX_BATCH records (transport/outputs.py) or at the end.
        assert len(payloads) <= len(records) // 2, (len(payloads), len(records))
    else:
        assert all(isinstance(d, dict) for d in decoded)  # diagnostics_batch_s = 0: one record per put
        assert len(payloads) == len(records)


def test_monitor_reads_single_records_and_batches(sessions):  # noqa: F811
    """The live monitor (`fusiond monitor`) takes both forms of the key; anything else is counted."""
    a, b = sessions
    mon = Monitor(a, health_key="fusiond/health", diagnostics_key="fusiond/diagnostics")
    mon.start()
    try:
        pub = b.declare_publisher("robot1/fusiond/diagnostics", congestion_control=zenoh.CongestionControl.BLOCK)

        def rec(k: int, channel: str = "orientation") -> DiagnosticsRecord:
            return DiagnosticsRecord(float(k), "imu", ["roll", "pitch"], [0.01, -0.01], [1e-4, 1e-4], 2.0, 2,
                                     False, channel=channel)

        def seen(channel: str) -> int:
            view = mon.daemons.get("robot1")
            ch = view.channels.get(("imu", channel)) if view else None
            return ch.total if ch else 0

        # the subscriber's declaration reaches the publisher's session asynchronously: repeat a
        # probe record (its own channel, so late copies do not count below) until one arrives
        wait_until(lambda: (pub.put(msgspec.json.encode(rec(0, "probe"))), seen("probe") > 0)[1], 10,
                   "the monitor's subscriber")
        pub.put(msgspec.json.encode([rec(1), rec(2), rec(3)]))
        pub.put(b"[{\"not\": \"a record\"}]")
        pub.put(msgspec.json.encode(rec(4)))
        wait_until(lambda: seen("orientation") == 4 and mon.undecodable == 1, 10, "a batch, a bad payload, a record")
        assert mon.daemons["robot1"].channels[("imu", "orientation")].last_stamp == 4.0
    finally:
        mon.close()


def test_decode_diagnostics_takes_one_record_or_an_array():
    r = DiagnosticsRecord(1.5, "wheel", ["vx"], [0.1], [0.01], 1.0, 1, False, channel="twist")
    assert decode_diagnostics(msgspec.json.encode(r)) == [r]
    assert decode_diagnostics(msgspec.json.encode([r, r])) == [r, r]
    assert decode_diagnostics(b"[]") == []
    for bad in (b"{}", b"[1]", b"nope", b""):
        with pytest.raises(msgspec.DecodeError):
            decode_diagnostics(bad)
