"""Jobs side by side in forked children (``fusiond.tune.forked``): the results of running them in turn."""

from __future__ import annotations

import os

import pytest

from fusiond.errors import FusiondError, TuneError

from fusiond.tune.forked import ForkedJobError, beside, run_side_by_side, workers_available

pytestmark = pytest.mark.skipif(workers_available() == 1, reason="replays run side by side on Linux with 2+ CPUs")


def _square_and_pid(n: int) -> tuple[int, int]:
    return n * n, os.getpid()


def test_results_come_back_in_order_and_from_other_processes():
    got = run_side_by_side(_square_and_pid, list(range(7)), workers=3)
    assert [value for value, _ in got] == [n * n for n in range(7)]
    assert all(pid != os.getpid() for _, pid in got)  # each ran in a child


def test_one_worker_runs_the_jobs_in_turn_here():
    got = run_side_by_side(_square_and_pid, [2, 3], workers=1)
    assert got == [(4, os.getpid()), (9, os.getpid())]


def test_a_large_result_travels_whole():
    big = run_side_by_side(lambda n: list(range(n)), [200_000, 3], workers=2)
    assert big[0] == list(range(200_000)) and big[1] == [0, 1, 2]


def test_an_answer_before_a_job_starts_stands_for_it():
    asked = []

    def before(n):
        asked.append(n)  # asked here, in this process, as each job is about to start
        return "skipped" if n == 2 else None

    got = run_side_by_side(lambda n: n + 100, [1, 2, 3], workers=2, before_each=before)
    assert got == [101, "skipped", 103]
    assert asked == [1, 2, 3]


def _raises(n: int) -> int:
    if n == 1:
        raise ValueError(f"job {n} refused")
    return n


def test_a_job_that_raises_in_a_child_raises_here():
    with pytest.raises(ValueError, match="job 1 refused"):
        run_side_by_side(_raises, [0, 1, 2], workers=2)


PARENT = os.getpid()


def _dies_in_a_child(n: int) -> int:
    if n == 0 and os.getpid() != PARENT:
        os._exit(3)  # killed, out of memory: no result is written
    return n * 10


def test_a_child_that_dies_loses_nothing_its_job_runs_again_here():
    from structlog.testing import capture_logs

    from fusiond.logs import configure

    # capture_logs replaces the processors, not the level's filter: an earlier test's `--quiet` (errors only)
    # would drop the warning before the capture sees it
    configure("warning")
    with capture_logs() as logs:
        assert run_side_by_side(_dies_in_a_child, [0, 1], workers=2) == [0, 10]
        assert beside(lambda: 1, lambda: _dies_in_a_child(0)) == (1, 0)
    reruns = [e for e in logs if e["event"] == "forked_job_rerun"]
    assert len(reruns) == 2 and "ended without a result" in reruns[0]["reason"]


def test_an_exception_that_does_not_pickle_comes_back_as_its_text():
    class Local(Exception):  # a local class: pickle cannot name it
        pass

    def job(n):
        raise Local(f"local {n}")

    with pytest.raises(ForkedJobError, match="Local: local 0"):
        run_side_by_side(job, [0, 1], workers=2)
    assert issubclass(ForkedJobError, TuneError) and issubclass(TuneError, FusiondError)


def test_workers_available_is_at_least_one():
    assert workers_available() >= 1


def test_beside_runs_one_job_here_and_the_other_in_a_child():
    here, there = beside(lambda: ("here", os.getpid()), lambda: ("there", os.getpid()))
    assert here == ("here", os.getpid()) and there[0] == "there" and there[1] != os.getpid()


def test_beside_raises_what_either_side_raises():
    with pytest.raises(ValueError, match="there"):
        beside(lambda: 1, lambda: _raises_value("there"))
    with pytest.raises(ValueError, match="here"):
        beside(lambda: _raises_value("here"), lambda: 2)


def _raises_value(said: str) -> int:
    raise ValueError(said)
