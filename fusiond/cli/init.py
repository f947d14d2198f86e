"""`fusiond init BAG [BAG ...] --out FILE`: a starting config from the bags, every choice commented, then
the doctor's replay of it."""

from __future__ import annotations

import argparse

from .common import holds_recording
from .replay import as_replay
from .replay import run as run_replay

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    holds_recording(p)
    p.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")
    p.add_argument("--out", required=True, metavar="FILE", help="the config to write")
    p.add_argument("--force", action="store_true", help="overwrite FILE if it exists")


def run(args: argparse.Namespace) -> int:
    """`fusiond init BAG --out FILE`: a commented starting config from the bags (init_config.py), then the
    doctor's replay of it."""
    from ..init_config import write_init

    code = write_init(args.bags, args.out, force=args.force)
    # the replay as `fusiond replay` makes it, its paste lines replayed too: a new user's first advice is proven
    return code or run_replay(as_replay(args.bags, args.out))
