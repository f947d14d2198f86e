"""Jobs shared with forked processes (fusiond.tune.forked): the results of running them here, in order."""

from __future__ import annotations

import os

from fusiond.tune.forked import map_forked, usable_cpus


def _square_and_pid(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def test_results_come_back_in_the_jobs_order_from_several_processes() -> None:
    out = map_forked(_square_and_pid, list(range(7)), 3)
    assert [r for r, _ in out] == [x * x for x in range(7)]
    pids = {pid for _, pid in out}
    assert os.getpid() in pids and len(pids) == 3  # share 0 here, shares 1 and 2 in children


def test_one_worker_runs_everything_here() -> None:
    assert {pid for _, pid in map_forked(_square_and_pid, [1, 2, 3], 1)} == {os.getpid()}
    assert map_forked(_square_and_pid, [], 4) == []


def test_a_share_a_child_cannot_send_is_run_here() -> None:
    """A child whose result cannot be pickled exits with an error: its share is run here instead."""
    parent = os.getpid()

    def unpicklable(x: int):
        return (x, lambda: None) if os.getpid() != parent else (x, None)

    assert [x for x, _ in map_forked(unpicklable, [0, 1, 2, 3], 2)] == [0, 1, 2, 3]


def test_usable_cpus_is_at_least_one() -> None:
    assert usable_cpus() >= 1
