"""The interface every sensor kind implements, and the narrow view of the core it is given.

A sensor model is built once per configured sensor from its typed config table and a
``SensorContext``. It turns a raw sample into filter input (``convert``, through its
policy: floors, overrides, "not measured" rules) and says what an applied input does to
the filter state (``apply``): updates through the EKF's own methods, the held motion
inputs, and its own slice of per-sensor state (``s.own[index]``: small and immutable, so
a history snapshot copies a reference). It never sees the core itself: the context holds
the state layout, the masks an update may need, a few flags, and three queries (a sensor's
timeout, the motion inputs held now, the forward acceleration). Time, ordering, late data, counters and the
consistency windows stay with the core.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

from ...config_tables import FilterConfig
from ..diagnostics import DiagnosticsRecord

if TYPE_CHECKING:
    import numpy as np

    from ...estimator import MotionInput, StateLayout
    from ..state import FilterState


class SensorContext:
    """What a sensor model may know of the core: the layout, masks and flags fixed at start-up,
    and three queries about held inputs. ``tilt_reference`` is set once every model exists (it
    asks the models whether they give roll/pitch)."""

    __slots__ = ("layout", "filter", "two_d", "tilt_reference", "absolute_yaw", "odom_index", "track_acceleration",
                 "tilt_mask", "position_mask", "delta_mask", "rest_mask", "timeout", "inputs_at", "forward_accel")

    def __init__(self, layout: "StateLayout", filter_cfg: FilterConfig, *, two_d: bool, absolute_yaw: bool,
                 odom_index: int, track_acceleration: bool, tilt_mask: np.ndarray, position_mask: np.ndarray,
                 delta_mask: np.ndarray | None, rest_mask: np.ndarray | None = None,
                 timeout: Callable[[int, "FilterState"], float],
                 inputs_at: Callable[["FilterState"], "MotionInput"],
                 forward_accel: Callable[["FilterState"], float]) -> None:
        self.layout = layout
        self.filter = filter_cfg
        self.two_d = two_d
        self.tilt_reference = False
        self.absolute_yaw = absolute_yaw  # an IMU gives absolute yaw (trusted as heading unless offset-estimated)
        self.odom_index = odom_index  # the odometry sensor, -1 if none
        # some IMU takes roll/pitch from gravity: the odometry keeps the forward acceleration for it
        self.track_acceleration = track_acceleration
        # A roll/pitch-only update may correct roll, pitch and the x/y gyro bias, never position,
        # heading, the z bias or a scale (which drive heading and position).
        self.tilt_mask = tilt_mask
        # While the GPS heading is unknown a fix may only move position.
        self.position_mask = position_mask
        # A pose delta beside an absolute sensor corrects tilt, biases and scales only (None: all).
        self.delta_mask = delta_mask
        # A standstill's bias update with nothing observing heading: biases and tilt only (None: all).
        self.rest_mask = rest_mask
        self.timeout = timeout  # (sensor index, state) -> how long that sensor's input is held
        self.inputs_at = inputs_at  # state -> the motion inputs held at its time
        # state -> the forward acceleration now (m/s^2; NaN while it changes too fast to know, 0.0 untracked)
        self.forward_accel = forward_accel


class SensorModel:
    """One configured sensor: its policy (raw sample -> input) and what its input does to the state.

    Subclasses set the class attributes and implement ``apply``; the hooks are optional.
    """

    config_type: ClassVar[type]  # the config table this kind is built from
    sample_type: ClassVar[type]  # the sample the transports decode for it
    policy_type: ClassVar[type]  # raw sample -> input, or Rejected
    predicts: ClassVar[bool] = False  # has an ``on_predict`` hook (called on every prediction step)
    shows_position: ClassVar[bool] = False  # has a ``shown_position`` hook (asked at every published pose)
    # the channels whose record says the sample, though applied, measured nothing (a receiver repeating its last
    # fix): such a sample is no sign of the sensor's life (``Step.measured``, the service's liveness)
    unmeasured: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, cfg: Any, index: int, ctx: SensorContext) -> None:
        self.cfg = cfg
        self.index = index
        self.name: str = cfg.name
        self.ctx = ctx
        self.policy = self.policy_type(cfg)
        self.convert = self.policy.convert  # sample -> input (raises Rejected)

    @property
    def gives_tilt(self) -> bool:
        """Can this sensor's messages constrain roll/pitch?"""
        return False

    def planar(self) -> None:
        """Two-D mode: z, roll and pitch are held at 0; stop offering what cannot be fused."""

    def on_start(self, s: "FilterState") -> None:
        """A fresh state: put this sensor's slice (``s.own[self.index]``, None by default) in place."""

    def on_predict(self, s: "FilterState", x0: np.ndarray, x1: np.ndarray) -> tuple[float, float, float] | None:
        """One prediction step moved the nominal state from x0 to x1 (only when ``predicts``). Returns
        a horizontal position covariance (m^2: xx, xy, yy) to add for that step, what the linearised
        motion model leaves out of it, or None."""
        return None

    def lost_components(self, s: "FilterState") -> tuple[str, ...]:
        """The components of its measurement the filter found at run time not to be measurements (a rate a
        driver fills in: the odometry's ``lost_channel``), as ``twist_measured`` names them; none by default."""
        return ()

    def estimated_keys(self, s: "FilterState") -> dict[str, float]:
        """This sensor's config keys whose value the filter estimated, each as the key would state it
        (its own sign and convention: pasted, it says what the filter learned); empty by default."""
        return {}

    def shown_position(self, s: "FilterState") -> tuple[float, float] | None:
        """The horizontal position to publish instead of the state's (only when ``shows_position``), or
        None: the state's. For a sensor whose frame leaves the state's position a device of the
        computation for a while (the GPS while the heading is searched for)."""
        return None

    def shown_origin(self, s: "FilterState") -> tuple[float, float] | None:
        """While ``shown_position`` is not None: the horizontal position the state's is dead-reckoned from
        along a heading not yet found (the smoother turns that displacement once it is), or None."""
        return None

    def apply(self, s: "FilterState", inp: Any, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        """What an applied input does to state s at ``stamp`` (already predicted there). Returns the
        diagnostics records of its updates when ``emit`` (a re-application after late data does
        not emit)."""
        raise NotImplementedError

    def record(self, stamp: float, components: list[str], residual: list[float], variance: list[float], nis: float,
               dof: int, rejected: bool, channel: str, late: bool, learning: bool = False) -> DiagnosticsRecord:
        """A diagnostics record of one of this sensor's updates."""
        return DiagnosticsRecord(stamp, self.name, components, residual, variance, nis, dof, rejected,
                                 channel=channel, late=late, learning=learning)


__all__ = ["SensorContext", "SensorModel"]
