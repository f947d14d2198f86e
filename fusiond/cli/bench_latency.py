"""`fusiond bench-latency`: sensor put -> fused pose latency and the daemon's CPU over Zenoh on loopback.

The benchmark is benchmarks/bench_latency.py of the source tree (cli/benchmarks.py finds it)."""

from __future__ import annotations

import argparse
import statistics

from .benchmarks import load
from .common import BENCH_NO_MULTICAST, count, positive

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=positive, default=10.0, help="measurement duration (default 10)")
    p.add_argument("--imu-hz", type=positive, default=1000.0, help="IMU messages per second sent (default 1000)")
    p.add_argument("--odom-hz", type=positive, default=100.0,
                   help="odometry messages per second sent; each yields a fused pose (default 100)")
    p.add_argument("--express", action="store_true", help="send the daemon's outputs unbatched (Zenoh express)")
    p.add_argument("--runs", type=count, default=1,
                   help="repeat the measurement, each run with new processes, and report the CPU ratio's median "
                        "(default 1)")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--no-multicast", action="store_true", help=BENCH_NO_MULTICAST)


def run(args: argparse.Namespace) -> int:
    bench_latency = load("bench_latency")
    results = [bench_latency.run_bench(seconds=args.seconds, imu_hz=args.imu_hz, odom_hz=args.odom_hz,
                                       express=args.express) for _ in range(args.runs)]
    if args.json:
        import msgspec

        # one run: its result, as always; several: {"runs": [...], "cpu_ratio_median": ...}
        out = results[0] if len(results) == 1 else {
            "runs": results, "cpu_ratio_median": statistics.median(r.cpu_ratio for r in results)}
        print(msgspec.json.encode(out).decode())
    else:
        print(bench_latency.format_table(results[-1]))
        if len(results) > 1:
            print(bench_latency.format_runs(results))
    return 0
