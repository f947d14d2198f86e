"""What each kind of sensor does to the filter state: one module per kind.

Each kind is a ``SensorKind``: the policy that turns its raw sample into filter input
(``core/sensors.py``), the sample type, ``apply`` (what an applied sample does: takes the
core for its layout, masks and config, the state, the sensor index, the input and its
stamp; returns the diagnostics records of its updates), and optional hooks for the
kind's own bookkeeping in the filter state: ``on_start`` (a fresh state) and
``on_predict`` (each prediction step, old and new nominal state). The core's time
handling knows none of them: adding a kind is a new module here, its policy and its
config table.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ...config import GpsSensor, ImuSensor, OdomSensor, PoseSensor
from ...samples import GpsSample, ImuSample, OdomSample, PoseSample
from ..sensors import GpsPolicy, ImuPolicy, OdomPolicy, PosePolicy
from . import gps, pose
from .gps import apply_gps
from .imu import apply_imu
from .odom import apply_odom
from .pose import accumulate_motion, apply_pose


@dataclass(frozen=True, slots=True)
class SensorKind:
    policy: type
    sample: type
    apply: Callable[..., list]
    on_start: Callable[[Any, Any], None] | None = None
    on_predict: Callable[[Any, Any, Any], None] | None = None


KINDS: dict[type, SensorKind] = {
    OdomSensor: SensorKind(OdomPolicy, OdomSample, apply_odom),
    ImuSensor: SensorKind(ImuPolicy, ImuSample, apply_imu),
    GpsSensor: SensorKind(GpsPolicy, GpsSample, apply_gps, gps.on_start, gps.on_predict),
    PoseSensor: SensorKind(PosePolicy, PoseSample, apply_pose, pose.on_start, pose.on_predict),
}

__all__ = ["KINDS", "SensorKind", "accumulate_motion", "apply_gps", "apply_imu", "apply_odom", "apply_pose"]
