"""`fusiond monitor`: the live per-sensor innovation/NIS view of running daemons (fusiond/monitor.py)."""

from __future__ import annotations

import argparse

from .common import positive
from .tool_session import tool_session

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="Zenoh endpoint to reach the daemons")
    p.add_argument("--config", help="TOML config: [zenoh] table and output keys (optional); with the robot's "
                   "[[sensors]], its daemon's verdicts are judged knowing them, as the replay's doctor does")
    p.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    p.add_argument("--timeout", type=positive, default=5.0,
                   help="seconds to find a daemon before giving up (default 5)")
    p.add_argument("--duration", type=positive, help="stop after S seconds (default: until Ctrl-C)")
    p.add_argument("--interval", type=positive, default=1.0, help="refresh period in seconds (default 1)")
    p.add_argument("--json", action="store_true", help="stream JSON lines instead of the terminal view")
    p.add_argument("--fleet", action="store_true", help="one line per daemon (status, link, worst NIS, drops, age), "
                                                        "worst first")
    p.add_argument("--namespace", metavar="NS", help="watch the daemon of this Zenoh namespace only")
    p.add_argument("--stale", type=positive, metavar="S", help="a daemon whose newest health answer is older "
                   "than S seconds reads lost (default: 3 x --interval, at least 2)")


def run(args: argparse.Namespace) -> int:
    from .. import monitor

    cfg, session = tool_session(args)
    try:
        return monitor.run(session, timeout=args.timeout, duration=args.duration, as_json=args.json,
                           interval=args.interval, health_key=cfg.output.health_key,
                           diagnostics_key=cfg.output.diagnostics_key, window=cfg.filter.nis_window,
                           fleet=args.fleet, namespace=args.namespace or "", stale_s=args.stale, cfg=cfg)
    finally:
        session.close()
