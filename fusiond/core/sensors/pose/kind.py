"""The pose sensor's descriptor (``SensorKind``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from ....config_tables import FilterConfig
from ....samples import PoseSample
from ..kind import SensorKind
from ..tunable import Param
from .model import PoseModel
from .table import POSE_MSGTYPES, PoseSensor
from .tunables import pose_tunables


class PoseKind(SensorKind):
    """An absolute pose (visual odometry, motion capture) defines the world frame and gives position,
    height, tilt and yaw; a differential one fuses deltas between its poses and defines nothing."""

    name = "pose"
    config_type = PoseSensor
    sample_type = PoseSample
    model_type = PoseModel
    ros_types = POSE_MSGTYPES
    frame_message = "pose"
    measures_position = True

    def defines_frame(self, cfg: PoseSensor) -> bool:
        return not cfg.differential

    def fuses_height(self, cfg: PoseSensor, filter_cfg: FilterConfig) -> bool:
        return not cfg.differential and (cfg.position_noise is None or cfg.position_noise[2] <= cfg.max_sigma[0])

    def ros_type(self, cfg: PoseSensor) -> str:
        return cfg.msgtype  # a CDR payload does not say which of the pose types it is

    def tunables(self, cfg: PoseSensor, samples: Sequence[object]) -> list[Param]:
        return pose_tunables(cfg, samples)

    def from_ros(self) -> Callable[[Any, str], Any]:
        from ....codecs.from_ros import pose_from_ros

        return pose_from_ros

    def decoder(self, cfg: PoseSensor) -> Callable[[Any], Any]:
        from ....codecs.decoders import make_decoder

        return make_decoder(self.name, cfg.encoding, cfg.name, msgtype=cfg.msgtype)


__all__ = ["PoseKind"]
