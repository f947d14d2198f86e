"""Independent jobs shared with forked processes, for a second core: each result the same as run here.

The doctor's advice lines are proven by one replay each, and the replays share nothing but what
they read (the recording's samples, the configured replay's records): they are pure functions of
what the process holds when they start. A forked child holds the same, so it computes the same
bits; it sends back only the small results (pickled through a pipe). The jobs are split by index
(job i to process i mod n, this one taking share 0), each process runs its share in order, and the
results come back in the jobs' order, so what is printed does not depend on which process finished
first. A child that fails or sends nothing usable has its share run here instead.

Only a caller that knows the process is fork-safe asks for more than one worker (the command-line
replay: no threads of its own alive by then); a child leaves by ``os._exit``, so it flushes no
inherited output buffer and runs no exit handler of the parent's.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable, Sequence
from typing import TypeVar

__all__ = ["map_forked", "usable_cpus"]

T = TypeVar("T")
R = TypeVar("R")


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def map_forked(fn: Callable[[T], R], jobs: Sequence[T], workers: int) -> list[R]:
    """``[fn(j) for j in jobs]``, the jobs shared with up to ``workers - 1`` forked children."""
    n = min(workers, len(jobs))
    if n <= 1 or not hasattr(os, "fork"):
        return [fn(j) for j in jobs]
    children: list[tuple[int, int, int]] = []  # (share, pid, read end)
    for share in range(1, n):
        r, w = os.pipe()
        try:
            pid = os.fork()
        except OSError:
            os.close(r)
            os.close(w)
            break
        if pid == 0:  # the child: its share, sent back, then gone without the parent's exit path
            code = 1
            try:
                os.close(r)
                data = pickle.dumps([fn(j) for j in jobs[share::n]], protocol=pickle.HIGHEST_PROTOCOL)
                with os.fdopen(w, "wb") as out:
                    out.write(data)
                code = 0
            finally:
                os._exit(code)
        os.close(w)
        children.append((share, pid, r))
    results: list[R | None] = [None] * len(jobs)
    done = {0}
    results[0::n] = [fn(j) for j in jobs[0::n]]
    for share, pid, r in children:
        with os.fdopen(r, "rb") as src:
            data = src.read()
        _, status = os.waitpid(pid, 0)
        if os.waitstatus_to_exitcode(status) == 0 and data:
            try:
                results[share::n] = pickle.loads(data)
                done.add(share)
            except Exception:  # noqa: BLE001 - a broken share is run here instead
                pass
    for share in range(1, n):
        if share not in done:
            results[share::n] = [fn(j) for j in jobs[share::n]]
    return results  # type: ignore[return-value]
