"""Measurement models: innovation y = z [-] h(x), Jacobian H on the error state, noise R.

Orientation is observed as fixed-axis roll, pitch, yaw (the ROS covariance
convention), each residual wrapped to [-pi, pi]. Euler angles of q and -q are
equal, which settles the quaternion sign ambiguity. Against the global attitude
error, roll and pitch have an exactly zero yaw column, so a roll/pitch-only
update cannot move heading (nor, through it, position).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from . import rotation as rot
from .orientation_residual import rpy_jacobian, rpy_residual
from .state import StateLayout, attitude_of

if TYPE_CHECKING:
    from .backend import Backend

# Roll/pitch/yaw rows used by each IMU orientation mode.
ORIENTATION_ROWS: dict[str, tuple[int, ...]] = {
    "absolute": (0, 1, 2),
    "relative": (0, 1, 2),
    "roll_pitch": (0, 1),
}
RPY_NAMES = ("roll", "pitch", "yaw")


def orientation(
    layout: StateLayout, x: np.ndarray, z_rpy: tuple[float, float, float], cov: tuple[float, ...],
    rows: tuple[int, ...], backend: "Backend | None" = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observe the selected roll/pitch/yaw rows of the attitude; cov is row-major 3x3 (9-tuple).

    y and H come from ``backend`` (the filter's: ``ekf.backend``), ``rpy_residual`` without one."""
    if backend is None:
        y, H = rpy_residual(layout, x, z_rpy, rows)
    else:
        y, H = backend.orientation(layout, x, z_rpy, rows)
    return y, H, _noise_rows(cov, rows)


_NOISE_CACHE: dict[tuple[tuple[float, ...], tuple[int, ...]], np.ndarray] = {}
_NOISE_CACHE_SIZE = 64


def _noise_rows(cov: tuple[float, ...], rows: tuple[int, ...]) -> np.ndarray:
    """R: the ``rows`` x ``rows`` part of the row-major 3x3 ``cov``, read-only.

    A sensor's covariance is usually the same in every message (a driver's constant, or the
    configured override), so R is built once per distinct (cov, rows) and shared; the cache is
    emptied when a sensor whose covariance changes per message fills it.
    """
    key = (tuple(cov), tuple(rows))  # equal values share an R (0.0 and -0.0 alike: the same sum)
    R = _NOISE_CACHE.get(key)
    if R is None:
        if len(_NOISE_CACHE) >= _NOISE_CACHE_SIZE:
            _NOISE_CACHE.clear()
        R = np.array([[cov[3 * i + j] for j in rows] for i in rows], dtype=float)
        R.flags.writeable = False
        _NOISE_CACHE[key] = R
    return R


