"""A receiver whose fixes stepped to a new level, which the filter followed (a step, not a loss), and a burst
that came back: the same step test followed it while it lasted."""

from __future__ import annotations

import bisect
import math

from ...core.sensors.gps import REACQUIRE_JUMP_S
from ..channels import PerChannel
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["GpsSteps"]


class GpsSteps(PerChannel):
    """Fixes that stepped to a new level while the motion model carried the estimate on."""

    name = kind = "step"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The ``position_step`` channel (core/sensors/gps/model.py ``_step_test``, ``_take_step``): each record is
        the fix at which the step test (a CUSUM of the run's agreement against outliers, at the false-alarm
        rate ``step_false_alarm``) took a run of gated-out fixes for the receiver's error stepping, and moved
        the position with it; its innovation is that step. The wheels and the gyro did not move the estimate
        off (a loss, ``position_reacquired``, is when they did): the receiver changed its solution (an RTK fix
        won or lost, another satellite set, multipath that stays). No key of the config's is wrong; a
        receiver that steps often is a sky view or antenna question."""
        name = key[0]
        fixes = ev.channels.get((name, "position"))
        steps = [(t, _step(fixes, t, y)) for t, y in zip(ch.stamps, ch.innovations) if len(y) >= 2]
        evidence = {"steps": float(ch.n)}
        bursts = _bursts(steps)
        if bursts:
            held, (east, north) = max(bursts, key=lambda b: math.hypot(*b[1]))
            evidence.update({"bursts": float(len(bursts)), "largest_burst_m": math.hypot(east, north),
                             "largest_burst_s": held})
            return [Verdict(name, "position_step", "warn",
                            f"the receiver's fixes left their level and came back {len(bursts)} time(s) (the largest "
                            f"{math.hypot(east, north):.1f} m: {east:+.1f} m east, {north:+.1f} m north, followed for "
                            f"{held:.1f} s): a burst (multipath) that held one offset for more than the step test's "
                            "fewest fixes is a step until it ends, so the filter followed it meanwhile. A receiver that bursts so "
                            "wants the step test off (step_false_alarm = 0: a run of gated-out fixes that began with "
                            f"a jump is then followed only after {REACQUIRE_JUMP_S:g} s) or stricter (1e-6: 10 fixes "
                            "at least). No replay can judge that without a reference: a fix the gate rejects costs "
                            "the innovations' likelihood more than one accepted at the burst's level",
                            sensor_key(name, "step_false_alarm"), evidence=evidence)]
        largest = ""
        if steps:
            t, (east, north) = max(steps, key=lambda st: math.hypot(*st[1]))
            size = math.hypot(east, north)
            evidence.update({"largest_step_m": size, "largest_step_east_m": east, "largest_step_north_m": north})
            when = f", {t - ev.t0:.0f} s into the run" if ev.t0 is not None else ""
            largest = f" (the largest {size:.1f} m: {east:+.1f} m east, {north:+.1f} m north{when})"
        return [Verdict(name, "position_step", "warn",
                        f"the receiver's fixes stepped {ch.n} time(s){largest}: from a jump on they held a new "
                        "level, agreeing with each other and moving with the wheels, so the filter took each "
                        "as the receiver's error stepping (the step test, at its false-alarm rate "
                        "step_false_alarm) and followed the fixes: the published position jumped with them, the "
                        "heading kept. The wheels "
                        "and the IMU did not cause it: the receiver changed its solution (an RTK fix won or lost, "
                        "another satellite set, multipath that stays). Nothing to change in the config; a "
                        "receiver that steps often has a sky view or antenna to look at",
                        evidence=evidence)]


def _step(fixes: ChannelStats | None, stamp: float, y: list[float]) -> tuple[float, float]:
    """(east, north) of the step taken at ``stamp``: the mean innovation of the run of gated-out fixes that ended
    in it (the step fix's own ``y`` and those the ``position`` channel rejected just before it), the offset the
    step test estimates (equal noises: its information-weighted mean is this mean)."""
    east, north, n = y[0], y[1], 1
    if fixes is not None and len(fixes.stamps) == len(fixes.innovations) == len(fixes.rejected_flags):
        k = bisect.bisect_left(fixes.stamps, stamp) - 1
        while k >= 0 and fixes.rejected_flags[k] and len(fixes.innovations[k]) >= 2:
            east, north, n = east + fixes.innovations[k][0], north + fixes.innovations[k][1], n + 1
            k -= 1
    return east / n, north / n


def _bursts(steps: list[tuple[float, tuple[float, float]]]) -> list[tuple[float, tuple[float, float]]]:
    """(how long it held, its offset) of each step followed by one that came back at least half way to the level
    it left, within REACQUIRE_JUMP_S: the time the core holds that level as a hypothesis the fixes may return to
    (``GpsModel._step_test``), so a return is a burst that ended, not a second step."""
    out = []
    for (t0, d0), (t1, d1) in zip(steps, steps[1:]):
        if t1 - t0 <= REACQUIRE_JUMP_S and math.hypot(d0[0] + d1[0], d0[1] + d1[1]) <= 0.5 * math.hypot(*d0):
            out.append((t1 - t0, d0))
    return out
