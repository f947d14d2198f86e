"""A generic error-state extended Kalman filter.

It knows nothing of sensors or time: a model hands it the propagated nominal
state with F and Q, or an innovation with H and R. The gain comes from a
Cholesky factorisation of S (LAPACK potrf/potrs, ~1 us on small S) instead of an
explicit inverse; the covariance update is Joseph form, then symmetrised, which
keeps it positive semi-definite in floating point.
"""

from __future__ import annotations

import math

import msgspec
import numpy as np
from scipy.linalg.lapack import dpotrf, dpotrs

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
        self._eye = np.eye(layout.error_dim)
        self.resets = 0  # covariance resets after a non-finite value

    # -- propagation -------------------------------------------------------
    def propagate(self, x_new: np.ndarray, F: np.ndarray, Q: np.ndarray) -> bool:
        """Accept a propagated state; False if the covariance had to be reset."""
        self.x = x_new
        P = F @ self.P @ F.T
        P += Q
        return self._store(P)

    def add_noise(self, Q: np.ndarray) -> bool:
        return self._store(self.P + Q)

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
        PHt = P @ H.T
        S = H @ PHt
        S += R
        L, info = dpotrf(S, lower=1, clean=0, overwrite_a=0)
        s_diag = np.diagonal(S).tolist()
        if info != 0:
            return UpdateResult(nis=math.nan, innovation_var=s_diag, rejected=True, singular=True)
        Sinv_y, _ = dpotrs(L, y, lower=1)
        nis = float(y @ Sinv_y)
        if not math.isfinite(nis):
            return UpdateResult(nis=nis, innovation_var=s_diag, rejected=True, singular=True)
        if math.sqrt(max(nis, 0.0)) > threshold:
            return UpdateResult(nis=nis, innovation_var=s_diag, rejected=True)
        KT, _ = dpotrs(L, PHt.T, lower=1)  # K^T = S^-1 H P
        K = KT.T
        if mask is not None:
            K = K * mask[:, None]
            KT = K.T
        dx = K @ y
        IKH = self._eye - K @ H
        P_new = IKH @ P @ IKH.T
        P_new += K @ R @ KT
        self.layout.boxplus(self.x, dx)
        self._store(P_new)
        return UpdateResult(nis=nis, innovation_var=s_diag, rejected=False)

    # -- covariance hygiene ------------------------------------------------
    def _store(self, P: np.ndarray) -> bool:
        P = 0.5 * (P + P.T)
        d = np.diagonal(P)
        if not np.isfinite(P).all():
            self.P = self.layout.initial_covariance()
            self.resets += 1
            return False
        if (d < 0.0).any():
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
        c._eye = self._eye
        c.resets = self.resets
        return c

    def snapshot(self) -> tuple[np.ndarray, np.ndarray]:
        return self.x.copy(), self.P.copy()

    def restore(self, snap: tuple[np.ndarray, np.ndarray]) -> None:
        self.x = snap[0].copy()
        self.P = snap[1].copy()
