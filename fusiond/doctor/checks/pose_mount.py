"""A visual odometry's camera turned in its mount beyond what extrinsic_rpy says (``doctor/pose_motion.py``).

Its deltas, read in base_link's axes through the configured mount, lean sideways or up against the direction the
wheels move the base in. Fused so, every forward metre is a sideways step the filter puts down to the heading:
on the highway car a camera 0.9 deg off made the estimate four times worse than no camera at all, while the
deltas' NIS read consistent (0.9 deg of a 1.5 m delta is 2.4 cm, within the stated noise). The fit names the yaw
to state where it is beyond MOUNT_SIGMAS of its standard error. The pitch is said, not pasted: the filter's tilt is
the IMU's, and a camera's pitch stated right against an IMU whose own mount is not (the highway car's IMU is pitched
4.3 deg, unstated) makes the two disagree on every delta (pasted with the yaw there: likelihood -442).
"""

from __future__ import annotations

import math

from ..attitude import full_mount, paste_mount
from ..check import MIN_UPDATES, BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["PoseMount"]

MOUNT_SIGMAS = 3.0  # a mount error named beyond this many of its standard errors (two-sided 0.3 %)
MIN_FORWARD_M = 10.0  # and over this much forward motion: a lever arm's share of a few turns in place says nothing


class PoseMount(BaseCheck):
    """A differential pose sensor's mount yaw (and its pitch, said), against the wheels' direction of motion."""

    name = "pose_mount"

    def run(self, ev: Evidence) -> list[Verdict]:
        motion = ev.pose_motion
        if motion is None:
            return []
        out = []
        for name in motion.sensors:
            fit = motion.fit(name)
            if fit is None or fit.n < MIN_UPDATES or fit.forward_m < MIN_FORWARD_M:
                continue
            if not abs(fit.yaw) > MOUNT_SIGMAS * fit.yaw_se:
                continue
            line = paste_mount(full_mount(ev.sensors[name], yaw=fit.yaw))
            out.append(Verdict(
                name, "mount", "warn",
                f"its deltas, read in base_link's axes through extrinsic_rpy, lean sideways against the direction the "
                f"wheels move the base in by {math.degrees(fit.yaw):+.2f} deg (+- {math.degrees(fit.yaw_se):.2f}) "
                f"over {fit.forward_m:.0f} m of forward motion ({fit.n} deltas): the sensor is turned by that in "
                "its mount beyond what extrinsic_rpy says, and every forward metre is then fused as a step sideways, "
                "which the filter puts down to the heading and the gyro's bias (a wheeled base moves along its own "
                "x; an omnidirectional one does not, and this is then its sideways motion). Their pitch against the "
                f"motion reads {math.degrees(fit.pitch):+.2f} deg (+- {math.degrees(fit.pitch_se):.2f}): the filter's "
                "tilt is the IMU's, so state it once the IMU's own mount is (imu/attitude)",
                sensor_key(name, "extrinsic_rpy"), line,
                evidence={"mount_yaw_error_rad": fit.yaw, "mount_yaw_se": fit.yaw_se,
                          "mount_pitch_error_rad": fit.pitch, "mount_pitch_se": fit.pitch_se,
                          "deltas": float(fit.n), "forward_m": fit.forward_m}))
        return out
