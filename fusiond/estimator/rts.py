"""The Rauch-Tung-Striebel smoothing gain, G = P_before F^T P_after^-1: the smoother's one solve.

The reference the compiled backend's fold (``_kernels.c`` rts_fold) is held to; the smoother reaches
either through the filter's backend (``Backend.rts_fold``). Pure maths: no clocks, no I/O.
"""

from __future__ import annotations

import numpy as np

__all__ = ["rts_gain"]


def rts_gain(P_before: np.ndarray, F: np.ndarray, P_after: np.ndarray) -> np.ndarray:
    """G = P_before F^T P_after^-1, on the components P_after gives any variance.

    A component held at an exact value (variance 0: two-D mode's z, roll, pitch, a block without
    prior) has no smoothing gain; the rest is a Cholesky solve (P_after is symmetric, so G^T =
    P_after^-1 F P_before: LAPACK's dposv called directly, a numpy solve's checks cost more than the
    arithmetic at this size), by least squares where P_after is singular there too."""
    C = F.dot(P_before)
    d = P_after.diagonal()
    if d.min() > 0.0:
        return _solve(P_after, C).T
    G = np.zeros_like(C)
    idx = np.flatnonzero(d > 0.0)
    if idx.size:
        G[:, idx] = _solve(P_after[idx[:, None], idx], C[idx]).T
    return G


def _solve(S: np.ndarray, C: np.ndarray) -> np.ndarray:
    """S^-1 C for a symmetric S: Cholesky, or least squares when S is not positive definite."""
    # imported here: scipy brings the logging module with it, which a replay that logs nothing never
    # imports (tests/unit/test_logs.py); only a smoothing replay pays for it
    from scipy.linalg.lapack import dposv

    _, x, info = dposv(S, C, lower=1, overwrite_a=0, overwrite_b=0)
    if info == 0:
        return x
    return np.linalg.lstsq(S, C, rcond=1e-12)[0]
