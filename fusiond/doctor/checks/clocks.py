"""A sensor whose clock is offset from the others: its samples dropped as far from filter time; or whose clock
does not keep time at all.

``clock.ClockOffsets`` measures each sensor's stamps against the others' newest at arrival; where a sensor's
samples were mostly dropped as ``future_stamp``/``stale_stamp``, the sensor whose clock is off gets one plain
verdict with its offset and the ``stamp_offset_s`` that brings it onto the others' clock.

That is not always the sensor dropped. The filter's time follows the first stamps it takes: an IMU stamped
1000 s behind the wheels and the GPS, and first in the recording, makes the wheels and the GPS look "ahead"
and they are the ones dropped, while their own offsets against the others' newest stamp are a fraction of a
second (the GPS's against the wheels'). The odd one out is the sensor whose offset is largest (``_culprit``):
the IMU at -1000 s. With two sensors the two offsets mirror each other (+5 s and -5 s): the odometry, whose
stamps the published poses carry, is then the reference, and the other sensor's clock is named. With three or
more, a clock ahead stands apart (``_lone_ahead``): it reads +X and every other sensor -X, the others agreeing
with each other; that sensor is named, the odometry too (its samples stamped on a boot clock, or 0.3 s ahead).

An offset within the history (an IMU on another computer's clock, 0.5 s ahead) drops nothing: every sample
of the sensor behind is applied late, re-applying the others after it, and the estimate pairs each wheel
speed with a gyro rate half a second away (the F1/10's heading error 9.5 -> 25 deg). Jitter makes a share
of a sensor late (the Jackal's wheels, one in five); a standing offset makes most of them late, by about the
same amount: past CLOCK_LATE_SHARE, and by more than any sensor's message period (sensors in step, one a
few milliseconds ahead, make the other's samples late by less than a period), the same verdict names the odd
clock out, when its stamps are AHEAD of the others'. Stamps behind them are also what a sensor correctly stamped but delivered late shows (a
receiver's fixes 0.2 s after their epoch), which the history is there to absorb: nothing in the stamps tells
that from a clock behind, so nothing is said of it. No delivery puts a stamp in the future, so a sensor behind
is never the culprit of late samples: the one ahead is, however large the offset behind.

A clock that does not run is no offset: a driver stamping every message 0, or one constant, reads as a clock
ever further behind (its median, half the run). Its stamps do not advance with the others' (``_stuck``): the
verdict names the driver's stamping, with no stamp_offset_s line, and no offset is said of it.
"""

from __future__ import annotations

from ... import reasons
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["Clocks", "dropped_by_clock"]

CLOCK_REASONS = (reasons.FUTURE_STAMP, reasons.STALE_STAMP)
# A sensor's stamps advance at the others' pace within this share, or its clock does not run: quartz clocks
# drift by tens of ppm, a thousandth of it; a driver stamping a constant (or 0) advances not at all
PACE_TOLERANCE = 0.1
# ... judged over at least this much of the others' time: stamps jitter by tens of milliseconds, which this
# span makes a pace good to a few per cent
PACE_SPAN_S = 2.0
CLOCK_DROP_SHARE = 0.5  # this share of a sensor's samples dropped as far from filter time: its clock, not a glitch
CLOCK_LATE_SHARE = 0.5  # ... or applied late (behind the others' newest stamp): a standing offset, not jitter
MIRROR = 2.0  # two offsets within this factor of each other are one offset seen from either side (module doc)


class Clocks(BaseCheck):
    """Samples dropped as far from filter time, explained by their sensor's clock."""

    name = "clocks"
    listed_after = ("drops",)  # both speak of a sensor's time: the drops first
    needs_config = False  # the core's counters, which a run without a config has too

    def run(self, ev: Evidence) -> list[Verdict]:
        """One verdict per sensor whose clock is off (``_culprit``) among those whose samples were mostly
        dropped as far from filter time; ``sensors`` (by name: their configs) gives the stamp_offset_s that
        brings it onto the others' clock."""
        if not ev.stats or ev.clocks is None:
            return []
        stats, clocks, sensors = ev.stats, ev.clocks, ev.sensors or {}
        offsets = {name: o for name in stats if (o := clocks.offset(name)) is not None}
        odom = ev.odom.name if ev.known and ev.odom is not None else None
        period = max((float(v.get("period", 0.0)) for v in stats.values()), default=0.0)  # the slowest sensor's
        out: dict[str, Verdict] = {}
        for name in stats:
            stuck = _stuck(name, clocks.pace(name), clocks.newest(name), stats[name])
            if stuck is not None:
                out[name] = stuck
        for name, st in stats.items():
            received = st.get("received", 0)
            far = _far(st)
            late = st.get("late", 0)
            behind = late >= CLOCK_LATE_SHARE * max(st.get("applied", 0), 1) and far < CLOCK_DROP_SHARE * received
            if received <= 0 or (far < CLOCK_DROP_SHARE * received and not behind) or name not in offsets:
                continue
            culprit = _culprit(offsets, odom, ahead_only=behind)
            if name in out or culprit is None or culprit in out or (behind and not offsets[culprit] > max(period, 0.0)):
                continue
            offset = offsets[culprit]
            side = "ahead of" if offset > 0 else "behind"
            configured = getattr(sensors.get(culprit), "stamp_offset_s", 0.0)
            if behind:
                dropped = (f"its stamps are ~{abs(offset):.2f} s {side} the other sensors': {late} of {name}'s "
                           f"{st.get('applied', 0)} samples were applied late (behind the others' newest stamp), "
                           "re-applying the others after each, and each is fused beside the others' samples taken "
                           f"{abs(offset):.2f} s {'later' if offset > 0 else 'earlier'} than it")
            elif culprit == name:
                dropped = f"{far} of {received} samples stamped ~{abs(offset):.1f} s {side} the other sensors"
            else:
                dropped = (f"its stamps are ~{abs(offset):.1f} s {side} the other sensors', and the filter's time "
                           f"followed them: {far} of {name}'s {received} samples were dropped as far from it")
            out[culprit] = Verdict(culprit, "time", "warn" if behind else "problem",
                                   f"{dropped}: its clock is offset (GPS time vs UTC? another computer's clock?). "
                                   "Stamp it with the same clock as the other sensors (the driver's time source), or "
                                   "shift it here", sensor_key(culprit, "stamp_offset_s"),
                                   f"stamp_offset_s = {configured - offset:.3f}",
                                   evidence={"clock_offset_s": offset, "dropped_far": float(far),
                                             "applied_late": float(late), "received": float(received),
                                             "dropped_sensor_offset_s": offsets[name]})
        return list(out.values())


