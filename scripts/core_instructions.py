"""Instructions per message of the fusion core, counted by valgrind (load-independent).

Wall and CPU times on a shared machine move with its load; an instruction count does not. This
runs the `FusionCore` loop of `fusiond bench` (samples decoded beforehand, then ingested, a pose
read after each odometry sample) under `valgrind --tool=callgrind` twice, over the first N and the
first 2N samples of a workload, and prints the difference per message: the interpreter's start,
the imports and the bag reading cancel out. The garbage collector is off while the samples are
fused (the count is the core's own work; the collector's is the replay's and the daemon's).

    .venv/bin/python scripts/core_instructions.py [--workload jackal|comma|synthetic] [--messages 1000]
        [--loop core|replay|doctor|proof]

`--loop`: `core` (the default) counts `FusionCore` alone; `replay` the replay's loop (`replay.run.Runner`)
without the doctor, as `replay --quiet` runs it; `doctor` the same loop with the doctor fed, and what it
was fed folded into its statistics at the end (`Doctor.series`, `Doctor.channels`), as a replay that
prints verdicts does; the difference of the last two is what the doctor costs a message. `proof`: the
replay of the doctor's advice (`fusiond.tune.likelihood.replay_records`: the core alone, the samples all
in memory, its snapshot plan made first).

`jackal`: data/jackal_test2.bag with examples/jackal.toml (up to its 6,121 messages).
`comma`: comma2k19's Example_1 (../shared/data/comma2k19_ex1, not in this repository) with
examples/comma2k19.toml: a car at 100 Hz IMU, 80 Hz wheels and 10 Hz GPS, every sample in order.
`synthetic`: the traffic of `fusiond bench-latency` (1 kHz IMU with roll/pitch and gyro, 100 Hz
odometry, driving a circle) with its configuration. Takes about a minute per workload.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # benchmarks/ of the source tree
WARM_UP = 200  # samples fused first in each count: imports and first allocations, alike in both runs
# numpy's BLAS threads, started at import, spin for a while in their wait; callgrind counts every thread's
# instructions, and how long they spin depends on how valgrind schedules them: with them the same count
# came out 174,000 one run and 201,000 the next, without them within 1 % (the core's matrices have a
# few dozen rows at most: one thread is what its products use anyway).
ONE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _jackal():
    from fusiond.config import load
    from fusiond.replay.bag import open_bag_samples

    cfg = load(ROOT / "examples" / "jackal.toml")
    with open_bag_samples([ROOT / "data" / "jackal_test2.bag"], cfg.sensors) as b:
        return cfg, list(b)


def _comma():
    from fusiond.config import load
    from fusiond.replay.bag import open_bag_samples

    cfg = load(ROOT / "examples" / "comma2k19.toml")
    with open_bag_samples([ROOT.parent / "shared" / "data" / "comma2k19_ex1"], cfg.sensors) as b:
        return cfg, list(b)


def _synthetic(messages: int):
    from fusiond.config import loads
    from fusiond.core.sensors import ImuSample, OdomSample
    from benchmarks import bench_latency

    cfg = loads(bench_latency._config_text(bench_latency.free_port()), "<core_instructions>")
    cov_o = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
    cov_g = (1e-5, 0.0, 0.0, 0.0, 1e-5, 0.0, 0.0, 0.0, 1e-5)
    twist_cov = tuple(1e-3 if i % 7 == 0 else 0.0 for i in range(36))
    v, w, out, k = 0.5, 0.2, [], 0
    while len(out) < messages:
        t = k / 1000.0
        q = (0.0, 0.0, math.sin(w * t / 2), math.cos(w * t / 2))
        out.append(ImuSample("imu", 1000.0 + t, q, cov_o, (0.0, 0.0, w), cov_g))
        if k % 10 == 0:
            out.append(OdomSample("wheel", 1000.0 + t + 0.0005, (v, 0.0, 0.0), (0.0, 0.0, w), twist_cov))
        k += 1
    return cfg, out


def _child(workload: str, count: int, loop: str) -> None:
    """Fuse WARM_UP samples, then the first ``count`` of the workload in a fresh core (``loop``: see
    the module's docstring)."""
    import gc

    import structlog

    from fusiond.core.fusion import FusionCore
    from fusiond.replay.run import Runner

    structlog.configure(logger_factory=structlog.ReturnLoggerFactory())  # the core's logs cost nothing here
    from fusiond.tune.likelihood import replay_records

    cfg, samples = {"jackal": _jackal, "comma": _comma}.get(workload, lambda: _synthetic(count + WARM_UP))()
    # The collector off while fusing: when its runs come depends on everything the process allocated
    # before (the bag reading, the workload's size), so one more or one fewer full collection in either
    # count moved the figure by thousands of instructions a message, or made it negative.
    gc.collect()
    gc.disable()
    for part in (samples[:WARM_UP], samples[:count]):
        if loop == "core":
            core = FusionCore(cfg)
            for s in part:
                if core.ingest(s).publish:
                    core.pose()
            continue
        if loop == "proof":
            replay_records(cfg, part)
            continue
        runner = Runner(cfg, keep_trace=False, doctor=loop == "doctor")
        for s in part:
            runner.feed(s)
        if runner.doctor is not None:
            runner.doctor.series()
            runner.doctor.channels
    print(min(count, len(samples)))


def _count(workload: str, count: int, loop: str) -> tuple[int, int]:
    """(samples fused, instructions) of one child under callgrind."""
    proc = subprocess.run(
        ["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", sys.executable, __file__,
         "--child", workload, str(count), loop], capture_output=True, text=True, check=True, cwd=ROOT,
        env={**os.environ, **ONE_THREAD})
    collected = re.search(r"Collected\s*:\s*([\d,]+)", proc.stderr)
    if collected is None:
        raise SystemExit(f"no instruction count in valgrind's output:\n{proc.stderr[-2000:]}")
    return int(proc.stdout.split()[-1]), int(collected.group(1).replace(",", ""))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workload", choices=("jackal", "comma", "synthetic"), default="jackal")
    ap.add_argument("--messages", type=int, default=1000, help="N: the runs fuse N and 2N samples")
    ap.add_argument("--loop", choices=("core", "replay", "doctor", "proof"), default="core")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _child(args.child[0], int(args.child[1]), args.child[2])
        return
    n1, i1 = _count(args.workload, args.messages, args.loop)
    n2, i2 = _count(args.workload, 2 * args.messages, args.loop)
    print(f"{args.workload} {args.loop}: {(i2 - i1) / (n2 - n1):,.0f} instructions per message "
          f"(callgrind, {n2 - n1} messages)")


if __name__ == "__main__":
    main()