def orientation_with_offset(
    layout: StateLayout, x: np.ndarray, z_rpy: tuple[float, float, float], cov: tuple[float, ...],
    rows: tuple[int, ...], backend: "Backend | None" = None, offset: str = "yaw_offset",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``orientation`` of a sensor whose yaw reads heading + o (o: the ``offset`` block):
    h_yaw = yaw(q) + o, so the yaw row gains a 1 in o's column."""
    y, H, R = orientation(layout, x, z_rpy, cov, rows, backend)
    if 2 in rows:
        k = rows.index(2)
        y[k] = rot.wrap(float(y[k]) - float(x[layout.nominal[offset]][0]))
        H[k, layout.error[offset].start] = 1.0
    return y, H, R


def zero_rate(
    layout: StateLayout, x: np.ndarray, gyro: tuple[float, float, float], cov: tuple[float, ...]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """At standstill the true rate is zero, so the gyro reads its bias: z = b + noise."""
    bs = layout.nominal["gyro_bias"]
    y = np.array(gyro) - x[bs]
    H = np.zeros((3, layout.error_dim))
    H[:, layout.error["gyro_bias"]] = _I3
    return y, H, np.array(cov).reshape(3, 3)


_I3 = np.eye(3)


def bias_axis(
    layout: StateLayout, x: np.ndarray, axis: int, mean_rate: float, var: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One gyro axis at rest, averaged over a window: its mean reading is that axis's bias."""
    n0 = layout.nominal["gyro_bias"].start
    y = np.array((mean_rate - float(x[n0 + axis]),))
    H = np.zeros((1, layout.error_dim))
    H[0, layout.error["gyro_bias"].start + axis] = 1.0
    return y, H, np.array(((var,),))


# -- absolute and relative position/pose (GPS, pose sensors) ------------------------------------------------------

POSITION_NAMES = ("x", "y", "z")
POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")
DELTA_NAMES = ("dx", "dy", "dz", "drx", "dry", "drz")


def _lever(q: rot.Quat, t: tuple[float, float, float]) -> tuple[float, float, float]:
    R = rot.matrix9(q)
    return (R[0] * t[0] + R[1] * t[1] + R[2] * t[2], R[3] * t[0] + R[4] * t[1] + R[5] * t[2],
            R[6] * t[0] + R[7] * t[1] + R[8] * t[2])


def position(
    layout: StateLayout, x: np.ndarray, z: tuple[float, float, float], cov: tuple[float, ...],
    lever: tuple[float, float, float] = (0.0, 0.0, 0.0), error: str | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sensor at ``lever`` (base_link) observed in the world: h = p + R t (+ b).

    With global attitude errors R_true t = R t + dtheta x (R t), so dh/dtheta = -[R t]x:
    a lever arm makes the position observe heading while the robot turns. ``error`` names
    an additive 3-block of the state the sensor's reading carries (the GPS Gauss-Markov
    error): h gains + b and H an identity on its columns.
    """
    q = attitude_of(x)
    a0, a1, a2 = _lever(q, lever)
    p0, p1, p2 = x[0:3].tolist()  # (one slice: the same floats as float(x[i]) each, at a third of the cost)
    if error is not None:
        b0 = layout.nominal[error].start
        e0, e1, e2 = x[b0 : b0 + 3].tolist()
        y = np.array((z[0] - p0 - (a0 + e0), z[1] - p1 - (a1 + e1), z[2] - p2 - (a2 + e2)))
    else:
        y = np.array((z[0] - p0 - a0, z[1] - p1 - a1, z[2] - p2 - a2))
    H = layout.position_rows(error).copy()  # the identities on p (and b); -[R t]x below
    H[0, 4] = a2
    H[0, 5] = -a1
    H[1, 3] = -a2
    H[1, 5] = a0
    H[2, 3] = a1
    H[2, 4] = -a0
    return y, H, np.array(cov, dtype=float).reshape(3, 3)


def _select_rows(y6, H6: np.ndarray, cov: tuple[float, ...], rows: tuple[int, ...]):
    """The measured ``rows`` of a 6-row pose observation (x y z, then the three rotations)."""
    C = np.array(cov, dtype=float).reshape(6, 6)
    if len(rows) == 6:
        return np.array(y6), H6, C
    idx = list(rows)
    # the rows' block (np.ix_ costs more); the column pick leaves it in Fortran order, which the compiled update
    # refuses (the Python reference would run it): copied in C order
    return np.array([y6[i] for i in rows]), H6[idx], C[idx][:, idx].copy()


def pose(
    layout: StateLayout, x: np.ndarray, z_pos: tuple[float, float, float], z_rpy: tuple[float, float, float],
    cov: tuple[float, ...], rows: tuple[int, ...], lever: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position (lever arm) and roll/pitch/yaw of a rigidly mounted sensor; ``rows`` of the 6; cov 6x6 row-major."""
    yp, Hp, _ = position(layout, x, z_pos, (0.0,) * 9, lever)
    h_rpy, Hrpy = rpy_jacobian(attitude_of(x))
    y6 = (*yp.tolist(), *(rot.wrap(z_rpy[i] - h_rpy[i]) for i in range(3)))
    H6 = np.zeros((6, layout.error_dim))
    H6[0:3] = Hp
    H6[3:6, 3:6] = Hrpy
    return _select_rows(y6, H6, cov, rows)


def relative_pose(pos0: tuple[float, float, float], q0: rot.Quat, pos1: tuple[float, float, float], q1: rot.Quat
                  ) -> tuple[tuple[float, float, float], rot.Quat]:
    """Pose 1 in the frame of pose 0: (R0^T (p1 - p0), q0^-1 q1)."""
    R = rot.matrix9(q0)
    d = (pos1[0] - pos0[0], pos1[1] - pos0[1], pos1[2] - pos0[2])
    return ((R[0] * d[0] + R[3] * d[1] + R[6] * d[2], R[1] * d[0] + R[4] * d[1] + R[7] * d[2],
             R[2] * d[0] + R[5] * d[1] + R[8] * d[2]), rot.mul(rot.conj(q0), q1))


def turned_delta(mount: rot.Quat, dpos: tuple[float, float, float], dq: rot.Quat
                 ) -> tuple[tuple[float, float, float], rot.Quat]:
    """A delta (``relative_pose``: in the sensor's axes at the earlier pose) of a sensor turned by ``mount`` in
    base_link, as the same motion in base_link's axes at the sensor's origin: conjugated by the mount,
    (R_bs dp, q_bs dq q_bs^-1)."""
    R = rot.matrix9(mount)
    return ((R[0] * dpos[0] + R[1] * dpos[1] + R[2] * dpos[2], R[3] * dpos[0] + R[4] * dpos[1] + R[5] * dpos[2],
             R[6] * dpos[0] + R[7] * dpos[1] + R[8] * dpos[2]), rot.normalize(rot.mul(rot.mul(mount, dq),
                                                                                       rot.conj(mount))))


def delta_pose(
    layout: StateLayout, x: np.ndarray, x_prev: np.ndarray, z_dpos: tuple[float, float, float], z_dq: rot.Quat,
    cov: tuple[float, ...], rows: tuple[int, ...], lever: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The sensor's motion since the previous message, in the previous sensor pose's frame.

    ``x_prev`` is the filter's state at the previous message (held fixed: the
    delta is a measurement of the current state given it, as robot_pose_ekf fuses
    visual odometry). Translation r = R0^T (s1 - s0) with s = p + R t; rotation
    residual Log(dq_meas dq_pred^-1) in the previous frame, where dq_pred depends on
    dtheta through Exp(R0^T dtheta): both rows of H carry R0^T.
    """
    q0 = (float(x_prev[3]), float(x_prev[4]), float(x_prev[5]), float(x_prev[6]))
    q1 = attitude_of(x)
    l0, l1 = _lever(q0, lever), _lever(q1, lever)
    s0 = (float(x_prev[0]) + l0[0], float(x_prev[1]) + l0[1], float(x_prev[2]) + l0[2])
    s1 = (float(x[0]) + l1[0], float(x[1]) + l1[1], float(x[2]) + l1[2])
    r, dq = relative_pose(s0, q0, s1, q1)
    e = rot.log(rot.mul(z_dq, rot.conj(dq)))
    y6 = (z_dpos[0] - r[0], z_dpos[1] - r[1], z_dpos[2] - r[2], *e)
    R0T = rot.matrix(q0).T
    a0, a1, a2 = l1
    H6 = np.zeros((6, layout.error_dim))
    H6[0:3, 0:3] = R0T
    H6[0:3, 3:6] = R0T @ np.array(((0.0, a2, -a1), (-a2, 0.0, a0), (a1, -a0, 0.0)))
    H6[3:6, 3:6] = R0T
    return _select_rows(y6, H6, cov, rows)
