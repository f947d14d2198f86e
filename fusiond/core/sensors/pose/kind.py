"""The pose sensor's descriptor (``SensorKind``)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from ....config_tables import FilterConfig
from ..kind import ModelIn, SensorKind
from ..tunable import Param
from .sample import PoseSample
from .table import POSE_MSGTYPES, PoseSensor
from .tunables import pose_tunables

if TYPE_CHECKING:
    from ....codecs.kind_codec import KindCodec


class PoseKind(SensorKind):
    """An absolute pose (visual odometry, motion capture) defines the world frame and gives position,
    height, tilt and yaw; a differential one fuses deltas between its poses and defines nothing."""

    name = "pose"
    config_type = PoseSensor
    sample_type = PoseSample
    model_type = ModelIn(f"{__package__}.model", "PoseModel")
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

    def codec(self) -> "KindCodec":
        from .codec import CODEC

        return CODEC
