"""A gyro whose range ends below the vehicle's turns: its z rate held at one value, plus or minus, for whole bins.

A MEMS gyro set to a low full-scale range (or a driver that clips) reads a faster turn as the end of its range:
the heading then turns short in every tight corner, by what the rate beyond the range would have added, and
nothing downstream can restore it (a race car's gyro held at 0.3 rad/s read its heading 97 deg off, where it
was 15). Noise makes every bin of a working gyro's samples vary; a rate held at the rail is the same float in
every sample. So the doctor's gyro bins (``series.gyro_z``, ``gyro_var``, ``gyro_n``: the samples' mean,
variance and count per bin) tell it: bins of RANGE_MIN_SAMPLES or more samples with no variance (but rounding), at the
largest rate the run read (its magnitude, either sign), in at least RANGE_MIN_BINS bins. A gyro at rest reads
noise about its bias, never one float for a whole bin, and a rate held that long is no vehicle's turn.
"""

from __future__ import annotations

import math

from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict

__all__ = ["GyroRange"]

RANGE_MIN_SAMPLES = 3  # samples in a bin, all the same float: more than a repeat
RANGE_MIN_BINS = 3  # bins held at the rail: a range the run met more than once
# a bin's mean within this share of the largest magnitude is at it, and its spread within this share of it is none:
# one float averaged over a bin is off by rounding only (1e-16 of it), a gyro's noise (1e-3 rad/s) by far more
RAIL_SHARE = 1e-6


class GyroRange(BaseCheck):
    """The gyro's z rate held at the end of its range for whole bins."""

    name = "gyro_range"
    group = "run"

    def run(self, ev: Evidence) -> list[Verdict]:
        imu, series = ev.imu, ev.series
        if imu is None or series is None or len(series.gyro_z) < RANGE_MIN_BINS:
            return []
        rates = [abs(z) for z in series.gyro_z if math.isfinite(z)]
        rail = max(rates, default=0.0)
        if not rail > 0.0:
            return []
        held = sum(1 for z, var, n in zip(series.gyro_z, series.gyro_var, series.gyro_n)
                   if n >= RANGE_MIN_SAMPLES and var <= (RAIL_SHARE * rail) ** 2
                   and abs(abs(z) - rail) <= RAIL_SHARE * rail)
        if held < RANGE_MIN_BINS:
            return []
        share = held / len(series.gyro_z)
        return [Verdict(imu.name, "range", "problem",
                        f"the gyro's z rate sits at exactly {rail:.4g} rad/s (either sign, every sample alike) in "
                        f"{held} of its {len(series.gyro_z)} bins ({100 * share:.0f}%): its range ends there, and a "
                        "faster turn reads as that rate, so the heading turns short in every such turn. Set the gyro's "
                        "full-scale range higher in its driver (a MEMS gyro's lowest, 250 deg/s, is 4.36 rad/s)",
                        evidence={"rail_rad_s": rail, "held_bins": float(held), "held_share": share})]
