"""A toy sensor kind, whole in this one module: a range-to-ground altimeter that measures the base's
height z in the world frame (a downward sonar or lidar over flat ground, mounted at base_link).

It is what a new kind takes: its [[sensors]] table, its sample, its policy and model, its wire
formats (a ``KindCodec``: ROS 2 CDR, JSON, msgpack) and its descriptor; ``register(AltimeterKind())``
makes config loading, the fusion core, the decoders, the encoders and the bag replay accept it
(tests/sensors/test_toy_kind.py).
"""

from __future__ import annotations

import math
from typing import Any

import msgspec
import numpy as np

from fusiond import reasons
from fusiond.config import FilterConfig, SensorTable
from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.core.sensors import Rejected, SensorKind, SensorModel

RANGE = "sensor_msgs/msg/Range"


class AltimeterSensor(SensorTable, tag="altimeter"):
    """[[sensors]] kind = "altimeter": sensor_msgs/msg/Range read as the base's height."""

    range_sigma: float = 0.05  # std dev of one reading, m
    mahalanobis_threshold: float = math.inf


class AltimeterSample(msgspec.Struct, gc=False):
    sensor: str
    stamp: float
    height: float  # m


class AltimeterPolicy:
    """Sample -> height; a reading that is not finite is refused."""

    def __init__(self, cfg: AltimeterSensor) -> None:
        self.cfg = cfg

    def convert(self, sample: AltimeterSample) -> float:
        if not math.isfinite(sample.height):
            raise Rejected(reasons.NON_FINITE, "height")
        return sample.height


class AltimeterModel(SensorModel):
    """One scalar update of z with the configured noise."""

    config_type = AltimeterSensor
    sample_type = AltimeterSample
    policy_type = AltimeterPolicy

    def apply(self, s: Any, inp: float, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        layout, ekf = self.ctx.layout, s.ekf
        H = np.zeros((1, layout.error_dim))
        H[0, layout.index("pose", 2, error=True)] = 1.0
        y = np.array([inp - float(ekf.x[layout.index("pose", 2)])])
        res = ekf.update(y, H, np.array([[self.cfg.range_sigma ** 2]]), self.cfg.mahalanobis_threshold)
        if not emit:
            return []
        return [self.record(stamp, ["z"], y.tolist(), res.innovation_var, res.nis, 1, res.rejected, "height", late)]


def altimeter_from_ros(msg: Any, sensor: str) -> AltimeterSample:
    stamp = msg.header.stamp
    return AltimeterSample(sensor, stamp.sec + stamp.nanosec * 1e-9, float(msg.range))


class AltimeterMessage(msgspec.Struct, kw_only=True):
    """A reading on a `json` or `msgpack` key: `stamp` s, `height` m."""

    stamp: float
    height: float


def altimeter_from_message(m: AltimeterMessage, sensor: str) -> AltimeterSample:
    return AltimeterSample(sensor, m.stamp, m.height)


def encode_altimeter_sample(sample: AltimeterSample, encoding: str, msgtype: str = RANGE) -> bytes:
    """A reading as its sensor publishes it: sensor_msgs/msg/Range (frame sonar) or the Struct."""
    from fusiond.codecs import typestore
    from fusiond.codecs.json_msgpack import encode_structured

    if encoding != "ros2-cdr":
        return encode_structured(AltimeterMessage(stamp=sample.stamp, height=sample.height), encoding)
    ts = typestore()
    Range, Header, Time = (ts.types[t] for t in (RANGE, "std_msgs/msg/Header", "builtin_interfaces/msg/Time"))
    sec = int(sample.stamp)
    msg = Range(Header(Time(sec, int(round((sample.stamp - sec) * 1e9))), "sonar"), 0, 0.1, 0.05, 10.0,
                sample.height)
    return bytes(ts.serialize_cdr(msg, RANGE))


class AltimeterKind(SensorKind):
    name = "altimeter"
    config_type = AltimeterSensor
    sample_type = AltimeterSample
    model_type = AltimeterModel
    ros_types = (RANGE,)

    def fuses_height(self, cfg: AltimeterSensor, filter_cfg: FilterConfig) -> bool:
        return True

    def noise_key(self, cfg: AltimeterSensor, channel: str) -> str | None:
        return "range_sigma" if channel == "height" else None

    def codec(self) -> Any:
        """Its wire formats: ROS 2 CDR of a Range, JSON and msgpack of ``AltimeterMessage``. The codecs
        are imported here, when a decoder is first asked for, never when the kind loads."""
        from fusiond.codecs import KindCodec

        return KindCodec(self.name, AltimeterSample, self.ros_types, altimeter_from_ros, encode_altimeter_sample,
                         AltimeterMessage, altimeter_from_message, zero=AltimeterSample("", 0.0, 0.0))


__all__ = ["RANGE", "AltimeterKind", "AltimeterMessage", "AltimeterModel", "AltimeterPolicy", "AltimeterSample", "AltimeterSensor", "encode_altimeter_sample"]
