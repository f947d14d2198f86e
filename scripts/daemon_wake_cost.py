"""What a wake-up costs a thread that fuses on this machine: the fusion core on the daemon benchmark's traffic,
run back to back and run by a thread woken for a few samples at a time (asleep between).

`fusiond bench-latency` holds the daemon's CPU to a bare zenoh-python subscriber's. A thread woken to fuse
takes several times the CPU a message the same core takes in a loop over the same samples: between two
wake-ups it sleeps, and it wakes with cold caches and pays the sleep's own system calls. That is why the
daemon fuses each sample on the thread that receives it (``transport/daemon.py``), which is awake for it
anyway, rather than handing it to a thread of its own. This measures both on the machine at hand, with no
Zenoh in the way:

- ``back to back``: ``FusionCore.ingest`` over the benchmark's samples (1 kHz IMU + 100 Hz odometry,
  decoded beforehand), in a thread that never sleeps;
- ``woken``: the same, the thread sleeping ``--sleep-ms`` every ``--per-wake`` samples; the sleeps' own
  CPU is reported apart, and left out of the core's;
- ``sleep alone``: the thread CPU one such sleep costs.

The thread CPU (``time.thread_time``) is the figure, as the benchmark's: the best of ``--rounds``.

    .venv/bin/python scripts/daemon_wake_cost.py [--seconds 10] [--per-wake 4] [--sleep-ms 3] [--rounds 3]
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/ of the source tree
from benchmarks import bench_latency  # noqa: E402


def _samples(seconds: float) -> tuple[Any, list[Any]]:
    """The benchmark's config and its traffic of ``seconds``, decoded as the daemon decodes it."""
    from fusiond.config import loads
    from fusiond.core.sensors import kind_of

    cfg = loads(bench_latency._config_text(bench_latency.free_port()))
    decoders = {kind_of(s).name: kind_of(s).decoder(s) for s in cfg.sensors}  # the daemon's own
    return cfg, [decoders[kind](payload) for _, kind, payload, _ in bench_latency._schedule(seconds, 1000.0, 100.0)]


def _in_thread(fn: Any) -> Any:
    """``fn()`` run in a thread of its own, its result returned."""
    out: list[Any] = []
    worker = threading.Thread(target=lambda: out.append(fn()))
    worker.start()
    worker.join()
    return out[0]


def core_cpu(cfg: Any, samples: list[Any], per_wake: int, sleep_s: float) -> tuple[float, float]:
    """(the core's thread CPU a sample, the sleeps' thread CPU a sample) fusing ``samples`` with a sleep of
    ``sleep_s`` before every ``per_wake`` samples (``per_wake`` 0: none)."""
    from fusiond.core.fusion import FusionCore

    core = FusionCore(cfg)
    ingest, clock = core.ingest, time.thread_time
    asleep = 0.0
    start = clock()
    for i, sample in enumerate(samples):
        if per_wake and i % per_wake == 0:
            before = clock()
            time.sleep(sleep_s)
            asleep += clock() - before
        ingest(sample)
    total = clock() - start
    return (total - asleep) / len(samples), asleep / len(samples)


def sleep_cpu(sleep_s: float, n: int = 1000) -> float:
    """The thread CPU one sleep of ``sleep_s`` costs."""
    start = time.thread_time()
    for _ in range(n):
        time.sleep(sleep_s)
    return (time.thread_time() - start) / n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds of traffic (1.1k samples a second)")
    ap.add_argument("--per-wake", type=int, default=4, help="samples fused a wake-up")
    ap.add_argument("--sleep-ms", type=float, default=3.0, help="the sleep between two wake-ups")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    if args.per_wake < 1 or not args.sleep_ms > 0.0 or args.rounds < 1 or not args.seconds > 0.0:
        ap.error("--per-wake, --rounds, --sleep-ms and --seconds must be positive")
    from fusiond.logs import configure

    configure("warning")
    cfg, samples = _samples(args.seconds)
    sleep_s = args.sleep_ms / 1000.0
    tight = min(_in_thread(lambda: core_cpu(cfg, samples, 0, 0.0))[0] for _ in range(args.rounds))
    woken = min((_in_thread(lambda: core_cpu(cfg, samples, args.per_wake, sleep_s)) for _ in range(args.rounds)),
                key=lambda r: r[0])
    alone = min(_in_thread(lambda: sleep_cpu(sleep_s)) for _ in range(args.rounds))
    print(f"fusion core on the daemon benchmark's traffic ({len(samples)} samples), thread CPU, best of "
          f"{args.rounds}:")
    print(f"  back to back         {tight * 1e6:7.1f} us a sample")
    print(f"  woken every {args.per_wake:<3d}      {woken[0] * 1e6:7.1f} us a sample, and its sleeps "
          f"{woken[1] * 1e6:.1f} us a sample more ({args.sleep_ms:g} ms each)")
    print(f"  sleep alone          {alone * 1e6:7.1f} us a sleep")
    print(f"  woken / back to back {woken[0] / tight:7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
