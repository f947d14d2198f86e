"""A sensor's stamps shifted by ``stamp_offset_s`` (a highway car: a receiver that stamps each fix when it
arrives, LAG after the epoch it measured; and a GPS on GPS time, 18 s ahead of the others' UTC).

A car at 20 m/s with 10 Hz fixes of 0.3 m: stamped LAG = 0.2 s late, each fix lies v LAG = 4 m behind where
the car is at its stamp. The filter, given no way to know, pulls the track back towards them. With
``stamp_offset_s = -LAG`` the fixes are fused at their epoch (the late-data history re-applies what followed).
"""

from __future__ import annotations

import math

import msgspec
import numpy as np

from fusiond.core.fusion import FusionCore
from fusiond.replay.run import run_samples
from fusiond.core.sensors import GpsSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at

LAG = 0.2  # s
SPEED = 20.0  # m/s


def _world() -> World:
    return World(duration=60.0, speed=SPEED, gps_rate=10.0, gps_sigma=0.3, standstill=2.0)


def _late(samples, lag: float, arrive_then: bool = True) -> list:
    """The GPS samples stamped ``lag`` late, and arriving then (a receiver's latency), or when measured (a clock
    offset: the stamp is wrong, not the delivery)."""
    out = [msgspec.structs.replace(s, stamp=s.stamp + lag) if isinstance(s, GpsSample) else s for s in samples]
    return sorted(out, key=lambda s: s.stamp) if arrive_then else out


def _rms_error(w: World, samples, offset: float) -> float:
    """Horizontal RMS error over the last 30 s, at every published pose."""
    core = FusionCore(robot_config(gps=f"datum = [48.137, 11.575, 520.0]\nstamp_offset_s = {offset}"))
    errs = []
    for s in samples:
        if core.ingest(s).publish and s.stamp > 1000.0 + 30.0:
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            errs.append(math.hypot(x[0] - tx, x[1] - ty))
    return float(np.sqrt(np.mean(np.square(errs))))


def test_a_late_receiver_is_fused_at_its_epoch():
    """Uncorrected, the fixes sit 4 m behind; the wheels (0.02 m/s of noise) hold the track against them only in
    part: the error lies between a quarter and all of v LAG (asserted over 1 m). Corrected, what is left is the
    fixes' 0.3 m noise averaged over many fixes: asserted under 0.3 m, and under a fifth of the uncorrected."""
    w = _world()
    samples = _late(simulate(w), LAG)
    late = _rms_error(w, samples, 0.0)
    fixed = _rms_error(w, samples, -LAG)
    assert late > 1.0
    assert fixed < 0.3 and fixed < late / 5


def test_a_gps_on_another_clock_is_named_with_the_offset_that_brings_it_back():
    """Fixes stamped 18 s ahead (GPS time vs UTC): dropped as far from filter time, and the doctor gives the
    stamp_offset_s to paste (-18 within the odometry's period). Pasted, every fix is fused."""
    w = _world()
    samples = _late(simulate(w), 18.0, arrive_then=False)
    cfg = robot_config(gps="datum = [48.137, 11.575, 520.0]")
    result = run_samples(samples, cfg)
    v = next(v for v in result.verdicts() if v.sensor == "gps" and v.channel == "time")
    assert v.key == "sensors.gps.stamp_offset_s", v
    offset = float(v.suggestion.split("=")[1])
    assert abs(offset + 18.0) < 0.1, v
    fixed = run_samples(samples, robot_config(gps=f"datum = [48.137, 11.575, 520.0]\nstamp_offset_s = {offset}"))
    gps = fixed.core.stats[fixed.core.index["gps"]]
    assert gps.received > 500 and gps.applied == gps.received - sum(gps.dropped.values())
    assert sum(gps.dropped.values()) <= 3  # at most the fixes beyond the end of the other sensors' run
