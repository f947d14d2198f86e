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
from .cholesky import whiten
from .state import StateLayout


class UpdateResult(msgspec.Struct, gc=False):
    nis: float
    innovation_var: list[float]
    rejected: bool
    singular: bool = False  # S was not positive definite: update skipped
    covariance_reset: bool = False  # P went non-finite and was reset (counted in ``ErrorStateEKF.resets``)


class ErrorStateEKF:
    """Nominal state ``x`` (on the manifold) and error covariance ``P``."""

    def __init__(self, layout: StateLayout, x: np.ndarray | None = None, P: np.ndarray | None = None) -> None:
        self.layout = layout
        self.x = layout.initial_state() if x is None else np.array(x, dtype=float)
        self.P = layout.initial_covariance() if P is None else np.array(P, dtype=float)
        # Covariance resets after a non-finite value, in propagate and update alike. It travels
        # with copies, so a history snapshot knows how many resets its timeline has had.
        self.resets = 0
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
        reset = not self._store(P_new)
        return UpdateResult(nis=nis, innovation_var=s_diag, rejected=False, covariance_reset=reset)

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

