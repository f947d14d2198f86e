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
