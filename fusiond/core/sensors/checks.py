"""Checks every sensor kind's policy shares: a refused sample and its reason, finite and plausible
values, unit quaternions, and the variance rules.

Message covariances lie (all zeros, 1e6 for "not measured", a gyro covariance ten
times the real noise), so every variance goes through a floor, a "not measured"
cap and the user's override from the config.
"""

from __future__ import annotations

import math

from ... import reasons

_QUAT_NORM_TOLERANCE = 0.1  # drivers round; anything further off is not a rotation
MAX_SPEED = 100.0  # m/s: beyond any wheeled robot, so a value this large is corrupt
MAX_RATE = 100.0  # rad/s: beyond any gyro's range (they saturate near 35 rad/s)


def plausible(values: tuple[float, float, float], limit: float) -> bool:
    a, b, c = values
    return -limit <= a <= limit and -limit <= b <= limit and -limit <= c <= limit


class Rejected(Exception):
    """A sample the core refuses; ``reason`` is a stable counter name."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


def unit_quaternion(q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """q normalised; a zero or clearly non-unit quaternion (beyond driver rounding) is refused."""
    unit = near_unit(q)
    if unit is not None:
        return unit
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n < 1e-6:
        raise Rejected(reasons.ZERO_QUATERNION)
    raise Rejected(reasons.NON_UNIT_QUATERNION, f"norm {n:.3f}")


def near_unit(q: tuple[float, float, float, float]) -> tuple[float, float, float, float] | None:
    """q normalised when its norm is 1 to driver rounding, else None (``unit_quaternion`` says why). Such a
    q is finite too (a NaN or infinite component makes the norm NaN or infinite): one test for both."""
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if abs(n - 1.0) <= _QUAT_NORM_TOLERANCE:
        return (x / n, y / n, z / n, w / n)
    return None


def finite(values) -> bool:
    return all(map(math.isfinite, values))


def resolve_variances(diag, floor: float, unmeasured: float, default: float) -> tuple[list[float], list[bool]]:
    """Floor tiny/zero variances; mark huge or non-finite ones as "not measured"."""
    out, measured = [], []
    for v in diag:
        if v >= unmeasured or v != v or v == math.inf:
            out.append(default)
            measured.append(False)
        else:
            out.append(v if v > floor else floor)
            measured.append(True)
    return out, measured


__all__ = ["MAX_RATE", "MAX_SPEED", "Rejected", "finite", "plausible", "resolve_variances", "unit_quaternion"]
