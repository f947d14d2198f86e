"""A fix is two measurement blocks: the horizontal and the vertical are gated apart, and while the
heading is unknown the position's covariance covers a track dead-reckoned the wrong way.

Thresholds from the simulations' physics: a white fix whose noise is stated right has a 2-dof NIS
above a gate of 5 sigma (25) with probability exp(-12.5) ~ 4e-6, so among a few thousand fixes a
horizontal fix gated out is a fix thrown away for something else (its altitude); a 3-sigma bound per
axis holds a true error with probability 0.997, so over some tens of fixes none should exceed it
(allowing one).
"""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import GpsSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at


@pytest.mark.long_sim
def test_a_wandering_altitude_gated_out_never_costs_the_horizontal_fix() -> None:
    """Altitude stated as 1.7 m like the horizontal, but wandering 15 m (Gauss-Markov over 60 s) with
    its own error state off: the altitude innovations are gated out as they wander beyond 5 sigma, and
    the east/north of those same fixes are fused."""
    w = World(duration=300.0, speed=1.0, gps_rate=5.0, gps_sigma=1.7, gps_alt_error_tau=60.0,
              gps_alt_error_sigma=15.0, seed=7)
    core = FusionCore(robot_config(gps="vertical_error_sigma = 0.0\nmahalanobis_threshold = 5.0"))
    horizontal, vertical = [], []
    for s in simulate(w):
        for r in core.ingest(s).records:
            if r.sensor == "gps" and r.channel == "position":
                horizontal.append(r.rejected)
            elif r.sensor == "gps" and r.channel == "altitude":
                vertical.append(r.rejected)
    assert sum(vertical) > 0.1 * len(vertical)  # the trait: the altitude wanders beyond its gate
    assert len(horizontal) > 1000 and sum(horizontal) == 0


def test_while_the_heading_is_unknown_the_position_covariance_covers_the_wrong_way_track() -> None:
    """A car at 15 m/s starting 90 deg off the heading the filter assumes, 10 Hz fixes of 0.5 m:
    until the heading is found, every published position error is within 3 sigma of its claimed
    covariance per axis (the track dead-reckoned east while the car drives north)."""
    w = World(duration=30.0, speed=15.0, start=(0.0, 0.0, math.pi / 2), standstill=0.0, gps_rate=10.0,
              gps_sigma=0.5, seed=2)
    core = FusionCore(robot_config(gps="position_noise = [0.5, 0.5, 1.0]"))
    outside, checked = 0, 0
    for s in simulate(w):
        core.ingest(s)
        if isinstance(s, GpsSample) and core.ready and not core.heading_known:
            t, x = core.pose()
            tx, ty, _ = truth_at(w, t)
            c = core.estimate().pose_covariance
            checked += 1
            outside += abs(x[0] - tx) > 3 * math.sqrt(c[0]) or abs(x[1] - ty) > 3 * math.sqrt(c[7])
    assert checked >= 5
    assert outside <= 1, (outside, checked)
