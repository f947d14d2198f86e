"""An accelerometer published in g: its specific force reads about 1 where gravity alone is 9.81 m/s^2.

sensor_msgs/Imu carries m/s^2 (REP 103). A driver that passes its chip's g through publishes a magnitude near 1
at rest and within G_UNITS_BAND (0.8-1.2) through ordinary driving (dynamic accelerations under 0.2 g), where an
accelerometer in m/s^2 reads near 9.81 and enters that band only while falling freely. fusiond reads such
samples as g wherever it reads the accelerometer (roll and pitch from gravity in the core, the doctor's
mounting fit), so its own estimate is right; anything else that reads the topic is not. The share of the
samples in the band tells the two apart: near 1 for a driver in g, near 0 for one in m/s^2, and IN_G_SHARE
lies between them; MIN_SAMPLES samples make a share (a second of a 100 Hz IMU).
"""

from __future__ import annotations

from ...core.sensors.imu import G_UNITS_BAND, GRAVITY
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict

__all__ = ["AccelUnits", "IN_G_SHARE", "MIN_SAMPLES"]

IN_G_SHARE = 0.5  # of the samples in the g band: between ~1 (a driver in g) and ~0 (one in m/s^2), module doc
MIN_SAMPLES = 100


class AccelUnits(BaseCheck):
    """The accelerometer's magnitude against gravity's: a unit of g."""

    name = "accel_units"
    group = "run"

    def run(self, ev: Evidence) -> list[Verdict]:
        imu, series = ev.imu, ev.series
        if imu is None or series is None or series.acc_samples < MIN_SAMPLES:
            return []
        share = series.acc_in_g / series.acc_samples
        if share < IN_G_SHARE:
            return []
        lo, hi = G_UNITS_BAND
        return [Verdict(imu.name, "units", "warn",
                        f"the accelerometer reads in g, not m/s^2: its magnitude is within {lo:g}-{hi:g} in "
                        f"{share:.0%} of {series.acc_samples} samples, where gravity alone is {GRAVITY:.2f} m/s^2. "
                        "sensor_msgs/Imu carries m/s^2 (REP 103): its driver passes the chip's g through. fusiond "
                        "reads such samples as g (roll and pitch from gravity, the mounting fit), so its estimate "
                        "is unaffected; anything else that reads the topic is not: fix the driver",
                        evidence={"in_g_share": share, "samples": float(series.acc_samples)})]
