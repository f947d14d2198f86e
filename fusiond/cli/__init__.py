"""Command line: `fusiond run | play | replay | doctor | init | info | report | tune | monitor | router | health |
set-pose | calibrate-imu | bench | bench-latency`.

One module per command (``fusiond/cli/<command>.py``) holds its options (``add_arguments``) and what it does
(``run``); this module lists the commands with their one-line help and dispatches. A command's module is
imported only when that command is parsed, and each imports what it needs when it runs, so that `--help`
reads no command module, `replay` does not pay for Zenoh nor `run` for matplotlib.
"""

from __future__ import annotations

import argparse
import atexit
import importlib
import os
import sys
import threading
from collections.abc import Collection, Sequence

from .common import LOG_LEVELS, VersionAction

__all__ = ["COMMANDS", "build_parser", "main", "run"]

# command -> (its module in this package, its line in `fusiond --help`), in the order the help lists them
COMMANDS: dict[str, tuple[str, str]] = {
    "replay": ("replay", "replay ROS 1/2 bags through the fusion core"),
    "doctor": ("doctor", "replay bags and print the doctor's verdicts with the summary; writes no file "
                         "(replay without outputs)"),
    "init": ("init", "write a starting config from a bag (topics, types, mounts), each choice commented, then "
                     "replay it with the doctor"),
    "info": ("info", "a bag's topics, types, counts, rates, stated covariances and what fusiond would use each for"),
    "report": ("report", "replay bags and write the HTML report (plots, the doctor's verdicts) into DIR "
                         "(replay --report DIR)"),
    "tune": ("tune", "fit the configured sensors' and the process's noise to bags by the innovations' likelihood, "
                     "check it on the held-back last 30 %%, write the tuned config"),
    "monitor": ("monitor", "live per-sensor innovation/NIS view of running daemons"),
    "router": ("router", "a Zenoh router for a fleet's daemons and monitors (as zenohd)"),
    "calibrate-imu": ("calibrate_imu", "measure a static IMU's noise and print it as config"),
    "bench": ("bench", "estimator, core and replay benchmarks on a bag"),
    "run": ("run", "the fusion daemon: subscribe to the sensors on Zenoh, publish the fused pose"),
    "play": ("play", "publish a bag's sensor topics onto Zenoh as zenoh-bridge-ros2dds would (as an rmw_zenoh node "
                     "with [ros] interop = \"rmw_zenoh\")"),
    "health": ("health", "query a running daemon's health; exit 0 when it is good enough"),
    "set-pose": ("set_pose", "re-initialise a running daemon's filter at a pose (robot_localization's set_pose); "
                             "prints the new health, whose pose is the one set"),
    "bench-latency": ("bench_latency", "sensor put -> fused pose latency over Zenoh on loopback"),
}


def build_parser(commands: Collection[str] | None = None) -> argparse.ArgumentParser:
    """The `fusiond` parser. ``commands``: the commands whose options it knows (default: all); the others are
    listed with their help line only, enough for `fusiond --help` and for argparse's "invalid choice"."""
    p = argparse.ArgumentParser(prog="fusiond", description="Wheel odometry + IMU EKF fusion over Eclipse Zenoh.")
    p.add_argument("--log-level", choices=LOG_LEVELS, help="default: info for run and play, warning otherwise")
    p.add_argument("--version", action=VersionAction, help="print the version and exit")
    # --log-level also after the subcommand, and in each subcommand's help (SUPPRESS: an absent one does
    # not overwrite the value given before the subcommand)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--log-level", choices=LOG_LEVELS, default=argparse.SUPPRESS,
                        help="log level of the structlog lines on stderr (default: info for run and play, "
                             "warning otherwise)")
    sub = p.add_subparsers(dest="command", required=True)
    for name, (module_name, help_line) in COMMANDS.items():
        parser = sub.add_parser(name, help=help_line, parents=[common])
        if commands is None or name in commands:
            module = importlib.import_module(f"{__name__}.{module_name}")
            module.add_arguments(parser)
            parser.set_defaults(func=module.run)
    return p


def _commands_in(argv: Sequence[str]) -> set[str]:
    """The commands an argument list may run: each of its words that names one. The command it runs is one
    of them; another (a bag named `info`, `--log-level info`) costs only its module's import."""
    return set(argv) & COMMANDS.keys()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser(_commands_in(argv)).parse_args(argv)
    from ..logs import configure

    # --quiet (replay's): the log's warnings too, unless a --log-level asks for them
    quiet = getattr(args, "quiet", False) is True and args.command == "replay"
    configure(args.log_level or ("error" if quiet else getattr(args, "default_log_level", "warning")))
    # The estimator's backend: compiled when built (the default, "auto"), or the numpy reference
    # (FUSIOND_KERNELS=numpy; estimator/backend.py). Each command that fuses passes
    # ``common.chosen_backend()`` to the cores it builds; an unknown name is refused here, before any runs.
    if os.environ.get("FUSIOND_KERNELS"):
        from ..errors import EstimatorError
        from .common import chosen_backend

        try:
            chosen_backend()
        except EstimatorError as e:
            print(f"fusiond: {e}", file=sys.stderr)
            return 2
    if getattr(args, "holds_recording", False):
        from ..collector import for_a_recording

        for_a_recording()
    try:
        return args.func(args)
    except BrokenPipeError:  # `fusiond doctor ... | head`: the reader left; no traceback for that
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # and none from the interpreter flushing stdout at exit
        return 1


def run() -> None:
    """The console script and ``python -m fusiond``: ``main`` on the process's arguments, then the exit.

    A command that leaves only this thread and no Zenoh session behind (a replay, the doctor, tune, a report)
    ends without the interpreter freeing its heap object by object: the recording, the records and the verdicts
    a replay holds take ~25 ms of a 0.7 s replay of the highway car to tear down, which the process's end does
    at once. The output streams are flushed and the exit handlers run first, as a normal exit runs them; a
    command that leaves threads or a Zenoh session exits as usual (their joins and closes run)."""
    code = main()
    if not isinstance(code, int) or threading.active_count() > 1 or "zenoh" in sys.modules:
        sys.exit(code)
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BrokenPipeError:  # the reader left before the last of the output (`fusiond doctor ... | head`)
            os.dup2(os.open(os.devnull, os.O_WRONLY), stream.fileno())
            code = 1
    os._exit(code)
