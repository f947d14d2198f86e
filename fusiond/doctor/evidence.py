"""The evidence every check reads: what a run showed, gathered once and shared.

A check needs some of the config, the cross-source series, the per-channel innovation
statistics, the twist and tilt statistics, the core's counters and the sensors' clocks; the
fits several checks read (the accelerometer's mounting yaw, the wheels' yaw-rate fit, the gyro
bias verdict per channel) are computed here once, on first use. ``findings`` holds what the
checks run so far found, by check name: a check that needs an earlier one's finding (the IMU's
yaw NIS reads the heading cross-check) reads it there, and the registry's order runs it first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

from ..config import Config, GpsSensor, ImuSensor, OdomSensor
from ..core.sensors.registry import kind_of
from .attitude import TiltStats
from .clock import ClockOffsets
from .gyro import bias_check
from .heading import wheel_yaw_fit
from .mounting import MountYaw, mount_yaw_fit
from .nis import ChannelStats
from .pose_motion import PoseMotion
from .series import Series
from .twist import TwistStats
from .verdict import Verdict

__all__ = ["Evidence", "Findings"]


class Findings:
    """What each check found, by check name, in the order the checks ran."""

    def __init__(self) -> None:
        self.by_check: dict[str, list[Verdict]] = {}
        self._slots: dict[int, tuple[str, str]] = {}

    def add(self, check: str, verdicts: list[Verdict]) -> None:
        self.by_check[check] = verdicts

    def file(self, v: Verdict, slot: tuple[str, str]) -> None:
        """File ``v`` under ``slot`` (a channel check files what it finds under the channel it judged)."""
        self._slots[id(v)] = slot

    def slot(self, v: Verdict) -> tuple[str, str]:
        """Where ``v`` is filed: where its check put it, else under its own sensor and channel."""
        return self._slots.get(id(v), (v.sensor, v.channel))

    def of(self, check: str) -> list[Verdict]:
        return self.by_check.get(check, [])

    def first(self, check: str) -> Verdict | None:
        """The check's only (or first) finding; None when it found nothing or has not run."""
        found = self.by_check.get(check)
        return found[0] if found else None


@dataclass
class Evidence:
    """One run's evidence. ``cfg`` is None for a remote monitor that sees only the diagnostics stream:
    ``known`` is then False, sensors are known by name only and the cross-source checks have nothing to
    work on (``config`` is then the default config, with no sensors)."""

    cfg: Config | None
    series: Series
    channels: dict[tuple[str, str], ChannelStats]
    twist: TwistStats
    tilt: TiltStats
    stats: dict[str, dict] | None = None  # per sensor {"received", "applied", "late", "dropped": {reason: n}}
    at_cap: bool = False  # the covariance sat at its cap at the end
    covariance_resets: int = 0
    # what the core estimated of the robot (e.g. wheel_scale; twist_pitch once estimated, not held)
    scales: dict[str, float] | None = None
    t0: float | None = None  # the run's first stamp: times in messages are counted from it
    clocks: ClockOffsets | None = None  # the sensors' stamp offsets measured at arrival
    repeats: dict[str, int] | None = None  # per sensor, messages that came twice, stamp and content alike
    pose_motion: PoseMotion | None = None  # the differential pose sensors' deltas in base_link's axes
    findings: Findings = field(default_factory=Findings)
    _bias_verdicts: dict[tuple[str, str], Verdict | None] = field(default_factory=dict, init=False, repr=False)

    @property
    def known(self) -> bool:
        return self.cfg is not None

    @cached_property
    def config(self) -> Config:
        return self.cfg if self.cfg is not None else Config()

    @cached_property
    def sensors(self) -> dict[str, object]:
        return {s.name: s for s in self.config.sensors}

    @cached_property
    def order(self) -> dict[str, int]:
        """A sensor's place in the config: the verdicts are listed in it."""
        return {s.name: i for i, s in enumerate(self.config.sensors)}

    @cached_property
    def odom(self) -> OdomSensor | None:
        return next((s for s in self.config.sensors if kind_of(s).drives_prediction), None)

    @cached_property
    def imu(self) -> ImuSensor | None:
        """The first configured IMU: the one the cross-source checks compare."""
        return next((s for s in self.config.sensors if kind_of(s).inertial), None)

    @cached_property
    def gps(self) -> GpsSensor | None:
        """The first configured GPS: the one the cross-source checks compare."""
        return next((s for s in self.config.sensors if kind_of(s).geodetic), None)

    @cached_property
    def gyro_fused(self) -> bool:
        return any(kind_of(s).fuses_gyro(s) for s in self.config.sensors)

    @cached_property
    def mount(self) -> MountYaw | None:
        """The mounting yaw the accelerometer measures against the wheels (None: not measurable)."""
        return mount_yaw_fit(self.series, self.imu) if self.known else None

    @cached_property
    def wheel_yaw(self) -> tuple[float, float] | None:
        """The wheels' yaw rate fitted against the gyro's: (scale, offset)."""
        return wheel_yaw_fit(self.series) if self.known else None

    @cached_property
    def odom_floored(self) -> tuple[int, float]:
        """Odometry yaw-rate samples whose stated sigma was raised to the floor, and their mean sigma."""
        s = self.series
        return (s.odom_wz_floored, s.odom_wz_floored_sigma_sum / s.odom_wz_floored if s.odom_wz_floored else math.nan)

    def active(self) -> list[tuple[tuple[str, str], ChannelStats]]:
        """The channels with updates, sorted by (sensor, channel)."""
        return [(k, ch) for k, ch in sorted(self.channels.items()) if ch.n]

    def bias_verdict(self, key: tuple[str, str]) -> Verdict | None:
        """The cross-source gyro-bias verdict with ``key``'s standstill statistics (None: not judged so)."""
        cache = self._bias_verdicts
        if key not in cache:
            cache[key] = bias_check(self.series, self.config, self.channels[key], self.gyro_fused, self.stats) if self.known else None
        return cache[key]

    def channel_imu(self, key: tuple[str, str]) -> ImuSensor:
        """The IMU behind an IMU channel: the configured one, or (a sensor known by name only) one with
        what the channel shows."""
        name, channel = key
        s = self.sensors.get(name)
        if s is not None and kind_of(s).inertial:
            return s
        if channel == "orientation":
            return ImuSensor(name=name, key=name,
                             orientation="absolute" if "yaw" in self.channels[key].components else "roll_pitch")
        return ImuSensor(name=name, key=name, angular_velocity=True)

    @cached_property
    def run_imu(self) -> ImuSensor | None:
        """The IMU the whole-run checks (lean, mounting, logging gaps, coasting) speak of: the IMU of the
        last orientation channel, or of the last gyro-bias channel judged without the cross-source series
        (sorted by sensor name); with neither, the first configured IMU. With one IMU, that IMU."""
        imu = self.imu
        for key, _ in self.active():
            if key[1] == "orientation" or (key[1] == "gyro_bias" and self.bias_verdict(key) is None):
                imu = self.channel_imu(key)
        return imu

    @cached_property
    def gyro_bias_stats(self) -> ChannelStats | None:
        """The first gyro-bias channel's statistics (the standstill updates), if any."""
        return self.channels.get(next(((n, c) for n, c in self.channels if c == "gyro_bias"), ("", "")))

    @cached_property
    def standstill_updates(self) -> int:
        return sum(ch.n for (_, c), ch in self.channels.items() if c == "gyro_bias")
