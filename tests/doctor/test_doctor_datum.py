"""A configured GPS datum far from where the robot drives (``doctor/checks/datum.py``)."""

from __future__ import annotations

import math

from fusiond.doctor.checks.datum import EARTH_RADIUS_M, TILT_RAD
from fusiond.estimator.geodesy import EnuFrame, enu_to_geodetic

from tests.support import sim_gps
from tests.support.configs import robot_config
from tests.support.verdicts import verdicts_of

WORLD = dict(duration=40.0, speed=5.0, gps_rate=5.0, gps_sigma=0.5)


def _datum_verdicts(datum: tuple[float, float, float]):
    samples = sim_gps.simulate(sim_gps.World(**WORLD))
    verdicts = verdicts_of(robot_config(gps=f"datum = {list(datum)}"), samples)
    return [v for v in verdicts if v.channel == "datum"], samples


def test_a_datum_with_latitude_and_longitude_swapped_is_named_with_the_first_fix_to_paste():
    """The world's fixes are near (48.137, 11.575); the datum typed as (11.575, 48.137), both in range, is
    4,500 km away: its plane tilts by ~40 deg there. Named as a problem, the swap said, the first fix to paste;
    pasted, nothing is said."""
    lat, lon, alt = sim_gps.World().datum
    found, samples = _datum_verdicts((lon, lat, alt))
    assert len(found) == 1 and found[0].level == "problem" and found[0].key == "sensors.gps.datum", found
    assert "swapped" in found[0].message and found[0].evidence["datum_tilt_rad"] > 0.5
    fixed = [v for v in verdicts_of(robot_config(gps=found[0].suggestion), samples) if v.channel == "datum"]
    assert fixed == []


def test_a_datum_within_the_tilt_the_imu_resolves_is_left_alone():
    """A map origin kept on purpose 20 km from the robot tilts its plane by 0.003 rad, below TILT_RAD: nothing
    said. One 40 km off (0.0063 rad) is named."""
    frame = EnuFrame(*sim_gps.World().datum)
    near = enu_to_geodetic(frame, 20000.0, 0.0, 0.0)
    assert 20000.0 / EARTH_RADIUS_M < TILT_RAD
    assert _datum_verdicts(near)[0] == []
    far = enu_to_geodetic(frame, 0.0, 40000.0, 0.0)
    found = _datum_verdicts(far)[0]
    assert len(found) == 1 and "swapped" not in found[0].message
    assert math.isclose(found[0].evidence["datum_distance_m"], 40000.0, rel_tol=0.01)
