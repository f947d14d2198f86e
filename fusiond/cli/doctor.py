"""`fusiond doctor BAG --config FILE`: `replay` with the doctor and no output files."""

from __future__ import annotations

import argparse

from .common import ADVICE_BUDGET, ALLOW_MISSING, holds_recording
from .replay import as_replay
from .replay import run as run_replay

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    holds_recording(p)
    p.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    p.add_argument("--config", required=True, help="TOML config (see config.toml)")
    p.add_argument("--advice-budget-s", **ADVICE_BUDGET)
    p.add_argument("--allow-missing", **ALLOW_MISSING)


def run(args: argparse.Namespace) -> int:
    """`fusiond doctor BAG --config FILE`: `replay` with the doctor and no output files; prints the
    summary with the doctor's verdicts. Exit codes as replay's."""
    return run_replay(as_replay(args.bags, args.config, "--advice-budget-s", repr(args.advice_budget_s),
                                 *(["--allow-missing"] if args.allow_missing else [])))
