"""The cross-source checks: the sources compared on the quantities they share.

They run first, before any channel is judged on its own innovations: what they find decides
who is to blame (``blame``), and an IMU yaw the heading check found agreeing with the gyro is
no disturbance whatever its NIS says (``channel_checks.OrientationNis``). Each needs the config
(the cross-source series are built from it): a monitor without one gets none of them.
"""

from __future__ import annotations

from .check import BaseCheck, found
from .evidence import Evidence
from .heading import heading_check, wheel_heading_check
from .lever import lever_verdict
from .speed import speed_check
from .twist import unmeasured_yaw_rate, yaw_rate_not_measured
from .verdict import Verdict

__all__ = ["LeverArm", "UnmeasuredYawRate", "YawRateNotMeasured", "WheelHeading", "Heading", "Speed"]


class LeverArm(BaseCheck):
    """The GPS antenna's lever arm, from how the fixes swing as the vehicle turns."""

    name = "lever"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(lever_verdict(ev.series, ev.config))


class UnmeasuredYawRate(BaseCheck):
    """A wheel yaw rate the odometry driver does not measure (exact zeros while the gyro turns)."""

    name = "unmeasured_yaw_rate"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.odom is None:
            return []
        return found(unmeasured_yaw_rate(ev.series, ev.odom))


class YawRateNotMeasured(BaseCheck):
    """No source of yaw rate fused at all while the odometry says the vehicle turns."""

    name = "yaw_rate_not_measured"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        if ev.odom is None:
            return []
        return found(yaw_rate_not_measured(ev.series, ev.odom, ev.imu, ev.gyro_fused))


class WheelHeading(BaseCheck):
    """The wheels' yaw rate against the gyro's; not asked when the wheels' yaw rate is known unmeasured
    (either check above already says so)."""

    name = "wheel_heading"
    group = "cross"
    needs = ("unmeasured_yaw_rate", "yaw_rate_not_measured")

    def run(self, ev: Evidence) -> list[Verdict]:
        if any(ev.findings.first(n) is not None for n in self.needs):
            return []
        return found(wheel_heading_check(ev.series, ev.config))


class Heading(BaseCheck):
    """An IMU's fused yaw against the gyro, the wheels and the GPS track."""

    name = "heading"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(heading_check(ev.series, ev.config))


class Speed(BaseCheck):
    """The wheel speed's scale against the GPS chords."""

    name = "speed"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        return found(speed_check(ev.series, ev.config, ev.scales))
