"""Any channel no other per-channel check judges: its NIS verdict, a warning unless consistent."""

from __future__ import annotations

from ..channels import PerChannel, figures
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict

__all__ = ["ChannelNis"]


class ChannelNis(PerChannel):
    """Any other channel: its NIS verdict, a warning unless consistent."""

    name = kind = "nis"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        verdict = ch.verdict()
        return [Verdict(key[0], key[1], "ok" if verdict == "ok" else "warn", f"{verdict} ({figures(ch, ev.t0)})")]
