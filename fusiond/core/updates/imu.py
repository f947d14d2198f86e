"""IMU: orientation observed as roll/pitch(/yaw) per mode; gyro as motion input; bias at rest."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ...estimator import observations as obs
from ...estimator import mat3
from ...estimator import rotation as rot
from ..diagnostics import DiagnosticsRecord
from ...config import ImuSensor
from ..sensors import ImuInput
import structlog

log = structlog.get_logger("fusiond.core")

if TYPE_CHECKING:
    from ..fusion import FusionCore
    from ..state import FilterState

GRAVITY = 9.80665  # m/s^2, standard gravity
G_UNITS_BAND = (0.8, 1.2)  # |specific force| in this band: the accelerometer reports in g
GRAVITY_DYNAMIC_GATE = 0.5  # m/s^2: |specific force| further than this from g is not "low dynamics"
ZERO_RATE_GATE = 5.0  # sqrt(NIS) gate of a standstill bias update: a hand-turned robot is not at rest
GYRO_COMPONENTS = ("gyro_x", "gyro_y", "gyro_z")
QUIET_SIGMAS = 3.0  # at rest the gyro reads noise + bias: beyond 3 sigma of each (prior bias) it is turning
MIN_WINDOW_SAMPLES = 5  # gyro samples averaged into one standstill update, at least
BIAS_MEAN_FLOOR = 1e-4  # rad/s: the mean of a window is no better than this (quantisation, vibration)
REOPEN_AFTER = 4  # consecutive rejected windows of one axis that agree: the bias estimate is what is wrong
AGREE_SIGMAS = 4.0
LEARNING_PRIOR_RATIO = 10.0  # prior variance this many times the window's: the update learns, it does not test  # ... "agree": their spread within this many sigma of one window's mean
ADAPTIVE_MIN, ADAPTIVE_MAX = 0.1, 100.0
YAW_JUMP_GATE = 5.0  # sigma of the sample-to-sample change of an absolute yaw's residual (yaw_agrees_with_gyro)


def apply_imu(core: "FusionCore", s: FilterState, idx: int, inp: ImuInput, stamp: float, emit: bool, late: bool):
    cfg: ImuSensor = core.sensors[idx]  # type: ignore[assignment]
    records: list[DiagnosticsRecord] = []
    if inp.gyro is not None:
        s.gyro, s.gyro_cov, s.gyro_last = inp.gyro, inp.gyro_cov, (idx, stamp)
        if core.has_bias:
            records.extend(learn_bias_at_rest(core, s, cfg, inp, stamp, emit, late))
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
    if inp.accel is not None:
        records.extend(tilt_from_gravity(core, s, cfg, inp.accel, stamp, emit, late))
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
        restore_heading(s, heading)
    if not res.rejected and (0 in rows or 1 in rows):
        s.tilt_seen = stamp
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


def restore_heading(s: FilterState, heading: float) -> None:
    """After a roll/pitch-only update: a world-x/y correction of a tilted body still turns
    its Euler yaw a little (second order); a rotation about world z puts the heading back
    exactly and leaves roll and pitch as the update set them."""
    q = tuple(s.ekf.x[3:7].tolist())
    s.ekf.set_attitude(rot.mul(rot.exp(0.0, 0.0, rot.wrap(heading - rot.yaw(q))), q))


def tilt_from_gravity(core: "FusionCore", s: FilterState, cfg: ImuSensor, accel: tuple[float, float, float],
                      stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
    """Roll and pitch from the accelerometer, when the IMU gives no orientation.

    At low dynamics the accelerometer reads the specific force R^T (0, 0, g) plus the
    centripetal term w x v: that term is removed with the gyro rate and the odometry
    twist held now, and a sample whose remaining magnitude is not g (braking,
    bumps) is skipped. Without this an ``orientation = "off"`` IMU left the tilt to
    integrate the gyro's x/y bias: tens of degrees and metres of z on a flat floor.
    """
    u = core.inputs_at(s)
    wx, wy, wz = u.angular
    vx, vy, vz = u.linear
    if u.world_frame:  # the twist is in the world: into the body
        vx, vy, vz = mat3.apply_transposed(rot.matrix9(tuple(s.ekf.x[3:7].tolist())), (vx, vy, vz))
    n = math.sqrt(accel[0] ** 2 + accel[1] ** 2 + accel[2] ** 2)
    if G_UNITS_BAND[0] < n < G_UNITS_BAND[1]:  # a driver that reports in g, not m/s^2
        accel = (accel[0] * GRAVITY, accel[1] * GRAVITY, accel[2] * GRAVITY)
    ax = accel[0] - (wy * vz - wz * vy)
    ay = accel[1] - (wz * vx - wx * vz)
    az = accel[2] - (wx * vy - wy * vx)
    if abs(math.sqrt(ax * ax + ay * ay + az * az) - GRAVITY) > GRAVITY_DYNAMIC_GATE:
        return []
    roll = math.atan2(ay, az)
    pitch = math.atan2(-ax, math.hypot(ay, az))
    if not s.attitude_ready:
        initialise_attitude(core, s, (roll, pitch, 0.0), False)
    var = cfg.gravity_tilt_noise**2
    y, H, R = obs.orientation(core.layout, s.ekf.x, (roll, pitch, 0.0), (var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var),
                              (0, 1))
    heading = rot.yaw(tuple(s.ekf.x[3:7].tolist()))
    res = s.ekf.update(y, H, R, cfg.mahalanobis_threshold, core.tilt_mask)
    if not res.rejected:
        restore_heading(s, heading)
        s.tilt_seen = stamp
    if not emit:
        return []
    return [DiagnosticsRecord(stamp, cfg.name, ["roll", "pitch"], y.tolist(), res.innovation_var, res.nis, 2,
                              res.rejected, channel="gravity", late=late)]


def quiet_bound(gyro_sigma: float, bias_sigma: float) -> float:
    """The largest raw gyro rate that is still "not turning": noise plus the prior bias range, each
    QUIET_SIGMAS wide. Judged on the raw reading, so that a wrong bias estimate cannot veto it. The
    standstill confirmation, the slip check and the doctor's standstill episodes all use it."""
    return QUIET_SIGMAS * (gyro_sigma + bias_sigma)


