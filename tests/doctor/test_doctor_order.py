"""The doctor's run order is derived from what each check declares, never written out.

A check runs after every check whose findings it reads (``needs``) or whose findings on a shared channel
are listed before its own (``listed_after``); otherwise by its group (cross-source, per channel, whole
run), then by name. A check that names no check, or checks that follow each other in a cycle, cannot be
ordered: that is a ``DoctorError``.
"""

from __future__ import annotations

import pytest

from fusiond.doctor.check import GROUPS, BaseCheck
from fusiond.doctor.registry import CHECKS, discovered, ordered
from fusiond.errors import DoctorError, FusiondError


def _check(name: str, group: str = "run", needs: tuple[str, ...] = (), after: tuple[str, ...] = ()) -> BaseCheck:
    c = BaseCheck()
    c.name, c.group, c.needs, c.listed_after = name, group, needs, after
    return c


def _names(checks) -> list[str]:
    return [c.name for c in checks]


def test_a_check_that_needs_another_runs_after_it_whatever_its_group_and_name():
    checks = [_check("a", "cross", needs=("z",)), _check("z", "run"), _check("m", "channel")]
    assert _names(ordered(checks)) == ["m", "z", "a"]
    assert _names(ordered(reversed(checks))) == ["m", "z", "a"]


def test_without_needs_the_groups_run_in_order_then_the_names():
    checks = [_check("b", "run"), _check("a", "run"), _check("c", "channel"), _check("d", "cross")]
    assert _names(ordered(checks)) == ["d", "c", "a", "b"]


def test_listed_after_orders_two_checks_of_one_group():
    assert _names(ordered([_check("a", after=("b",)), _check("b")])) == ["b", "a"]


@pytest.mark.parametrize("checks", [
    [_check("a", needs=("b",)), _check("b", needs=("a",))],
    [_check("a", needs=("b",)), _check("b", after=("c",)), _check("c", needs=("a",)), _check("d")],
    [_check("a", needs=("a",))],
])
def test_a_cycle_is_a_doctor_error(checks):
    with pytest.raises(DoctorError, match="cycle"):
        ordered(checks)


def test_a_need_that_is_no_check_a_twice_used_name_and_an_unknown_group_are_doctor_errors():
    with pytest.raises(DoctorError, match="no check"):
        ordered([_check("a", needs=("nowhere",))])
    with pytest.raises(DoctorError, match="two checks"):
        ordered([_check("a"), _check("a")])
    with pytest.raises(DoctorError, match="unknown group"):
        ordered([_check("a", "later")])
    assert issubclass(DoctorError, FusiondError)


def test_the_registry_runs_each_check_after_what_it_follows_and_the_groups_in_order():
    names = _names(CHECKS)
    for i, check in enumerate(CHECKS):
        for before in (*check.needs, *check.listed_after):
            assert before in names[:i], (check.name, before)
    free = [c for c in CHECKS if not c.needs and not c.listed_after]
    assert [GROUPS.index(c.group) for c in free] == sorted(GROUPS.index(c.group) for c in free)


def test_each_check_module_holds_one_check_and_the_registry_runs_them_all():
    from pathlib import Path

    import fusiond.doctor.checks

    modules = sorted(p.stem for p in Path(fusiond.doctor.checks.__file__).parent.glob("*.py") if p.stem != "__init__")
    assert [type(c).__module__.rsplit(".", 1)[1] for c in discovered()] == modules
    assert sorted(_names(CHECKS)) == sorted(_names(discovered())) and len(CHECKS) == len(modules)
