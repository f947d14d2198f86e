"""The Zenoh session of a client tool (play, health, set-pose, monitor, calibrate-imu) and the words its
messages use for where it looked: shared, so that every tool reaches a daemon and says so the same way."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import EXIT_USAGE, load_config

__all__ = ["in_namespace", "reached", "tool_session", "zenoh_errors"]


def zenoh_errors():
    """The config's and the session's error classes, imported when a command that opens a session runs."""
    from ..config import ConfigError
    from ..transport.session import SessionError

    return ConfigError, SessionError


def tool_session(args: argparse.Namespace, listen: list[str] | None = None, unreachable_exit: int = 1):
    """A Zenoh session for a client tool (play, health, monitor, calibrate-imu) of the daemon that the
    config describes: its [zenoh] table if a config is given, --connect wins. Errors exit: a bad config
    with 2, a session that cannot open with ``unreachable_exit``."""
    from ..config import Config
    from ..transport.session import client_config, open_session

    config = getattr(args, "config", None)
    cfg = load_config(config) if config else Config()
    ConfigError, SessionError = zenoh_errors()
    from ..config import check_endpoint

    for option, endpoints in (("--connect", getattr(args, "connect", None)), ("--listen", listen)):
        for ep in endpoints or []:
            try:
                check_endpoint(ep, option)
            except ConfigError as err:
                print(f"fusiond: {err}", file=sys.stderr)
                raise SystemExit(EXIT_USAGE) from None
    base = Path(config).resolve().parent if config else None
    zc = cfg.zenoh
    if getattr(args, "no_multicast", False):
        import msgspec

        zc = msgspec.structs.replace(zc, multicast_scouting=False)
    try:
        return cfg, open_session(client_config(zc, base_dir=base, connect=args.connect, listen=listen))
    except ConfigError as err:
        prefix = f"{config}: " if config else ""
        print(f"fusiond: config error: {prefix}{err}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    except SessionError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        raise SystemExit(unreachable_exit) from None


def reached(args: argparse.Namespace, cfg) -> str:
    """Where a tool's session looked for the daemon, for a "no answer" line: an operator reads whether
    it dialled the wrong endpoint or had nothing to dial at all."""
    from ..transport.session import client_endpoints

    endpoints = client_endpoints(cfg.zenoh, getattr(args, "connect", None))
    scouting = cfg.zenoh.multicast_scouting and not getattr(args, "no_multicast", False)
    if endpoints:
        return "dialled " + ", ".join(endpoints) + (" and scouted by multicast" if scouting else "")
    if scouting:
        return "scouted by multicast only: give --connect ENDPOINT to dial the daemon"
    return ("nothing to reach: no --connect, no [zenoh] connect or listen endpoint in the config, and multicast "
            "scouting off")


def in_namespace(cfg) -> str:
    """How a tool's message names the robot it asked: its namespace (the key on the wire), if any."""
    ns = cfg.zenoh.namespace
    return f" in namespace {ns!r}" if ns else " (no namespace)"
