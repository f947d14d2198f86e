"""The console script's exit (``fusiond.cli.run``): a command that leaves only its own thread ends without the
interpreter's teardown of its heap, yet with everything a normal exit gives: the whole output, the exit code,
the exit handlers run; one that leaves a thread behind exits normally (the thread is joined)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from fusiond.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _python(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, cwd=ROOT, timeout=120)


@pytest.mark.e2e
def test_the_process_ends_with_the_whole_output_its_code_and_its_exit_handlers(jackal_bag: Path, capsys) -> None:
    assert main(["info", str(jackal_bag)]) == 0
    said = capsys.readouterr().out
    got = _python("import atexit, sys; from fusiond.cli import run; "
                  "atexit.register(lambda: print('exit handler ran')); sys.argv = ['fusiond', 'info', sys.argv[1]]; "
                  "run()", str(jackal_bag))
    assert got.returncode == 0
    assert got.stdout == said + "exit handler ran\n"  # piped: block-buffered, flushed whole at the end
    missing = _python("import sys; from fusiond.cli import run; sys.argv = ['fusiond', 'info', 'no_such.bag']; run()")
    assert missing.returncode == main(["info", "no_such.bag"]) != 0
    assert "no_such.bag" in missing.stderr


@pytest.mark.e2e
def test_a_command_that_leaves_a_thread_exits_normally_and_the_thread_ends_its_work(jackal_bag: Path,
                                                                                      tmp_path: Path) -> None:
    done = tmp_path / "done"
    got = _python("import pathlib, sys, threading, time; from fusiond.cli import run; done = pathlib.Path(sys.argv[2]); "
                  "threading.Thread(target=lambda: (time.sleep(0.5), done.write_text('joined'))).start(); "
                  "sys.argv = ['fusiond', 'info', sys.argv[1]]; run()", str(jackal_bag), str(done))
    assert got.returncode == 0
    assert done.read_text() == "joined"
