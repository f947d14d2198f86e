"""No source of yaw rate fused while the odometry says the vehicle turns: the heading lags every turn."""

from __future__ import annotations

import numpy as np

from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["YawRateNotMeasured"]

# samples stating the yaw rate not measured beyond half of all: the driver does not measure it (a driver that
# measures it states it so in every sample; one that does not, in every one)
UNMEASURED_FRACTION = 0.5


class YawRateNotMeasured(BaseCheck):
    """No source of yaw rate fused at all while the odometry says the vehicle turns."""

    name = "yaw_rate_not_measured"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        """Nothing measures the turn rate: the odometry marks its yaw rate "not measured" (a driver sending
        covariance 1e6, or twist_measured) and no gyro is fused. The heading then only changes through the
        absolute updates (IMU yaw, GPS), lagging every turn; against the gyro it looks like a wheel yaw rate
        of 0 x the gyro, but it is neither slip nor a scale: fuse the gyro."""
        if ev.odom is None:
            return []
        series, odom, imu, gyro_fused = ev.series, ev.odom, ev.imu, ev.gyro_fused
        if gyro_fused or not series.odom_n:
            return []
        n = int(np.sum(series.odom_n))
        unmeasured = int(np.sum(series.odom_wz_unmeasured))
        if n == 0 or unmeasured < UNMEASURED_FRACTION * n:
            return []
        msg = (f"the odometry does not measure yaw rate ({unmeasured} of {n} samples state it not measured: "
               "variance >= twist_max_sigma^2, or twist_measured) and the gyro is not fused: nothing measures the "
               "turn rate, so the heading only follows the absolute updates, lagging every turn (not skid-steer slip)")
        evidence = {"yaw_rate_unmeasured_fraction": unmeasured / n}
        if imu is None:
            return [Verdict(odom.name, "heading", "problem", msg + "; add an IMU and fuse its gyro", evidence=evidence)]
        return [Verdict(odom.name, "heading", "problem", msg + "; fuse the gyro: angular_velocity = true",
                        sensor_key(imu.name, "angular_velocity"), "angular_velocity = true", evidence)]