def learn_bias_at_rest(core: "FusionCore", s: FilterState, cfg: ImuSensor, inp: ImuInput, stamp: float,
                       emit: bool, late: bool) -> list[DiagnosticsRecord]:
    """At a confirmed standstill the gyro reads its bias: learn it, per axis, robustly.

    Some drives report exactly zero speed while the vehicle still coasts or turns, so
    the odometry alone does not confirm a standstill: the gyro must be quiet too (each
    axis within QUIET_SIGMAS of its noise plus the prior bias range, judged on the raw
    reading so that a wrong bias estimate cannot veto it). Samples are averaged over a
    window of ``standstill_s`` and each window makes one scalar update per axis, gated on
    its own: a wrong x/y bias (learned through roll/pitch) no longer blocks the z bias that
    drives heading. When an axis's windows keep being rejected while agreeing with each
    other, the estimate (locked in by an earlier false standstill) is what is wrong: its
    variance is re-opened to the prior and the evidence let in, so one bad update cannot
    lock out every later one.
    """
    fc = core.cfg.filter
    odom = core.odom_index
    resting = (
        s.still_since is not None
        and stamp - s.still_since >= fc.standstill_s
        and s.last[odom] is not None
        and stamp - s.last[odom] <= core.timeout(odom, s)
    )
    g, gc = inp.gyro, inp.gyro_cov
    if not resting or any(abs(g[i]) > quiet_bound(math.sqrt(gc[4 * i]), fc.gyro_bias_sigma) for i in range(3)):
        s.bias_window = None  # moving, or turning with the wheels at rest: not a standstill
        return []
    w = s.bias_window
    if w is None:
        w = (stamp, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    w = (w[0], w[1] + 1, w[2] + g[0], w[3] + g[1], w[4] + g[2], w[5] + gc[0], w[6] + gc[4], w[7] + gc[8])
    if w[1] < MIN_WINDOW_SAMPLES or stamp - w[0] < fc.standstill_s:
        s.bias_window = w
        return []
    s.bias_window = None
    n = w[1]
    rejects = list(s.bias_rejects)
    e0 = core.layout.error["gyro_bias"].start
    axes = (0, 1, 2) if core.tilt_reference and not core.two_d else (2,)
    ys, svars, nis, rejected, learning = [], [], 0.0, False, False
    for axis in axes:
        mean = w[2 + axis] / n
        var = max(w[5 + axis] / (n * n), BIAS_MEAN_FLOOR**2)
        # An update whose prior is far wider than the window's noise mostly learns the bias: its
        # NIS tests the prior (gyro_bias_sigma), not the gyro's noise, so it is marked as learning
        # and left out of the consistency tests.
        learning |= float(s.ekf.P[e0 + axis, e0 + axis]) > LEARNING_PRIOR_RATIO * var
        y, H, R = obs.bias_axis(core.layout, s.ekf.x, axis, mean, var)
        res = s.ekf.update(y, H, R, ZERO_RATE_GATE)
        if res.rejected:
            recent = (rejects[axis] + (mean,))[-REOPEN_AFTER:]
            if len(recent) == REOPEN_AFTER and max(recent) - min(recent) <= AGREE_SIGMAS * math.sqrt(var):
                log.warning("gyro_bias_reopened", sensor=cfg.name, axis=GYRO_COMPONENTS[axis], stamp=stamp,
                            estimate=float(s.ekf.x[core.layout.nominal["gyro_bias"].start + axis]), at_rest=mean)
                s.ekf.reset_variance(e0 + axis, fc.gyro_bias_sigma**2)
                y, H, R = obs.bias_axis(core.layout, s.ekf.x, axis, mean, var)
                res = s.ekf.update(y, H, R, ZERO_RATE_GATE)
                learning = True
                recent = ()
            rejects[axis] = recent
        else:
            rejects[axis] = ()
        ys.append(float(y[0]))
        svars.append(res.innovation_var[0])
        nis += res.nis
        rejected |= res.rejected
    s.bias_rejects = tuple(rejects)
    if not emit:
        return []
    return [DiagnosticsRecord(stamp, cfg.name, [GYRO_COMPONENTS[a] for a in axes], ys, svars, nis, len(axes),
                              rejected, channel="gyro_bias", late=late, learning=learning)]


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
