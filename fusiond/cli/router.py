"""`fusiond router`: a Zenoh router for a fleet's daemons and monitors, so that a fleet needs no zenohd."""

from __future__ import annotations

import argparse
import sys

from .common import EXIT_USAGE
from .tool_session import zenoh_errors

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", action="append", metavar="ENDPOINT", default=None,
                   help="endpoint to listen on (repeatable; default tcp/0.0.0.0:7447)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT", help="another router to connect to")
    p.add_argument("--multicast", action="store_true", help="scout for and answer peers by multicast (off)")
    p.set_defaults(default_log_level="info")


def run(args: argparse.Namespace) -> int:
    from ..transport.router import router_config, run_router

    ConfigError, SessionError = zenoh_errors()
    from ..config import check_endpoint

    listen = args.listen or ["tcp/0.0.0.0:7447"]
    try:
        for option, endpoints in (("--listen", listen), ("--connect", args.connect or [])):
            for ep in endpoints:
                check_endpoint(ep, option)
        conf = router_config(listen, args.connect or [], multicast_scouting=args.multicast)
        return run_router(conf, ready=lambda session: print(f"router {session.zid()} listening on "
                                                            f"{', '.join(listen)}", flush=True))
    except ConfigError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return EXIT_USAGE
    except SessionError as err:
        print(f"fusiond: router: {err}", file=sys.stderr)
        return 1
