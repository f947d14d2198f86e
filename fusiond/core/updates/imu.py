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
        rpy = inp.rpy
        if not s.attitude_ready:
            initialise_attitude(core, s, rpy, cfg.orientation == "absolute")
        if cfg.orientation == "relative":
            off = s.yaw_offset.get(cfg.name)
            if off is None:
                off = rot.wrap(rpy[2] - rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2])
                s.yaw_offset[cfg.name] = off
            rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] - off))
        y, H, R = obs.orientation(core.layout, s.ekf.x, rpy, inp.rpy_cov, inp.rows)
        scale = adaptive_scale(core, s, cfg, "orientation")
        tilt_only = 2 not in inp.rows
        if tilt_only:
            heading = rot.yaw(tuple(s.ekf.x[3:7].tolist()))
        res = s.ekf.update(y, H, R * scale if scale != 1.0 else R, cfg.mahalanobis_threshold,
                           core.tilt_mask if tilt_only else None)
        if tilt_only and not res.rejected:
            # A world-x/y correction of a tilted body still turns its Euler yaw a little
            # (second order); a rotation about world z puts the heading back exactly and
            # leaves roll and pitch as the update set them.
            q = tuple(s.ekf.x[3:7].tolist())
            s.ekf.x[3:7] = rot.mul(rot.exp(0.0, 0.0, rot.wrap(heading - rot.yaw(q))), q)
        if cfg.adaptive:
            adapt(core, s, cfg, "orientation", res.nis, len(inp.rows))
        if emit:
            records.append(DiagnosticsRecord(stamp, cfg.name, [obs.RPY_NAMES[i] for i in inp.rows], y.tolist(),
                                             res.innovation_var, res.nis, len(inp.rows), res.rejected,
                                             channel="orientation", late=late))
    return records


def initialise_attitude(core: "FusionCore", s: FilterState, rpy: tuple[float, float, float], with_yaw: bool) -> None:
    """Take roll/pitch (and yaw when absolute) from the first orientation sample."""
    yaw = rpy[2] if with_yaw else rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2]
    s.ekf.x[3:7] = rot.from_rpy(rpy[0], rpy[1], yaw)
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
