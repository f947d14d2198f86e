"""Pose sensors (visual odometry, motion capture, ceiling camera): absolute or differential."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...estimator import mat3
from ...estimator import observations as obs
from ...estimator import rotation as rot
from ..diagnostics import DiagnosticsRecord
from ...config import PoseSensor
from ..sensors import PoseInput
from .frame import set_position

if TYPE_CHECKING:
    from ..fusion import FusionCore
    from ..state import FilterState

NO_MOTION = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def apply_pose(core: "FusionCore", s: FilterState, idx: int, inp: PoseInput, stamp: float, emit: bool, late: bool):
    cfg: PoseSensor = core.sensors[idx]  # type: ignore[assignment]
    if cfg.differential:
        return apply_pose_delta(core, s, idx, cfg, inp, stamp, emit, late)
    ekf = s.ekf
    if not s.frame_ready:
        initialise_from_pose(core, s, cfg, inp)
        return []
    y, H, R = obs.pose(core.layout, ekf.x, inp.position, inp.rpy, inp.cov, inp.rows, cfg.extrinsic_xyz)
    res = ekf.update(y, H, R, cfg.mahalanobis_threshold)
    if not res.rejected and (3 in inp.rows or 4 in inp.rows):
        s.tilt_seen = stamp
    if not emit:
        return []
    return [DiagnosticsRecord(stamp, cfg.name, [obs.POSE_NAMES[i] for i in inp.rows], y.tolist(),
                              res.innovation_var, res.nis, len(inp.rows), res.rejected, channel="pose", late=late)]


def initialise_from_pose(core: "FusionCore", s: FilterState, cfg: PoseSensor, inp: PoseInput) -> None:
    """The first absolute pose defines the world frame: position and heading (and roll/pitch
    when no IMU has set them) are taken from it, with its variances."""
    ekf = s.ekf
    r, p, y = rot.to_rpy((float(ekf.x[3]), float(ekf.x[4]), float(ekf.x[5]), float(ekf.x[6])))
    mr, mp, my = inp.rpy
    rows = inp.rows
    if not s.attitude_ready:
        r = mr if 3 in rows else r
        p = mp if 4 in rows else p
    y = my if 5 in rows else y
    ekf.set_attitude(rot.from_rpy(r, p, y))
    var = [inp.cov[7 * i] for i in range(6)]
    pos_rows = tuple(i for i in rows if i < 3)
    set_position(s, inp.position, (var[0], 0.0, 0.0, 0.0, var[1], 0.0, 0.0, 0.0, var[2]),
                       cfg.extrinsic_xyz, pos_rows)
    if 5 in rows:
        ekf.reset_covariance([5], np.array([[var[5]]]))
    s.frame_ready = True
    s.pose_anchor = {}  # differential sensors restart in the new frame


def apply_pose_delta(core: "FusionCore", s: FilterState, idx: int, cfg: PoseSensor, inp: PoseInput, stamp: float,
                      emit: bool, late: bool):
    """Fuse the sensor's motion since its previous message against the filter's motion since
    then (accumulated by the predictions, kept with the anchor in the snapshot): the
    sensor's drifting origin never enters. The stated noise (message covariance or override) is
    that of one delta, as robot_pose_ekf reads visual odometry's covariance: VO's error
    lives in its increments."""
    ekf = s.ekf
    anchor = s.pose_anchor.get(cfg.name)
    s.pose_anchor = {**s.pose_anchor, cfg.name: (inp.position, inp.q, NO_MOTION)}
    if anchor is None:
        return []
    pos0, q0, (dp, dqf) = anchor
    # The filter's pose at the previous message, moved along with every correction made
    # since (x_now o D^-1): the delta then checks only the predicted motion D, and does
    # not undo what other sensors (GPS, heading initialisation) corrected meanwhile.
    qn = (float(ekf.x[3]), float(ekf.x[4]), float(ekf.x[5]), float(ekf.x[6]))
    qa = rot.mul(qn, rot.conj(dqf))
    a = mat3.apply(rot.matrix9(qa), dp)
    x_prev = (float(ekf.x[0]) - a[0], float(ekf.x[1]) - a[1], float(ekf.x[2]) - a[2], *qa)
    dpos, dq = obs.relative_pose(pos0, q0, inp.position, inp.q)
    y, H, R = obs.delta_pose(core.layout, ekf.x, x_prev, dpos, dq, inp.cov, inp.rows, cfg.extrinsic_xyz)
    res = ekf.update(y, H, R, cfg.mahalanobis_threshold, core.delta_mask)
    if not emit:
        return []
    return [DiagnosticsRecord(stamp, cfg.name, [obs.DELTA_NAMES[i] for i in inp.rows], y.tolist(),
                              res.innovation_var, res.nis, len(inp.rows), res.rejected, channel="pose_delta",
                              late=late)]


def accumulate_motion(anchors: dict, x0: np.ndarray, x1: np.ndarray) -> dict:
    """Compose one prediction step's relative motion (x0^-1 x1) onto each differential anchor (a new dict).

    The motion is expressed in the body frame at the anchor, so corrections of the
    world pose (updates, heading initialisation) between messages do not enter it.
    """
    q0 = (float(x0[3]), float(x0[4]), float(x0[5]), float(x0[6]))
    step_p, step_q = obs.relative_pose((float(x0[0]), float(x0[1]), float(x0[2])), q0,
                                       (float(x1[0]), float(x1[1]), float(x1[2])),
                                       (float(x1[3]), float(x1[4]), float(x1[5]), float(x1[6])))
    out = {}
    for name, (mp, mq, (dp, dq)) in anchors.items():
        a = mat3.apply(rot.matrix9(dq), step_p)
        out[name] = (mp, mq, ((dp[0] + a[0], dp[1] + a[1], dp[2] + a[2]), rot.normalize(rot.mul(dq, step_q))))
    return out


def on_start(core: "FusionCore", s: FilterState) -> None:
    s.pose_anchor = {}  # differential pose: name -> (measured position, q, predicted motion since (dp, dq))


def on_predict(s: FilterState, x0, x1) -> None:
    """Carry each differential sensor's anchor along the predicted motion."""
    if s.pose_anchor:
        s.pose_anchor = accumulate_motion(s.pose_anchor, x0, x1)
