"""While the GPS heading is searched for, the published position is the expected one, not the state's
dead-reckoning along a placeholder heading (``GpsModel.shown_position``); and the search's end is said once.

Thresholds from the simulation's physics: a car already driving at v when the first fix comes, fixes
every T = 1 / gps_rate with white noise sigma per axis, the filter's placeholder heading 90 deg off the
truth (it starts east, the car drives north). A pose comes with each odometry message, the fixes'
stamps among theirs, so it is at most D <= v T beyond the newest fix fused. The state dead-reckons D along the
placeholder, so its position is off by |D_placeholder - D_true| = sqrt(2) D; the published one moves
k D along it, k = exp(-s2 / 2) with s2 = HEADING_UNKNOWN_SIGMA^2, off by sqrt(1 + k^2) D. Both start
from where the newest fix put the base, within 4 sqrt(2) sigma of the truth.
"""

from __future__ import annotations

import math

import msgspec

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors.gps import HEADING_UNKNOWN_SIGMA
from fusiond.core.sensors.gps import model as gps_model
from fusiond.core.sensors import GpsSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at

SPEED = 30.0  # m/s: a car on a highway when the recording starts
GPS_RATE = 10.0
GPS_SIGMA = 0.1


def test_a_moving_car_is_published_where_it_may_be_while_its_heading_is_unknown() -> None:
    w = World(duration=6.0, standstill=0.0, speed=SPEED, start=(0.0, 0.0, math.pi / 2), gps_rate=GPS_RATE,
              gps_sigma=GPS_SIGMA, seed=3)
    core = FusionCore(robot_config(gps=""))
    shown, state = [], []
    for s in simulate(w):
        step = core.ingest(s)
        if step.publish and core.ready and not core.heading_known:
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            p = core.state.ekf.position()
            shown.append(math.hypot(x[0] - tx, x[1] - ty))
            state.append(math.hypot(p[0] - tx, p[1] - ty))
            assert core.estimate().position[:2] == (x[0], x[1])  # the daemon publishes the same position
    assert len(shown) >= 4, "the heading was found before the search could be watched"
    k = math.exp(-0.5 * HEADING_UNKNOWN_SIGMA**2)
    travel = SPEED / GPS_RATE
    anchor = 4.0 * math.sqrt(2.0) * GPS_SIGMA
    bound = math.sqrt(1.0 + k * k) * travel + anchor
    assert max(shown) <= bound, (max(shown), bound)
    # the bound tells the two apart: the state's own position, published as it was, exceeds it
    assert max(state) > bound, (max(state), bound)
    assert core.heading_known  # and the search still ends: the fixes found the heading


class _Events:
    """Stands in for the GPS model's logger: the event names it was given, in order (whatever
    configuration of structlog earlier tests left behind)."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def __getattr__(self, level: str):
        return lambda event, **_: self.names.append(event)


def test_the_end_of_the_heading_search_is_logged_once_when_fixes_are_re_applied(monkeypatch) -> None:
    """Fixes stamped ahead of the odometry (a receiver clock 0.15 s early) are re-applied at every
    odometry message stamped before them (late data); the search's end is one event, not one per
    re-application."""
    w = World(duration=8.0, standstill=0.0, speed=5.0, gps_rate=10.0, gps_sigma=0.1, seed=4)
    samples = [msgspec.structs.replace(s, stamp=s.stamp + 0.15) if isinstance(s, GpsSample) else s
               for s in simulate(w)]
    core = FusionCore(robot_config(gps=""))
    logged = _Events()
    monkeypatch.setattr(gps_model, "log", logged)
    late = sum(core.ingest(s).late for s in samples)
    assert late > 10  # the odometry behind the fixes was applied from the history
    assert core.heading_known
    events = logged.names
    assert events.count("gps_heading_initialised") == 1, events
    assert events.count("gps_heading_provisional") <= 1, events


def test_the_fixes_fitted_before_the_heading_is_applied_turn_the_published_position() -> None:
    """Before the track spans heading_init_m, its fit is not applied to the state, but it already says where
    the car goes: the published displacement since the newest fix is E[R(psi)] D = exp(-v/2) R(theta) D over
    the fit's (theta, v), not the fifth of D along the placeholder. Two fixes L = v T apart with sigma per axis
    fit the heading to v_theta = 2 sigma^2 / L^2 (more fixes: less), so a pose D <= L past the newest fix is off
    by the anchor's 4 sqrt(2) sigma, plus D times 4 sqrt(v_theta) for the turn and 1 - exp(-v_theta / 2) for
    the shrink. The car does 10 m/s, fixes of 0.02 m at 10 Hz: 0.23 m; the placeholder's mean is ~1 m off."""
    speed, rate, sigma = 10.0, 10.0, 0.02
    w = World(duration=4.0, standstill=0.0, speed=speed, start=(0.0, 0.0, math.pi / 2), gps_rate=rate,
              gps_sigma=sigma, seed=5)
    core = FusionCore(robot_config(gps=""))
    errors = []
    for s in simulate(w):
        step = core.ingest(s)
        own = next(o for o in core.state.own if isinstance(o, gps_model.GpsOwn))
        if step.publish and not core.heading_known and own.track is not None and len(own.track.points) >= 2 \
                and not own.track.applied:  # fitted, not yet applied
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            errors.append(math.hypot(x[0] - tx, x[1] - ty))
    assert len(errors) >= 4, "the fit was applied before a guess could be watched"
    travel = speed / rate
    v_theta = 2.0 * sigma**2 / travel**2
    bound = 4.0 * math.sqrt(2.0) * sigma + travel * (4.0 * math.sqrt(v_theta) - math.expm1(-0.5 * v_theta))
    assert max(errors) <= bound, (max(errors), bound)
