"""GPS: position fixes in ENU at the datum; heading from a rigid fit of the first metres of travel.

Heading. A GPS measures where the antenna is, not where it points. Until travel has
shown the heading, the fix may move position only (channel ``position_unaligned``) and
the published heading variance says it is unknown (HEADING_UNKNOWN_SIGMA, rad). Every fix
since the first is paired with the dead-reckoned antenna position at its stamp; a
least-squares rigid fit (``estimator.rigid_fit``) of that track to the fixes gives the
heading correction and its uncertainty. Once that uncertainty is below
HEADING_PROVISIONAL_SIGMA the fit is applied: the state turns about the antenna (which the
fix has just put where the GPS says), so the position dead-reckoned along the wrong heading
since the previous fix turns with the heading, P turns with both, and the heading's
variance is re-set to the fit's. The fit keeps being refined with every fix (the stored
track turned with the state, so each new fit measures what is left) and re-applied until
its uncertainty is below HEADING_READY_SIGMA; then the heading is known and fixes become
ordinary, gated updates (channel ``position``).

Altitude. Consumer receivers' altitude wanders by metres over minutes while they state
1-2 m; by default (``vertical_error_sigma``) the vertical carries a Gauss-Markov error state,
so the fixes pull z only as far as that wander and the odometry allow.

Axes. A fix axis whose stated variance exceeds ``max_sigma``^2 is not measured and not
fused (a 2D receiver, or ``position_noise = [.., .., 1e6]`` to leave out altitude).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ...estimator import observations as obs
from ..diagnostics import DiagnosticsRecord
import structlog

from ...config import GpsSensor
from ...estimator.geodesy import EnuFrame
from ...estimator.rigid_fit import RigidFit, fit_rigid
from ..sensors import GpsInput
from .frame import lever, set_position

if TYPE_CHECKING:
    from ..fusion import FusionCore
    from ..state import FilterState

log = structlog.get_logger("fusiond.core")

HEADING_MIN_TRAVEL = 0.3  # dead-reckoned / GPS extent below this: pushed, slipping or GPS wander, start over
HEADING_UNKNOWN_SIGMA = math.pi / math.sqrt(3.0)  # std dev of a heading uniform on the circle, rad
HEADING_PROVISIONAL_SIGMA = 0.3  # rad: apply the rigid fit provisionally (fixes still move position only)
HEADING_READY_SIGMA = 0.05  # rad: the heading is known, fixes become full (gated) updates
HEADING_MAX_FIXES = 400  # fixes kept for the fit; beyond, every other one is dropped (the extent stays)
FROZEN_MIN_TRAVEL = 0.05  # m of dead-reckoned travel after which a bit-identical repeated fix is a frozen receiver
ENU_NAMES = ("east", "north", "up")
_ZERO3 = (0.0, 0.0, 0.0)


@dataclass(frozen=True, slots=True)
class GpsTrack:
    """What the GPS keeps between fixes (immutable: shared by history snapshots): while the heading
    is unknown, the fixes paired with the dead-reckoned antenna position at their stamps; always,
    the newest coordinates, to recognise a frozen receiver. ``base`` + the state's ``travel`` is
    the dead-reckoned base position."""

    points: tuple[tuple[float, float, float, float, float], ...]  # (gx, gy, dx, dy, weight)
    base: tuple[float, float, float]
    first: tuple[float, float]  # the first fix
    applied: bool = False  # a provisional fit has been applied
    extent: float = 0.0  # farthest fix from the first so far, m (a loop back to the start keeps it)
    t0: float = 0.0  # stamp of the first fix
    last_lla: tuple[float, float, float] | None = None  # the newest fix's coordinates, as received ...
    last_dr: tuple[float, float] = (0.0, 0.0)  # ... and the dead-reckoned base position when they first came


def apply_gps(core: "FusionCore", s: FilterState, idx: int, inp: GpsInput, stamp: float, emit: bool, late: bool):
    cfg: GpsSensor = core.sensors[idx]  # type: ignore[assignment]
    if s.enu is None:
        s.enu = EnuFrame(*inp.lla)  # no datum configured: the first valid fix (in stamp order)
    z = s.enu.enu(*inp.lla)
    ekf = s.ekf
    error = "gps_error" if core.layout.has("gps_error") else None
    rows = measured_axes(cfg, inp.cov)
    if core.two_d:  # altitude is not fused: z is held at 0
        rows = tuple(r for r in rows if r != 2)
    if not s.frame_ready:
        set_position(s, z, inp.cov, cfg.extrinsic_xyz, rows)
        split = (0, 1, 2)
        if cfg.datum is None and 2 in rows:
            # The datum's altitude is this fix's: the frame's zero height is where the antenna is
            # now, exactly, whatever this fix's own error. (With a configured datum the first
            # altitude is as uncertain as the fix, slow error included.)
            ekf.reset_covariance([2], np.zeros((1, 1)))
            split = (0, 1)
        if error is not None:
            _split_first_fix(s, core.layout, error, split)
        s.frame_ready = True
        s.pose_anchor = {}
        base = (float(ekf.x[0]), float(ekf.x[1]), float(ekf.x[2]))
        s.gps_anchor = GpsTrack((), base, (z[0], z[1]), t0=stamp, last_lla=inp.lla, last_dr=base[0:2])
        s.travel = _ZERO3
        if core.absolute_yaw and not core.layout.has("yaw_offset"):
            s.heading_ready = True  # an IMU's absolute yaw trusted as the heading in ENU
        else:
            ekf.reset_covariance([5], np.array([[HEADING_UNKNOWN_SIGMA**2]]))
            gps_heading(core, s, cfg, z, inp.cov, stamp)
        return []
    if frozen(s, inp.lla):
        # A receiver repeating its last fix with a new stamp while the wheels moved: not a measurement.
        if not emit:
            return []
        return [DiagnosticsRecord(stamp, cfg.name, [ENU_NAMES[i] for i in rows], [0.0] * len(rows),
                                  [inp.cov[4 * i] for i in rows], 0.0, len(rows), True, channel="position_frozen",
                                  late=late)]
    y, H, R = obs.position(core.layout, ekf.x, z, inp.cov, cfg.extrinsic_xyz, error)
    if len(rows) < 3:
        if not rows:
            return []
        y, H, R = y[list(rows)], H[list(rows)], R[np.ix_(rows, rows)]
    if s.heading_ready:
        res = ekf.update(y, H, R, cfg.mahalanobis_threshold)
        channel = "position"
    else:
        # Heading unknown: the fix may move position only, and is not gated (a dead-reckoned
        # track along a wrong heading must not lock the filter out of the GPS). A Gauss-Markov
        # GPS error is a "consider" state here: its variance widens S (H has its columns) but
        # the offset a wrong heading builds up must not be absorbed into it as GPS error.
        res = ekf.update(y, H, R, math.inf, core.position_mask)
        channel = "position_unaligned"
        gps_heading(core, s, cfg, z, inp.cov, stamp)  # after the fix has put the antenna where it is
    if not emit:
        return []
    # While the heading is unknown, the innovation carries the dead-reckoning along a wrong
    # heading: its NIS tests the heading search, not the receiver's noise (learning).
    return [DiagnosticsRecord(stamp, cfg.name, [ENU_NAMES[i] for i in rows], y.tolist(), res.innovation_var, res.nis,
                              len(rows), res.rejected, channel=channel, late=late,
                              learning=channel == "position_unaligned")]


def frozen(s: FilterState, lla: tuple[float, float, float]) -> bool:
    """Is this fix a repeat of the previous one (bit for bit) although the robot has moved more than
    FROZEN_MIN_TRAVEL since those coordinates first came? Independent fixes of a moving antenna are
    never bit-identical; a robot at rest (odometry exactly zero: no dead-reckoned travel) may get
    repeats and fuses them. Remembers the fix otherwise."""
    track: GpsTrack = s.gps_anchor
    t = s.travel
    dr = (track.base[0] + t[0], track.base[1] + t[1])
    if lla == track.last_lla:
        return math.hypot(dr[0] - track.last_dr[0], dr[1] - track.last_dr[1]) > FROZEN_MIN_TRAVEL
    s.gps_anchor = replace(track, last_lla=lla, last_dr=dr)
    return False


def measured_axes(cfg: GpsSensor, cov) -> tuple[int, ...]:
    """The ENU axes the fix measures: a variance above ``max_sigma``^2 means "not measured"."""
    limit = cfg.max_sigma * cfg.max_sigma
    return tuple(i for i in range(3) if cov[4 * i] <= limit)


def gps_heading(core: "FusionCore", s: FilterState, cfg: GpsSensor, z: tuple[float, float, float], cov,
                stamp: float) -> None:
    """Add this fix to the track and fit; apply the fit once it is good enough (module doc)."""
    track: GpsTrack = s.gps_anchor
    ekf = s.ekf
    a = lever(ekf.x, cfg.extrinsic_xyz)
    t = s.travel
    dx, dy = track.base[0] + t[0] + a[0], track.base[1] + t[1] + a[1]  # dead-reckoned antenna
    var = max(cov[0], cov[4])
    wander = 0.0  # variance of the receiver's slowly wandering error (the Gauss-Markov state's prior)
    if cfg.error_tau_s > 0.0 and cfg.error_sigma is not None:
        wander = max(cfg.error_sigma[0], cfg.error_sigma[1]) ** 2
        var += wander
    points = track.points + ((z[0], z[1], dx, dy, 1.0 / var),)
    if len(points) > HEADING_MAX_FIXES:
        points = points[::2] + ((points[-1],) if len(points) % 2 == 0 else ())
    extent = max(track.extent, math.hypot(z[0] - track.first[0], z[1] - track.first[1]))
    track = replace(track, points=points, extent=extent)
    s.gps_anchor = track
    if extent < max(cfg.heading_init_m, 4.0 * math.sqrt(var)):
        return
    d0 = points[0]
    if math.hypot(dx - d0[2], dy - d0[3]) < HEADING_MIN_TRAVEL * math.hypot(z[0] - d0[0], z[1] - d0[1]):
        # GPS wander or a pushed robot: the wheels did not make this track. Start over here.
        s.gps_anchor = replace(track, points=((z[0], z[1], dx, dy, 1.0 / var),), first=(z[0], z[1]), extent=0.0,
                               t0=stamp)
        return
    fit = fit_rigid(list(points))
    if fit is None:
        return
    if wander > 0.0:
        # A slowly wandering error moves neighbouring fixes together: it bends the track as a
        # whole, which the residuals cannot show. Over the track's duration T its ends differ by
        # var(b(T) - b(0)) = 2 sigma_b^2 (1 - exp(-T / tau)), spread over the track's extent.
        drift = 2.0 * wander * -math.expm1(-(stamp - track.t0) / cfg.error_tau_s)
        fit = replace(fit, var_theta=fit.var_theta + drift / (extent * extent))
    if fit.var_theta > HEADING_PROVISIONAL_SIGMA**2:
        return
    _apply_fit(core, s, cfg, fit, track)


def _apply_fit(core: "FusionCore", s: FilterState, cfg: GpsSensor, fit: RigidFit, track: GpsTrack) -> None:
    """Turn the state by the fit's angle about the antenna, which this fix has just put where the
    GPS says: the position dead-reckoned along the wrong heading since the previous fix turns with
    the heading, and P turns with both (``ErrorStateEKF.rotate_yaw``). The heading's row of P is
    then re-set to the fit's variance: its old correlations described the wrong heading."""
    ekf = s.ekf
    a = lever(ekf.x, cfg.extrinsic_xyz)
    ekf.rotate_yaw(fit.theta, (float(ekf.x[0]) + a[0], float(ekf.x[1]) + a[1]))
    if core.layout.has("yaw_offset"):  # an absolute IMU yaw reads the same: its offset turns the other way
        ekf.shift("yaw_offset", [-fit.theta])
    # While the heading was unknown, the position's correlations with the gyro bias and the scales
    # were built through a heading error of ~1.8 rad: kept, they would feed the next fixes'
    # innovations into those states. They are dropped with the heading's row and column; the
    # position's own covariance and its relation to the GPS error state are what the fixes made them.
    group = [0, 1, 2]
    if core.layout.has("gps_error"):
        group += list(range(core.layout.error["gps_error"].start, core.layout.error["gps_error"].stop))
    ekf.decorrelate(group)
    ekf.reset_covariance([5], np.array([[fit.var_theta]]))
    # the stored track is now seen in the turned frame: the next fit measures what is left
    points = tuple((gx, gy, *fit.apply(px, py), w) for gx, gy, px, py, w in track.points)
    t = s.travel
    bx, by = fit.apply(track.base[0] + t[0], track.base[1] + t[1])
    s.travel = _ZERO3
    s.pose_anchor = {}  # the frame turned under them: deltas restart from the next message
    sigma = math.sqrt(fit.var_theta)
    ready = sigma <= HEADING_READY_SIGMA
    s.heading_ready = ready
    s.gps_anchor = replace(track, points=() if ready else points, base=(bx, by, track.base[2] + t[2]), applied=True,
                           last_dr=fit.apply(*track.last_dr))
    if ready:
        log.info("gps_heading_initialised", sensor=cfg.name, yaw_correction=fit.theta, sigma=sigma,
                 fixes=len(points))
    elif not track.applied:
        log.info("gps_heading_provisional", sensor=cfg.name, yaw_correction=fit.theta, sigma=sigma,
                 fixes=len(points))


