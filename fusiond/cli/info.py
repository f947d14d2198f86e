"""`fusiond info BAG`: what a bag holds (topics, types, counts, rates, stated covariances), before any config."""

from __future__ import annotations

import argparse

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("bags", nargs="+", help="bag file(s) (ROS 1 .bag or ROS 2 directory/.mcap)")


def run(args: argparse.Namespace) -> int:
    """`fusiond info BAG`: topics, types, counts, rates, stated covariances, what fusiond would use (bag_info.py)."""
    from ..bag_info import print_info

    return print_info(args.bags)
