"""The IMU's mounting yaw the accelerometer measures against the wheels (``mounting.mount_yaw_fit``)."""

from __future__ import annotations

import math

from ..attitude import full_mount, lean_of, paste_mount
from ..check import MIN_UPDATES, BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["Mounting"]


class Mounting(BaseCheck):
    """The IMU's mounting yaw the accelerometer measures against the wheels."""

    name = "mounting"
    listed_after = ("lean",)  # both speak of the IMU's attitude: the lean first

    def run(self, ev: Evidence) -> list[Verdict]:
        """The accelerometer's verdict on the mounting yaw; none when the driving could not tell."""
        imu, mount, tilt = ev.run_imu, ev.mount, ev.tilt
        if imu is None or mount is None:
            return []
        evidence = mount.evidence()
        deg = math.degrees(mount.delta)
        se_deg = math.degrees(mount.se)
        if mount.named:
            means, _, leaning = lean_of(tilt, MIN_UPDATES)
            lean = (means[0], means[1]) if leaning else (0.0, 0.0)
            return [Verdict(imu.name, "attitude", "problem",
                            f"the accelerometer's horizontal axes are turned by {deg:+.1f} deg (+- {se_deg:.1f}) "
                            f"against the motion the wheels and the gyro report ({mount.samples} s of driving): the "
                            "IMU is mounted yawed by that and extrinsic_rpy does not say so (the gyro's z rate cannot "
                            "show it; the IMU's roll and pitch land on the wrong base axes). The full mount is below",
                            sensor_key(imu.name, "extrinsic_rpy"), paste_mount(full_mount(imu, lean, mount.delta)),
                            evidence)]
        if mount.resolved:
            return [Verdict(imu.name, "attitude", "ok",
                            f"the accelerometer agrees with the wheels' motion: mounting yaw {deg:+.1f} deg "
                            f"(+- {se_deg:.1f}) against extrinsic_rpy", evidence=evidence)]
        return []
