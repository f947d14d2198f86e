"""Any channel no other per-channel check judges: its NIS verdict, a warning unless consistent, naming the noise key
its kind names for the channel (``SensorKind.noise_key``: a kind from another package has no check of its own)."""

from __future__ import annotations

from ...core.sensors.registry import kind_of
from ..channels import PerChannel, figures
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["ChannelNis"]


class ChannelNis(PerChannel):
    """Any other channel: its NIS verdict, a warning unless consistent."""

    name = kind = "nis"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        verdict = ch.verdict()
        head = f"{verdict} ({figures(ch, ev.t0)})"
        sc = ev.sensors.get(key[0]) if ev.config is not None and verdict != "ok" else None
        field = kind_of(sc).noise_key(sc, key[1]) if sc is not None else None
        if not field:
            return [Verdict(key[0], key[1], "ok" if verdict == "ok" else "warn", head)]
        side = "smaller" if verdict == "nis_high" else "larger"
        return [Verdict(key[0], key[1], "warn",
                        f"{head}: the noise stated for it ({field}) is {side} than its innovations show, or the "
                        "sensor errs otherwise; `fusiond tune` fits it on this recording", sensor_key(key[0], field))]
