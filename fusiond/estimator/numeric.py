"""Central-difference Jacobians on the manifold, to check the analytic ones.

Slow by design (2n model evaluations): tests only, never the filter.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from . import rotation as rot
from .state import StateLayout


def _perturbed(layout: StateLayout, x: np.ndarray, j: int, eps: float) -> np.ndarray:
    dx = np.zeros(layout.error_dim)
    dx[j] = eps
    xp = x.copy()
    layout.boxplus(xp, dx)
    return xp


def transition_jacobian(
    layout: StateLayout, f: Callable[[np.ndarray], np.ndarray], x: np.ndarray, eps: float = 1e-6
) -> np.ndarray:
    """d (f(x [+] d) [-] f(x)) / d d at d = 0."""
    fx = f(x)
    F = np.empty((layout.error_dim, layout.error_dim))
    for j in range(layout.error_dim):
        plus = layout.boxminus(f(_perturbed(layout, x, j, eps)), fx)
        minus = layout.boxminus(f(_perturbed(layout, x, j, -eps)), fx)
        F[:, j] = (plus - minus) / (2 * eps)
    return F


def measurement_jacobian(
    layout: StateLayout, h: Callable[[np.ndarray], np.ndarray], x: np.ndarray, eps: float = 1e-6, angular: bool = True
) -> np.ndarray:
    """d h(x [+] d) / d d at d = 0; differences wrapped when h returns angles."""
    hx = h(x)
    H = np.empty((len(hx), layout.error_dim))
    for j in range(layout.error_dim):
        dp = h(_perturbed(layout, x, j, eps)) - hx
        dm = h(_perturbed(layout, x, j, -eps)) - hx
        if angular:
            dp = np.array([rot.wrap(a) for a in dp])
            dm = np.array([rot.wrap(a) for a in dm])
        H[:, j] = (dp - dm) / (2 * eps)
    return H
