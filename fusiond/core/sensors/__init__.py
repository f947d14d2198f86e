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

from ...lazy_exports import lazy_exports
from .base import SensorContext, SensorModel
from .checks import Rejected
from .formats import codec_named, codec_of, encode_sample, make_decoder
from .gps import GpsKind, GpsSample, GpsSensor
from .imu import ImuKind, ImuSample, ImuSensor
from .kind import LayoutView, ModelIn, SensorKind
from .odom import OdomKind, OdomSample, OdomSensor
from .pose import POSE_MSGTYPES, PoseKind, PoseSample, PoseSensor
from .registry import (ENTRY_POINT_GROUP, KINDS, config_types, discover, kind_named, kind_of, kind_reading, register,
                       require, unregister)

# the kinds' models and what they define need numpy and the estimator: imported when first read, so that
# a config loads without them (``kind.ModelIn``)
_EXPORTS = {
    "GpsInput": "gps", "GpsModel": "gps", "GpsPolicy": "gps",
    "ImuInput": "imu", "ImuModel": "imu", "ImuPolicy": "imu", "quiet_bound": "imu",
    "OdomInput": "odom", "OdomModel": "odom", "OdomPolicy": "odom",
    "PoseInput": "pose", "PoseModel": "pose", "PosePolicy": "pose",
}
_, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)


def build_models(sensors: list, ctx: SensorContext) -> list[SensorModel]:
    """One model per configured sensor, in configuration order (their index in the state)."""
    return [kind_of(cfg).model_type(cfg, i, ctx) for i, cfg in enumerate(sensors)]


__all__ = sorted([
    "ENTRY_POINT_GROUP", "KINDS", "POSE_MSGTYPES", "GpsKind", "GpsSample", "GpsSensor", "ImuKind", "ImuSample",
    "ImuSensor", "LayoutView", "ModelIn", "OdomKind", "OdomSample", "OdomSensor", "PoseKind", "PoseSample",
    "PoseSensor", "Rejected", "SensorContext", "SensorKind", "SensorModel", "build_models", "codec_named",
    "codec_of", "config_types", "discover", "encode_sample", "kind_named", "kind_of", "kind_reading",
    "make_decoder", "register", "require", "unregister", *_EXPORTS,
])
