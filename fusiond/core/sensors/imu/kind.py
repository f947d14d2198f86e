"""The IMU's descriptor: its gyro brings a bias (and, opted in, a yaw-rate scale), an absolute yaw
beside a world frame an estimated offset, and an orientation read from gravity needs the odometry's
forward acceleration."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from ....errors import ConfigError
from ..kind import LayoutView, ModelIn, SensorKind
from ..tunable import Param
from .sample import ImuSample
from .table import ImuSensor
from .tunables import imu_tunables

if TYPE_CHECKING:
    from ....codecs.kind_codec import KindCodec
    from ....estimator import StateBlock


class ImuKind(SensorKind):
    """An IMU: orientation (roll/pitch, optionally yaw) as updates, its gyro as a motion input."""

    name = "imu"
    config_type = ImuSensor
    sample_type = ImuSample
    model_type = ModelIn(f"{__package__}.model", "ImuModel")
    ros_types = ("sensor_msgs/msg/Imu",)
    inertial = True

    def validate(self, cfg: ImuSensor, at: Callable[[str], str]) -> None:
        if cfg.gyro_scale_estimation and not cfg.angular_velocity:
            raise ConfigError(f"{at('gyro_scale_estimation')}: needs angular_velocity = true")
        if not (0.0 <= cfg.orientation_rate_hz < math.inf):
            raise ConfigError(f"{at('orientation_rate_hz')}: must be >= 0 and finite (0: every sample)")

    def fuses_yaw(self, cfg: ImuSensor) -> bool:
        return cfg.fuses_yaw

    def absolute_yaw(self, cfg: ImuSensor) -> bool:
        return cfg.absolute_yaw

    def fuses_gyro(self, cfg: ImuSensor) -> bool:
        return cfg.angular_velocity

    def tracks_acceleration(self, cfg: ImuSensor) -> bool:
        return cfg.tilt_from_gravity

    def state_blocks(self, cfg: ImuSensor, view: LayoutView) -> list[StateBlock]:
        # numeric code: imported when a filter is built, not when a config is loaded (ModelIn)
        from ....estimator import GyroBiasBlock, GyroScaleBlock, YawOffsetBlock

        fc = view.filter
        blocks: list[StateBlock] = []
        if cfg.angular_velocity:
            blocks.append(GyroBiasBlock(fc.gyro_bias_sigma, fc.gyro_bias_walk))
        if cfg.gyro_scale_estimation:
            blocks.append(GyroScaleBlock(fc.gyro_scale_sigma, fc.gyro_scale_walk))
        # An absolute yaw beside an absolute position or pose: heading + an estimated offset.
        if cfg.absolute_yaw and cfg.yaw_offset_sigma > 0.0 and view.absolute:
            blocks.append(YawOffsetBlock(cfg.yaw_offset_sigma, cfg.yaw_offset_walk))
        return blocks

    def idle_keys(self, cfg: ImuSensor, view: LayoutView) -> list[tuple[str, str]]:
        if cfg.gyro_scale_estimation and not view.heading:
            return [("gyro_scale_estimation", "nothing tells the heading (no GPS, pose or IMU yaw fused): the "
                                              "gyro's scale is in the state but nothing observes it, it stays at 1")]
        return []

    def tunables(self, cfg: ImuSensor, samples: Sequence[object]) -> list[Param]:
        return imu_tunables(cfg, samples)

    def codec(self) -> "KindCodec":
        from .codec import CODEC

        return CODEC

    def zero_covariance(self, cfg: ImuSensor) -> Callable[[Any], bool] | None:
        use_orientation = cfg.fuses_orientation and cfg.orientation_noise is None
        use_gyro = cfg.angular_velocity and cfg.gyro_noise is None
        if not (use_orientation or use_gyro):
            return None

        def check(s: Any) -> bool:
            oc, gc = s.orientation_covariance, s.angular_velocity_covariance
            if use_orientation and oc[0] != -1.0 and (oc[0] == 0.0 or oc[4] == 0.0 or oc[8] == 0.0):
                return True
            return use_gyro and gc[0] != -1.0 and (gc[0] == 0.0 or gc[4] == 0.0 or gc[8] == 0.0)

        return check


__all__ = ["ImuKind"]
