"""Whether the odometry's driver fills the pose only, the twist left zero.

robot_pose_ekf read a wheel odometry's pose, and a driver written for it may never fill the twist: the filter,
driven by the twist, keeps the robot where it started while the messages' own pose drives on. Over the same
intervals between messages (``twist.TwistStats``), the positions travel and the twists say how far the robot
went: a driver that fills both says about the same (the wheel scale apart), one that fills the pose only says
nothing. ``twist_from_pose`` takes the twist from consecutive poses (``core/sensors/odom/pose_twist.py``).
"""

from __future__ import annotations

from ...core.sensors.odom.pose_twist import POSE_PATH_M
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["PoseOnly"]

# The twists' path below this share of the positions': no wheel scale error explains it (a twist that reads 10 %
# of the speed is a unit mistake the speed checks name; one that reads nothing is not filled).
TWIST_SHARE = 0.1


class PoseOnly(BaseCheck):
    """Whether the odometry's driver fills the pose only, the twist left zero."""

    name = "pose_only"

    def run(self, ev: Evidence) -> list[Verdict]:
        odom = ev.odom
        if odom is None or odom.twist_from_pose:
            return []
        t = ev.twist
        pose, twist = t.pose_travel, t.twist_travel
        if pose < POSE_PATH_M or twist >= TWIST_SHARE * pose:
            return []
        return [Verdict(odom.name, "twist", "problem",
                        f"the odometry's own pose travelled {pose:.1f} m while its twist says the robot went "
                        f"{twist:.2f} m: the driver fills the pose only (as robot_pose_ekf reads odometry) and the "
                        "filter, which the twist drives, kept the robot where it started. Take the twist from "
                        "consecutive poses", sensor_key(odom.name, "twist_from_pose"), "twist_from_pose = true",
                        evidence={"pose_travel_m": pose, "twist_travel_m": twist})]
