"""`fusiond tune BAG [BAG ...] --config FILE --out TUNED.toml`: fit the configured noise to the bags (fusiond/tune)
and write the complete tuned config. scipy is imported by the fit, only when this command runs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import (ALLOW_MISSING, EXIT_USAGE, chosen_backend, holds_recording,
                     load_config, output_error)

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    holds_recording(p)
    p.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    p.add_argument("--config", required=True, help="TOML config (see config.toml): the sensors and the start")
    p.add_argument("--out", required=True, metavar="TUNED.toml", help="write the complete tuned config here")
    p.add_argument("--keys", action="append", metavar="KEY[,KEY]",
                   help="fit only these (e.g. imu.gyro_noise, wheel.twist_noise, filter); default: every tunable key")
    p.add_argument("--budget-s", type=float, default=120.0, metavar="S",
                   help="stop the fit after S seconds of replays (default 120; the held-back check runs after)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--allow-missing", **ALLOW_MISSING)


def run(args: argparse.Namespace) -> int:
    """Fit the configured noise to the bags (fusiond/tune) and write the complete tuned config."""
    cfg = load_config(args.config, needs="tune")
    problem = output_error(args.out, "--out")
    if problem:
        print(f"fusiond: {problem}", file=sys.stderr)
        return EXIT_USAGE
    if not args.budget_s > 0.0:
        print(f"fusiond: --budget-s {args.budget_s:g}: must be a positive number of seconds", file=sys.stderr)
        return EXIT_USAGE
    from ..errors import ConfigError, ReplayError
    from ..tune import format_table, read_samples, select, tunable_params, tune, write

    keys = [k for part in args.keys for k in part.split(",")] if args.keys else None
    try:
        if keys is not None:
            select(tunable_params(cfg), keys)  # an unknown key fails before the bags are read
        samples = read_samples([Path(b) for b in args.bags], cfg,
                               warn=lambda message: print(f"fusiond: warning: {message}", file=sys.stderr),
                               allow_missing=args.allow_missing)
        result = tune(samples, cfg, keys, budget_s=args.budget_s, progress=not args.quiet, backend=chosen_backend())
    except (ConfigError, ReplayError) as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    bags = ", ".join(Path(b).name for b in args.bags)
    b, a = result.heldback_before, result.heldback_after
    held = f"; held-back -log L {b.neg_loglik:.1f} -> {a.neg_loglik:.1f}" if b is not None and a is not None else ""
    header = (f"fusiond tune of {bags} from {args.config}: {len(result.changed)} key(s) tuned{held}.\n"
              "Keys at their default are left out; config.toml documents them.")
    # the user's own file with the tuned keys edited in (its comments kept), else the whole config written
    write(args.out, result.config, result.comments, header, original=(Path(args.config).read_text(), cfg))
    print(format_table(result))
    print(f"tuned config {args.out}")
    return 0
