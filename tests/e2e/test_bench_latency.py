"""`fusiond bench-latency` measures what it says: the daemon and the bare subscriber (each in its own
process) receive the same traffic, every odometry put is answered by a pose, and the CPU figures are
the two processes' own. No timing is asserted (performance is reported by the bench, not tested)."""

from __future__ import annotations

import math

import msgspec

from benchmarks.bench_latency import format_runs, format_table, run_bench


def test_the_bench_feeds_the_daemon_and_the_bare_subscriber_the_same_traffic():
    r = run_bench(seconds=1.0, imu_hz=200.0, odom_hz=20.0, warmup_s=0.5, idle_s=0.2, diagnostics_batch_s=0.05)
    # 1.5 s of schedule: 300 IMU + 30 odometry messages, 200 + 20 of them in the measured second
    assert r.sent_total == 330 and (r.imu_sent, r.odom_sent) == (200, 20)
    assert r.bare_received == r.daemon_received == r.sent_total  # loopback, reliable: nothing lost
    assert r.queue_drops == 0 and r.core_drops == 0
    assert r.poses_matched == r.odom_sent and r.poses_unmatched == 0 and r.pose.n == r.odom_sent
    # both processes did work in the window (each payload decoded or copied); the ratio is theirs
    assert r.cpu_daemon_pct > 0 and r.cpu_bare_pct > 0 and math.isfinite(r.cpu_worker_pct)
    assert math.isclose(r.cpu_ratio, r.cpu_daemon_pct / r.cpu_bare_pct)
    assert r.diagnostics_batch_s == 0.05
    # each pass fuses one or more samples: at most one pass per message of the window (plus one straddling its
    # start), at least one
    assert r.messages_in_window == 220 and 1 <= r.passes <= r.messages_in_window + 1
    assert "bare subscriber" in format_table(r)

    # `--runs`: a line a run, and the ratio's median and range over them (three runs: the middle one's ratio)
    runs = [msgspec.structs.replace(r, cpu_ratio=ratio, cpu_daemon_pct=daemon, cpu_bare_pct=10.0)
            for ratio, daemon in ((2.3, 23.0), (1.9, 19.0), (2.05, 20.5))]
    table = format_runs(runs).splitlines()
    assert len(table) == 1 + 3 + 1 and table[2].split()[:4] == ["2", "1.90", "19.0", "10.0"]
    assert table[-1].startswith("CPU ratio daemon / bare subscriber over 3 runs: median 2.05 (1.90-2.30); "
                                "the daemon's process median 20.5 %, the bare subscriber's 10.0 %"), table[-1]
