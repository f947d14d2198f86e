"""`fusiond bench`: the estimator, core and replay benchmarks on a bag, optionally with the latency one.

The benchmarks themselves are benchmarks/bench.py and benchmarks/bench_latency.py of the source tree
(cli/benchmarks.py finds them); this module checks the inputs first, so that a wrong bag or config is
refused before a minute of estimator benchmarks."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .benchmarks import REPO_ROOT, load
from .common import BENCH_NO_MULTICAST, EXIT_USAGE, load_config, positive

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bag", help="bag to replay for the core and replay benchmarks (default: the Jackal bag "
                                  "data/jackal_test2.bag of the source tree)")
    p.add_argument("--config", help="TOML config the bag is replayed with (default: examples/jackal.toml of "
                                    "the source tree)")
    p.add_argument("--quick", action="store_true", help="fewer repeats")
    p.add_argument("--latency", action="store_true", help="also the Zenoh end-to-end latency benchmark")
    p.add_argument("--seconds", type=positive, default=10.0, help="latency benchmark duration")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.add_argument("--no-multicast", action="store_true", help=BENCH_NO_MULTICAST)


# `bench`'s defaults: the Jackal bag and its config of the source tree fusiond runs from
BENCH_BAG = REPO_ROOT / "data" / "jackal_test2.bag"
BENCH_CONFIG = REPO_ROOT / "examples" / "jackal.toml"


def _bench_input_error(bag: Path, cfg) -> str | None:
    """Why ``bench`` cannot replay this bag with this config, as ``replay`` would refuse it (no odometry
    sensor, a file that is no bag, the odometry or world-frame topic not in it), or None."""
    from ..core.sensors.registry import kind_of
    from ..replay.bag import BagError, open_bag_samples
    from ..replay.run import check_topics

    if not any(kind_of(s).drives_prediction for s in cfg.sensors):
        return "the config has no odometry sensor to replay the bag with (add an odom [[sensors]] table)"
    try:
        with open_bag_samples([bag], cfg.sensors) as opened:
            check_topics(opened, cfg, None)
    except BagError as err:
        return str(err)
    return None


def run(args: argparse.Namespace) -> int:
    import msgspec

    bench = load("bench")
    bag = Path(args.bag) if args.bag else BENCH_BAG
    config = args.config or str(BENCH_CONFIG)
    if bag.is_dir():  # bench.run replays a bag file only (it skips anything else): say so, not "no such bag"
        print(f"fusiond: bench: --bag {bag} is a directory (a ROS 2 bag?); bench takes one bag file, a ROS 1 .bag "
              "or a ROS 2 .mcap", file=sys.stderr)
        return EXIT_USAGE
    if not bag.is_file():
        default = "" if args.bag else " (the default, data/jackal_test2.bag of the source tree fusiond runs from)"
        print(f"fusiond: bench: no such bag {bag}{default}; give one with --bag", file=sys.stderr)
        return EXIT_USAGE
    cfg = load_config(config)
    problem = _bench_input_error(bag, cfg)
    if problem:  # found now, not after a minute of estimator benchmarks
        print(f"fusiond: bench: {problem}", file=sys.stderr)
        return EXIT_USAGE
    result = bench.run(bag, Path(config), cfg, quick=args.quick)
    if args.latency:
        # The daemon as `fusiond run` runs it: outputs batched, not express (transport/outputs.py); its CPU
        # is the target's. `bench-latency --express` measures the express variant.
        lat = load("bench_latency").run_bench(seconds=args.seconds, imu_hz=1000.0, odom_hz=100.0, express=False)
        flat: dict[str, float] = {}
        for k, v in msgspec.to_builtins(lat).items():
            if isinstance(v, dict):  # latency statistics: pose, raw_hop, ... -> pose_p50_us, ...
                flat.update({f"{k}_{sk}": sv for sk, sv in v.items() if isinstance(sv, (int, float))})
            elif isinstance(v, (int, float)):
                flat[k] = v
        result["latency"] = flat
        result["targets"] = bench.targets(result)  # with the daemon's CPU ratio as well
    if args.json:
        print(msgspec.json.encode(result).decode())
    else:
        print(bench.format_table(result))
    return 0
