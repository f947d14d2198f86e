"""The checks, in the order they run, derived from what each declares.

Each module under ``checks/`` holds one check (``discovered``): a check is added by adding its module.
Each check names its ``group`` (``check.GROUPS``: the cross-source checks, then one per channel kind,
then the whole-run checks and the core's counters), the checks whose findings it reads (``needs``) and
those whose findings on a channel it shares are listed before its own (``listed_after``). Within a
channel, findings are listed in run order (the most severe leads when they are merged), so the order is
part of what the doctor prints: a check runs after every check it names, and otherwise by its group,
then by name. A name that is no check, or a cycle, is a :class:`DoctorError`.
"""

from __future__ import annotations

import heapq
import importlib
import pkgutil
from collections.abc import Iterable

from ..errors import DoctorError
from . import checks as _checks
from .check import GROUPS, BaseCheck, Check

__all__ = ["CHECKS", "discovered", "ordered"]


def ordered(checks: Iterable[Check]) -> tuple[Check, ...]:
    """``checks`` in run order: a topological sort of what each must follow (``needs`` and ``listed_after``),
    ties broken by (group, name)."""
    by_name: dict[str, Check] = {}
    for c in checks:
        if c.name in by_name:
            raise DoctorError(f"two checks are named {c.name!r}")
        if c.group not in GROUPS:
            raise DoctorError(f"check {c.name!r}: unknown group {c.group!r} (one of {', '.join(GROUPS)})")
        by_name[c.name] = c
    waiting = {name: set(c.needs) | set(c.listed_after) for name, c in by_name.items()}
    followers: dict[str, list[str]] = {name: [] for name in by_name}
    for name, before in waiting.items():
        for b in before:
            if b not in by_name:
                raise DoctorError(f"check {name!r} follows {b!r}, which is no check")
            followers[b].append(name)

    def rank(name: str) -> tuple[int, str]:
        return GROUPS.index(by_name[name].group), name

    ready = [rank(name) for name, before in waiting.items() if not before]
    heapq.heapify(ready)
    out: list[Check] = []
    while ready:
        _, name = heapq.heappop(ready)
        out.append(by_name[name])
        for f in followers[name]:
            waiting[f].discard(name)
            if not waiting[f]:
                heapq.heappush(ready, rank(f))
    if len(out) < len(by_name):
        stuck = sorted(name for name, before in waiting.items() if before)
        raise DoctorError(f"the doctor's checks follow each other in a cycle: {', '.join(stuck)}")
    return tuple(out)


def discovered() -> list[Check]:
    """One instance of each check class, found in its module under ``checks/`` (one check a module)."""
    out: list[Check] = []
    for info in sorted(pkgutil.iter_modules(_checks.__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{_checks.__name__}.{info.name}")
        found = [c for c in vars(module).values() if isinstance(c, type) and issubclass(c, BaseCheck)
                 and c.__module__ == module.__name__ and c.name]
        if len(found) != 1:
            raise DoctorError(f"checks/{info.name}.py holds {len(found)} checks, not one")
        out.append(found[0]())
    return out


CHECKS: tuple[Check, ...] = ordered(discovered())
