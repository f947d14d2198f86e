"""The gyro bias when no standstill update was ever made (no gyro-bias channel): ``gyro.bias_check`` on the
series alone."""

from __future__ import annotations

from ..check import BaseCheck, found
from ..evidence import Evidence
from ..gyro import bias_check
from ..verdict import Verdict

__all__ = ["GyroBiasUnseen"]


class GyroBiasUnseen(BaseCheck):
    """The gyro bias when no standstill update was ever made (no gyro-bias channel)."""

    name = "gyro_bias_unseen"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.gyro_bias_stats is not None:
            return []
        return found(bias_check(ev.series, ev.config, None, ev.gyro_fused, ev.stats))
