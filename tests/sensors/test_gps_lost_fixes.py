"""A GPS driver's lost fixes dressed as fixes: latitude and longitude 0 under a fix status, and
covariances of all zeros (the brief's "lost measurements reported as perfect").

Fused, one placeholder fix at (0, 0) is ~5,000 km from a robot at 48 N 11 E: with a floored
covariance of 1 cm it would drag the pose there and the wheel scale with it. A covariance of
zeros floored to 1 cm would trust an ordinary fix 100x more than a consumer receiver deserves.
"""

from __future__ import annotations

import math

import msgspec
import pytest

from fusiond import reasons
from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.gps import GpsPolicy
from fusiond.core.sensors import GpsSample

from tests.support.sim_gps import World, simulate, truth_at
from tests.support.gps_pose import _gps_config, _gps_world

UNKNOWN = (2.5, 2.5, 5.0)  # GpsSensor.unknown_position_sigma's default


def _policy() -> GpsPolicy:
    return GpsPolicy(_gps_config().sensors[2])


def test_a_fix_at_exactly_zero_zero_is_no_fix_whatever_its_status():
    with pytest.raises(Exception) as err:
        _policy().convert(GpsSample("gps", 1.0, 0.0, 0.0, 0.0, status=0, position_covariance=(0.0,) * 9,
                                    covariance_type=2))
    assert err.value.reason == reasons.NO_FIX
    # a fix near, but not at, (0, 0) is a fix (the Gulf of Guinea has roads too)
    near = _policy().convert(GpsSample("gps", 1.0, 1e-7, 0.0, 0.0, status=0, position_covariance=(1.0,) * 9,
                                       covariance_type=2))
    assert near.lla == (1e-7, 0.0, 0.0)


def test_a_covariance_of_zeros_states_nothing_and_takes_the_unknown_noise():
    zeros = _policy().convert(GpsSample("gps", 1.0, 48.1, 11.5, 520.0, position_covariance=(0.0,) * 9,
                                        covariance_type=2))
    assert [zeros.cov[0], zeros.cov[4], zeros.cov[8]] == [s * s for s in UNKNOWN]
    # one axis stated exactly is still floored, not "unknown": the receiver said something
    one = _policy().convert(GpsSample("gps", 1.0, 48.1, 11.5, 520.0,
                                      position_covariance=(0.0, 0, 0, 0, 0.0, 0, 0, 0, 4.0), covariance_type=2))
    assert [one.cov[0], one.cov[4], one.cov[8]] == [0.01**2, 0.01**2, 4.0]


def _with_placeholders(samples: list, every: int) -> list:
    """Every ``every``-th GPS fix replaced by a driver's "no fix": (0, 0, 0), covariance zeros, status FIX."""
    out, k = [], 0
    for s in samples:
        if isinstance(s, GpsSample):
            k += 1
            if k % every == 0:
                s = msgspec.structs.replace(s, latitude=0.0, longitude=0.0, altitude=0.0,
                                            position_covariance=(0.0,) * 9, status=0)
        out.append(s)
    return out


def test_placeholder_fixes_are_dropped_and_counted_and_change_nothing_else():
    """Placeholders instead of one fix in 25 (at 5 Hz: one every 5 s): the run equals the one
    without those fixes at all, to the bit, and each is counted as no_fix."""
    w = _gps_world()
    samples = simulate(w)
    lost = _with_placeholders(samples, 25)
    placeholders = sum(1 for a, b in zip(samples, lost) if a is not b)
    removed = [b for a, b in zip(samples, lost) if a is b]
    cores = []
    for run in (lost, removed):
        core = FusionCore(_gps_config())
        for s in run:
            core.ingest(s)
        cores.append(core)
    assert placeholders >= 20
    assert cores[0].stats[2].dropped == {reasons.NO_FIX: placeholders}
    assert (cores[0].pose()[1] == cores[1].pose()[1]).all()
    t, x = cores[0].pose()
    tx, ty, _ = truth_at(w, t)
    # where the robot is (within 3 sigma of one 0.3 m fix), not off the coast of Africa
    assert math.hypot(x[0] - tx, x[1] - ty) < 3 * w.gps_sigma


def _with_burst(samples: list, t0: float, n: int, north_m: float) -> list:
    """``n`` consecutive fixes from stamp ``t0`` on moved ``north_m`` north (multipath off a building)."""
    out, k = [], 0
    for s in samples:
        if isinstance(s, GpsSample) and s.stamp >= t0 and k < n:
            k += 1
            s = msgspec.structs.replace(s, latitude=s.latitude + north_m / 111_320.0)
        out.append(s)
    return out


def _max_error(core_samples: list, w: World, t0: float, t1: float, cfg) -> tuple[float, int]:
    """(largest position error published in [t0, t1], GPS fixes rejected in it)."""
    core, worst, rejected = FusionCore(cfg), 0.0, 0
    for s in core_samples:
        step = core.ingest(s)
        rejected += sum(1 for r in step.records if r.sensor == "gps" and r.rejected and t0 <= r.stamp <= t1)
        if step.publish and t0 <= core.pose()[0] <= t1:
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            worst = max(worst, math.hypot(x[0] - tx, x[1] - ty))
    return worst, rejected


def test_a_multipath_burst_is_gated_out_by_default():
    """Five fixes (1 s at 5 Hz) 25 m off, 60 s into the run. By default the gate (sqrt(NIS) 5, where a
    good fix is within ~3) rejects all five and the pose stays within 3 sigma of a 0.3 m fix; without
    a gate each fix pulls the pose toward the burst by its gain, metres at the first fix already."""
    w = _gps_world()
    samples = _with_burst(simulate(w), 1060.0, 5, 25.0)
    default, rejected = _max_error(samples, w, 1059.0, 1063.0, _gps_config())
    ungated, _ = _max_error(samples, w, 1059.0, 1063.0, _gps_config("mahalanobis_threshold = inf"))
    assert rejected == 5
    assert default < 3 * w.gps_sigma
    assert ungated > 1.0


def test_a_slow_receivers_multipath_burst_is_a_jump_not_the_filter_lost():
    """A 1 Hz receiver whose epochs come 1.05 s apart (1 m noise): five fixes, 5 s, 35 m off right after good
    ones. The burst's first fix is the next fix after an accepted one, so the run began with a jump, and a jump is
    believed only after REACQUIRE_JUMP_S or the step test (6 fixes): the burst stays gated out and the pose where
    the wheels and the good fixes put it. Read as a filter lost (its first fix 1.05 s after the accepted one, over
    JUMP_AFTER_S), the fifth fix was taken as the position (REACQUIRE_S), the wheels rescaled to it, and the pose
    pulled 35 m off."""
    from structlog.testing import capture_logs

    from fusiond.logs import configure

    w = _gps_world(gps_rate=1.0 / 1.05, gps_sigma=1.0)
    samples = _with_burst(simulate(w), 1060.0, 5, 35.0)
    configure("warning")  # capture_logs keeps the level's filter: an earlier test's --quiet would drop warnings
    with capture_logs() as logs:
        worst, rejected = _max_error(samples, w, 1059.0, 1070.0, _gps_config())
    assert rejected == 5
    assert not [e for e in logs if e["event"] in ("gps_reacquired", "gps_rescaled_wheels")], logs
    assert worst < 3 * w.gps_sigma, worst
