"""How much of the daemon's CPU is transport and how much is the fusion core, in one table.

Runs `fusiond bench-latency`'s benchmark (daemon, bare zenoh-python subscriber and load
generator in their own processes, 1 kHz IMU + 100 Hz odometry, live stamps) twice per round,
alternating: once with the real daemon, once with its core stubbed out (each sample is decoded and
accepted, and each odometry sample answered with a pose at its own stamp, without the real
`core.ingest`). The stubbed run is the daemon's transport floor: subscribers, inbox, the core's
lock, decoding, health, a pose put per odometry message, the worker's timers, the Zenoh session. Its ratio to the bare subscriber is the best the daemon's
ratio could be with a free core; the difference to the real run is the core's share.

    .venv/bin/python scripts/daemon_transport_floor.py [--rounds 3] [--seconds 8]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ of the source tree
from benchmarks import bench_latency  # noqa: E402


def _floor_child(conn: Any, config_text: str, express: bool) -> None:
    """The benchmark's daemon child with the fusion core cut out (spawned: runs in the child): every
    decoded sample is accepted, and each odometry sample answered with a pose at its own stamp."""
    from fusiond.codecs import encode_pose_cdr
    from fusiond.core.fusion import Step
    from fusiond.core.sensors import OdomSample
    from fusiond.transport.daemon import Daemon

    zero_cov = (0.0,) * 36
    real_start = Daemon.start

    def start_without_core(self: Daemon) -> None:
        last = [0.0]  # stamp of the newest odometry sample: the generator matches poses to its puts by it

        def ingest(sample: Any) -> Step:
            if isinstance(sample, OdomSample):
                last[0] = sample.stamp
                return Step(sample.sensor, True, publish=True)
            return Step(sample.sensor, True)

        def publish() -> None:
            self.outputs.pose.put(encode_pose_cdr(last[0], "odom", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), zero_cov))

        self.core.ingest = ingest  # type: ignore[method-assign]
        self._publish_estimate = publish  # type: ignore[method-assign]
        real_start(self)

    Daemon.start = start_without_core  # type: ignore[method-assign]
    bench_latency._daemon_child(conn, config_text, express)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=8.0)
    args = ap.parse_args()
    real_child = bench_latency._daemon_child
    rows: dict[str, list[tuple[float, ...]]] = {"daemon": [], "transport floor": []}
    for _ in range(args.rounds):
        for label, child in (("daemon", real_child), ("transport floor", _floor_child)):
            bench_latency._daemon_child = child  # run_bench spawns whatever this name holds
            try:
                r = bench_latency.run_bench(seconds=args.seconds)
            finally:
                bench_latency._daemon_child = real_child
            drops = r.queue_drops + r.core_drops
            if drops or r.daemon_received != r.sent_total:
                raise SystemExit(f"{label}: {drops} drops, {r.daemon_received}/{r.sent_total} received")
            rows[label].append((r.cpu_daemon_pct, r.cpu_bare_pct, r.cpu_ratio, r.cpu_worker_pct,
                                r.passes / max(r.messages_in_window, 1)))
    print(f"{'run':<16}{'daemon %':>10}{'bare %':>9}{'ratio':>8}{'worker %':>10}{'pass/msg':>10}"
          f"   (medians of {args.rounds} rounds)")
    for label, values in rows.items():
        cols = [statistics.median(v[i] for v in values) for i in range(5)]
        print(f"{label:<16}{cols[0]:>10.1f}{cols[1]:>9.1f}{cols[2]:>8.2f}{cols[3]:>10.1f}{cols[4]:>10.2f}")


if __name__ == "__main__":
    main()
