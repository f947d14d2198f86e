"""The daemon's fusing CPU with `[output] smoothed_key` against the same daemon without it.

The `Daemon` of `fusiond run` on a loopback session, fed in real time by a generator session in this
process with `fusiond bench-latency`'s pre-encoded traffic (1 kHz IMU + 100 Hz odometry, live stamps),
as `scripts/profile_daemon_cpu.py` does; the runs alternate, off and on, for a few rounds (the
machine is shared: the median of each is reported, and every run). The thread time of the daemon's
passes (`Daemon._fuse_inbox`, on whichever thread holds the core) is split into the core's `ingest`
(which records the window's anchors when on) and the estimate publish (which smooths the lagged pose
and puts it when on). A benchmark, not a test: it asserts nothing.

    .venv/bin/python scripts/smoothed_key_bench.py [--rounds 3] [--seconds 10] [--lag 1.0]
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path


from fusiond.config import loads
from fusiond.transport.daemon import Daemon
from fusiond.transport.session import build_config, open_session

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ of the source tree
from benchmarks import bench_latency as bench  # noqa: E402


def run_once(seconds: float, lag: float | None) -> dict[str, float]:
    """One daemon fed ``seconds`` of traffic; ``lag`` None: without the smoothed key. The passes' CPU in us
    a message: total, core, publish; and the smoothed poses put."""
    port = bench.free_port()
    text = bench._config_text(port)
    if lag is not None:
        text = text.replace("[output]\n", f'[output]\nsmoothed_key = "bench/smoothed"\nsmooth_lag_s = {lag!r}\n')
    cfg = loads(text, "<smoothed bench>")
    d_session = open_session(build_config(cfg.zenoh))
    daemon = Daemon(cfg, d_session, monitor=False)
    acc = dict.fromkeys(("passes", "core", "publish"), 0.0)
    daemon._fuse_inbox = bench.thread_timed(daemon._fuse_inbox, acc, "passes")
    daemon.core.ingest = bench.thread_timed(daemon.core.ingest, acc, "core")
    daemon._publish_estimate = bench.thread_timed(daemon._publish_estimate, acc, "publish")
    daemon.start()
    n = bench.feed_daemon(daemon, cfg, port, seconds)
    d_session.close()
    return {"total": 1e6 * acc["passes"] / n, "core": 1e6 * acc["core"] / n,
            "publish": 1e6 * acc["publish"] / n, "core_share": 100 * acc["passes"] / seconds,
            "smoothed": float(daemon.outputs.smoothed_published), "poses": float(daemon.published),
            "anchors": float(len(daemon.core._smoothing.anchors)) if daemon.core._smoothing is not None else 0.0}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--lag", type=float, default=1.0)
    args = ap.parse_args()
    runs: dict[str, list[dict[str, float]]] = {"off": [], "on": []}
    for r in range(args.rounds):
        for name, lag in (("off", None), ("on", args.lag)):
            res = run_once(args.seconds, lag)
            runs[name].append(res)
            print(f"round {r + 1} {name:>3}: passes {res['total']:6.1f} us/msg ({res['core_share']:4.1f}% of a core), "
                  f"core {res['core']:6.1f}, publish {res['publish']:5.1f}; poses {res['poses']:.0f}, "
                  f"smoothed {res['smoothed']:.0f}, anchors held {res['anchors']:.0f}", flush=True)
    med = {k: {f: statistics.median(r[f] for r in v) for f in v[0]} for k, v in runs.items()}
    off, on = med["off"], med["on"]
    print(f"median of {args.rounds}, 1 kHz IMU + 100 Hz odometry, {args.seconds:g} s, smooth_lag_s = {args.lag:g}:")
    for k in ("total", "core", "publish"):
        print(f"  {k:<8} off {off[k]:6.1f}  on {on[k]:6.1f}  +{on[k] - off[k]:5.1f} us/msg")
    print(f"  passes   off {off['core_share']:.1f}%  on {on['core_share']:.1f}% of a core")


if __name__ == "__main__":
    main()
