"""Rotation helpers on plain floats.

Quaternions are (x, y, z, w) tuples, as in ROS. Everything here runs in the
filter's inner loop, so it avoids scipy Rotation objects (7-18 us a call) and
numpy for 4-vectors, where Python float arithmetic is several times faster.
Euler angles are fixed-axis roll-pitch-yaw (R = Rz(yaw) Ry(pitch) Rx(roll)), as in
URDF and tf2.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import EstimatorError

Quat = tuple[float, float, float, float]
IDENTITY: Quat = (0.0, 0.0, 0.0, 1.0)
TWO_PI = 2.0 * math.pi


def wrap(angle: float) -> float:
    """Angle in [-pi, pi)."""
    return (angle + math.pi) % TWO_PI - math.pi


def normalize(q: Quat) -> Quat:
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0.0 or not math.isfinite(n):
        raise EstimatorError("quaternion has zero or non-finite norm")
    return (x / n, y / n, z / n, w / n)


def mul(a: Quat, b: Quat) -> Quat:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def conj(q: Quat) -> Quat:
    return (-q[0], -q[1], -q[2], q[3])


def exp(vx: float, vy: float, vz: float) -> Quat:
    """Quaternion of the rotation vector v (axis * angle)."""
    angle = math.sqrt(vx * vx + vy * vy + vz * vz)
    if angle < 1e-8:
        # Second-order series keeps exp/log consistent to machine precision near zero.
        return normalize((0.5 * vx, 0.5 * vy, 0.5 * vz, 1.0 - angle * angle / 8.0))
    s = math.sin(0.5 * angle) / angle
    return (vx * s, vy * s, vz * s, math.cos(0.5 * angle))


def _mul_unit(a: Quat, b: Quat) -> Quat:
    """normalize(mul(a, b)) in one call: the same float expressions as the two."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    x = aw * bx + ax * bw + ay * bz - az * by
    y = aw * by - ax * bz + ay * bw + az * bx
    z = aw * bz + ax * by - ay * bx + az * bw
    w = aw * bw - ax * bx - ay * by - az * bz
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 0.0 or not math.isfinite(n):
        raise EstimatorError("quaternion has zero or non-finite norm")
    return (x / n, y / n, z / n, w / n)


def advance(q: Quat, vx: float, vy: float, vz: float) -> Quat:
    """normalize(mul(q, exp(v))): q moved by the body-frame rotation vector v (attitude propagation)."""
    return _mul_unit(q, exp(vx, vy, vz))


def turn(vx: float, vy: float, vz: float, q: Quat) -> Quat:
    """normalize(mul(exp(v), q)): q turned by the world-frame rotation vector v (the global attitude
    boxplus)."""
    return _mul_unit(exp(vx, vy, vz), q)


def log(q: Quat) -> tuple[float, float, float]:
    """Rotation vector of q, angle in [0, pi]: q and -q give the same answer."""
    x, y, z, w = q
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-8:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    k = 2.0 * math.atan2(s, w) / s
    return (x * k, y * k, z * k)


def matrix(q: Quat) -> np.ndarray:
    """Rotation matrix of a unit quaternion (body to world)."""
    x, y, z, w = q
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return np.array(
        (
            (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)),
            (2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)),
            (2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)),
        )
    )


def matrix9(q: Quat) -> tuple[float, ...]:
    """Rotation matrix of a unit quaternion as a row-major 9-tuple of floats."""
    x, y, z, w = q
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy),
        2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx),
        2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy),
    )


def from_rpy(roll: float, pitch: float, yaw: float) -> Quat:
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def yaw(q: Quat) -> float:
    """The yaw of to_rpy(q), without the roll and pitch."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def to_rpy(q: Quat) -> tuple[float, float, float]:
    x, y, z, w = q
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    sp = 2.0 * (w * y - z * x)
    pitch = math.asin(max(-1.0, min(1.0, sp)))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return roll, pitch, yaw
