"""What several commands share: exit codes, loading the config as a one-line error, checking an output path
before a long run, argparse types for numbers, the option specs that more than one command takes, and the
options of a command that reaches a running daemon over Zenoh (``add_daemon_client_arguments``).

Imports only the standard library at module level: every command, ``--help`` included, reads this module.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

__all__ = ["ADVICE_BUDGET", "ALLOW_MISSING", "BENCH_NO_MULTICAST", "EXIT_UNHEALTHY", "EXIT_USAGE", "LOG_LEVELS",
           "VersionAction", "add_daemon_client_arguments", "chosen_backend", "count", "holds_recording",
           "load_config", "non_negative", "output_error", "positive"]

EXIT_USAGE = 2
EXIT_UNHEALTHY = 1
LOG_LEVELS = ["debug", "info", "warning", "error"]


def holds_recording(parser: argparse.ArgumentParser) -> None:
    """Mark a command as one that replays a recording held in memory: ``main`` spaces the cyclic collector's
    young collections out for it from the start, its imports included (``collector.for_a_recording``)."""
    parser.set_defaults(holds_recording=True)


def chosen_backend():
    """The estimator's backend that FUSIOND_KERNELS names (``estimator.backend.from_environment``), None
    when it names none (the default: compiled when built). Read here, not in the estimator (no I/O
    there), and only when set: the commands that do not fuse need not import numpy. An unknown name is
    an EstimatorError (``main`` checks it before any command runs)."""
    if not os.environ.get("FUSIOND_KERNELS"):
        return None
    from ..estimator.backend import from_environment

    return from_environment(os.environ)


def load_config(path: str, needs: str = ""):
    """The config, or exit 2 with one line. ``needs``: what the command does with its sensors (a config
    without any is refused, naming that, instead of failing later on what it cannot find)."""
    from ..config import ConfigError, load

    try:
        cfg = load(path)
    except ConfigError as err:
        print(f"fusiond: config error: {err}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    if needs and not cfg.sensors:
        print(f"fusiond: config error: {path}: no [[sensors]] configured: nothing to {needs}; add at least the "
              "odometry sensor (see config.toml)", file=sys.stderr)
        raise SystemExit(EXIT_USAGE)
    return cfg


def output_error(path: str, option: str, directory: bool = False) -> str | None:
    """Why an output path cannot be written (checked before a long replay, not after it), or None."""
    p = Path(path)
    if directory and p.exists() and not p.is_dir():
        return f"{option} {path}: names an existing file; --report writes a directory (index.html and images)"
    if not directory and p.is_dir():
        return f"{option} {path}: is a directory"
    if p.exists():
        return None if os.access(p, os.W_OK) else f"{option} {path}: not writable"
    parent = p.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        return f"{option} {path}: {parent} is a file, not a directory"
    return None if os.access(parent, os.W_OK) else f"{option} {path}: cannot create it ({parent} is not writable)"


def _version() -> str:
    """The installed distribution's version (pyproject.toml), read only when asked for."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("fusiond")
    except PackageNotFoundError:  # run from a source tree that was never installed
        return "unknown (not installed)"


class VersionAction(argparse.Action):
    """`fusiond --version`: "fusiond <version>" on stdout, exit 0 (argparse's own action would read the
    version when the parser is built, i.e. on every command)."""

    def __init__(self, option_strings: list[str], dest: str = argparse.SUPPRESS, **kwargs) -> None:
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        print(f"fusiond {_version()}")
        parser.exit(0)


def _number(text: str, *, zero: bool) -> float:
    """An option's number, finite and positive (or, with ``zero``, also 0): argparse's own error otherwise, so that
    a duration, timeout or rate of no meaning is refused before anything runs (not as a traceback later)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (math.isfinite(value) and (value >= 0.0 if zero else value > 0.0)):
        raise argparse.ArgumentTypeError(f"{text}: must be {'0 or more' if zero else 'a positive number'}")
    return value


def positive(text: str) -> float:
    return _number(text, zero=False)


def non_negative(text: str) -> float:
    return _number(text, zero=True)


def count(text: str) -> int:
    """An option's whole number of times, 1 or more (argparse's own error otherwise)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text}: must be 1 or more")
    return value


# replay, doctor and report: how long the doctor's paste lines may be replayed before they are printed
ADVICE_BUDGET = dict(type=float, default=60.0, metavar="S",
                     help="replay each of the doctor's paste lines on the bags before printing it, for up to S "
                          "seconds (default 60; 0: print them unreplayed)")

# Every command that opens a Zenoh session takes --no-multicast, so that it can be typed on any of them. The
# latency benchmark's sessions (bench-latency, bench --latency) connect to each other on loopback and never
# scout: for them the flag states what already holds.
BENCH_NO_MULTICAST = "do not scout for peers by multicast (always so: the benchmark's sessions are on loopback)"


ALLOW_MISSING = {"action": "store_true",
                 "help": "replay without a configured sensor whose topic is not in the bag (a warning); "
                         "default: that is an error naming the topic"}


def add_daemon_client_arguments(p: argparse.ArgumentParser, *, reads: str, config_required: bool = False,
                                key: str | None = None, timeout: bool = False) -> None:
    """The options of a command that opens a Zenoh session to a running daemon (health, set-pose, play,
    calibrate-imu): ``--config``, ``--connect``, ``--key``, ``--no-multicast``, ``--timeout``.

    Every such command reaches the daemon the same way (``tool_session``: the config's [zenoh] table,
    ``--connect`` wins, else the config's connect, else its listen endpoints on loopback), so those options
    read the same on each. What differs is the command's own: ``reads``, what it takes from the config
    beside the namespace and endpoints; ``config_required``, a command that cannot run without one; ``key``,
    the help of its key (None: it has no --key); ``timeout``, whether it waits for an answer."""
    p.add_argument("--config", required=config_required,
                   help=f"TOML config of the daemon ({reads}, namespace, endpoints)")
    p.add_argument("--connect", action="append", metavar="ENDPOINT",
                   help="Zenoh endpoint to connect to (repeatable); default: the config's connect, else its listen "
                        "endpoints on loopback")
    if key is not None:
        p.add_argument("--key", help=key)
    p.add_argument("--no-multicast", action="store_true", help="do not scout for peers by multicast")
    if timeout:
        p.add_argument("--timeout", type=positive, default=2.0, help="seconds to wait for an answer (default 2)")
