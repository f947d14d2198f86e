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

from ..config import Config, GpsSensor, ImuSensor, OdomSensor, PoseSensor
from ..estimator import (
    GpsErrorBlock, GyroBiasBlock, GyroScaleBlock, PoseBlock, StateLayout, TwistPitchBlock, WheelScaleBlock,
    YawOffsetBlock,
)


def absolute_sensor(sc) -> bool:
    """Does this sensor define the world frame (a GPS, or a pose that is not differential)?"""
    return isinstance(sc, GpsSensor) or (isinstance(sc, PoseSensor) and not sc.differential)


def fuses_height(cfg: Config, sensor) -> bool:
    """Does this sensor's absolute height reach the filter (a GPS altitude, an absolute pose's z, whose
    stated noise is not beyond its max_sigma), outside two_d_mode?"""
    if cfg.filter.two_d_mode:
        return False
    if isinstance(sensor, GpsSensor):
        return sensor.position_noise is None or sensor.position_noise[2] <= sensor.max_sigma
    if isinstance(sensor, PoseSensor) and not sensor.differential:
        return sensor.position_noise is None or sensor.position_noise[2] <= sensor.max_sigma[0]
    return False


def absolute_height(cfg: Config) -> bool:
    """Is an absolute height fused by any sensor (``fuses_height``)?"""
    return any(fuses_height(cfg, s) for s in cfg.sensors)


def state_layout(cfg: Config) -> StateLayout:
    """The error-state blocks this configuration's sensors need, in a fixed order."""
    fc = cfg.filter
    sensors = cfg.sensors
    blocks = [PoseBlock(fc.initial_sigma[0], fc.initial_sigma[1])]
    if any(isinstance(s, ImuSensor) and s.angular_velocity for s in sensors):
        blocks.append(GyroBiasBlock(fc.gyro_bias_sigma, fc.gyro_bias_walk))
    if any(isinstance(s, ImuSensor) and s.gyro_scale_estimation for s in sensors):
        blocks.append(GyroScaleBlock(fc.gyro_scale_sigma, fc.gyro_scale_walk))
    # A wheel scale is observable once an absolute position is fused: on by default there.
    absolute = any(absolute_sensor(s) for s in sensors)
    if any(isinstance(s, OdomSensor) and (s.scale_estimation or (s.scale_estimation is None and absolute))
           for s in sensors):
        blocks.append(WheelScaleBlock(fc.wheel_scale_sigma, fc.wheel_scale_walk))
    # The twist's pitch in the body is observable from an absolute height while moving. Not on by default:
    # over a short drive it is confounded with the altitude's wander, and an error model that calls a slow
    # wander white (error_tau_s of seconds) lets it take the wander for a slope and z follow it.
    if absolute_height(cfg) and any(isinstance(s, OdomSensor) and s.twist_frame == "body" and s.pitch_estimation
                                    for s in sensors):
        blocks.append(TwistPitchBlock(fc.twist_pitch_sigma, fc.twist_pitch_walk))
    # An absolute IMU yaw beside an absolute position or pose: heading + an estimated offset.
    yaw_imu = next((s for s in sensors if isinstance(s, ImuSensor) and s.orientation == "absolute"
                    and s.yaw_offset_sigma > 0.0), None)
    if yaw_imu is not None and absolute:
        blocks.append(YawOffsetBlock(yaw_imu.yaw_offset_sigma, yaw_imu.yaw_offset_walk))
    for sc in sensors:  # at most one GPS (it defines the world frame)
        if isinstance(sc, GpsSensor) and sc.error_tau_s > 0.0 and sc.error_sigma is not None:
            blocks.append(GpsErrorBlock(sc.error_tau_s, sc.error_sigma))
        elif isinstance(sc, GpsSensor) and sc.vertical_error_sigma > 0.0:  # the altitude's wander alone
            blocks.append(GpsErrorBlock(sc.vertical_error_tau_s, (0.0, 0.0, sc.vertical_error_sigma)))
    return StateLayout(blocks)


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


__all__ = ["UpdateMasks", "absolute_height", "absolute_sensor", "fuses_height", "state_layout", "update_masks"]
