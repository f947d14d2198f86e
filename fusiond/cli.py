"""Command line: `fusiond replay | bench | ...`. Each command imports what it needs when it runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_USAGE = 2


def _load_config(path: str):
    from .config import ConfigError, load

    try:
        return load(path)
    except ConfigError as err:
        print(f"fusiond: config error: {err}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None


def cmd_replay(args: argparse.Namespace) -> int:
    cfg = _load_config(args.config)
    from .replay.bag import BagError
    from .replay.run import replay, summary

    try:
        result = replay(
            [Path(p) for p in args.bags],
            cfg,
            tum=Path(args.tum) if args.tum else None,
            diagnostics=Path(args.diagnostics) if args.diagnostics else None,
            keep_trace=bool(args.plot),
            progress=not args.quiet,
        )
    except BagError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    if args.plot:
        from .replay.plot import plot_replay

        plot_replay(result, Path(args.plot), title=", ".join(Path(b).name for b in args.bags))
    if not args.quiet:
        print(summary(result))
    if result.final is None:
        return 1
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="fusiond", description="Wheel odometry + IMU EKF fusion over Eclipse Zenoh.")
    p.add_argument("--log-level", default="warning", choices=["debug", "info", "warning", "error"])
    sub = p.add_subparsers(dest="command", required=True)

    r = sub.add_parser("replay", help="replay ROS 1/2 bags through the fusion core")
    r.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    r.add_argument("--config", required=True, help="TOML config (see config.toml)")
    r.add_argument("--tum", help="write the trajectory as TUM lines (stamp x y z qx qy qz qw)")
    r.add_argument("--diagnostics", help="write one JSON diagnostics record per update (JSON lines)")
    r.add_argument("--plot", help="write a PNG of the trajectory and NIS per sensor")
    r.add_argument("--quiet", action="store_true", help="no progress bar, no summary")
    r.set_defaults(func=cmd_replay)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from .logs import configure

    configure(args.log_level)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
