"""A GPS the filter lost and found again, and whether a logging gap explains it."""

from __future__ import annotations

from ..channels import PerChannel
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict

__all__ = ["Reacquired"]

REACQUIRE_AFTER_GAP_S = 30.0  # a GPS reacquired this soon after a logging gap ended is blamed on the gap


class Reacquired(PerChannel):
    """A GPS the filter lost and found again."""

    name = kind = "reacquired"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The ``position_reacquired`` channel (core/sensors/gps/model.py ``_locked_out``): each record is a fix that
        ended a run of gated-out fixes which agreed with each other and moved with the wheels, the filter's
        position having drifted beyond its gate; the position was taken from it and the heading searched
        again. Its NIS tests the drift, not the receiver (learning): what it says is that the filter lost the
        GPS. One cause is named: a logging gap (``gaps``: the odometry's silences, (stamp, length s)) that ended
        within REACQUIRE_AFTER_GAP_S before every reacquisition, or, with none before any, the motion model; with
        some of each, or without the gaps to look at, the verdict says it cannot tell."""
        name, gaps = key[0], ev.series.odom_gaps if ev.known else None
        head = (f"the filter lost this GPS {ch.n} time(s): its fixes were gated out for seconds while agreeing with "
                "each other and moving with the wheels, so the position was taken from the fix again and the heading "
                "searched anew. The estimate had drifted beyond its own uncertainty")
        evidence = {"reacquired": float(ch.n)}
        stamps = ch.stamps if len(ch.stamps) == ch.n else [ch.first_stamp] if ch.n == 1 and ch.first_stamp else None
        if gaps is None or not stamps:
            return [Verdict(name, "position_reacquired", "warn",
                            head + "; whether a logging gap or the motion model "
                            "cannot be told here (no odometry series "
                            "and stamps to look for gaps in)", evidence=evidence)]
        after_gap = []
        for t in stamps:
            ends = [(start + length, length) for start, length in gaps
                    if 0.0 <= t - (start + length) <= REACQUIRE_AFTER_GAP_S]
            after_gap.append(max((length for _, length in ends), default=0.0))
        blamed = sum(length > 0.0 for length in after_gap)
        evidence["after_logging_gap"] = float(blamed)
        if blamed == len(after_gap):
            longest = max(after_gap)
            return [Verdict(name, "position_reacquired", "warn",
                            head + f": each time just after a logging gap (the longest {longest:.1f} s), which the "
                            "dead reckoning crossed without input further than the position's uncertainty allowed "
                            "(bounded by filter.covariance_cap); the fixes after it put the position back",
                            evidence={**evidence, "longest_gap_s": longest})]
        if blamed == 0:
            return [Verdict(name, "position_reacquired", "warn",
                            head + ": with no logging gap before it, so the motion model drifted: see the wheel "
                            "(twist_frame, the wheels' scale) and imu (gyro bias, mounting) verdicts",
                            evidence=evidence)]
        return [Verdict(name, "position_reacquired", "warn",
                        head + f": {blamed} time(s) just after a logging gap and {len(after_gap) - blamed} "
                        "without one; which one cause explains them cannot be told: see the wheel and imu verdicts "
                        "for the latter",
                        evidence=evidence)]
