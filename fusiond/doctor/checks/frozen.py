"""Fixes repeated unchanged while the wheels moved on: a receiver holding its last position."""

from __future__ import annotations

from ...core.sensors.gps import FROZEN_JITTER
from ..channels import PerChannel
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict

__all__ = ["Frozen"]


class Frozen(PerChannel):
    """Fixes repeated unchanged (a receiver holding its last position)."""

    name = kind = "frozen"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The ``position_frozen`` channel (core/sensors/gps/model.py ``_frozen``): every record is a fix that repeated
        an earlier one (bit for bit, or to FROZEN_JITTER) while the wheels moved on, and was not fused, so its
        NIS says nothing. What it says is that the receiver lost its fix and kept publishing it as if it had
        one: a fault of the receiver (or its driver), no key of the config's."""
        name, fixes = key[0], sum(c.n for (n, _), c in ev.channels.items() if n == key[0])
        share = ch.n / fixes if fixes else 0.0
        return [Verdict(name, "position_frozen", "warn",
                        f"{ch.n} fixes ({100 * share:.1f}% of the GPS's) repeated an earlier fix while the wheels "
                        f"moved on (to within {100 * FROZEN_JITTER:g} cm): the receiver lost its fix and kept "
                        "publishing it, "
                        "with a fix status. Not fused; the pose was dead-reckoned meanwhile. Nothing to change in the "
                        "config: check the receiver's sky view and antenna, or have its driver publish status NO_FIX",
                        evidence={"frozen_fixes": float(ch.n), "frozen_share": share})]
