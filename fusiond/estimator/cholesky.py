"""Cholesky whitening of the small innovation covariance S, in Python floats.

With S = L L^T, the whitened innovation z = L^-1 y gives NIS = z.z, and with
W = L^-1 H P the gain terms follow without ever forming S^-1:
    dx = W^T z,    K S K^T = K H P = W^T W.
S is at most a few rows (3 for an orientation update), where plain float
arithmetic beats a LAPACK call through scipy (and spares the process a 0.2 s
scipy.linalg import).
"""

from __future__ import annotations

import math


def _inverse_root(s: float) -> float | None:
    """L^-1 of the 1x1 S = [s], None unless s is positive and finite."""
    if not s > 0.0 or s == math.inf:
        return None
    return 1.0 / math.sqrt(s)


def _inverse_factor_2x2(a: float, b: float, c: float) -> tuple[float, float, float] | None:
    """(i00, i10, i11), the entries of L^-1 for S = [[a, b], [b, c]] = L L^T in closed form, None when
    S is not positive definite."""
    if not a > 0.0 or a == math.inf:
        return None
    l00 = math.sqrt(a)
    l10 = b / l00
    d = c - l10 * l10
    if not d > 0.0 or d == math.inf:
        return None
    l11 = math.sqrt(d)
    i00, i11 = 1.0 / l00, 1.0 / l11
    return i00, -l10 * i00 * i11, i11


def whiten(S: list[list[float]], y: list[float]) -> tuple[list[list[float]], list[float]] | None:
    """(L^-1, L^-1 y) for S = L L^T, or None when S is not positive definite.

    Closed forms for the 1x1 and 2x2 cases the IMU updates produce; a loop otherwise.
    """
    m = len(S)
    if m == 1:
        r = _inverse_root(S[0][0])
        if r is None:
            return None
        return [[r]], [y[0] * r]
    if m == 2:
        inv = _inverse_factor_2x2(S[0][0], S[1][0], S[1][1])
        if inv is None:
            return None
        i00, i10, i11 = inv
        return [[i00, 0.0], [i10, i11]], [i00 * y[0], i10 * y[0] + i11 * y[1]]
    L = factor(S)
    if L is None:
        return None
    inv = inverse_lower(L)
    return inv, [sum(a * b for a, b in zip(row, y)) for row in inv]


def gain_rows(S: list[list[float]], y: list[float]) -> tuple[list[float], list[float]] | None:
    """(z, rows) for S = L L^T, or None when S is not positive definite.

    z = L^-1 y is the whitened innovation; ``rows`` is the (m + 1) x m matrix [L^-1; (L^-T z)^T]
    row-major. Left-multiplying H P by it gives W = L^-1 H P and, in its last row, the
    correction K y = P H^T S^-1 y = (H P)^T L^-T z, in one product. Closed forms for the 1x1
    and 2x2 cases the IMU updates produce (the same floats as ``whiten``).
    """
    m = len(S)
    if m == 1:
        r = _inverse_root(S[0][0])
        if r is None:
            return None
        z0 = y[0] * r
        return [z0], [r, z0 * r]
    if m == 2:
        inv = _inverse_factor_2x2(S[0][0], S[1][0], S[1][1])
        if inv is None:
            return None
        i00, i10, i11 = inv
        z0, z1 = i00 * y[0], i10 * y[0] + i11 * y[1]
        return [z0, z1], [i00, 0.0, i10, i11, z0 * i00 + z1 * i10, z1 * i11]
    white = whiten(S, y)
    if white is None:
        return None
    inv, z = white
    rows = [v for row in inv for v in row]
    rows += [sum([z[i] * inv[i][j] for i in range(j, m)]) for j in range(m)]  # L^-T z
    return z, rows


def factor(S: list[list[float]]) -> list[list[float]] | None:
    """Lower-triangular L with S = L L^T, or None when S is not positive definite."""
    m = len(S)
    L = [[0.0] * m for _ in range(m)]
    for i in range(m):
        Li = L[i]
        for j in range(i + 1):
            Lj = L[j]
            acc = S[i][j]
            for k in range(j):
                acc -= Li[k] * Lj[k]
            if i == j:
                if not acc > 0.0 or not math.isfinite(acc):
                    return None
                Li[i] = math.sqrt(acc)
            else:
                Li[j] = acc / Lj[j]
    return L


def inverse_lower(L: list[list[float]]) -> list[list[float]]:
    """L^-1 by forward substitution (a solve against the identity, column by column)."""
    m = len(L)
    inv = [[0.0] * m for _ in range(m)]
    for c in range(m):
        for i in range(c, m):
            acc = 1.0 if i == c else 0.0
            Li = L[i]
            for k in range(c, i):
                acc -= Li[k] * inv[k][c]
            inv[i][c] = acc / Li[i]
    return inv
