"""The odometry's descriptor (``SensorKind``)."""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from ..kind import LayoutView, ModelIn, SensorKind
from ..tunable import Param
from .sample import OdomSample
from .table import OdomSensor
from .tunables import odom_tunables

if TYPE_CHECKING:
    from ....codecs.kind_codec import KindCodec
    from ....estimator import StateBlock


class OdomKind(SensorKind):
    """Wheel odometry: the motion input that drives the prediction; its messages prompt a publish.

    Its wheel speed scale becomes observable once something defines the world frame (on by default
    there), and the twist's pitch in the body once an absolute height is fused (opt-in)."""

    name = "odom"
    config_type = OdomSensor
    sample_type = OdomSample
    model_type = ModelIn(f"{__package__}.model", "OdomModel")
    ros_types = ("nav_msgs/msg/Odometry",)
    drives_prediction = True
    prompts_publish = True

    def state_blocks(self, cfg: OdomSensor, view: LayoutView) -> list[StateBlock]:
        # numeric code: imported when a filter is built, not when a config is loaded (ModelIn)
        from ....estimator import TwistPitchBlock, WheelScaleBlock

        fc = view.filter
        blocks: list[StateBlock] = []
        if cfg.scale_estimation or (cfg.scale_estimation is None and view.absolute):
            blocks.append(WheelScaleBlock(fc.wheel_scale_sigma, fc.wheel_scale_walk))
        # Not free from the start by default: over a short drive the twist's pitch is confounded with the
        # altitude's wander, and an error model that calls a slow wander white lets it take the wander for a
        # slope. "auto" holds it at the mount as configured (no variance, no walk: a rigid mount) until the
        # wander state holds a height its model refutes (``TwistPitchBlock.release_sigma``).
        if view.absolute_height and cfg.twist_frame == "body" and cfg.pitch_estimation is True:
            blocks.append(TwistPitchBlock(fc.twist_pitch_sigma, fc.twist_pitch_walk))
        elif view.height_wander and cfg.twist_frame == "body" and cfg.pitch_estimation == "auto":
            blocks.append(TwistPitchBlock(0.0, 0.0, release_sigma=fc.twist_pitch_sigma))
        return blocks

    def idle_keys(self, cfg: OdomSensor, view: LayoutView) -> list[tuple[str, str]]:
        if cfg.pitch_estimation is not True or (view.absolute_height and cfg.twist_frame == "body"):
            return []
        if view.filter.two_d_mode:
            why = "two_d_mode holds the pitch at 0"
        elif cfg.twist_frame != "body":
            why = "the twist is in the driver's world frame (twist_frame = \"world\"), turned by its own pose"
        else:
            why = "no sensor fuses an absolute height (a GPS altitude, an absolute pose's z) to observe it"
        return [("pitch_estimation", why + ": the twist's pitch is not estimated")]

    def tunables(self, cfg: OdomSensor, samples: Sequence[object]) -> list[Param]:
        return odom_tunables(cfg, samples)

    def codec(self) -> "KindCodec":
        from .codec import CODEC

        return CODEC

    def zero_covariance(self, cfg: OdomSensor) -> Callable[[Any], bool] | None:
        if cfg.twist_noise is not None:
            return None
        variances = operator.itemgetter(0, 7, 14, 21, 28, 35)  # the diagonal of the 6x6
        return lambda s: 0.0 in variances(s.twist_covariance)


__all__ = ["OdomKind"]
