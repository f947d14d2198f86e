"""Samples the core dropped: too old for the history (with the history that covers their lag), or for
another reason."""

from __future__ import annotations

import math

from ... import reasons
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, filter_key

__all__ = ["Drops"]

# A share of a sensor's samples dropped as duplicate stamps beyond which they are stamped in groups, not
# republished now and then: a message sent twice is rare; at a fifth, every fifth sample at least shares
# its stamp, which only a driver stamping several samples at once gives
BUNCHED_SHARE = 0.2


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
                said = "; ".join(f"{k}={v} ({reasons.MEANINGS.get(k, k)})" for k, v in sorted(bad.items()))
                repeated = (ev.repeats or {}).get(name, 0)
                out.append(Verdict(name, "input", "warn",
                                   f"dropped samples: {said}{_repeated(repeated)}{_bunched(bad, received, repeated)}"))
        return out


def _repeated(repeated: int) -> str:
    """What the duplicate stamps that were the same message again say (``Doctor.repeats``)."""
    if not repeated:
        return ""
    return (f". {repeated} of the duplicate stamps were the same message again, stamp and content alike (a second "
            "publisher, or a bridge or recorder doubling the topic): nothing of the data was lost")


def _bunched(dropped: dict[str, int], received: int, repeated: int = 0) -> str:
    """What a share of samples dropped as duplicate stamps says: a few, a message republished; a steady
    share, samples stamped in groups (k = received / kept of them share one stamp), which a driver that
    reads its sensor's FIFO and stamps the read, not each sample, gives. The filter keeps one sample a
    stamp, the group's first, so it fuses 1/k of the data, each sample (k - 1) periods older than its
    stamp says. ``repeated``: of those, the same message again (``_repeated``), which are no group: left out."""
    d = dropped.get(reasons.DUPLICATE_STAMP, 0) - repeated
    received -= repeated
    if d <= 0 or d < BUNCHED_SHARE * received:
        return ""
    k = received / max(received - d, 1)
    return (f". {100 * d / received:.0f}% of its samples shared their stamp with the one before: groups of about "
            f"{k:.1f} consecutive samples carry one stamp, as a driver gives that reads the sensor's FIFO and stamps "
            "the read, not each sample. The filter keeps the first of each stamp and drops the rest, so it fuses "
            f"1 in {k:.1f} of them, each older than its stamp by up to the group's span. Stamp each sample at its own "
            "time in the driver (the read stamp less the FIFO's sample period per place), or publish each as it is "
            "measured; no setting here recovers the dropped ones")


