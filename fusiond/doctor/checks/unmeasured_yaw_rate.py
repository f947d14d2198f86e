"""A wheel yaw rate the odometry driver does not measure: exact zeros while the gyro turns.

A driver that lost its yaw rate publishes 0 with covariance 0: to the filter a perfect measurement of
"not turning". Against the gyro it looks like slip in every turn. The difference is in the numbers: slip
reads a wrong rate, a lost component reads exactly zero (with zero variance) while the gyro turns. That is
"not measured", declared with ``twist_measured``.
"""

from __future__ import annotations

import numpy as np

from ...core.sensors.odom.lost_channel import TWIST
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["UnmeasuredYawRate"]

TURNING_RAD_S = 0.05  # the gyro says the robot turns (well above any gyro's noise and bias)
UNMEASURED_FRACTION = 0.5  # in turns, this share of exact zeros is a component the driver does not measure
ALL_ZEROS_FRACTION = 0.99  # ... and in gentle turns only: (nearly) every moving sample an exact zero
MIN_TURNED_RAD = 1.0  # ... over a run whose heading the gyro turned by at least this much


class UnmeasuredYawRate(BaseCheck):
    """A wheel yaw rate the odometry driver does not measure (exact zeros while the gyro turns)."""

    name = "unmeasured_yaw_rate"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.odom is None:
            return []
        series, odom = ev.series, ev.odom
        if len(series.gyro_t) < 10 or len(series.odom_t) < 10 or not odom.twist_measured[5]:
            return []
        tg, z = np.array(series.gyro_t), np.array(series.gyro_z)
        to = np.array(series.odom_t)
        bias = float(np.interp(to, series.est_t, series.est_bias_z).mean()) if series.est_bias_z else 0.0
        gyro_at = np.interp(to, tg, z) - bias
        turning = np.abs(gyro_at) > TURNING_RAD_S
        n = np.array(series.odom_n)[turning].sum()
        zeros = np.array(series.odom_zero_wz)[turning].sum()
        where = f"where the gyro turns faster than {TURNING_RAD_S} rad/s"
        if n < 20 or zeros / n < UNMEASURED_FRACTION:
            # A vehicle that only turns gently (a highway's curves, under TURNING_RAD_S) never shows that. But no
            # real yaw rate reads exactly 0 with variance 0 in every moving sample of a run whose heading the gyro
            # turns by radians: that is a driver filling in a component it does not measure.
            moving = ~np.array(series.odom_rest, dtype=bool)
            n = np.array(series.odom_n)[moving].sum()
            zeros = np.array(series.odom_zero_wz)[moving].sum()
            turned = float(np.ptp(series.gyro_heading)) if len(series.gyro_heading) else 0.0
            if n < 20 or zeros < ALL_ZEROS_FRACTION * n or turned < MIN_TURNED_RAD:
                return []
            where = f"while moving, over a run the gyro turned through {turned:.1f} rad"
        frac = zeros / n
        # with every other component the filter found filled in (log twist_component_lost): one line, as the
        # run's log and `fusiond init` declare them
        lost = set((ev.stats or {}).get(odom.name, {}).get("lost", ())) | {"wz"}
        measured = ["false" if not on or c in lost else "true" for c, on in zip(TWIST, odom.twist_measured)]
        return [Verdict(odom.name, "yaw_rate", "problem",
                        f"the wheel yaw rate reads exactly 0 with variance 0 in {100 * frac:.0f}% of the {int(n)} "
                        f"samples {where}: the driver does not measure it (not slip). A fused gyro makes the filter "
                        "take it as not measured (log twist_component_lost); declare it so that it is never used nor "
                        "checked",
                        sensor_key(odom.name, "twist_measured"), f"twist_measured = [{', '.join(measured)}]",
                        {"zero_fraction_in_turns": float(frac), "turning_samples": float(n)})]
