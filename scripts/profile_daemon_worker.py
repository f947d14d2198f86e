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
from pathlib import Path


from fusiond.config import loads
from fusiond.transport.daemon import Daemon
from fusiond.transport.session import build_config, open_session

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ of the source tree
from benchmarks import bench_latency as bench  # noqa: E402


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
    daemon._decoders = [bench.thread_timed(d, acc, "decode") for d in daemon._decoders]
    daemon.core.ingest = bench.thread_timed(daemon.core.ingest, acc, "core")
    daemon._publish_estimate = bench.thread_timed(daemon._publish_estimate, acc, "publish")
    daemon._flush_diagnostics = bench.thread_timed(daemon._flush_diagnostics, acc, "diagnostics")
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
    n = bench.feed_daemon(daemon, cfg, port, args.seconds)
    d_session.close()

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
