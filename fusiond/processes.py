"""May this process fork children that share its memory, and how many may run at once.

Replay reads a bag in a forked child while it fuses (``replay.read_ahead``), and tune and the doctor's
advice replay configs side by side in forked children (``tune.forked``): both ask here.
"""

from __future__ import annotations

import os
import sys

__all__ = ["forks", "workers_available"]


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
