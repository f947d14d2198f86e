"""A gyro published in degrees per second: its rate 57.3 times what the wheels and the IMU's own yaw turn by.

sensor_msgs/Imu carries rad/s (REP 103); a driver that passes its chip's deg/s through makes the gyro read
180/pi times the turn. Nothing in one message shows it, and the filter then does everything wrong at once:
its fastest samples exceed the plausible rate and are dropped, the heading turns 57 times too far, the
standstills look like turns and every gyro figure the doctor quotes is scaled. Against another source of the
turn it is unmistakable: the wheels' yaw rate fitted against the gyro's (``heading.wheel_yaw_fit``) and the
IMU's own yaw against the integrated gyro (``heading.yaw_scale``) each read a scale of pi/180.

A physical scale error stays near 1 (a skid-steer's wheels read 0.3-3 times the turn, a gyro's scale within
percent): a scale within UNITS_BAND of pi/180 is the unit, not the vehicle. The verdict names the IMU and the
driver; no key of fusiond's converts units (the message's contract is rad/s).
"""

from __future__ import annotations

import math

from ..check import BaseCheck
from ..evidence import Evidence
from ..heading import timed, yaw_scale
from ..verdict import Verdict

__all__ = ["GyroUnits", "DEG_PER_RAD_SCALE", "UNITS_BAND"]

DEG_PER_RAD_SCALE = math.pi / 180.0  # the scale another source reads against a gyro in deg/s
UNITS_BAND = 3.0  # a scale within this factor of pi/180 (so 19-170 times smaller than 1): the unit (module doc)


def in_degrees(k: float) -> bool:
    """Is ``k`` (another source's turn per the gyro's) the scale of a gyro in deg/s?"""
    return math.isfinite(k) and k > 0.0 and abs(math.log(k / DEG_PER_RAD_SCALE)) < math.log(UNITS_BAND)


class GyroUnits(BaseCheck):
    """The gyro's rate against the wheels' yaw rate and the IMU's own yaw: a unit of deg/s."""

    name = "gyro_units"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        imu, series = ev.imu, ev.series
        if imu is None or series is None or len(series.gyro_t) < 10:
            return []
        seen: list[tuple[str, float]] = []
        fit = ev.wheel_yaw
        if fit is not None:
            seen.append(("the wheels' yaw rate", fit[0]))
        ti, yi = timed(series.imu_yaw_at, series.imu_yaw)
        tg, hg = timed(series.gyro_heading_at, series.gyro_heading)
        if len(ti) >= 10 and len(tg) >= 10:
            seen.append(("the IMU's own yaw", yaw_scale(ti, yi, tg, hg, [*series.gyro_breaks, *series.imu_breaks])))
        units = [(source, k) for source, k in seen if in_degrees(k)]
        if not units:
            return []
        said = " and ".join(f"{source} turns {k:.4f} of it ({1.0 / k:.1f}x less)" for source, k in units)
        evidence = {f"scale_vs_{'wheels' if 'wheels' in source else 'imu_yaw'}": k for source, k in units}
        return [Verdict(imu.name, "units", "problem",
                        f"the gyro reads in degrees per second: {said}, and 180/pi = 57.3. sensor_msgs/Imu carries "
                        "rad/s (REP 103): its driver passes the chip's deg/s through. Until it publishes rad/s the "
                        "filter turns the heading 57 times too far, drops the fastest samples as implausible "
                        "(beyond 100 rad/s) and reads every standstill as a turn; every other gyro figure here is "
                        "scaled by it", evidence=evidence)]
