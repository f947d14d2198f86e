"""3x3 matrix algebra on row-major 9-tuples of floats.

In the filter's inner loop a numpy call on a 3x3 costs about a microsecond of
overhead; the same product in Python floats costs less.
"""

from __future__ import annotations

Mat3 = tuple[float, ...]  # row-major, 9 floats


def sandwich(A: Mat3, S: Mat3, scale: float = 1.0) -> tuple:
    """scale * A S A^T for 3x3 A (row-major 9-tuple) and S (row-major 9-list); nested tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    s0, s1, s2, s3, s4, s5, s6, s7, s8 = S
    # M = A S
    m0 = a0 * s0 + a1 * s3 + a2 * s6
    m1 = a0 * s1 + a1 * s4 + a2 * s7
    m2 = a0 * s2 + a1 * s5 + a2 * s8
    m3 = a3 * s0 + a4 * s3 + a5 * s6
    m4 = a3 * s1 + a4 * s4 + a5 * s7
    m5 = a3 * s2 + a4 * s5 + a5 * s8
    m6 = a6 * s0 + a7 * s3 + a8 * s6
    m7 = a6 * s1 + a7 * s4 + a8 * s7
    m8 = a6 * s2 + a7 * s5 + a8 * s8
    return _times_transposed((m0, m1, m2, m3, m4, m5, m6, m7, m8), A, scale)


def sandwich_diag(A: Mat3, s0: float, s4: float, s8: float, scale: float = 1.0) -> tuple:
    """``sandwich`` for a diagonal S = diag(s0, s4, s8) (the usual sensor covariance).

    M = A S scales A's columns; the products are the general ones' floats (their other terms
    are exact zeros), so both give the same bits.
    """
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    m0, m1, m2 = a0 * s0, a1 * s4, a2 * s8
    m3, m4, m5 = a3 * s0, a4 * s4, a5 * s8
    m6, m7, m8 = a6 * s0, a7 * s4, a8 * s8
    return _times_transposed((m0, m1, m2, m3, m4, m5, m6, m7, m8), A, scale)


def _times_transposed(M: Mat3, A: Mat3, scale: float) -> tuple:
    """scale * M A^T as nested tuples, its upper triangle mirrored: M = A S with S symmetric makes
    it symmetric (the second half of ``sandwich`` and ``sandwich_diag``)."""
    m0, m1, m2, m3, m4, m5, m6, m7, m8 = M
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    c00 = (m0 * a0 + m1 * a1 + m2 * a2) * scale
    c01 = (m0 * a3 + m1 * a4 + m2 * a5) * scale
    c02 = (m0 * a6 + m1 * a7 + m2 * a8) * scale
    c11 = (m3 * a3 + m4 * a4 + m5 * a5) * scale
    c12 = (m3 * a6 + m4 * a7 + m5 * a8) * scale
    c22 = (m6 * a6 + m7 * a7 + m8 * a8) * scale
    return ((c00, c01, c02), (c01, c11, c12), (c02, c12, c22))


def mul(A: Mat3, B: Mat3, k: float = 1.0) -> Mat3:
    """k * A B for row-major 3x3 tuples."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = B
    return (
        (a0 * b0 + a1 * b3 + a2 * b6) * k, (a0 * b1 + a1 * b4 + a2 * b7) * k, (a0 * b2 + a1 * b5 + a2 * b8) * k,
        (a3 * b0 + a4 * b3 + a5 * b6) * k, (a3 * b1 + a4 * b4 + a5 * b7) * k, (a3 * b2 + a4 * b5 + a5 * b8) * k,
        (a6 * b0 + a7 * b3 + a8 * b6) * k, (a6 * b1 + a7 * b4 + a8 * b7) * k, (a6 * b2 + a7 * b5 + a8 * b8) * k,
    )


def apply(A: Mat3, v: tuple[float, float, float]) -> tuple[float, float, float]:
    x, y, z = v
    return (A[0] * x + A[1] * y + A[2] * z, A[3] * x + A[4] * y + A[5] * z, A[6] * x + A[7] * y + A[8] * z)


def apply_transposed(A: Mat3, v: tuple[float, float, float]) -> tuple[float, float, float]:
    """A^T v (for a rotation: back into the body frame)."""
    return (A[0] * v[0] + A[3] * v[1] + A[6] * v[2], A[1] * v[0] + A[4] * v[1] + A[7] * v[2],
            A[2] * v[0] + A[5] * v[1] + A[8] * v[2])


def flat(nested: tuple) -> Mat3:
    """Nested 3x3 (as ``sandwich`` returns) to a row-major 9-tuple."""
    return (*nested[0], *nested[1], *nested[2])


def diag(a: float, b: float, c: float) -> Mat3:
    return (a, 0.0, 0.0, 0.0, b, 0.0, 0.0, 0.0, c)


def add_diag(A: Mat3, d: float) -> Mat3:
    """A + d I."""
    return (A[0] + d, A[1], A[2], A[3], A[4] + d, A[5], A[6], A[7], A[8] + d)
