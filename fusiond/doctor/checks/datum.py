"""A configured GPS datum far from where the robot drives.

The world frame is the tangent plane (ENU) at the datum. Away from it the plane leaves the local level:
at a horizontal distance d its vertical is tilted by d / R from the local one (R the Earth's radius),
so a level drive climbs or sinks in the frame by that slope, which the IMU's gravity contradicts and the
doctor's lean check would call a mount pitch (a datum with latitude and longitude swapped, 2,560 km off:
"pitched +24 deg"). A datum whose tilt at the first fix exceeds TILT_RAD is named, with the first fix as
the datum to paste: a map origin kept on purpose belongs within a few tens of kilometres of the robot.
"""

from __future__ import annotations

import math

from ...estimator.geodesy import EnuFrame
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["Datum"]

EARTH_RADIUS_M = 6371000.0  # mean radius: the tilt d / R to a part in a few hundred
# The tilt a consumer IMU's gravity resolves (it levels to a few tenths of a degree): 0.29 deg, a datum 32 km off.
# Closer, the plane's slope is below what the filter's own attitude can tell apart.
TILT_RAD = 0.005


class Datum(BaseCheck):
    """A configured GPS datum far enough from the first fix that its plane tilts against the local level."""

    name = "datum"

    def run(self, ev: Evidence) -> list[Verdict]:
        gps = ev.gps
        origin = ev.series.gps_origin
        if gps is None or gps.datum is None or origin is None:
            return []
        e, n, _ = EnuFrame(*gps.datum).enu(*origin)
        d = math.hypot(e, n)
        tilt = d / EARTH_RADIUS_M
        evidence = {"datum_distance_m": d, "datum_tilt_rad": tilt}
        if tilt <= TILT_RAD:
            return []
        lat, lon, alt = origin
        swapped = ""
        if -90.0 <= gps.datum[1] <= 90.0 and math.hypot(gps.datum[0] - lon, gps.datum[1] - lat) < 1.0:
            swapped = " (its latitude and longitude look swapped)"
        return [Verdict(gps.name, "datum", "problem",
                        f"the configured datum is {d / 1000.0:.0f} km from the first fix{swapped}: the world frame "
                        f"is the plane tangent there, which tilts by {math.degrees(tilt):.1f} deg against the level "
                        "where the robot drives, so a level drive climbs in it and the IMU's gravity disagrees (read "
                        "as a mount pitch). A datum near the robot, the first fix say, keeps the plane level",
                        sensor_key(gps.name, "datum"), f"datum = [{lat:.7f}, {lon:.7f}, {alt:.2f}]",
                        evidence=evidence)]
