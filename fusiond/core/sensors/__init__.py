"""Sensor kinds: one module each, every one a ``SensorModel`` (``base.py``).

A model is built once per configured sensor from its typed config table and a narrow
``SensorContext``; it converts raw samples into filter input (its policy: floors,
overrides, "not measured" rules, mounting rotations) and applies them to the filter
state through the EKF's own methods, keeping what it must remember between messages in
its own immutable slice of the state (``FilterState.own[index]``). The core's time
handling knows none of them: adding a kind is a new module here (or a package, as ``imu/``
with its gyro-bias learning and gap turn), its config table, and a line in ``MODELS``.
"""

from __future__ import annotations

from ...config import GpsSensor, ImuSensor, OdomSensor, PoseSensor
from .base import SensorContext, SensorModel
from .checks import Rejected
from .gps import GpsInput, GpsModel, GpsPolicy
from .imu import ImuInput, ImuModel, ImuPolicy, quiet_bound
from .odom import OdomInput, OdomModel, OdomPolicy
from .pose import PoseInput, PoseModel, PosePolicy

MODELS: dict[type, type[SensorModel]] = {
    OdomSensor: OdomModel,
    ImuSensor: ImuModel,
    GpsSensor: GpsModel,
    PoseSensor: PoseModel,
}


def build_models(sensors: list, ctx: SensorContext) -> list[SensorModel]:
    """One model per configured sensor, in configuration order (their index in the state)."""
    return [MODELS[type(cfg)](cfg, i, ctx) for i, cfg in enumerate(sensors)]


__all__ = [
    "MODELS", "GpsInput", "GpsModel", "GpsPolicy", "ImuInput", "ImuModel", "ImuPolicy", "OdomInput", "OdomModel",
    "OdomPolicy", "PoseInput", "PoseModel", "PosePolicy", "Rejected", "SensorContext", "SensorModel", "build_models",
    "quiet_bound",
]
