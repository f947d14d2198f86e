"""`fusiond health`: a running daemon's health answer; the exit code says whether it is good enough, for a
container's HEALTHCHECK or a systemd watchdog."""

from __future__ import annotations

import argparse
import sys

from .common import EXIT_UNHEALTHY, add_daemon_client_arguments
from .tool_session import in_namespace, reached, tool_session

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    add_daemon_client_arguments(p, reads="health key", key="health key (default: output.health_key of the config)",
                                timeout=True)
    p.add_argument("--min-status", choices=["ok", "degraded", "starting", "failed"], default="degraded",
                   help="worst status that still exits 0 (default degraded: a daemon still starting, which "
                        "publishes nothing yet, exits 1, inside a container's start period; failed = any answer)")


# `starting` publishes nothing yet: below `degraded` (a silent sensor, poses still published), above `failed`
_STATUS_RANK = {"failed": 0, "starting": 1, "degraded": 2, "ok": 3}


def run(args: argparse.Namespace) -> int:
    import json

    from ..transport.session import query_health

    cfg, session = tool_session(args, unreachable_exit=EXIT_UNHEALTHY)
    key = args.key or cfg.output.health_key
    try:
        answers = query_health(session, key, args.timeout)
    finally:
        session.close()
    if not answers:
        waited = f"within {args.timeout:g} s"  # an unserved query is asked again until then
        print(f"fusiond: no health answer on {key!r}{in_namespace(cfg)} {waited} ({reached(args, cfg)})",
              file=sys.stderr)
        return EXIT_UNHEALTHY
    worst = None
    for raw in answers:
        print(raw.decode())
        status = json.loads(raw).get("status")
        rank = _STATUS_RANK.get(status, -1)
        worst = rank if worst is None else min(worst, rank)
    return 0 if worst is not None and worst >= _STATUS_RANK[args.min_status] else EXIT_UNHEALTHY
