"""Where the daemon's worker thread spends its CPU at 1 kHz IMU + 100 Hz odometry, live stamps.

The `Daemon` of `fusiond run` on a loopback session, fed by a generator session in this
process with the same pre-encoded traffic as `fusiond bench-latency`, paced in real time.
The worker's CPU (thread time) is split by wrapping, on this instance only, the decoders,
`core.ingest`, the estimate publisher and the diagnostics flush: what is left is the
worker loop itself (queue wake-ups, health bookkeeping). `--cprofile` prints a cProfile
of the worker thread instead (it inflates Python-heavy code: use it for the ranking only).

    .venv/bin/python scripts/profile_daemon_worker.py [--seconds 10] [--diagnostics-batch-s 0.05] [--cprofile]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from fusiond.config import loads
from fusiond.transport.daemon import Daemon
from fusiond.transport.session import build_config, open_session, query_health

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ of the source tree
from benchmarks import bench_latency as bench  # noqa: E402


def timed(fn: Callable[..., Any], acc: dict[str, float], key: str) -> Callable[..., Any]:
    clock = time.thread_time

    def wrapper(*args: Any) -> Any:
        t = clock()
        try:
            return fn(*args)
        finally:
            acc[key] += clock() - t

    return wrapper


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--diagnostics-batch-s", type=float, default=None)
    ap.add_argument("--cprofile", action="store_true")
    args = ap.parse_args()

    port = bench.free_port()
    cfg = loads(bench._config_text(port, args.diagnostics_batch_s), "<profile>")
    d_session = open_session(build_config(cfg.zenoh))
    daemon = Daemon(cfg, d_session, monitor=False)
    acc = dict.fromkeys(("decode", "core", "publish", "diagnostics"), 0.0)
    daemon._decoders = [timed(d, acc, "decode") for d in daemon._decoders]
    daemon.core.ingest = timed(daemon.core.ingest, acc, "core")
    daemon._publish_estimate = timed(daemon._publish_estimate, acc, "publish")
    daemon._flush_diagnostics = timed(daemon._flush_diagnostics, acc, "diagnostics")
    profile = cProfile.Profile() if args.cprofile else None
    if profile is not None:
        work = daemon._work

        def profiled() -> None:
            profile.enable()
            try:
                work()
            finally:
                profile.disable()

        daemon._work = profiled
    daemon.start()
    g_session = open_session(build_config(msgspec.structs.replace(
        cfg.zenoh, listen=[], connect=[f"tcp/127.0.0.1:{port}"])))
    block = zenoh.CongestionControl.BLOCK
    pubs = {k: g_session.declare_publisher(f"bench/{k}", express=True, congestion_control=block).put
            for k in ("imu", "odom")}
    deadline = time.monotonic() + 10.0
    while not query_health(g_session, cfg.output.health_key, 0.5):
        if time.monotonic() > deadline:
            raise SystemExit("the daemon did not answer its health query within 10 s")
    schedule = bench._schedule(args.seconds, 1000.0, 100.0)
    start = time.perf_counter()
    for offset, kind, payload, _ in schedule:
        delay = start + offset - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        pubs[kind](payload)
    deadline = time.monotonic() + 5.0
    while sum(s.applied for s in daemon.report().sensors.values()) < len(schedule) and time.monotonic() < deadline:
        time.sleep(0.01)
    daemon.stop()
    g_session.close()
    d_session.close()

    n = len(schedule)
    total = daemon.worker_cpu_s
    print(f"{n} messages in {args.seconds:g} s; worker thread CPU {total:.3f} s = "
          f"{100 * total / args.seconds:.1f}% of a core, {1e6 * total / n:.1f} us a message")
    if profile is None:
        rest = total - sum(acc.values())
        for key, value in (*acc.items(), ("worker loop, health, rest", rest)):
            print(f"  {key:<28}{1e6 * value / n:8.1f} us/msg {100 * value / total:6.1f}% of the worker")
        print(f"diagnostics puts {daemon.diagnostics_puts}")
    else:
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats("tottime").print_stats(25)
        print(out.getvalue())


if __name__ == "__main__":
    main()
