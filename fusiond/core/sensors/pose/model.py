"""Pose sensors (visual odometry, motion capture, ceiling camera): absolute or differential.

An absolute pose is an update of the pose rows it measures; its first message defines the
world frame when no GPS does. A differential sensor (visual odometry with a drifting
origin) is fused as the motion between its consecutive messages against the filter's
predicted motion over the same interval, kept in its slice of the state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import msgspec
import numpy as np

from .... import reasons
from ....estimator import YAW_ROW, attitude_of, mat3, position_of
from ....estimator import observations as obs
from ....estimator import rotation as rot
from ....logs import get_logger
from ...diagnostics import DiagnosticsRecord, chi2_ppf
from ..base import SensorContext, SensorModel
from ..checks import Rejected, finite, plausible, unit_quaternion
from ..frame import new_frame, set_position
from .sample import PoseSample
from .table import PoseSensor

if TYPE_CHECKING:
    from ..state import FilterState

log = get_logger(__name__)

# A differential sensor's delta across a silence beyond its timeout, with no gate configured, is taken for a
# restart of its chain when a chain that went on would give one as far out this rarely (``_apply_delta``)
RESTART_FALSE_ALARM = 1e-6

NO_MOTION = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


class PoseAnchor(msgspec.Struct, frozen=True, gc=False):
    """A differential sensor's slice of the state: its previous message (position, quaternion), the
    filter's predicted motion since then (in the body frame at that message), the world frame
    it was taken in (``FilterState.frame_epoch``: a frame defined or turned since restarts it), when
    the sensor is silent from (that message's stamp plus its timeout), that message's stamp and the sensor's
    typical period then."""

    position: tuple[float, float, float]
    q: tuple[float, float, float, float]
    moved: tuple[tuple[float, float, float], tuple[float, float, float, float]]
    epoch: int
    until: float = math.inf
    stamp: float = math.nan
    period: float = 0.0


@dataclass(slots=True)
class PoseInput:
    """Sensor pose (position, unit quaternion, its rpy) with a 6x6 covariance (x y z roll pitch yaw,
    row-major 36-tuple; diagonal but where a mount rotation turned it) and the usable rows; ``dof``: the
    components the sensor measures (None: the rows)."""

    position: tuple[float, float, float]
    q: tuple[float, float, float, float]
    rpy: tuple[float, float, float]
    cov: tuple[float, ...]
    rows: tuple[int, ...]
    dof: int | None = None


class PosePolicy:
    """Covariances of pose sensors are as unreliable as any: the diagonal is used, floored,
    replaced by the config's noise when given, and a component above ``max_sigma`` is not
    measured (a 2D visual odometry sends 1e6 for z, roll and pitch)."""

    def __init__(self, cfg: PoseSensor) -> None:
        self.cfg = cfg
        pmin, omin = cfg.position_min_sigma**2, cfg.orientation_min_sigma**2
        self._floor = [pmin] * 3 + [omin] * 3
        self._max = [cfg.max_sigma[0] ** 2] * 3 + [cfg.max_sigma[1] ** 2] * 3
        self._unknown = [cfg.unknown_sigma[0] ** 2] * 3 + [cfg.unknown_sigma[1] ** 2] * 3
        self._pos_override = None if cfg.position_noise is None else [v * v for v in cfg.position_noise]
        self._ori_override = None if cfg.orientation_noise is None else [v * v for v in cfg.orientation_noise]
        self._held: tuple[int, ...] = ()
        # the sensor's orientation in base_link (extrinsic_rpy): None for none, the common case, read as before
        self.mount_q = rot.from_rpy(*cfg.extrinsic_rpy) if any(cfg.extrinsic_rpy) else None
        self._mount = None if self.mount_q is None else np.array(rot.matrix9(self.mount_q)).reshape(3, 3)

    def planar(self) -> None:
        """Two-D mode: z, roll and pitch are held at 0 and never fused."""
        self._held = (2, 3, 4)

    def convert(self, s: PoseSample) -> PoseInput:
        if not (finite(s.position) and finite(s.orientation)):
            raise Rejected(reasons.NON_FINITE, "pose")
        if not plausible(s.position, 1e6):
            raise Rejected(reasons.IMPLAUSIBLE_VALUE, "position beyond 1000 km")
        q = unit_quaternion(s.orientation)
        c = s.covariance
        if len(c) == 36:
            diag = [c[7 * i] for i in range(6)]
            if any(d < 0.0 for d in diag):
                raise Rejected(reasons.NEGATIVE_COVARIANCE, "pose")
        elif len(c) == 0:
            diag = list(self._unknown)
        else:
            raise Rejected(reasons.BAD_COVARIANCE, "pose covariance must have 36 entries")
        if self._pos_override is not None:
            diag[0:3] = self._pos_override
        if self._ori_override is not None:
            diag[3:6] = self._ori_override
        rows = []
        var = [0.0] * 6
        for i, d in enumerate(diag):
            if d != d or d >= self._max[i] or i in self._held:
                continue
            var[i] = d if d > self._floor[i] else self._floor[i]
            rows.append(i)
        if not rows:
            raise Rejected(reasons.NOTHING_TO_FUSE, "every pose component is marked not measured")
        if self._mount is not None:
            return self._mounted(s.position, q, var, rows)
        cov = [0.0] * 36
        for i in range(6):
            cov[7 * i] = var[i] if var[i] > 0.0 else 1.0
        return PoseInput(s.position, q, rot.to_rpy(q), tuple(cov), tuple(rows))

    def _mounted(self, position: tuple[float, float, float], q: tuple[float, float, float, float], var: list[float],
                 rows: list[int]) -> PoseInput:
        """The pose of a frame at the sensor's origin with base_link's axes (extrinsic_rpy undone: q R_bs^T), and
        the covariance of what the sensor measures in its own axes turned into that frame (R_bs C R_bs^T): the
        orientation's, and for a differential sensor the position's too (its deltas are in the sensor's axes; an
        absolute position is the world's). A block the sensor measures in part keeps its unmeasured axes at
        max_sigma: turned, they stay what the sensor does not measure. A delta is turned by ``turn_delta``."""
        M = self._mount
        C = np.zeros((6, 6))
        out_rows: list[int] = []
        turned = (0, 3) if self.cfg.differential else (3,)
        for b in (0, 3):
            measured = [i for i in range(b, b + 3) if i in rows]
            if not measured:
                continue
            d = [var[i] if i in measured else self._max[i] for i in range(b, b + 3)]
            C[b:b + 3, b:b + 3] = M @ np.diag(d) @ M.T if b in turned else np.diag(d)
            out_rows += [i for i in range(b, b + 3) if i not in self._held and (b in turned or i in measured)]
        for i in range(6):
            if C[i, i] <= 0.0:
                C[i, i] = 1.0
        q = q if self.cfg.differential else rot.normalize(rot.mul(q, rot.conj(self.mount_q)))
        return PoseInput(position, q, rot.to_rpy(q), tuple(C.ravel().tolist()), tuple(out_rows), len(rows))

    def turn_delta(self, dpos: tuple[float, float, float], dq: tuple[float, float, float, float]
                   ) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
        """A differential sensor's delta in base_link's axes (``observations.turned_delta``; as it is without a
        mount)."""
        if self.mount_q is None:
            return dpos, dq
        return obs.turned_delta(self.mount_q, dpos, dq)


class PoseModel(SensorModel):
    config_type = PoseSensor
    sample_type = PoseSample
    policy_type = PosePolicy

    def __init__(self, cfg: PoseSensor, index: int, ctx: SensorContext) -> None:
        super().__init__(cfg, index, ctx)
        self.predicts = cfg.differential  # carries its anchor along the predicted motion

    @property
    def gives_tilt(self) -> bool:
        return not self.cfg.differential

    def planar(self) -> None:
        self.policy.planar()

    def apply(self, s: "FilterState", inp: PoseInput, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        if self.cfg.differential:
            return self._apply_delta(s, inp, stamp, emit, late)
        ekf = s.ekf
        if not s.frame_ready:
            self._define_frame(s, inp)
            return []
        y, H, R = obs.pose(self.ctx.layout, ekf.x, inp.position, inp.rpy, inp.cov, inp.rows, self.cfg.extrinsic_xyz)
        res = ekf.update(y, H, R, self.cfg.mahalanobis_threshold)
        if not res.rejected and (3 in inp.rows or 4 in inp.rows):
            s.tilt_seen = stamp
        if not emit:
            return []
        return [self.record(stamp, [obs.POSE_NAMES[i] for i in inp.rows], y.tolist(), res.innovation_var, res.nis,
                            inp.dof or len(inp.rows), res.rejected, "pose", late)]

    def _define_frame(self, s: "FilterState", inp: PoseInput) -> None:
        """The first absolute pose defines the world frame: position and heading (and roll/pitch
        when no IMU has set them) are taken from it, with its variances."""
        ekf = s.ekf
        r, p, y = rot.to_rpy(ekf.attitude())
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
                     self.cfg.extrinsic_xyz, pos_rows)
        if 5 in rows:
            ekf.reset_covariance([YAW_ROW], np.array([[var[5]]]))
        s.frame_ready = True
        new_frame(s)  # differential sensors restart in the new frame

    def _apply_delta(self, s: "FilterState", inp: PoseInput, stamp: float, emit: bool,
                     late: bool) -> list[DiagnosticsRecord]:
        """Fuse the sensor's motion since its previous message against the filter's motion since
        then (accumulated by the predictions, kept with the anchor in the snapshot): the
        sensor's drifting origin never enters. The stated noise (message covariance or override) is
        that of one delta, as robot_pose_ekf reads visual odometry's covariance: VO's error
        lives in its increments.

        A message after the sensor was silent beyond its timeout (``FusionCore.timeout``) may start a new chain
        instead: a visual odometry that lost tracking starts again from a new origin (its pose jumps back to
        identity), and that jump is no motion. Its delta is then gated (the configured mahalanobis_threshold, else
        the chi-square quantile of RESTART_FALSE_ALARM: a chain that went on through the silence is taken for a
        restart that rarely), its stated covariance taken once for each message period it spans (the increments
        of the messages not sent): within the gate it is the motion across the silence (a logging gap the sensor's
        own chain spans), beyond it the chain starts again from this message and the log says so."""
        ekf = s.ekf
        anchor: PoseAnchor | None = s.own[self.index]
        s.own[self.index] = PoseAnchor(inp.position, inp.q, NO_MOTION, s.frame_epoch,
                                       stamp + self.ctx.timeout(self.index, s), stamp, s.period[self.index])
        if anchor is None or anchor.epoch != s.frame_epoch:
            return []
        dp, dqf = anchor.moved
        # The filter's pose at the previous message, moved along with every correction made
        # since (x_now o D^-1): the delta then checks only the predicted motion D, and does
        # not undo what other sensors (GPS, heading initialisation) corrected meanwhile.
        qn = ekf.attitude()
        qa = rot.mul(qn, rot.conj(dqf))
        a = mat3.apply(rot.matrix9(qa), dp)
        p = ekf.position()
        x_prev = (p[0] - a[0], p[1] - a[1], p[2] - a[2], *qa)
        dpos, dq = self.policy.turn_delta(*obs.relative_pose(anchor.position, anchor.q, inp.position, inp.q))
        y, H, R = obs.delta_pose(self.ctx.layout, ekf.x, x_prev, dpos, dq, inp.cov, inp.rows, self.cfg.extrinsic_xyz)
        gate = self.cfg.mahalanobis_threshold
        silent = stamp > anchor.until
        if silent:
            # the delta spans the increments of every message the sensor did not send, each as uncertain as one
            if anchor.period > 0.0:
                R = R * max(1.0, (stamp - anchor.stamp) / anchor.period)
            if not math.isfinite(gate):
                gate = math.sqrt(chi2_ppf(1.0 - RESTART_FALSE_ALARM, inp.dof or len(inp.rows)))
        res = ekf.update(y, H, R, gate, self.ctx.delta_mask)
        if silent and res.rejected:
            if emit:  # once: not again for each re-application after a late sample
                log.warning("pose_chain_restarted", sensor=self.name, stamp=stamp,
                            beyond_timeout_s=stamp - anchor.until, nis=res.nis,
                            reason="silent beyond its timeout, then a delta the filter's motion rules out: its "
                                   "deltas start again from this message (a visual odometry that lost tracking "
                                   "starts from a new origin)")
            return []
        if not emit:
            return []
        return [self.record(stamp, [obs.DELTA_NAMES[i] for i in inp.rows], y.tolist(), res.innovation_var, res.nis,
                            inp.dof or len(inp.rows), res.rejected, "pose_delta", late)]

    def on_predict(self, s: "FilterState", x0: np.ndarray, x1: np.ndarray) -> None:
        """Compose one prediction step's relative motion (x0^-1 x1) onto the anchor's.

        The motion is expressed in the body frame at the anchor, so corrections of the
        world pose (updates, heading initialisation) between messages do not enter it.
        """
        anchor: PoseAnchor | None = s.own[self.index]
        if anchor is None or anchor.epoch != s.frame_epoch:
            return None
        q0 = attitude_of(x0)
        step_p, step_q = obs.relative_pose(position_of(x0), q0, position_of(x1), attitude_of(x1))
        dp, dq = anchor.moved
        a = mat3.apply(rot.matrix9(dq), step_p)
        moved = ((dp[0] + a[0], dp[1] + a[1], dp[2] + a[2]), rot.normalize(rot.mul(dq, step_q)))
        s.own[self.index] = PoseAnchor(anchor.position, anchor.q, moved, anchor.epoch, anchor.until, anchor.stamp,
                                       anchor.period)
        return None


__all__ = ["PoseAnchor", "PoseInput", "PoseModel", "PosePolicy"]
