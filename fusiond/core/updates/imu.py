"""IMU: orientation observed as roll/pitch(/yaw) per mode; gyro as motion input; bias at rest."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ...estimator import observations as obs
from ...estimator import rotation as rot
from ..diagnostics import DiagnosticsRecord
from ...config import ImuSensor
from ..sensors import ImuInput

if TYPE_CHECKING:
    from ..fusion import FusionCore
    from ..state import FilterState

ZERO_RATE_GATE = 5.0  # sqrt(NIS) gate of the standstill bias update: a hand-turned robot is not at rest
GYRO_COMPONENTS = ["gyro_x", "gyro_y", "gyro_z"]
ADAPTIVE_MIN, ADAPTIVE_MAX = 0.1, 100.0
YAW_JUMP_GATE = 5.0  # sigma of the sample-to-sample change of an absolute yaw's residual (yaw_agrees_with_gyro)


def apply_imu(core: "FusionCore", s: FilterState, idx: int, inp: ImuInput, stamp: float, emit: bool, late: bool):
    cfg: ImuSensor = core.sensors[idx]  # type: ignore[assignment]
    records: list[DiagnosticsRecord] = []
    if inp.gyro is not None:
        s.gyro, s.gyro_cov, s.gyro_last = inp.gyro, inp.gyro_cov, (idx, stamp)
        odom = core.odom_index
        resting = (
            core.has_bias
            and s.still_since is not None
            and stamp - s.still_since >= core.cfg.filter.standstill_s
            and s.last[odom] is not None
            and stamp - s.last[odom] <= core.timeout(odom, s)
        )
        if resting:
            y, H, R = obs.zero_rate(core.layout, s.ekf.x, inp.gyro, inp.gyro_cov)
            res = s.ekf.update(y, H, R, ZERO_RATE_GATE)
            if emit:
                records.append(DiagnosticsRecord(stamp, cfg.name, GYRO_COMPONENTS, y.tolist(), res.innovation_var,
                                                 res.nis, 3, res.rejected, channel="gyro_bias", late=late))
    if inp.rpy is not None and inp.rows:
        rpy, rows = inp.rpy, inp.rows
        absolute = cfg.orientation == "absolute"
        if absolute and (cfg.yaw_offset or cfg.magnetic_declination):  # navsat_transform's convention
            rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] + cfg.yaw_offset + cfg.magnetic_declination))
        if not s.attitude_ready:
            initialise_attitude(core, s, rpy, absolute)
        if cfg.orientation == "relative":
            off = s.yaw_offset.get(cfg.name)
            if off is None:
                off = rot.wrap(rpy[2] - rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2])
                s.yaw_offset[cfg.name] = off
            rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] - off))
        offset = absolute and core.layout.has("yaw_offset")
        if offset and 2 in rows:
            jump, allowed = yaw_jump(core, s, cfg, rpy[2], inp.rpy_cov[8], stamp)
            if jump * jump > YAW_JUMP_GATE**2 * allowed:
                rows = tuple(i for i in rows if i != 2)  # this sample's yaw is not fused (counted as rejected)
                if emit:
                    records.append(DiagnosticsRecord(stamp, cfg.name, ["yaw"], [jump], [allowed], jump * jump / allowed,
                                                     1, True, channel="yaw_jump", late=late))
        if rows:
            records += _fuse_orientation(core, s, cfg, rpy, inp.rpy_cov, rows, offset, stamp, emit, late)
    return records


def _fuse_orientation(core: "FusionCore", s: FilterState, cfg: ImuSensor, rpy, cov, rows: tuple[int, ...],
                      offset: bool, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
    observe = obs.orientation_with_offset if offset else obs.orientation
    y, H, R = observe(core.layout, s.ekf.x, rpy, cov, rows)
    scale = adaptive_scale(core, s, cfg, "orientation")
    tilt_only = 2 not in rows
    if tilt_only:
        heading = rot.yaw(tuple(s.ekf.x[3:7].tolist()))
    res = s.ekf.update(y, H, R * scale if scale != 1.0 else R, cfg.mahalanobis_threshold,
                       core.tilt_mask if tilt_only else None)
    if tilt_only and not res.rejected:
        # A world-x/y correction of a tilted body still turns its Euler yaw a little
        # (second order); a rotation about world z puts the heading back exactly and
        # leaves roll and pitch as the update set them.
        q = tuple(s.ekf.x[3:7].tolist())
        s.ekf.set_attitude(rot.mul(rot.exp(0.0, 0.0, rot.wrap(heading - rot.yaw(q))), q))
    if offset and not tilt_only:
        s.yaw_offset[cfg.name + "/yaw_residual"] = _yaw_residual(core, s, rpy[2])  # after the update
    if cfg.adaptive:
        adapt(core, s, cfg, "orientation", res.nis, len(rows))
    if not emit:
        return []
    return [DiagnosticsRecord(stamp, cfg.name, [obs.RPY_NAMES[i] for i in rows], y.tolist(), res.innovation_var,
                              res.nis, len(rows), res.rejected, channel="orientation", late=late)]


def _yaw_residual(core: "FusionCore", s: FilterState, yaw: float) -> float:
    o = float(s.ekf.x[core.layout.nominal["yaw_offset"]][0])
    return rot.wrap(yaw - rot.yaw(tuple(s.ekf.x[3:7].tolist())) - o)


def yaw_jump(core: "FusionCore", s: FilterState, cfg: ImuSensor, yaw: float, var: float,
             stamp: float) -> tuple[float, float]:
    """How far the yaw reading jumped against the gyro-carried heading since the previous sample,
    and the variance the model allows that jump.

    Between two samples the filter's heading follows the gyro, so the yaw residual (reading -
    heading - offset) changes only by the reading's noise (twice) and the offset's random walk
    over the interval. A larger jump is the reading's own (a disturbance switching on, a
    magnetometer near a motor): beyond YAW_JUMP_GATE sigma that sample's yaw is not fused. The
    residual is remembered either way, so a disturbance that persists is fused from the next
    sample on, and its slow part goes into the offset.
    """
    r = _yaw_residual(core, s, yaw)
    prev = s.yaw_offset.get(cfg.name + "/yaw_residual")
    last = s.yaw_offset.get(cfg.name + "/yaw_stamp", stamp)
    s.yaw_offset[cfg.name + "/yaw_residual"] = r
    s.yaw_offset[cfg.name + "/yaw_stamp"] = stamp
    allowed = 2.0 * var + cfg.yaw_offset_walk**2 * max(stamp - last, 0.0)
    return (0.0 if prev is None else rot.wrap(r - prev)), allowed


def initialise_attitude(core: "FusionCore", s: FilterState, rpy: tuple[float, float, float], with_yaw: bool) -> None:
    """Take roll/pitch (and yaw when absolute) from the first orientation sample."""
    yaw = rpy[2] if with_yaw else rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2]
    s.ekf.set_attitude(rot.from_rpy(rpy[0], rpy[1], yaw))
    s.attitude_ready = True


def adaptive_scale(core: "FusionCore", s: FilterState, cfg: ImuSensor, channel: str) -> float:
    if not cfg.adaptive:
        return 1.0
    return s.adaptive.get(f"{cfg.name}/{channel}", [1.0, 0.0, 0])[0]


def adapt(core: "FusionCore", s: FilterState, cfg: ImuSensor, channel: str, nis: float, dof: int) -> None:
    """Window of NIS/dof; at its end R's scale moves by the window mean (bounded)."""
    if not math.isfinite(nis):
        return
    a = s.adaptive.setdefault(f"{cfg.name}/{channel}", [1.0, 0.0, 0])
    a[1] += nis / dof
    a[2] += 1
    if a[2] >= cfg.adaptive_window:
        a[0] = min(max(a[0] * (a[1] / a[2]), ADAPTIVE_MIN), ADAPTIVE_MAX)
        a[1], a[2] = 0.0, 0