def _stuck(name: str, pace: dict[str, tuple[float, float]], newest: float | None, st: dict) -> Verdict | None:
    """A sensor whose stamps advance slower than every other sensor's (``ClockOffsets.pace``, over at least
    PACE_SPAN_S of each, by more than PACE_TOLERANCE): a driver stamping a constant, or never filling the stamp
    (0). No stamp_offset_s mends it (the offset grows with the run: it read as a clock 30 s behind, the run's
    median), so the verdict names the driver's stamping. Only slower: a sensor reads faster than one that went
    silent while it went on (an IMU dead after 60 s of 160 made the wheels' clock read 2.7 times fast), which is
    that sensor's silence, not this one's clock."""
    rates = [own / others for own, others in pace.values() if others >= PACE_SPAN_S]
    if not rates or not all(r < 1.0 - PACE_TOLERANCE for r in rates):
        return None
    own, others = max(pace.values(), key=lambda p: p[1])
    said = ("every sample is stamped 0: the driver never fills the header's stamp" if newest == 0.0 else
            f"its stamps advance {own:.3g} s while the other sensors' advance {others:.3g} s: the driver stamps a "
            "clock that does not run (a constant, a stalled time source)")
    fused, received = st.get("applied", 0), st.get("received", 0)
    taken = (f"not one of its {received} samples was fused" if not fused else
             f"{fused} of its {received} samples were fused, each at a time it was not taken")
    return Verdict(name, "time", "problem",
                   f"{said}. The filter orders and pairs every sample by its stamp: {taken}, and no stamp_offset_s "
                   "mends a clock that does not keep time. Stamp each message with the time of its reading in the "
                   "driver (the same clock as the other sensors)",
                   evidence={"stamp_span_s": own, "others_span_s": others, "received": float(received),
                             "applied": float(fused)})


def dropped_by_clock(st: dict) -> int:
    """How many of a sensor's samples (its core counters ``st``) were dropped as far from filter time, when
    they are the share that says its clock is off (CLOCK_DROP_SHARE), else 0: another check then knows its
    samples are not on the others' time."""
    far = _far(st)
    return far if far > 0 and far >= CLOCK_DROP_SHARE * max(st.get("received", 0), 1) else 0


def _far(st: dict) -> int:
    """How many of a sensor's samples (its core counters ``st``) were dropped as far from filter time."""
    return sum(st.get("dropped", {}).get(r, 0) for r in CLOCK_REASONS)


def _culprit(offsets: dict[str, float], odom: str | None, ahead_only: bool = False) -> str | None:
    """The sensor whose clock is off: the one ahead that every other sensor sees alike (``_lone_ahead``), else the
    largest offset; of two sensors alone that mirror each other (within MIRROR), not the odometry (module doc).
    ``ahead_only`` (samples applied late): only a clock ahead makes the others late. When the largest offset is
    one behind (a receiver's delivery lag, which the history absorbs; or a sensor measuring another's lead as part
    of its own: an IMU 0.06 s behind beside a GPS 0.25 s ahead reads -0.31 s), the culprit is the sensor furthest
    ahead but the odometry, the reference where two mirror each other; None when there is none."""
    ranked = sorted(offsets, key=lambda n: -abs(offsets[n]))
    if not ranked:
        return None
    lone = _lone_ahead(offsets)
    if lone is not None:
        return lone
    top = ranked[0]
    if len(ranked) == 2 and top == odom and abs(offsets[ranked[1]]) * MIRROR >= abs(offsets[top]):
        top = ranked[1]
    if not ahead_only or offsets[top] > 0.0:
        return top
    return max((n for n in offsets if offsets[n] > 0.0 and n != odom), key=offsets.__getitem__, default=None)


def _lone_ahead(offsets: dict[str, float]) -> str | None:
    """Of three sensors or more, the one whose stamps are ahead of all the others', which agree with each other:
    each sample's offset is taken against the newest stamp of the other sensors, so a clock X ahead reads +X
    while every other sensor, its newest "other" being that clock, reads about -X (within MIRROR). Two sensors
    on one clock and a third ahead is not the mirror of two (module doc): the odometry can be that third. None
    when no one sensor stands so apart (a clock behind reads -X beside others near 0: the largest offset)."""
    if len(offsets) < 3:
        return None
    ahead = [n for n, o in offsets.items() if o > 0.0]
    if len(ahead) != 1:
        return None
    lead = offsets[ahead[0]]
    if all(o < 0.0 and -o * MIRROR >= lead and lead * MIRROR >= -o for n, o in offsets.items() if n != ahead[0]):
        return ahead[0]
    return None
