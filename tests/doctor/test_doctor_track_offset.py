"""The doctor's IMU-yaw-against-GPS-track offset (``heading.yaw_along``): an absolute yaw compared with
the direction of the GPS chords must read its offset, and a correct yaw none, whatever the turns.

A GPS chord of 10 m at 1.5 m/s spans ~7 s. This robot drives straight but for left turns of 0.4 rad/s
lasting 8 s every 30 s (a skid-steer's lap: curvature that starts and stops, turning one way), so
many chords run straight, then turn, or turn, then run straight. The chord is the displacement, sum v (cos yaw, sin yaw) dt: exact for any curvature, and an offset o of the yaw turns it
by o. The yaw at the chord's middle instant equals its direction only on arcs of constant curvature;
with the turns mostly to one side it would read a correct magnetometer as 0.13 rad (3 standard errors)
off, a PROBLEM with a yaw_offset to paste. The thresholds are the verdict's own: an offset is named
beyond max(TRACK_OFFSET_RAD, 3 standard errors), and the one measured must lie within 3 of them of the truth.
"""

from __future__ import annotations

import pytest

from fusiond.doctor.checks.heading import TRACK_OFFSET_RAD

from tests.support import sim_gps
from tests.support.configs import robot_config
from tests.support.verdicts import one, verdicts_of

GPS = "position_noise = [1.0, 1.0, 2.0]"


def _world(offset: float) -> sim_gps.World:
    arcs = tuple((10.0 + 30.0 * k, 18.0 + 30.0 * k, 0.4) for k in range(8))
    return sim_gps.World(duration=240.0, speed=1.5, gps_rate=2.0, gps_sigma=1.0, imu_yaw_offset=offset,
                         imu_yaw_disturbance=(0.0, 60.0), imu_yaw_sigma=0.01, seed=9, arcs=arcs)


def _verdict(offset: float):
    samples = sim_gps.simulate(_world(offset))
    cfg = robot_config(gps=GPS, orientation="absolute", imu="orientation_noise = [0.002, 0.002, 0.01]")
    return one(verdicts_of(cfg, samples), "imu", "orientation")


def test_a_correct_absolute_yaw_has_no_offset_against_the_track():
    v = _verdict(0.0)
    se = v.evidence["imu_vs_gps_track_offset_se_rad"]
    assert abs(v.evidence["imu_vs_gps_track_offset_rad"]) < max(TRACK_OFFSET_RAD, 3.0 * se), v
    assert "yaw_offset" not in v.suggestion and v.level == "ok", v


@pytest.mark.parametrize("offset", [0.3, -0.5])
def test_an_offset_yaw_reads_its_offset(offset):
    v = _verdict(offset)
    se = v.evidence["imu_vs_gps_track_offset_se_rad"]
    assert v.evidence["imu_vs_gps_track_offset_rad"] == pytest.approx(offset, abs=3.0 * se), v


def test_the_yaw_along_a_chord_is_the_direction_of_its_displacement():
    """A chord of 8 s that runs straight for 4 s, then turns at 0.4 rad/s for 4 s, at 1.5 m/s: its
    displacement is 6 m straight, then an arc of radius R = 1.5 / 0.4 = 3.75 m through 1.6 rad,
    (R sin 1.6, R (1 - cos 1.6)): direction atan2(3.86, 9.75) = 0.377 rad. The middle instant's heading
    is 0 (the turn has not begun): 0.38 rad off, with the sense of the turn. yaw_along sums the odometry
    bins' speed along the yaw: the displacement's direction to within the 0.2 s bins' quadrature
    (~1e-3 rad), and an offset of the yaw turns it by exactly that offset."""
    import math

    import numpy as np

    from fusiond.doctor.checks.heading import yaw_along
    from fusiond.doctor.series import Series

    t = np.arange(0.1, 8.0, 0.2)  # bin middles
    heading = np.where(t < 4.0, 0.0, 0.4 * (t - 4.0))
    series = Series(odom_t=t.tolist(), odom_v=[1.5] * len(t))
    r = 1.5 / 0.4
    exact = math.atan2(r * (1.0 - math.cos(1.6)), 6.0 + r * math.sin(1.6))
    assert exact == pytest.approx(0.377, abs=0.001)
    assert yaw_along(series, t, heading, 0.0, 8.0) == pytest.approx(exact, abs=0.005)
    # the middle instant's yaw (interpolated between bins, as the midpoint comparison read it): ~0.36 rad off
    assert exact - float(np.interp(4.0, t, heading)) > 0.35
    along = yaw_along(series, t, heading, 0.0, 8.0)
    assert yaw_along(series, t, heading + 0.3, 0.0, 8.0) == pytest.approx(along + 0.3, abs=1e-12)
