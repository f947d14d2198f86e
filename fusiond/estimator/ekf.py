"""A generic error-state extended Kalman filter.

It knows nothing of sensors or time: a model hands it the propagated nominal
state with F and Q, or an innovation with H and R. The gain comes from a
Cholesky factorisation of S (see ``cholesky``) instead of an explicit inverse,
and the covariance update K S K^T = W^T W is symmetric by construction; a masked
(Schmidt) update uses the Joseph form's closed form.

The numerics run in a backend chosen when the filter is built (``backend.py``): the Python
reference (numpy products, the gain from a Cholesky factorisation in Python floats) or the same
steps as one compiled call each; tests hold the two to the same estimates. What stays here is what
either needs: the buffers (P is written into a spare n x n buffer that is then swapped with P; P
itself is never shared: copies and history snapshots copy it) and the checks on every step that
guard the next one: a non-finite P is reset (counted in ``resets``), a negative variance clipped.
Symmetrising is hygiene against rounding, not correctness (the gain uses P H^T only):
``cap_covariance``, called once per second of message time by the core, does it with the caps.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import msgspec
import numpy as np
from . import rotation as rot
from .backend import APPLIED, DEFAULT, NEEDS_CHECK, SINGULAR, Backend, UpdateWorkspace
from ..errors import EstimatorError
from .state import YAW_ROW, StateLayout, attitude_of, position_of

if TYPE_CHECKING:
    from .smoother import OpenSegment


class UpdateResult(msgspec.Struct, gc=False):
    nis: float
    innovation_var: list[float]
    rejected: bool
    singular: bool = False  # S was not positive definite: update skipped
    covariance_reset: bool = False  # P went non-finite and was reset (counted in ``ErrorStateEKF.resets``)


class ErrorStateEKF:
    """Nominal state ``x`` (on the manifold) and error covariance ``P``.

    ``P`` is replaced by a new array on every step that changes it (read it, do not keep
    a reference across steps: its buffer is reused two steps later). ``backend`` runs the
    numerics (``backend.py``; default: compiled when built, else the Python reference); the
    motion and observation models take it from ``backend`` too.
    """

    def __init__(self, layout: StateLayout, x: np.ndarray | None = None, P: np.ndarray | None = None,
                 backend: Backend = DEFAULT) -> None:
        self.layout = layout
        self.backend = backend.for_layout(layout)
        self.x = layout.initial_state() if x is None else np.array(x, dtype=float)
        self.P = layout.initial_covariance() if P is None else np.array(P, dtype=float)
        # Covariance resets after a non-finite value, in propagate and update alike. It travels
        # with copies, so a history snapshot knows how many resets its timeline has had.
        self.resets = 0
        self._mask: np.ndarray | None = None  # the last mask seen, with its float form and weights
        self._keep: np.ndarray | None = None
        self._joseph: np.ndarray | None = None
        self._spare: np.ndarray | None = None  # the next P's buffer (never self.P); allocated on first use
        self._ws = UpdateWorkspace(layout.error_dim)  # scratch shared with copies (single-threaded use per core)
        # The smoother's view of this filter's timeline (``record``); None: nothing is recorded, and
        # each step pays one attribute test.
        self._rec: OpenSegment | None = None

    # -- propagation -------------------------------------------------------
    def propagate(self, x_new: np.ndarray, F: np.ndarray, Q: np.ndarray) -> bool:
        """Accept a propagated state; False if the covariance had to be reset."""
        if self._rec is not None:
            return self._recorded_propagate(x_new, F, Q)
        self.x = x_new
        spare = self._spare
        if spare is None:
            spare = self._spare = np.empty(self.P.shape)
        P_new = self.backend.propagate(F, self.P, Q, spare)
        if P_new is None:
            self.P = self.layout.initial_covariance()
            self.resets += 1
            return False
        if P_new is spare:
            self._spare = self.P
        self.P = P_new
        return True

    # -- correction --------------------------------------------------------
    def update(
        self, y: np.ndarray, H: np.ndarray, R: np.ndarray, threshold: float = math.inf, mask: np.ndarray | None = None,
        hold_heading: bool = False,
    ) -> UpdateResult:
        """Kalman update with a Mahalanobis gate on sqrt(NIS).

        ``mask`` (bool per error component) limits what the update may change: the
        gain rows of the others are zeroed (a Schmidt "consider" update) and the
        Joseph form keeps P right for that sub-optimal gain. A roll/pitch update
        uses it so that correlations in P cannot leak it into heading or position, and
        ``hold_heading`` so that its correction about world x/y of a tilted body leaves the
        yaw exactly where it was (``state.hold_heading_of``).
        """
        if self._rec is not None:
            return self._recorded_update(y, H, R, threshold, mask, hold_heading)
        P_new = self._spare
        if P_new is None:
            P_new = self._spare = np.empty(self.P.shape)
        keep = joseph = None
        if mask is not None:
            if mask is not self._mask:
                self._mask, self._keep, self._joseph = self._ws.mask(mask)
            keep, joseph = self._keep, self._joseph
        status, nis, s_diag = self.backend.update(self.layout, self.x, self.P, H, R, y, threshold * threshold, keep,
                                                  joseph, hold_heading, P_new, self._ws)
        if status == APPLIED:
            self._spare, self.P = self.P, P_new
            return UpdateResult(nis=nis, innovation_var=s_diag, rejected=False)
        if status == NEEDS_CHECK:  # the reference's P, or a negative or non-finite variance: the checks
            return UpdateResult(nis=nis, innovation_var=s_diag, rejected=False,
                                covariance_reset=not self._store(P_new))
        return UpdateResult(nis=nis, innovation_var=s_diag, rejected=True, singular=status == SINGULAR)

    # -- recording for the smoother (fusiond.estimator.smoother) ------------------------------------
    def record(self, segment: OpenSegment | None) -> None:
        """Report every step from here on to ``segment`` (``SmoothingRecorder.open``), which folds them with
        this filter's backend; None stops."""
        if segment is not None:
            segment.backend = self.backend
        self._rec = segment

    @property
    def recording(self) -> OpenSegment | None:
        return self._rec

    def anchor(self, stamp: float, shown: tuple[float, float, float] | None = None,
               origin: tuple[float, float] | None = None) -> None:
        """An output moment for the smoother: the estimate at this moment is one it returns smoothed
        (``shown``: the position published instead of the state's, ``origin``: where the state's is
        dead-reckoned from then: ``smoother.Anchor``)."""
        if self._rec is not None:
            self._rec.anchor(stamp, self.x, self.P, shown, origin)

    def end_segment(self) -> None:
        """The smoother does not link what comes next to what came before (a time gap, a jump)."""
        if self._rec is not None:
            self._rec.cut()

    def _recorded_propagate(self, x_new: np.ndarray, F: np.ndarray, Q: np.ndarray) -> bool:
        rec, P0 = self._rec, self.P  # P0 is kept: the step writes the next P into another buffer
        self._rec = None
        try:
            ok = self.propagate(x_new, F, Q)
        finally:
            self._rec = rec
        if ok:
            rec.transition(P0, F, self.P)
        else:
            rec.cut()
        return ok

    def _recorded_update(self, y, H, R, threshold, mask, hold_heading) -> UpdateResult:
        rec, x0, P0 = self._rec, self.x.copy(), self.P
        self._rec = None
        try:
            res = self.update(y, H, R, threshold, mask, hold_heading)
        finally:
            self._rec = rec
        if res.covariance_reset:
            rec.cut()
        elif not res.rejected:
            rec.correction(self.layout, x0, self.x, P0, self.P)
        return res

    def _cut(self) -> None:
        if self._rec is not None:
            self._rec.cut()

    def _mapped(self, P0: np.ndarray, J: np.ndarray) -> None:
        """P became J P0 J^T (a change of variables): a transition without noise for the smoother."""
        if self._rec is not None:
            self._rec.transition(P0, J, self.P)

    # -- covariance hygiene ------------------------------------------------
    def _store(self, P_new: np.ndarray) -> bool:
        """Accept P - K S K^T (written in the spare buffer); False if it had to be reset.

        The diagonal is enough to see a non-finite result: P was finite, and an overflow or
        NaN in C = W^T W at (i, j) comes from W's column i or j, whose C_ii or C_jj (a sum of
        squares) is then non-finite too, also where the mask weight is 0 (inf * 0 = NaN).
        """
        d = P_new.diagonal().tolist()  # Python floats: cheaper than two numpy reductions at this size
        if not math.isfinite(sum(d)):
            self.P = self.layout.initial_covariance()
            self.resets += 1
            return False
        if min(d) < 0.0:
            # Rounding can push a tiny variance below zero: clip the spectrum.
            P_new += P_new.T
            P_new *= 0.5
            w, V = np.linalg.eigh(P_new)
            np.copyto(P_new, (V * np.maximum(w, 0.0)) @ V.T)
        self._spare, self.P = self.P, P_new
        return True

    def reset_variance(self, i: int, var: float) -> None:
        """Forget what is known about error component i: its correlations go, its variance is var.

        For a state whose estimate turned out to be wrong (its updates are rejected, yet they
        agree with each other): re-opening it lets the evidence in again.
        """
        P = self.P.copy()
        P[i, :] = 0.0
        P[:, i] = 0.0
        P[i, i] = var
        self.P = P
        self._cut()

    def hold_planar(self, nominal_zero: tuple[int, ...], error_zero) -> None:
        """Two-D mode (robot_localization's ``two_d_mode``): z, roll and pitch exactly 0, through the
        backend (``planar.hold_planar`` says what is held; ``error_zero``: the error components' indices
        as a tuple, which the compiled backend writes in one call, or an array or ``planar_mask`` of them)."""
        rec = self._rec
        if rec is not None:
            x0, P0 = self.x.copy(), self.P.copy()
        self.backend.hold_planar(self.x, self.P, nominal_zero, error_zero)
        if rec is not None:  # a correction of the held components: the nominal state moved, P lost them
            rec.correction(self.layout, x0, self.x, P0, self.P)

    def cap_covariance(self, caps: np.ndarray) -> None:
        """Hygiene at a slow cadence (the core calls it once per second of message time and after
        a gap): symmetrise P against rounding, then scale rows/columns whose variance exceeds its
        cap (keeps correlations, stays PSD). A capped variance is knowledge the filter did not gain:
        the smoother's segment ends there (the symmetrising alone changes nothing it uses)."""
        P = self.P
        P += P.T
        P *= 0.5
        d = np.diagonal(P)
        over = d > caps
        if over.any():
            scale = np.ones_like(d)
            scale[over] = np.sqrt(caps[over] / d[over])
            P *= np.outer(scale, scale)
            self._cut()

    # -- state surgery (world frame definition, heading initialisation, sensor offsets) ---------------------
    # The core never writes x or P itself: a re-set of part of the state goes through these,
    # which keep P symmetric and positive semi-definite.

    def reset_covariance(self, idx: list[int], block: np.ndarray) -> None:
        """Forget what P says about the error components ``idx``: their rows and columns are
        zeroed (no correlation left with anything else) and ``block`` becomes their covariance."""
        P = self.P.copy()
        P[idx, :] = 0.0
        P[:, idx] = 0.0
        P[np.ix_(idx, idx)] = block
        self.P = P
        self._cut()

    def reattribute(self, src: tuple[int, int], dst: tuple[int, int], src_var: float,
                    release: tuple[list[int], np.ndarray] | None = None) -> None:
        """What the additive component ``src`` (nominal index, error index) holds belongs to ``dst``: dst takes
        it (x[dst] += x[src], with its variance and correlations: dst' = dst + src), src starts again at 0 with
        ``src_var`` and no correlation, and the components ``release[0]``, held until now, are given the
        covariance ``release[1]``. Any sum of dst and src (a measurement of both) is unchanged. P stays PSD;
        for the smoother a change it does not see through."""
        (sn, se), (dn, de) = src, dst
        self.x[dn] += self.x[sn]
        self.x[sn] = 0.0
        P = self.P.copy()
        P[de, :] += P[se, :]
        P[:, de] += P[:, se]
        P[se, :] = 0.0
        P[:, se] = 0.0
        P[se, se] = src_var
        if release is not None:
            idx, block = release
            P[idx, :] = 0.0
            P[:, idx] = 0.0
            P[np.ix_(idx, idx)] = block
        self.P = P
        self._cut()

    def widen(self, idx: list[int], C: np.ndarray) -> None:
        """Add ``C`` (PSD) to the covariance of the error components ``idx``: an independent error they
        took on at once (a GPS receiver's step, whose mean the caller moved the state by). P stays PSD;
        for the smoother a change it does not see through."""
        P = self.P.copy()
        P[np.ix_(idx, idx)] += C
        self.P = P
        self._cut()

    def decorrelate(self, group: list[int]) -> None:
        """Zero the covariances between the components ``group`` and all others: what P said about
        how they move together no longer holds. P becomes block diagonal in (group, rest), each
        block a principal submatrix of a PSD matrix: still PSD."""
        rest = [i for i in range(self.layout.error_dim) if i not in set(group)]
        P = self.P.copy()
        P[np.ix_(group, rest)] = 0.0
        P[np.ix_(rest, group)] = 0.0
        self.P = P
        self._cut()

    def keep_beyond_pose(self, other: "ErrorStateEKF") -> None:
        """Take every block after the pose (biases, scales, offsets) from ``other``, with their
        covariance among themselves; their correlation with the (re-set) pose is dropped."""
        self.x[7:] = other.x[7:]
        P = self.P.copy()
        P[6:, :] = 0.0
        P[:, 6:] = 0.0
        P[6:, 6:] = other.P[6:, 6:]
        self.P = P
        self._cut()

    def position(self) -> tuple[float, float, float]:
        """The nominal position (m)."""
        return position_of(self.x)

    def attitude(self) -> tuple[float, float, float, float]:
        """The nominal attitude quaternion (x y z w)."""
        return attitude_of(self.x)

    def yaw_variance(self) -> float:
        """The heading's variance (rad^2): the global attitude error's z component."""
        return self.P.item(YAW_ROW, YAW_ROW)  # a Python float (asked at every prediction while a GPS keeps a track)

    def set_position(self, p, rows: tuple[int, ...] = (0, 1, 2)) -> None:
        """Set the nominal position components ``rows`` (covariance: ``reset_covariance``)."""
        for i in rows:
            self.x[i] = p[i]
        self._cut()

    def set_attitude(self, q) -> None:
        """Set the nominal attitude quaternion (x y z w); the covariance is unchanged."""
        self.x[3:7] = q
        self._cut()

    def shift(self, name: str, delta: list[float]) -> None:
        """Add ``delta`` to an additive block's nominal value (the covariance is unchanged)."""
        s = self.layout.nominal[name]
        self.x[s] = self.x[s] + np.asarray(delta, dtype=float)
        self._cut()

    def map_errors(self, J: np.ndarray) -> None:
        """The error state is re-defined as J dx (a change of variables): P' = J P J^T."""
        P0 = self.P
        self.P = J @ P0 @ J.T
        self._mapped(P0, J)

    def rotate_yaw(self, angle: float, center: tuple[float, float] = (0.0, 0.0)) -> None:
        """Turn the pose about the world z axis through ``center`` by ``angle``.

        p' = c + Rz (p - c), q' = Rz q. The errors turn with it: dp' = Rz dp and, the
        attitude error being global (R_true = Exp(dtheta) R), Rz Exp(dtheta) R =
        Exp(Rz dtheta) Rz R gives dtheta' = Rz dtheta. So P' = J P J^T with
        J = diag(Rz, Rz, I): orthogonal, P stays what it was, seen in the turned frame.
        """
        c, s = math.cos(angle), math.sin(angle)
        x = self.x
        dx, dy = float(x[0]) - center[0], float(x[1]) - center[1]
        x[0], x[1] = center[0] + c * dx - s * dy, center[1] + s * dx + c * dy
        J = self._turn_attitude(angle)
        J[0:2, 0:2] = J[3:5, 3:5]
        P0 = self.P
        self.P = J @ P0 @ J.T
        self._mapped(P0, J)
        if self._rec is not None:  # the heading was found off by the angle: the smoother turns the search's past
            self._rec.heading_turn(angle)

    def turn_heading(self, angle: float, yaw_var: float) -> None:
        """Turn the attitude about the world z axis by ``angle`` (q' = Rz q), the position where it is,
        and make the heading's variance ``yaw_var`` (what is known of it after the turn).

        For a turn the filter did not see (made in a logging gap, shown by another sensor's own yaw).
        The attitude error turns with it (dtheta' = Rz dtheta, as in ``rotate_yaw``): P' = J P J^T
        with J = Rz on the attitude block. The yaw error, the z component, is unchanged by Rz. Then
        P'[yaw, yaw] becomes ``yaw_var``: widened by adding the difference (an error independent of
        the rest), narrowed by scaling the yaw row and column (a change of variables, dtheta_z' =
        f dtheta_z, whose correlations shrink with it). Either way P stays PSD.
        """
        J = self._turn_attitude(angle)
        P = J @ self.P @ J.T
        now = float(P[5, 5])
        target = max(yaw_var, 0.0)
        if target >= now:
            P[5, 5] = target
        elif now > 0.0:
            f = math.sqrt(target / now)
            P[5, :] *= f
            P[:, 5] *= f
        self.P = P
        self._cut()

    def _turn_attitude(self, angle: float) -> np.ndarray:
        """q' = Rz(angle) q; returns J, the identity but for Rz on the attitude block (dtheta' = Rz dtheta),
        for the caller to complete and apply as P' = J P J^T."""
        c, s = math.cos(angle), math.sin(angle)
        x = self.x
        q = rot.mul(rot.exp(0.0, 0.0, angle), attitude_of(x))
        x[3:7] = rot.normalize(q)
        J = np.eye(self.layout.error_dim)
        J[3:5, 3:5] = ((c, -s), (s, c))
        return J

    def copy(self, into: "ErrorStateEKF | None" = None) -> "ErrorStateEKF":
        """A copy with its own x and P; ``into`` reuses an existing object's arrays, written in place
        (``_copied_into``), or, when they do not fit, is replaced by a new object."""
        c = into
        if c is not None and not _copied_into(self, c):
            c = None
        if c is None:
            c = ErrorStateEKF.__new__(ErrorStateEKF)
            c.x = self.x.copy()
            c.P = self.P.copy()
            c._spare = None
        c.layout = self.layout
        c.backend = self.backend
        c.resets = self.resets
        c._rec = None if self._rec is None else self._rec.copy()
        c._mask, c._keep, c._joseph = self._mask, self._keep, self._joseph
        c._ws = self._ws
        return c

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x.copy(), self.P.copy()

    def restore(self, x, P) -> None:
        """Take a nominal state and covariance that ``snapshot`` gave (a filter resuming after a
        restart). Refused, with nothing changed, unless both fit this layout and are finite, the
        quaternion has a norm and P is symmetric (to rounding) with a non-negative diagonal: a
        resumed filter must be as sound as a running one. A quaternion off unit norm is normalised;
        otherwise both are taken as they are, so a resumed filter is the saved one to the bit."""
        x = np.array(x, dtype=float).reshape(-1)
        P = np.array(P, dtype=float)
        n, e = self.layout.nominal_dim, self.layout.error_dim
        if x.shape != (n,) or P.size != e * e:
            raise EstimatorError(f"state of {x.size} values and covariance of {P.size} do not fit this layout "
                                 f"({n} and {e} x {e})")
        P = P.reshape(e, e)
        if not (np.isfinite(x).all() and np.isfinite(P).all()):
            raise EstimatorError("state or covariance is not finite")
        if (np.diagonal(P) < 0.0).any() or not np.allclose(P, P.T, rtol=1e-9, atol=1e-12):
            raise EstimatorError("covariance is not symmetric with a non-negative diagonal")
        q = tuple(x[3:7].tolist())
        if abs(math.fsum(v * v for v in q) - 1.0) > 1e-12:  # a unit quaternion is taken bit for bit
            x[3:7] = rot.normalize(q)
        self.x = x
        self.P = P  # as saved, bit for bit: the running filter's own rounding asymmetry is within the check
        self._spare = None  # the next P's buffer must not be the array just taken
        self._cut()


def _copied_into(src: ErrorStateEKF, dst: ErrorStateEKF) -> bool:
    """Write src's x and P into dst's arrays; False (nothing written) when they do not fit (the
    compiled backend does it in one call: a history snapshot is written once per message, and the two
    numpy assignments with their shape checks cost twice the call)."""
    return src.backend.copy_into(src.x, src.P, dst.x, dst.P)
