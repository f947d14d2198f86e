"""IMU attitude: orientation noise in the frame its key applies in, and the mounting (lean).

``orientation_noise`` is stated in the IMU's own axes (the policy rotates it into
base_link with ``extrinsic_rpy``), while the innovations are base-frame roll,
pitch, yaw. For a diagonal IMU-frame noise C, base component k has variance
sum_j R_kj^2 C_j (R: IMU -> base); the doctor solves that for the IMU-axis sigmas
it can see, so a noise measured on base pitch of an IMU rolled by 90 degrees is
reported where it belongs: on the IMU's yaw.

A steady lean of the estimate on level ground is a mounting rotation missing from
``extrinsic_rpy`` (``lean_of``); so is an accelerometer whose horizontal axes are turned
against the motion the wheels report (``mounting``: an IMU mounted yawed, which neither
the gyro nor the lean shows). The lean and mounting checks (``checks/lean.py``,
``checks/mounting.py``) share these, and both print the full mount (the tilt, the yaw
and the configured one composed, ``full_mount``) as one ready-to-paste value.
"""

from __future__ import annotations

import math
from itertools import chain

import numpy as np

from ..config import ImuSensor, PoseSensor
from ..core.sensors.imu.axes import seen_axes, weights
from ..estimator import rotation as rot
from .nis import ChannelStats
from .settled import Settled

LEAN_RAD = 0.03  # a mean lean of ~1.7 degrees that barely varies

CHUNK = 4096  # poses noted before their angles are computed (bounded memory)
AXES = ("roll", "pitch", "yaw")


class TiltStats:
    """Estimated roll/pitch over the run: a steady lean on level ground is a mounting error.

    Fed the estimate's quaternion at every published pose, so it only notes it; roll, pitch and their
    sums are computed a chunk at a time (the sums by ``np.cumsum``, which adds in order: the same floats
    as adding one pose at a time; the angles by ``math``, as ``rotation.to_rpy`` computes them)."""

    def __init__(self) -> None:
        self._pending: list[tuple[float, float, float, float]] = []
        self._n = 0
        self._sums = [0.0, 0.0]
        self._squares = [0.0, 0.0]
        self._up = [0.0, 0.0, 0.0]  # sum of world up seen in the body, R^T e_z (see ``inverted_lean``)

    def add_orientation(self, q: tuple[float, float, float, float]) -> None:
        """The estimate's attitude (x, y, z, w)."""
        self._pending.append(q)
        if len(self._pending) >= CHUNK:
            self._settle()

    n = Settled("_n")
    sums = Settled("_sums")
    squares = Settled("_squares")
    up = Settled("_up")

    def _settle(self) -> None:
        pending, n = self._pending, len(self._pending)
        if not n:
            return
        self._pending = []
        x, y, z, w = np.fromiter(chain.from_iterable(pending), dtype=float, count=4 * n).reshape(n, 4).T
        roll = np.fromiter(map(math.atan2, (2.0 * (w * x + y * z)).tolist(), (1.0 - 2.0 * (x * x + y * y)).tolist()),
                           dtype=float, count=n)
        sin_pitch = np.fmax(-1.0, np.fmin(1.0, 2.0 * (w * y - z * x)))  # max(-1, min(1, .)), NaN as Python's
        pitch = np.fromiter(map(math.asin, sin_pitch.tolist()), dtype=float, count=n)
        angles = np.column_stack((roll, pitch))
        self._n += n
        self._sums = np.cumsum(np.concatenate(([self._sums], angles)), axis=0)[-1].tolist()
        self._squares = np.cumsum(np.concatenate(([self._squares], angles * angles)), axis=0)[-1].tolist()
        up = np.column_stack((2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)))
        self._up = (np.array(self._up) + up.sum(axis=0)).tolist()


def imu_axis_sigmas(ch: ChannelStats, imu: ImuSensor) -> tuple[list[float], list[str]]:
    """Measured innovation sigmas in the IMU's axes (where orientation_noise applies), and for each
    IMU axis the base component it mostly lands on. Axes the channel cannot see keep the configured
    value (or NaN)."""
    R = rot.matrix(rot.from_rpy(*imu.extrinsic_rpy))  # IMU -> base
    rows = [AXES.index(c) for c in ch.components]
    M = ch.second_moment()
    W = np.array(weights(imu.extrinsic_rpy))[rows]
    var_base = np.array([M[i][i] for i in range(len(rows))])
    seen = list(seen_axes(imu.extrinsic_rpy, tuple(rows)))
    configured = list(imu.orientation_noise) if imu.orientation_noise is not None else [math.nan] * 3
    out = list(configured)
    if seen:
        fixed = [j for j in range(3) if j not in seen]
        rhs = var_base - sum((W[:, j] * (configured[j] ** 2 if math.isfinite(configured[j]) else 0.0)
                              for j in fixed), np.zeros(len(rows)))
        sol, *_ = np.linalg.lstsq(W[:, seen], rhs, rcond=None)
        for j, v in zip(seen, sol):
            out[j] = math.sqrt(max(float(v), imu.orientation_min_sigma ** 2))
    lands = [AXES[int(np.argmax(np.abs(R[:, j])))] for j in range(3)]
    return out, lands


