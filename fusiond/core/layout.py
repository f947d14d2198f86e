"""Which state blocks a configuration needs, and which error states each kind of update may move.

The state is sized by the sensors: a gyro brings its bias, a GPS or absolute pose makes
the wheel scale observable (on by default there), an absolute IMU yaw beside them brings
an offset, a GPS its slowly wandering error. The masks say what an update is allowed to
correct when its measurement cannot tell states apart (tilt-only, heading unknown, pose
deltas beside an absolute sensor).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config_tables import Config
from ..estimator import PoseBlock, StateBlock, StateLayout
from .sensors.kind import LayoutView
from .sensors.registry import kind_of

# The blocks' order in the state, whichever sensor asks for them first (a saved state's fingerprint
# and every index depend on it); a block a new kind brings that is not named here follows these.
BLOCK_ORDER = ("pose", "gyro_bias", "gyro_scale", "wheel_scale", "twist_pitch", "yaw_offset", "gps_error")


def absolute_sensor(sc) -> bool:
    """Does this sensor define the world frame (a GPS, or a pose that is not differential)?"""
    return kind_of(sc).defines_frame(sc)


def fuses_height(cfg: Config, sensor) -> bool:
    """Does this sensor's absolute height reach the filter (a GPS altitude, an absolute pose's z, whose
    stated noise is not beyond its max_sigma), outside two_d_mode?"""
    return not cfg.filter.two_d_mode and kind_of(sensor).fuses_height(sensor, cfg.filter)


def absolute_height(cfg: Config) -> bool:
    """Is an absolute height fused by any sensor (``fuses_height``)?"""
    return any(fuses_height(cfg, s) for s in cfg.sensors)


def layout_view(cfg: Config) -> LayoutView:
    """What each kind may know of the whole configuration (``LayoutView``)."""
    return LayoutView(cfg.filter, any(absolute_sensor(s) for s in cfg.sensors), absolute_height(cfg),
                      any(kind_of(s).heading_reference(s) for s in cfg.sensors),
                      any(fuses_height(cfg, s) and kind_of(s).height_wander(s) for s in cfg.sensors))


def idle_keys(cfg: Config) -> list[tuple[str, str, str]]:
    """(sensor, key, why) for each key the rest of the configuration leaves without effect
    (``SensorKind.idle_keys``)."""
    view = layout_view(cfg)
    return [(s.name, key, why) for s in cfg.sensors for key, why in kind_of(s).idle_keys(s, view)]


def state_blocks(cfg: Config) -> list[StateBlock]:
    """The error-state blocks this configuration's sensors ask for (``SensorKind.state_blocks``): one per
    name, the first sensor's in configuration order (at most one GPS, one absolute IMU yaw counts),
    sorted into ``BLOCK_ORDER``."""
    fc = cfg.filter
    view = layout_view(cfg)
    chosen: dict[str, StateBlock] = {}
    for s in cfg.sensors:
        for block in kind_of(s).state_blocks(s, view):
            chosen.setdefault(block.name, block)
    known = {name: i for i, name in enumerate(BLOCK_ORDER)}
    ordered = sorted(chosen.values(), key=lambda b: known.get(b.name, len(known)))  # stable: new kinds in order
    return [PoseBlock(fc.initial_sigma[0], fc.initial_sigma[1])] + ordered


def state_layout(cfg: Config) -> StateLayout:
    """The error-state blocks this configuration's sensors need, in a fixed order."""
    return StateLayout(state_blocks(cfg))


@dataclass(frozen=True, slots=True)
class UpdateMasks:
    """Boolean masks over the error state: True where an update of that kind may correct."""

    tilt: np.ndarray  # a roll/pitch-only update
    position: np.ndarray  # a GPS fix while the heading is unknown
    delta: np.ndarray | None  # a differential pose beside an absolute sensor (None: no absolute sensor)
    rest: np.ndarray | None  # a standstill's gyro-bias update while nothing observes heading (None: all)


def update_masks(layout: StateLayout, has_frame_sensor: bool, heading_observed: bool | None = None) -> UpdateMasks:
    """``heading_observed`` False: the standstill bias update is masked (``rest``); default: as
    ``has_frame_sensor``."""
    n = layout.error_dim
    # A roll/pitch-only update may correct roll, pitch and the x/y gyro bias, never
    # position, heading, the z bias or a scale (which drive heading and position).
    tilt = np.ones(n, dtype=bool)
    tilt[[0, 1, 2, 5]] = False
    if layout.has("gyro_bias"):
        tilt[layout.error["gyro_bias"].start + 2] = False
    for name in ("gyro_scale", "wheel_scale", "twist_pitch", "gps_error", "yaw_offset"):
        if layout.has(name):
            tilt[layout.error[name]] = False
    # While the GPS heading is unknown a fix may only move position: a wrong heading
    # must not be "explained" by attitude, biases or scales.
    position = np.zeros(n, dtype=bool)
    position[0:3] = True
    # A pose delta fused against the filter's previous pose acts on the absolute pose as
    # if that previous pose were exact, which collapses P of position and heading. Alone
    # that is robot_pose_ekf's behaviour; beside an absolute sensor it would lock the GPS
    # out, so there the delta may correct tilt, biases and scales only (Schmidt update).
    # The exact treatment, cloning the previous pose into the state, is not done yet.
    delta = None
    if has_frame_sensor:
        delta = np.ones(n, dtype=bool)
        delta[[0, 1, 2, 5]] = False
        for name in ("gps_error", "yaw_offset"):  # a pose delta says nothing about these
            if layout.has(name):
                delta[layout.error[name]] = False
    # A bias learned at a standstill is correlated with the heading it drifted while unknown. With
    # nothing observing heading (no GPS or absolute pose, no IMU yaw fused) and filter.continuous_odom,
    # the output frame is an odom frame, which REP-105 requires to be continuous: the bias corrects the
    # heading's rate from now on, and the heading and position the old bias bent are left where they
    # are (Schmidt update) rather than turned at once by tens of degrees. Beside a heading reference
    # the correlated correction is the right one and the update is not masked.
    heading_observed = has_frame_sensor if heading_observed is None else heading_observed
    rest = None
    if not heading_observed and layout.has("gyro_bias"):
        rest = np.ones(n, dtype=bool)
        rest[[0, 1, 2, 5]] = False
    return UpdateMasks(tilt, position, delta, rest)


__all__ = ["BLOCK_ORDER", "UpdateMasks", "absolute_height", "absolute_sensor", "fuses_height", "idle_keys",
           "layout_view", "state_blocks", "state_layout", "update_masks"]
