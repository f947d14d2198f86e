"""A generic error-state extended Kalman filter.

It knows nothing of sensors or time: a model hands it the propagated nominal
state with F and Q, or an innovation with H and R. The gain comes from a
Cholesky factorisation of S (see ``cholesky``) instead of an explicit inverse,
and the covariance update K S K^T = W^T W is symmetric by construction; a masked
(Schmidt) update uses the Joseph form's closed form. P is then symmetrised and
checked: a non-finite P is reset (counted), a negative variance clipped.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
from . import rotation as rot
from .cholesky import whiten
from .state import StateLayout


class UpdateResult(msgspec.Struct, gc=False):
    nis: float
    innovation_var: list[float]
    rejected: bool
    singular: bool = False  # S was not positive definite: update skipped


class ErrorStateEKF:
    """Nominal state ``x`` (on the manifold) and error covariance ``P``."""

    def __init__(self, layout: StateLayout, x: np.ndarray | None = None, P: np.ndarray | None = None) -> None:
        self.layout = layout
        self.x = layout.initial_state() if x is None else np.array(x, dtype=float)
        self.P = layout.initial_covariance() if P is None else np.array(P, dtype=float)
        self.resets = 0  # covariance resets after a non-finite value
        self._mask: np.ndarray | None = None
        self._weights = np.ones((layout.error_dim, layout.error_dim))

    # -- propagation -------------------------------------------------------
    def propagate(self, x_new: np.ndarray, F: np.ndarray, Q: np.ndarray) -> bool:
        """Accept a propagated state; False if the covariance had to be reset."""
        self.x = x_new
        P = np.dot(np.dot(F, self.P), F.T)
        P += Q
        if not math.isfinite(P.sum()):  # one reduction: any NaN/inf makes the sum non-finite
            self.P = self.layout.initial_covariance()
            self.resets += 1
            return False
        self.P = P  # F P F^T + Q is symmetric PSD up to rounding; update() re-symmetrises
        return True

    # -- correction --------------------------------------------------------
    def update(
        self, y: np.ndarray, H: np.ndarray, R: np.ndarray, threshold: float = math.inf, mask: np.ndarray | None = None
    ) -> UpdateResult:
        """Kalman update with a Mahalanobis gate on sqrt(NIS).

        ``mask`` (bool per error component) limits what the update may change: the
        gain rows of the others are zeroed (a Schmidt "consider" update) and the
        Joseph form keeps P right for that sub-optimal gain. A roll/pitch update
        uses it so that correlations in P cannot leak it into heading or position.
        """
        P = self.P
        PHt = np.dot(P, H.T)
        S = np.dot(H, PHt)
        S += R
        S_rows = S.tolist()
        s_diag = [S_rows[i][i] for i in range(len(S_rows))]
        white = whiten(S_rows, y.tolist())
        if white is None:
            return UpdateResult(nis=math.nan, innovation_var=s_diag, rejected=True, singular=True)
        Linv, z = white  # z = L^-1 y, the whitened innovation
        nis = math.fsum(v * v for v in z)
        if not math.isfinite(nis):
            return UpdateResult(nis=nis, innovation_var=s_diag, rejected=True, singular=True)
        if nis > threshold * threshold:
            return UpdateResult(nis=nis, innovation_var=s_diag, rejected=True)
        W = np.dot(Linv, PHt.T)  # L^-1 H P
        dx = np.dot(z, W)  # K y = P H^T S^-1 y = W^T z
        C = np.dot(W.T, W)  # K S K^T = K H P for the optimal gain K = P H^T S^-1
        if mask is None:
            P_new = P - C
        else:
            # Gain rows zeroed by the mask (M K): Joseph's P - MKHP - PH^TK^TM + MKSK^TM
            # collapses to P - C * W with W_ij = 1 - (1 - m_i)(1 - m_j).
            dx *= mask
            P_new = P - C * self._mask_weights(mask)
        self.layout.boxplus(self.x, dx)
        self._store(P_new)
        return UpdateResult(nis=nis, innovation_var=s_diag, rejected=False)

    def _mask_weights(self, mask: np.ndarray) -> np.ndarray:
        if self._mask is not mask:
            keep = 1.0 - mask.astype(float)
            self._mask, self._weights = mask, 1.0 - np.outer(keep, keep)
        return self._weights

    # -- covariance hygiene ------------------------------------------------
    def _store(self, P: np.ndarray) -> bool:
        P += P.T
        P *= 0.5
        if not math.isfinite(P.sum()):
            self.P = self.layout.initial_covariance()
            self.resets += 1
            return False
        if P.diagonal().min() < 0.0:
            # Rounding can push a tiny variance below zero: clip the spectrum.
            w, V = np.linalg.eigh(P)
            P = (V * np.maximum(w, 0.0)) @ V.T
        self.P = P
        return True

    def cap_covariance(self, caps: np.ndarray) -> None:
        """Scale rows/columns whose variance exceeds its cap (keeps correlations, stays PSD)."""
        d = np.diagonal(self.P)
        over = d > caps
        if over.any():
            scale = np.ones_like(d)
            scale[over] = np.sqrt(caps[over] / d[over])
            self.P = self.P * np.outer(scale, scale)

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

    def decorrelate(self, group: list[int]) -> None:
        """Zero the covariances between the components ``group`` and all others: what P said about
        how they move together no longer holds. P becomes block diagonal in (group, rest), each
        block a principal submatrix of a PSD matrix: still PSD."""
        rest = [i for i in range(self.layout.error_dim) if i not in set(group)]
        P = self.P.copy()
        P[np.ix_(group, rest)] = 0.0
        P[np.ix_(rest, group)] = 0.0
        self.P = P

    def set_position(self, p, rows: tuple[int, ...] = (0, 1, 2)) -> None:
        """Set the nominal position components ``rows`` (covariance: ``reset_covariance``)."""
        for i in rows:
            self.x[i] = p[i]

    def set_attitude(self, q) -> None:
        """Set the nominal attitude quaternion (x y z w); the covariance is unchanged."""
        self.x[3:7] = q

    def shift(self, name: str, delta: list[float]) -> None:
        """Add ``delta`` to an additive block's nominal value (the covariance is unchanged)."""
        s = self.layout.nominal[name]
        self.x[s] = self.x[s] + np.asarray(delta, dtype=float)

    def map_errors(self, J: np.ndarray) -> None:
        """The error state is re-defined as J dx (a change of variables): P' = J P J^T."""
        self.P = J @ self.P @ J.T

    def rotate_yaw(self, angle: float, center: tuple[float, float] = (0.0, 0.0)) -> None:
        """Turn the pose about the world z axis through ``center`` by ``angle``.

        p' = c + Rz (p - c), q' = Rz q. The errors turn with it: dp' = Rz dp and, the
        attitude error being global (R_true = Exp(dtheta) R), Rz Exp(dtheta) R =
        Exp(Rz dtheta) Rz R gives dtheta' = Rz dtheta. So P' = J P J^T with
        J = diag(Rz, Rz, I): orthogonal, P stays what it was, seen in the turned frame.
        """
        c, s = math.cos(angle), math.sin(angle)
        Rz = np.array(((c, -s, 0.0), (s, c, 0.0), (0.0, 0.0, 1.0)))
        x = self.x
        dx, dy = float(x[0]) - center[0], float(x[1]) - center[1]
        x[0], x[1] = center[0] + c * dx - s * dy, center[1] + s * dx + c * dy
        q = rot.mul(rot.exp(0.0, 0.0, angle), (float(x[3]), float(x[4]), float(x[5]), float(x[6])))
        x[3:7] = rot.normalize(q)
        J = np.eye(self.layout.error_dim)
        J[0:3, 0:3] = Rz
        J[3:6, 3:6] = Rz
        self.P = J @ self.P @ J.T

    def copy(self) -> "ErrorStateEKF":
        c = ErrorStateEKF.__new__(ErrorStateEKF)
        c.layout = self.layout
        c.x = self.x.copy()
        c.P = self.P.copy()
        c.resets = self.resets
        c._mask, c._weights = self._mask, self._weights
        return c

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x.copy(), self.P.copy()

