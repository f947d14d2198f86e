"""The gyro at the standstills, judged on a gyro-bias channel's updates.

The cross-source verdict (``gyro.bias_check`` with the series, ``Evidence.bias_verdict``) when there is
one; else the channel's own, with the IMU known by what the channel shows.
"""

from __future__ import annotations

from ...config import Config
from ..channels import PerChannel, figures
from ..evidence import Evidence
from ..gyro import bias_check
from ..nis import ChannelStats
from ..series import Series
from ..verdict import Verdict

__all__ = ["GyroBiasAtRest"]


class GyroBiasAtRest(PerChannel):
    """The gyro at the standstills: the cross-source verdict when there is one, else the channel's own."""

    name = kind = "gyro_bias"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        v = ev.bias_verdict(key)
        if v is None:
            v = bias_check(Series(), Config(sensors=[ev.channel_imu(key)]), ch, True) or Verdict(
                key[0], key[1], "ok", f"consistent ({figures(ch, ev.t0)})")
        return [v]
