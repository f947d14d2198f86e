"""Keep a Python thread state on the Zenoh threads that run the daemon's callbacks.

zenoh-python runs a direct callback (`Callback(indirect=False)`) on Zenoh's own receive
thread, which Python did not create. For each call, PyO3 acquires the GIL with
`PyGILState_Ensure`, which on such a thread creates a fresh thread state, and releases it
with `PyGILState_Release`, which destroys it again: per message a thread state allocated,
its frame data stack mapped (`mmap`) and page-faulted in, then unmapped. Measured with
`perf` on `fusiond bench-latency` at 1 kHz IMU + 100 Hz odometry, that churn sat in the
receive threads' kernel time; keeping one thread state per receive thread cut the daemon
process by ~4-6 % of a core in alternating runs (about a sixth of the daemon's CPU).

The remedy is the documented nesting of the GIL state API (pybind11 offers the same as
`gil_scoped_acquire::inc_ref`): the first callback on a thread calls `PyGILState_Ensure`
once more and never releases it, so the thread state's counter stays above zero and
PyO3's per-call Release only releases the GIL instead of destroying the state. The state
then lives as long as the thread (one per receive thread, a few KiB); the interpreter
frees any left at exit. A `threading.local` marks threads already done: its values live
in the thread state, so it persists exactly when the pin holds.

Only CPython has this API; elsewhere `keep_thread_state` does nothing.
"""

from __future__ import annotations

import ctypes
import sys
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["keep_thread_state", "with_kept_thread_state"]

_marks = threading.local()
_ensure: Callable[[], int] | None = None
if sys.implementation.name == "cpython" and hasattr(ctypes, "pythonapi"):
    _ensure = ctypes.pythonapi.PyGILState_Ensure
    _ensure.argtypes = []
    _ensure.restype = ctypes.c_int


def keep_thread_state() -> None:
    """From a callback (the GIL held): keep this thread's Python thread state after it returns."""
    if _ensure is not None and not getattr(_marks, "kept", False):
        _ensure()
        _marks.kept = True


def with_kept_thread_state(callback: Callable[[Any], None]) -> Callable[[Any], None]:
    """`callback`, keeping the thread state of the thread it runs on from its first call."""

    def call(arg: Any) -> None:
        if not getattr(_marks, "kept", False):
            keep_thread_state()
        callback(arg)

    return call
