"""Where the daemon's fusing spends its CPU at 1 kHz IMU + 100 Hz odometry, live stamps.

The `Daemon` of `fusiond run` on a loopback session, fed by a generator session in this
process with the same pre-encoded traffic as `fusiond bench-latency`, paced in real time.
Samples are fused on the threads that receive them, one pass at a time (`Daemon._fuse_inbox`,
whichever thread holds the core): the passes' CPU (thread time) is split by wrapping, on this
instance only, the passes, the decoders, `core.ingest` and the estimate publisher; what is left
is the pass's own loop and health bookkeeping. The worker thread, which keeps the timers (the
diagnostics batch, health's copy of the core's counters), is reported beside, its flushes apart.
`--cprofile` prints a cProfile of the passes instead (it inflates Python-heavy code: use it for
the ranking only).

    .venv/bin/python scripts/profile_daemon_cpu.py [--seconds 10] [--diagnostics-batch-s 0.05] [--cprofile]
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
    acc = dict.fromkeys(("passes", "decode", "core", "publish", "diagnostics"), 0.0)
    daemon._decoders = [bench.thread_timed(d, acc, "decode") for d in daemon._decoders]
    daemon.core.ingest = bench.thread_timed(daemon.core.ingest, acc, "core")
    daemon._publish_estimate = bench.thread_timed(daemon._publish_estimate, acc, "publish")
    daemon._flush_diagnostics = bench.thread_timed(daemon._flush_diagnostics, acc, "diagnostics")
    profile = cProfile.Profile() if args.cprofile else None
    fuse = daemon._fuse_inbox
    if profile is not None:  # one pass at a time holds the core: the profiler is on one thread at a time

        def profiled() -> None:
            profile.enable()
            try:
                fuse()
            finally:
                profile.disable()

        daemon._fuse_inbox = profiled
    else:
        daemon._fuse_inbox = bench.thread_timed(fuse, acc, "passes")
    daemon.start()
    n = bench.feed_daemon(daemon, cfg, port, args.seconds)
    d_session.close()

    worker = daemon.worker_cpu_s
    if profile is None:
        total = acc["passes"]
        print(f"{n} messages in {args.seconds:g} s, {daemon.passes} passes; their CPU {total:.3f} s = "
              f"{100 * total / args.seconds:.1f}% of a core, {1e6 * total / n:.1f} us a message")
        parts = [(k, acc[k]) for k in ("decode", "core", "publish")]
        for key, value in (*parts, ("the pass's loop, health", total - sum(v for _, v in parts))):
            print(f"  {key:<28}{1e6 * value / n:8.1f} us/msg {100 * value / total:6.1f}% of the passes")
        print(f"worker thread (timers, and any pass it made) {1e6 * worker / n:.1f} us a message, of which the "
              f"diagnostics batches {1e6 * acc['diagnostics'] / n:.1f}; diagnostics puts {daemon.diagnostics_puts}")
    else:
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats("tottime").print_stats(25)
        print(out.getvalue())


if __name__ == "__main__":
    main()
