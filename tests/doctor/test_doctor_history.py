"""A sensor whose samples arrive later than the history reaches back: the doctor says how long it must be."""

from __future__ import annotations

import math

import msgspec

from fusiond import reasons
from fusiond.replay.run import run_samples

from tests.support.sim_faults import shift_stamps
from tests.support.sim_gps import simulate
from tests.support.verdicts import one, verdicts_of
from tests.support.gps_pose import _gps_config, _gps_world

LAG_S = 1.5  # the GPS's stamps 1.5 s behind its messages' place in the stream (history_s is 1 s by default)


def test_samples_older_than_the_history_get_a_history_s_that_covers_them():
    """Every fix stamped 1.5 s before the other sensors' newest stamp when it arrives: all are too old
    for the default 1 s history. The verdict names filter.history_s with a value covering the lag of
    99 % of them (1.5 s, plus a fifth, rounded up to 0.1 s); pasted, no fix is dropped as too old."""
    samples = shift_stamps(simulate(_gps_world(duration=30.0)), "gps", -LAG_S)
    cfg = _gps_config()
    v = one(verdicts_of(cfg, samples), "gps", "time")
    assert v.key == "filter.history_s" and v.suggestion.startswith("history_s = ")
    value = float(v.suggestion.split("=")[1])
    assert LAG_S < value <= math.ceil(12.0 * (LAG_S + 0.01)) / 10.0  # the lag: 1.5 s + the IMU's 10 ms period
    longer = msgspec.structs.replace(cfg, filter=msgspec.structs.replace(cfg.filter, history_s=value))
    assert reasons.TOO_OLD not in run_samples(samples, longer).core.stats[2].dropped
