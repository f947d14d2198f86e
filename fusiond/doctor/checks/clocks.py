"""A sensor whose clock is offset from the others: its samples dropped as far from filter time.

``clock.ClockOffsets`` measures each sensor's stamps against the others' newest at arrival; a sensor whose
samples were mostly dropped as ``future_stamp``/``stale_stamp`` gets one plain verdict with that offset
and the ``stamp_offset_s`` that brings it onto the others' clock.
"""

from __future__ import annotations

from ... import reasons
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["Clocks"]

CLOCK_REASONS = (reasons.FUTURE_STAMP, reasons.STALE_STAMP)
CLOCK_DROP_SHARE = 0.5  # this share of a sensor's samples dropped as far from filter time: its clock, not a glitch


class Clocks(BaseCheck):
    """Samples dropped as far from filter time, explained by their sensor's clock."""

    name = "clocks"
    listed_after = ("drops",)  # both speak of a sensor's time: the drops first
    needs_config = False  # the core's counters, which a run without a config has too

    def run(self, ev: Evidence) -> list[Verdict]:
        """A verdict for each sensor whose samples were mostly dropped as far from filter time; ``sensors`` (by
        name: their configs) gives the stamp_offset_s that brings them onto the others' clock."""
        if not ev.stats or ev.clocks is None:
            return []
        stats, clocks, sensors = ev.stats, ev.clocks, ev.sensors
        out = []
        for name, st in stats.items():
            received = st.get("received", 0)
            far = sum(st.get("dropped", {}).get(r, 0) for r in CLOCK_REASONS)
            if received <= 0 or far < CLOCK_DROP_SHARE * received:
                continue
            offset = clocks.offset(name)
            if offset is None:
                continue
            side = "ahead of" if offset > 0 else "behind"
            configured = getattr((sensors or {}).get(name), "stamp_offset_s", 0.0)
            out.append(Verdict(name, "time", "problem",
                               f"{far} of {received} samples stamped ~{abs(offset):.1f} s {side} the other sensors: "
                               "its clock is offset (GPS time vs UTC?), so they were dropped as far from filter time. "
                               "Stamp them with the same clock as the other sensors (the driver's time source), or "
                               "shift them here", sensor_key(name, "stamp_offset_s"),
                               f"stamp_offset_s = {configured - offset:.3f}",
                               evidence={"clock_offset_s": offset, "dropped_far": float(far),
                                         "received": float(received)}))
        return out