def noise_suggestion(ch: ChannelStats, imu: ImuSensor) -> tuple[str, str, list[float]]:
    """('orientation_noise = [...]', a note on the frame, the line's values) in the IMU's axes."""
    sig, lands = imu_axis_sigmas(ch, imu)
    filled = [s if math.isfinite(s) else 1.0 for s in sig]
    note = "in the IMU's own axes (the key applies before extrinsic_rpy)"
    moved = [f"IMU {AXES[j]} lands on base {lands[j]}" for j in range(3) if lands[j] != AXES[j]]
    if moved:
        note += ": " + ", ".join(moved)
    return "orientation_noise = [" + ", ".join(f"{v:.4f}" for v in filled) + "]", note, filled


def full_mount(imu: ImuSensor | PoseSensor, lean: tuple[float, float] = (0.0, 0.0),
               yaw: float = 0.0) -> tuple[float, ...]:
    """The IMU's (or a camera's) true mounting as roll, pitch, yaw: Rz(yaw) * tilt(lean) * configured.

    A lean: estimated base = q_imu * q_cfg^-1 = yaw * q_true * q_cfg^-1, so on level ground
    q_true = tilt * q_cfg. A yaw error from the accelerometer is a turn about base z before that
    (see ``mounting``); for a configured mount without tilt it simply adds to the configured yaw."""
    q = rot.mul(rot.from_rpy(lean[0], lean[1], 0.0), rot.from_rpy(*imu.extrinsic_rpy))
    return rot.to_rpy(rot.mul(rot.from_rpy(0.0, 0.0, yaw), q))


def paste_mount(rpy: tuple[float, ...]) -> str:
    return "extrinsic_rpy = [" + ", ".join(f"{v:.4f}" for v in rpy) + "]"


def inverted_lean(tilt: TiltStats) -> tuple[list[float], list[float], list[int]] | None:
    """The lean of an estimate that is upside down on average, None otherwise.

    An IMU mounted upside down (its z axis down, ``extrinsic_rpy`` left at 0) makes the filter
    believe the robot is: roll near +-pi, wrapping between the two from pose to pose, so the
    angles' mean is near 0 and their spread near pi and the lean check above sees nothing (the
    position is still right: the gyro's inverted z rate about the inverted body z is the right
    turn about world z). The mean of world up seen in the body (R^T e_z) does not wrap: pointing
    down on average, its roll/pitch are the mount, and its length (1 when it never moves) gives
    the spread as the circular standard deviation sqrt(-2 ln |mean|)."""
    n = tilt.n
    if n <= 0:  # no attitude estimated (nothing published): nothing leans
        return None
    ux, uy, uz = (v / n for v in tilt.up)
    if not uz < 0.0:
        return None
    length = math.sqrt(ux * ux + uy * uy + uz * uz)
    roll, pitch = math.atan2(uy, uz), math.asin(max(-1.0, min(1.0, -ux / length)))
    spread = math.sqrt(-2.0 * math.log(min(length, 1.0))) if length > 0.0 else math.inf
    return [roll, pitch], [spread, spread], [k for k, a in enumerate((roll, pitch)) if abs(a) > LEAN_RAD
                                                 and spread < 0.5 * abs(a)]


def lean_of(tilt: TiltStats, min_updates: int = 50) -> tuple[list[float], list[float], list[int]]:
    """Mean and std of the estimated roll and pitch, and the axes that lean steadily."""
    if tilt.n < min_updates:
        return [], [], []
    inverted = inverted_lean(tilt)
    if inverted is not None:
        return inverted
    means, stds = [], []
    for k in range(2):
        m = tilt.sums[k] / tilt.n
        means.append(m)
        stds.append(math.sqrt(max(tilt.squares[k] / tilt.n - m * m, 0.0)))
    return means, stds, [k for k in range(2) if abs(means[k]) > LEAN_RAD and stds[k] < 0.5 * abs(means[k])]
