"""Forked children that share this process's memory and write back through a pipe: whether they may run
here, how many at once, and how one is started and stopped.

Replay reads a bag in a forked child while it fuses (``replay.read_ahead``), and tune and the doctor's
advice replay configs side by side in forked children (``tune.forked``): both start and stop them here.
"""

from __future__ import annotations

import fcntl
import os
import signal
import sys
from collections.abc import Callable

__all__ = ["fork_writer", "forks", "stop_child", "workers_available", "write_all"]


def forks() -> bool:
    """Are jobs run in forked children here? On Linux, where a forked child of a process that has used
    numpy is safe (macOS's Accelerate is not fork-safe; Windows has no fork)."""
    return sys.platform.startswith("linux") and hasattr(os, "fork")


def workers_available() -> int:
    """How many jobs may run at once: the CPUs this process may use; 1 where jobs are not forked (``forks``)."""
    if not forks():
        return 1
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def fork_writer(write: Callable[[int], None], pipe_bytes: int = 0) -> tuple[int, int]:
    """Fork a child that runs ``write(fd)`` on the write end of a new pipe, then ends (``os._exit``: 0, or 1
    when it raised, and the parent reads a pipe that closes without what it waited for); (the pipe's read end,
    the child's pid). What this process has buffered on stdout and stderr is flushed first, so that it is
    written once, by this process. ``pipe_bytes``: the pipe's buffer, asked of Linux (0: its default)."""
    read_end, write_end = os.pipe()
    if pipe_bytes:
        try:
            fcntl.fcntl(write_end, fcntl.F_SETPIPE_SZ, pipe_bytes)
        except (AttributeError, OSError):  # an older kernel or a lower limit: the default buffer still works
            pass
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        pid = os.fork()
    except OSError:
        os.close(read_end)
        os.close(write_end)
        raise
    if pid == 0:  # the child: never returns into the caller's code
        status = 0
        try:
            os.close(read_end)
            write(write_end)
        except BaseException:  # noqa: BLE001 - the parent sees the pipe close without a result
            status = 1
        finally:
            os._exit(status)  # no atexit handlers, no second flush of the parent's buffers
    os.close(write_end)
    return read_end, pid


def write_all(fd: int, data: bytes) -> None:
    """Write all of ``data`` to ``fd`` (a pipe takes what its buffer holds at a time)."""
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def stop_child(read_end: int, pid: int) -> None:
    """Close a running child's pipe, kill it and reap it (a call that raises leaves no child behind)."""
    os.close(read_end)
    try:
        os.kill(pid, signal.SIGKILL)
    except OSError:  # it had ended already
        pass
    os.waitpid(pid, 0)
