"""Independent replays side by side: each in a forked child process, on every CPU this process may use.

Proving the doctor's advice replays the recording once per paste line, each line on its own copy of
the config, and no replay reads another's result: on a machine with two cores two lines take the
time of one. Tune's probes are such replays too, and each of its held-back checks has a prediction of
the held-back fixes to make beside it (``beside``). A forked child shares the parent's recording (its samples, the reference terms) without
copying or pickling it; only the small result travels back, pickled through a pipe. The results are
those of running the jobs in turn, in the order given: the child runs the same function on the same
objects, in a process of its own.

Elsewhere than on Linux (``workers_available``), with one CPU, or with one job, the jobs run in turn in
this process. A job that raises in a child raises here (its exception pickled back, or a
``ForkedJobError`` with its text when it does not pickle): no job starts after it, the running ones are
waited for, and of those that failed the first in ``items`` order raises, as it would have in turn. A
child that ends without a word (killed, out of memory) loses nothing: its job runs again here, and the
log says so (``forked_job_rerun``).
"""

from __future__ import annotations

import os
import pickle
import selectors
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

from ..errors import TuneError
from ..logs import get_logger
from ..processes import fork_writer, stop_child, workers_available, write_all
from ..processes import forks as _forks

log = get_logger(__name__)

__all__ = ["ForkedJobError", "beside", "run_side_by_side", "workers_available"]

A = TypeVar("A")
B = TypeVar("B")

T = TypeVar("T")
R = TypeVar("R")


class ForkedJobError(TuneError):
    """A job in a forked child raised an exception that could not be carried back (its text is)."""


def run_side_by_side(job: Callable[[T], R], items: Sequence[T], workers: int | None = None,
                     before_each: Callable[[T], R | None] | None = None) -> list[R]:
    """``[job(item) for item in items]``, the jobs in forked children, at most ``workers`` at once.
    The default runs them all at once up to two per CPU (``workers_available``): three jobs on two CPUs
    share them and end together after 1.5 jobs' time, where one per CPU would take two. ``before_each(item)``,
    asked in this process as each job is about to start, may answer for it instead (a budget run out): its
    non-None answer is the item's result."""
    if workers is None:
        cpus = workers_available()
        workers = 1 if cpus == 1 else min(len(items), 2 * cpus)
    workers = max(1, workers)
    if workers == 1 or len(items) < 2 or not _forks():
        in_turn = []
        for item in items:
            answer = _answer(before_each, item)
            in_turn.append(answer if answer is not None else job(item))
        return in_turn
    results: list[Any] = [None] * len(items)
    failed: dict[int, BaseException] = {}  # once a job fails no other starts; the first one's error is raised
    lost: list[tuple[int, Exception]] = []  # jobs whose child died without a word: run again here
    running: dict[int, tuple[int, int, bytearray]] = {}  # read end -> (item index, child pid, bytes read)
    selector = selectors.DefaultSelector()
    upcoming = iter(range(len(items)))
    try:
        while True:
            while len(running) < workers and not failed:
                index = next(upcoming, None)
                if index is None:
                    break
                answer = _answer(before_each, items[index])
                if answer is not None:
                    results[index] = answer
                    continue
                read_end, pid = _start(job, items[index])
                running[read_end] = (index, pid, bytearray())
                selector.register(read_end, selectors.EVENT_READ)
            if not running:
                break
            for key, _ in selector.select():
                fd = key.fd
                chunk = os.read(fd, 1 << 16)
                if chunk:
                    running[fd][2].extend(chunk)
                    continue
                index, pid, data = running.pop(fd)
                selector.unregister(fd)
                os.close(fd)
                os.waitpid(pid, 0)
                try:
                    results[index] = _result(data, index)
                except _ChildDied as died:
                    lost.append((index, died))
                except Exception as err:  # noqa: BLE001 - raised below, once the running jobs have ended
                    failed[index] = err
    finally:
        for fd, (_, pid, _) in running.items():  # an error here: no child outlives the call
            selector.unregister(fd)
            stop_child(fd, pid)
        selector.close()
    if failed:
        raise failed[min(failed)]
    for index, died in lost:
        results[index] = _rerun(lambda: job(items[index]), index, died)
    return results


def beside(here: Callable[[], A], there: Callable[[], B]) -> tuple[A, B]:
    """``(here(), there())``: ``there`` in a forked child while ``here`` runs in this process (what ``here``
    logs or keeps stays here); in turn, here first, where ``workers_available`` is 1 (not Linux, one CPU)."""
    if workers_available() == 1:
        return here(), there()
    read_end, pid = _start(lambda _: there(), None)
    try:
        mine = here()
    except BaseException:
        stop_child(read_end, pid)
        raise
    data = bytearray()
    try:
        while chunk := os.read(read_end, 1 << 16):
            data.extend(chunk)
    finally:
        os.close(read_end)
        os.waitpid(pid, 0)
    try:
        return mine, _result(data, 0)
    except _ChildDied as died:
        return mine, _rerun(there, 0, died)


def _rerun(job: Callable[[], R], index: int, died: Exception) -> R:
    """A job whose child ended without a word, run again in this process: nothing is lost, and the log says so."""
    log.warning("forked_job_rerun", job=index, reason=str(died))
    return job()


def _answer(before_each: Callable[[Any], Any] | None, item: Any) -> Any:
    return None if before_each is None else before_each(item)


def _start(job: Callable[[Any], Any], item: Any) -> tuple[int, int]:
    """Fork a child that runs ``job(item)`` and writes ("ok", result) or ("error", exception), pickled,
    to a pipe; (the pipe's read end, the child's pid)."""
    def write(fd: int) -> None:
        try:
            payload = pickle.dumps(("ok", job(item)), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as err:  # noqa: BLE001 - carried back to the parent, which raises it
            try:
                payload = pickle.dumps(("error", err), protocol=pickle.HIGHEST_PROTOCOL)
            except Exception:  # noqa: BLE001 - an exception that does not pickle: its text
                payload = pickle.dumps(("error", ForkedJobError(f"{type(err).__name__}: {err}")))
        write_all(fd, payload)

    return fork_writer(write)


class _ChildDied(Exception):
    """A child that ended without writing its result (killed, out of memory)."""


def _result(data: bytearray, index: int) -> Any:
    """What the child of job ``index`` sent back: its result, or its exception raised here."""
    try:
        tag, value = pickle.loads(bytes(data))
    except Exception as err:  # noqa: BLE001 - nothing or half a result was written
        raise _ChildDied(f"forked job {index} ended without a result ({err})") from None
    if tag == "error":
        raise value
    return value
