"""The GPS's descriptor (``SensorKind``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from ....config_tables import FilterConfig
from ....errors import ConfigError
from ..kind import LayoutView, ModelIn, SensorKind
from ..tunable import Param
from .sample import GpsSample
from .table import GpsSensor
from .tunables import difference_variance, gps_tunables, slow_errors

if TYPE_CHECKING:
    from ....codecs.kind_codec import KindCodec
    from ....estimator import StateBlock


class GpsKind(SensorKind):
    """A NavSatFix receiver: it defines the world frame (ENU at its datum), its heading is measured
    from travel, and its receiver's slowly wandering error is a state block of its own."""

    name = "gps"
    config_type = GpsSensor
    sample_type = GpsSample
    model_type = ModelIn(f"{__package__}.model", "GpsModel")
    ros_types = ("sensor_msgs/msg/NavSatFix",)
    geodetic = True
    frame_message = "GPS fix"
    measures_position = True

    def validate(self, cfg: GpsSensor, at: Callable[[str], str]) -> None:
        if cfg.datum is not None and not (-90.0 <= cfg.datum[0] <= 90.0 and -180.0 <= cfg.datum[1] <= 180.0):
            raise ConfigError(f"{at('datum')}: latitude must be in [-90, 90] and longitude in [-180, 180]")
        if not 0.0 <= cfg.step_false_alarm < 1.0:
            raise ConfigError(f"{at('step_false_alarm')}: must be in [0, 1)")
        if cfg.heading_init_m <= 0.0:
            raise ConfigError(f"{at('heading_init_m')}: must be positive")
        if cfg.error_tau_s > 0.0 and cfg.error_sigma is None:
            raise ConfigError(f"{at('error_sigma')}: needed when error_tau_s > 0")
        if cfg.vertical_error_sigma > 0.0 and cfg.vertical_error_tau_s <= 0.0:
            raise ConfigError(f"{at('vertical_error_tau_s')}: must be positive when vertical_error_sigma > 0")

    def defines_frame(self, cfg: GpsSensor) -> bool:
        return True

    def fuses_height(self, cfg: GpsSensor, filter_cfg: FilterConfig) -> bool:
        return cfg.position_noise is None or cfg.position_noise[2] <= cfg.max_sigma

    def height_wander(self, cfg: GpsSensor) -> bool:
        if cfg.error_tau_s > 0.0 and cfg.error_sigma is not None:
            return cfg.error_sigma[2] > 0.0
        return cfg.vertical_error_sigma > 0.0

    def state_blocks(self, cfg: GpsSensor, view: LayoutView) -> list[StateBlock]:
        # numeric code: imported when a filter is built, not when a config is loaded (ModelIn)
        from ....estimator import GpsErrorBlock

        if cfg.error_tau_s > 0.0 and cfg.error_sigma is not None:
            return [GpsErrorBlock(cfg.error_tau_s, cfg.error_sigma)]
        if cfg.vertical_error_sigma > 0.0:  # the altitude's wander alone
            return [GpsErrorBlock(cfg.vertical_error_tau_s, (0.0, 0.0, cfg.vertical_error_sigma))]
        return []

    def datum(self, cfg: GpsSensor) -> tuple[float, float, float] | None:
        return cfg.datum

    def tunables(self, cfg: GpsSensor, samples: Sequence[object]) -> list[Param]:
        return gps_tunables(cfg, samples)

    def slow_errors(self, cfg: GpsSensor, span: float) -> dict[str, float]:
        return slow_errors(cfg, span)

    def difference_variance(self, cfg: GpsSensor, dt: float) -> list[float]:
        return difference_variance(cfg, dt)

    def codec(self) -> "KindCodec":
        from .codec import CODEC

        return CODEC


__all__ = ["GpsKind"]
