"""What a check is: a name, what it reads of the other checks, and one way to run it on the run's evidence.

Every check, whether it compares the sources (heading, speed, lever arm), reads one channel's
innovations or judges the whole run, is run the same way: given the shared :class:`Evidence`,
it returns its findings as :class:`Verdict` structs (none when it has nothing to say). Who is to
blame when two findings meet is not a check's business: the rule table (``blame``) decides. Where
it runs is derived from what it declares (``registry.ordered``): its ``group``, the checks whose
findings it reads (``needs``) and those whose findings on a channel it shares are listed before its
own (``listed_after``).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from .evidence import Evidence
from .verdict import Verdict

__all__ = ["GROUPS", "MIN_UPDATES", "BaseCheck", "Check", "found", "run_check"]

# The order groups run in. The cross-source checks first: what they find decides who is to blame. Then
# one check per channel kind, each judging a channel on its own innovations. Then the whole-run checks
# and the core's counters, which speak last of a channel the others have spoken of.
GROUPS = ("cross", "channel", "run")

MIN_UPDATES = 50  # the twist-frame, lean and mounting checks need this many samples (not NIS: that uses what there is)


@runtime_checkable
class Check(Protocol):
    """A check. ``name`` is how the blame rules and later checks refer to its findings; ``needs`` names
    the checks whose findings it reads (``Evidence.findings``) and ``listed_after`` those whose findings
    on a channel it shares are listed before its own: the registry runs both first."""

    name: str
    group: str
    needs: tuple[str, ...]
    listed_after: tuple[str, ...]
    needs_config: bool

    def run(self, ev: Evidence) -> list[Verdict]:
        ...


class BaseCheck:
    """What most checks share: they read no other check's findings, and they need the config (the
    cross-source series are built from it, the sensors' tables name the keys)."""

    name = ""
    group = "run"
    needs: tuple[str, ...] = ()
    listed_after: tuple[str, ...] = ()
    needs_config = True


def run_check(check: Check, ev: Evidence) -> list[Verdict]:
    """What ``check`` finds in ``ev``: nothing from a check that needs the config when there is none (a
    remote monitor, which sees only the diagnostics stream), so no check has to ask."""
    return check.run(ev) if ev.known or not check.needs_config else []


def found(v: Verdict | None) -> list[Verdict]:
    """A check function's single verdict (or None) as a finding list."""
    return [] if v is None else [v]
