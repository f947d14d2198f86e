"""The CLI's shape: one module per command, and a command line that reads only its own command's module.

`fusiond --help` and `fusiond replay --help` are typed often and run on every container healthcheck
(`fusiond health`): the parser imports a command's module only when that command is on the line, and
parses it exactly as the parser with every command does.
"""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from fusiond.cli import COMMANDS, build_parser


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(action.choices)


def test_each_command_is_a_module_with_its_options_and_its_run():
    assert list(_subparsers(build_parser())) == list(COMMANDS)
    for name, (module_name, help_line) in COMMANDS.items():
        module = importlib.import_module(f"fusiond.cli.{module_name}")
        assert callable(module.add_arguments) and callable(module.run), name
        assert module.__doc__ and help_line, name


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_command_parsed_alone_has_the_options_of_the_whole_parser(command):
    whole, alone = _subparsers(build_parser())[command], _subparsers(build_parser({command}))[command]
    assert alone.format_help() == whole.format_help()
    assert alone._defaults == whole._defaults


def _cli_modules_loaded(*argv: str) -> set[str]:
    code = ("import sys\nfrom fusiond.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "print(sorted(m for m in sys.modules if m.startswith('fusiond.cli.')))")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, check=True).stdout
    return set(eval(out.strip().splitlines()[-1]))


def test_help_reads_no_command_module_and_a_command_only_its_own():
    assert _cli_modules_loaded("--help") == {"fusiond.cli.common"}
    assert _cli_modules_loaded("replay", "--help") == {"fusiond.cli.common", "fusiond.cli.replay"}
    # a word naming another command (a log level, a bag) costs that module's import, nothing else
    assert _cli_modules_loaded("--log-level", "info", "replay", "--help") == {
        "fusiond.cli.common", "fusiond.cli.info", "fusiond.cli.replay"}


_DAEMON_CLIENTS = ("health", "set-pose", "play", "calibrate-imu")  # they open a session to a running daemon


def _options(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {a.option_strings[0]: a for a in parser._actions if a.option_strings}


def test_the_commands_that_reach_a_daemon_take_its_options_alike():
    """health, set-pose, play and calibrate-imu reach the daemon the same way (``tool_session``): --connect
    and --no-multicast read the same on each, --timeout on those that wait for an answer, and --config says
    what the command reads of it beside the namespace and endpoints (required where it cannot run without)."""
    commands = _subparsers(build_parser())
    options = {name: _options(commands[name]) for name in _DAEMON_CLIENTS}
    for flag in ("--connect", "--no-multicast"):
        actions = [options[name][flag] for name in _DAEMON_CLIENTS]
        assert len({(a.help, a.metavar, type(a).__name__, a.default) for a in actions}) == 1, flag
    timeouts = [options[name]["--timeout"] for name in ("health", "set-pose")]
    assert len({(a.help, a.type, a.default) for a in timeouts}) == 1
    assert not {"--timeout"} & (set(options["play"]) | set(options["calibrate-imu"]))
    for name in _DAEMON_CLIENTS:
        config = options[name]["--config"]
        assert config.help.startswith("TOML config of the daemon (") and config.help.endswith(", namespace, endpoints)")
        assert config.required == (name == "play"), name
    assert "--key" not in options["play"] and all("--key" in options[name] for name in ("health", "set-pose",
                                                                                        "calibrate-imu"))


_REPLAYS_A_RECORDING = {"replay", "doctor", "report", "tune", "init"}


def test_the_commands_that_replay_a_recording_raise_the_collectors_threshold_and_no_other(jackal_bag, tmp_path):
    """A command holding a recording in memory spaces the cyclic collector's young collections out from its
    start (``collector.for_a_recording``); the others (the daemon first) keep the interpreter's threshold."""
    import gc

    from fusiond.cli import main
    from fusiond.collector import YOUNG

    commands = _subparsers(build_parser())
    marked = {name for name, parser in commands.items() if parser.get_default("holds_recording")}
    assert marked == _REPLAYS_A_RECORDING
    before = gc.get_threshold()
    config = tmp_path / "jackal.toml"
    config.write_text((Path(__file__).parents[2] / "examples" / "jackal.toml").read_text())
    try:
        gc.set_threshold(700, *before[1:])
        assert main(["info", str(jackal_bag)]) == 0
        assert gc.get_threshold()[0] == 700
        assert main(["replay", str(jackal_bag), "--config", str(config), "--quiet"]) == 0
        assert gc.get_threshold() == (YOUNG, *before[1:])
    finally:
        gc.set_threshold(*before)
