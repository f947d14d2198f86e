"""Sensor kinds: one package each (``odom/``, ``imu/``, ``gps/``, ``pose/``) with its [[sensors]]
table, its sample, its ``SensorModel`` (``base.py``) and its ``SensorKind`` descriptor (``kind.py``), registered
by its `kind` tag in ``registry.py``.

``fusiond.config`` re-exports the built-in kinds' tables. A model is built once per configured
sensor from its typed config table and a narrow ``SensorContext``; it converts raw samples into
filter input (its policy: floors, overrides, "not measured" rules, mounting rotations) and applies
them to the filter state through the EKF's own methods, keeping what it must remember between
messages in its own immutable slice of the state (``FilterState.own[index]``). The core's time
handling knows none of them, and what the rest of fusiond asks of a kind (does it define the world
frame, which state blocks, which decoder) its descriptor answers (``formats.py`` finds its wire formats by
its name or its sample's type: ``make_decoder``, ``encode_sample``): adding a kind is a new package here (or
a single module) and one ``register`` call (docs/SENSOR_KINDS.md, "Adding a sensor kind").
"""

from __future__ import annotations

from .base import SensorContext, SensorModel
from .checks import Rejected
from .formats import codec_named, codec_of, encode_sample, make_decoder
from .gps import GpsInput, GpsKind, GpsModel, GpsPolicy, GpsSample, GpsSensor
from .imu import ImuInput, ImuKind, ImuModel, ImuPolicy, ImuSample, ImuSensor, quiet_bound
from .kind import LayoutView, SensorKind
from .odom import OdomInput, OdomKind, OdomModel, OdomPolicy, OdomSample, OdomSensor
from .pose import POSE_MSGTYPES, PoseInput, PoseKind, PoseModel, PosePolicy, PoseSample, PoseSensor
from .registry import (ENTRY_POINT_GROUP, KINDS, config_types, discover, kind_named, kind_of, kind_reading, register,
                       require, unregister)


def build_models(sensors: list, ctx: SensorContext) -> list[SensorModel]:
    """One model per configured sensor, in configuration order (their index in the state)."""
    return [kind_of(cfg).model_type(cfg, i, ctx) for i, cfg in enumerate(sensors)]


__all__ = [
    "ENTRY_POINT_GROUP", "KINDS", "POSE_MSGTYPES", "GpsInput", "GpsKind", "GpsModel", "GpsPolicy", "GpsSample", "GpsSensor", "ImuInput", "ImuKind",
    "ImuModel", "ImuPolicy", "ImuSample", "ImuSensor", "LayoutView", "OdomInput", "OdomKind", "OdomModel", "OdomPolicy",
    "OdomSample", "OdomSensor", "PoseInput", "PoseKind", "PoseModel", "PosePolicy", "PoseSample", "PoseSensor", "Rejected", "SensorContext",
    "SensorKind", "SensorModel", "build_models", "codec_named", "codec_of", "config_types", "discover",
    "encode_sample", "kind_named", "kind_of", "kind_reading", "make_decoder", "quiet_bound",
    "register", "require", "unregister",
]
