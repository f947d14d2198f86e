"""Samples the core dropped: too old for the history (with the history that covers their lag), or for
another reason."""

from __future__ import annotations

import math

from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, filter_key

__all__ = ["Drops"]


class Drops(BaseCheck):
    """Samples the core dropped: too old for the history, or for another reason."""

    name = "drops"
    needs_config = False  # the core's counters, which a run without a config has too

    def run(self, ev: Evidence) -> list[Verdict]:
        if not ev.stats:
            return []
        stats, clocks = ev.stats, ev.clocks
        out = []
        for name, st in stats.items():
            received = max(st.get("received", 0), 1)
            dropped = st.get("dropped", {})
            old = dropped.get("too_old", 0)
            if old / received > 0.01:
                msg = (f"{old} samples ({100 * old / received:.1f}%) arrived older than the history: "
                       "their sensor's stamps lag more than filter.history_s")
                line = ""
                lag = clocks.lag(name) if clocks is not None else None
                if lag is not None and lag > 0.0:
                    # the history must reach back over the lag of 99 % of the samples, with a fifth to spare
                    line = f"history_s = {math.ceil(12.0 * lag) / 10.0:g}"
                    msg += (f" (99% of them arrive within {lag:.2f} s of the other sensors' newest stamp). Each such "
                            "sample re-applies that much history; a lag this steady may be the sensor's clock (a stamp "
                            "set late or early), which a longer history only hides: check its driver's stamping")
                out.append(Verdict(name, "time", "warn", msg, filter_key("history_s"), line))
            bad = {k: v for k, v in dropped.items() if k != "too_old"}
            if bad:
                reasons = ", ".join(f"{k}={v}" for k, v in sorted(bad.items()))
                out.append(Verdict(name, "input", "warn", f"dropped samples: {reasons}"))
        return out


