"""A GPS whose heading was never found: every fix fused as position only, none judged."""

from __future__ import annotations

import math

from ..channels import PerChannel
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["Unaligned"]

UNALIGNED_LARGE = 2.0  # predicted innovation rms this many times the measured one: the stated noise hides the heading


class Unaligned(PerChannel):
    """A GPS whose heading was never found: every fix fused as position only."""

    name = kind = "unaligned"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The ``position_unaligned`` channel of a GPS whose heading search never ended: every fix was fused
        as a position-only update, ungated, and none was judged against the stated noise. The search fits
        the fixes to the wheels' track and waits until the fit's heading uncertainty is small; a stated noise
        (``position_noise``, or ``error_sigma``'s wander) far above the fixes' real scatter keeps it large
        forever (a mower's GPS stated 10x too noisy: heading error 19.5 deg instead of 4.7, every verdict ok).
        The innovations' rms against what S predicted shows it: far below, the statement is what is wrong."""
        gps, up = ev.sensors[key[0]], ev.channels.get((key[0], "altitude"))
        seen = [ch.learning_component(i) for i in range(len(ch.components))]
        rms, pred = [r for r, _ in seen], [p for _, p in seen]
        if len(rms) == 2 and up is not None and up.n and up.components == ["up"]:
            rms.append(up.component(0)[1])  # the fix's altitude, judged as its own block
        horizontal = [(r, p) for c, r, p in zip(ch.components, rms, pred) if c in ("east", "north")]
        measured = math.sqrt(sum(r * r for r, _ in horizontal) / len(horizontal)) if horizontal else math.nan
        predicted = math.sqrt(sum(p * p for _, p in horizontal) / len(horizontal)) if horizontal else math.nan
        head = (f"the heading was never found from the GPS: all {ch.n} fixes were fused as position only, ungated and "
                f"unjudged (innovations' horizontal rms {measured:.2f} m, {predicted:.2f} m predicted)")
        evidence = {"unaligned_fixes": float(ch.n), "innovation_rms_m": measured, "predicted_rms_m": predicted}
        if math.isfinite(measured) and measured > 0.0 and predicted > UNALIGNED_LARGE * measured:
            return [Verdict(gps.name, "position_unaligned", "warn",
                            f"{head}: the fixes scatter far less than stated, so the fit of their track never became "
                            "certain enough. The innovations' rms (an upper bound of the receiver's noise) "
                            "suggest the value below", sensor_key(gps.name, "position_noise"),
                            "position_noise = [" + ", ".join(f"{r:.2g}" for r in rms) + "]" if len(rms) == 3 else "",
                            evidence=evidence)]
        return [Verdict(gps.name, "position_unaligned", "warn",
                        f"{head}: the fixes did not line up with the wheels' track. Check the odometry (twist_frame, "
                        "the wheels' scale) and that the vehicle drove at least heading_init_m in a line",
                        sensor_key(gps.name, "heading_init_m"), evidence=evidence)]
