"""GPS: position fixes in ENU at the datum; heading from the first metres of travel."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ...estimator import observations as obs
from ...estimator import rotation as rot
from ..diagnostics import DiagnosticsRecord
import structlog

from ...config import GpsSensor
from ...estimator.geodesy import EnuFrame
from ..sensors import GpsInput
from .frame import lever, set_position

if TYPE_CHECKING:
    from ..fusion import FusionCore
    from ..state import FilterState

log = structlog.get_logger("fusiond.core")

HEADING_MIN_TRAVEL = 0.3  # odometry chord / GPS chord below this: pushed, slipping or a GPS jump, start over
HEADING_SIGMA_FLOOR = 0.02  # rad added to the chord-angle uncertainty of the initial GPS heading
ENU_NAMES = ("east", "north", "up")
_ZERO3 = (0.0, 0.0, 0.0)


def apply_gps(core: "FusionCore", s: FilterState, idx: int, inp: GpsInput, stamp: float, emit: bool, late: bool):
    cfg: GpsSensor = core.sensors[idx]  # type: ignore[assignment]
    if s.enu is None:
        s.enu = EnuFrame(*inp.lla)  # no datum configured: the first valid fix (in stamp order)
    z = s.enu.enu(*inp.lla)
    ekf = s.ekf
    error = "gps_error" if core.layout.has("gps_error") else None
    if not s.frame_ready:
        set_position(s, z, inp.cov, cfg.extrinsic_xyz)
        if error is not None:
            _split_first_fix(s, core.layout, error)
        s.frame_ready = True
        s.pose_anchor = {}
        if core.absolute_yaw:
            s.heading_ready = True  # the IMU's absolute yaw is the heading in ENU
        else:
            s.gps_anchor = (z, lever(ekf.x, cfg.extrinsic_xyz))
            s.travel = _ZERO3
        return []
    if not s.heading_ready:
        gps_heading(core, s, cfg, z, inp.cov)
    y, H, R = obs.position(core.layout, ekf.x, z, inp.cov, cfg.extrinsic_xyz, error)
    if core.two_d:  # altitude is not fused: z is held at 0
        y, H, R = y[:2], H[:2], R[:2, :2]
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
    if not emit:
        return []
    return [DiagnosticsRecord(stamp, cfg.name, list(ENU_NAMES[:len(y)]), y.tolist(), res.innovation_var, res.nis,
                              len(y),
                              res.rejected, channel=channel, late=late)]


def gps_heading(core: "FusionCore", s: FilterState, cfg: GpsSensor, z: tuple[float, float, float], cov) -> None:
    """Initial heading from the first metres of travel: the angle between the GPS chord and
    the dead-reckoned chord of the antenna since the first fix. A wrong initial yaw rotates
    the whole dead-reckoned track about its start, so the chord angles differ by exactly
    the yaw error, whatever the path's shape."""
    z0, l0 = s.gps_anchor
    gx, gy = z[0] - z0[0], z[1] - z0[1]
    d = math.hypot(gx, gy)
    sigma = math.sqrt(max(cov[0], cov[4]))
    if cfg.error_tau_s > 0.0 and cfg.error_sigma is not None:  # the slow error moves the chord too
        sigma = math.hypot(sigma, max(cfg.error_sigma[0], cfg.error_sigma[1]))
    if d < max(cfg.heading_init_m, 4.0 * sigma):
        return
    l1 = lever(s.ekf.x, cfg.extrinsic_xyz)
    fx, fy = s.travel[0] + l1[0] - l0[0], s.travel[1] + l1[1] - l0[1]
    if math.hypot(fx, fy) < HEADING_MIN_TRAVEL * d:
        s.gps_anchor, s.travel = (z, l1), _ZERO3  # GPS wander or a pushed robot: start over
        return
    dyaw = rot.wrap(math.atan2(gy, gx) - math.atan2(fy, fx))
    ekf = s.ekf
    q = (float(ekf.x[3]), float(ekf.x[4]), float(ekf.x[5]), float(ekf.x[6]))
    ekf.x[3:7] = rot.normalize(rot.mul(rot.exp(0.0, 0.0, dyaw), q))
    sig = math.sqrt(2.0) * sigma / d + HEADING_SIGMA_FLOOR
    P = ekf.P.copy()
    P[5, :] = 0.0
    P[:, 5] = 0.0
    P[5, 5] = sig * sig
    ekf.P = P
    s.heading_ready = True
    s.gps_anchor, s.travel = None, _ZERO3
    s.pose_anchor = {}  # the frame turned under them: deltas restart from the next message
    log.info("gps_heading_initialised", sensor=cfg.name, yaw_correction=dyaw, sigma=sig, chord_m=d)


def _split_first_fix(s: FilterState, layout, error: str) -> None:
    """The first fix put the base at z - R t, but z also carries the GPS error b: the base
    position is off by -(b + noise), so P_pp gains P_bb and P_pb = -P_bb (b keeps its prior)."""
    P = s.ekf.P.copy()
    eb = layout.error[error]
    P[0:3, :] -= P[eb, :]  # dp <- dp - db: rows and columns of the linear map [I -I]
    P[:, 0:3] -= P[:, eb]
    # set_position zeroed the position rows (P_pb was 0): now P_pp + P_bb and P_pb = -P_bb
    s.ekf.P = P