def _split_first_fix(s: FilterState, layout, error: str, rows: tuple[int, ...] = (0, 1, 2)) -> None:
    """The first fix put the base at z - R t, but z also carries the GPS error b: the base
    position is off by -(b + noise), so P_pp gains P_bb and P_pb = -P_bb (b keeps its prior).
    That is the change of variables dp <- dp - db: J = I with -I in the position rows' b columns."""
    J = np.eye(layout.error_dim)
    eb = layout.error[error].start
    for i in rows:
        J[i, eb + i] = -1.0
    s.ekf.map_errors(J)


def on_start(core: "FusionCore", s: FilterState) -> None:
    """A fresh state: the ENU frame at the configured datum (or none yet), heading unknown."""
    gps = core.sensors[core.gps_index]
    s.enu = EnuFrame(*gps.datum) if isinstance(gps, GpsSensor) and gps.datum is not None else None
    s.heading_ready = False
    s.gps_anchor = None  # the track since the first fix, while the heading is being found
    s.travel = _ZERO3  # dead-reckoned base motion since that fix


def on_predict(s: FilterState, x0, x1) -> None:
    """While the heading is pending, accumulate the dead-reckoned motion of each prediction."""
    if s.gps_anchor is not None:
        tr = s.travel
        s.travel = (tr[0] + float(x1[0] - x0[0]), tr[1] + float(x1[1] - x0[1]), tr[2] + float(x1[2] - x0[2]))
