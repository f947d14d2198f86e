"""`fusiond run --config FILE`: the daemon (transport/daemon.py); SIGINT/SIGTERM stop it cleanly."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .common import EXIT_USAGE, chosen_backend, load_config
from .tool_session import zenoh_errors

__all__ = ["add_arguments", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", required=True, help="TOML config (see config.toml)")
    p.add_argument("--no-multicast", action="store_true",
                   help="do not scout for peers by multicast (overrides zenoh.multicast_scouting)")
    p.set_defaults(default_log_level="info")


def run(args: argparse.Namespace) -> int:
    cfg = load_config(args.config, needs="subscribe to: the daemon would wait forever for input")
    if getattr(args, "no_multicast", False):
        import msgspec

        cfg = msgspec.structs.replace(cfg, zenoh=msgspec.structs.replace(cfg.zenoh, multicast_scouting=False))
    from ..transport.daemon import run as run_daemon

    ConfigError, SessionError = zenoh_errors()
    try:
        return run_daemon(cfg, base_dir=Path(args.config).resolve().parent, backend=chosen_backend())
    except ConfigError as err:
        print(f"fusiond: config error: {args.config}: {err}", file=sys.stderr)
        return EXIT_USAGE
    except SessionError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return 1
