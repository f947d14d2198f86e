"""IMU mounting yaw: the accelerometer's horizontal axes against the motion the wheels and gyro report.

An IMU turned about z (90 degrees, 180 degrees) with ``extrinsic_rpy`` left at 0 is
invisible to the gyro check (a rotation about z leaves the z rate as it is) and, on
level ground, to the lean check. The accelerometer shows it: while driving with
speed v and yaw rate w, the body-frame specific force minus gravity is
(dv/dt, v w) on base_link's x (forward) and y (left) axes (REP-103; the centripetal
acceleration of a turn to the left points left). Put through the configured
rotation, an IMU whose true mounting differs by a turn ``delta`` about base z gives

    m = Rz(-delta) e + b,    e = (dv/dt, v w),

with b a constant (accelerometer bias, gravity leaking through a tilt the IMU's own
attitude did not remove). With c = cos(delta), s = sin(delta) that is linear in
(c, s, b_x, b_y); least squares over the driving samples gives delta = atan2(s, c)
and, from the residual scatter, its standard error. The true mounting is then
Rz(delta) composed before the configured one, so the key to paste is the configured
triple with delta added to its yaw.

Both series are smoothed over SMOOTH_BINS bins (the same box for both, so the
relation stays linear); every window is fitted, and the standard error counts the
n / SMOOTH_BINS independent samples they hold.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import ImuSensor
from .series import BIN_S, Series


# A yaw error delta in the mounting puts sin(delta) of the IMU's roll on base pitch (and of the
# centripetal tilt correction on the wrong axis): at 0.05 rad (3 degrees) a 0.1 rad side slope
# becomes a 0.005 rad pitch error, a sixth of the lean check's LEAN_RAD (0.03), i.e. 0.5 % of the
# distance driven in height. Smaller errors are not worth a verdict.
MOUNT_YAW_RAD = 0.05
MOUNT_MIN_SPEED = 0.2  # m/s either way: slower, dv/dt and v w are too small and the wheels too coarse to compare
SMOOTH_BINS = 5  # 1 s at 5 Hz: vibration averaged, manoeuvres (seconds long) kept
MOUNT_MIN_SAMPLES = 20  # decimated driving samples: 20 s of driving
# |(c, s)| is 1 for an accelerometer that sees the motion turned; at half or twice that it is not a turn
# (a mirrored axis, e.g. one sign flipped in the driver, fits with |(c, s)| near 0; wrong units near 10):
# the angle then means nothing and is not named
GAIN_BAND = (0.5, 2.0)
MAX_ALIGN_S = 1.5 * BIN_S  # an accelerometer bin with no wheel bin this close is not compared
MOUNT_Z_SIGMAS = 3.0  # a mounting yaw is named beyond 3 standard errors (0.27 % two-sided)


@dataclass
class MountYaw:
    """The fitted mounting yaw error (rad; the true mount is Rz(delta) * configured) and its evidence."""

    delta: float
    se: float
    gain: float  # |(c, s)|: ~1 when the accelerometer and the wheels agree on the size of the motion
    samples: int
    expected_rms: float  # m/s^2: how much horizontal acceleration the driving gave to fit against
    residual_rms: float
    bias_x: float = 0.0  # m/s^2: b on base x (accelerometer bias, gravity leaking through a tilt), for checks/coast.py

    @property
    def named(self) -> bool:
        """Clearly nonzero: beyond the threshold and beyond MOUNT_Z_SIGMAS standard errors."""
        return self.turned and abs(self.delta) > max(MOUNT_YAW_RAD, MOUNT_Z_SIGMAS * self.se)

    @property
    def resolved(self) -> bool:
        """Known well enough to say the mounting agrees (a 3-sigma band inside the threshold)."""
        return self.turned and MOUNT_Z_SIGMAS * self.se < MOUNT_YAW_RAD

    @property
    def turned(self) -> bool:
        """The accelerometer sees the motion at its size, only turned: the fit's angle is meaningful."""
        return GAIN_BAND[0] <= self.gain <= GAIN_BAND[1]

    def evidence(self) -> dict[str, float]:
        return {"mount_yaw_error_rad": self.delta, "mount_yaw_error_se": self.se, "accel_vs_wheels_gain": self.gain,
                "mount_fit_samples": float(self.samples), "mount_expected_rms": self.expected_rms,
                "mount_residual_rms": self.residual_rms}


def _box(x: np.ndarray, k: int) -> np.ndarray:
    return np.convolve(x, np.ones(k) / k, mode="same")


def _near(t: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """For each t, whether a sample of ``ref`` (sorted) lies within MAX_ALIGN_S."""
    i = np.clip(np.searchsorted(ref, t), 1, len(ref) - 1)
    return np.minimum(np.abs(ref[i] - t), np.abs(ref[i - 1] - t)) <= MAX_ALIGN_S


def mount_yaw_fit(series: Series, imu: ImuSensor | None) -> MountYaw | None:
    """The fit, or None without an accelerometer, wheels, or enough driving to tell."""
    if imu is None or len(series.acc_t) < SMOOTH_BINS * MOUNT_MIN_SAMPLES or len(series.odom_t) < 10:
        return None
    ta = np.asarray(series.acc_t)
    mx, my = np.asarray(series.acc_x), np.asarray(series.acc_y)
    to, vo = np.asarray(series.odom_t), np.asarray(series.odom_v)
    # dv/dt from neighbouring wheel bins (central differences; NaN across a silence)
    dvdt = np.gradient(vo, to) if len(to) > 2 else np.zeros(len(to))
    gaps = np.diff(to) > 2.5 * BIN_S
    bad = np.zeros(len(to), dtype=bool)
    bad[:-1] |= gaps
    bad[1:] |= gaps
    # ... and beside a bin exactly at rest: a drive dropping to zero at speed (a coast, a lost frame) is no
    # deceleration (a real stop passes through speeds below MOUNT_MIN_SPEED first, which are not fitted anyway)
    rest = np.asarray(series.odom_rest, dtype=bool)
    bad[:-1] |= rest[1:]
    bad[1:] |= rest[:-1]
    dvdt[bad] = np.nan
    if len(series.gyro_t) >= 10:  # the gyro's z: a turn about z leaves it unchanged, and it is not skid-steer-scaled
        tw, ww = np.asarray(series.gyro_t), np.asarray(series.gyro_z)
        ok_w = _near(ta, tw)
    else:
        tw, ww = to, np.asarray(series.odom_wz)
        ok_w = np.ones(len(ta), dtype=bool)
    v = np.interp(ta, to, vo)
    ex = np.interp(ta, to, dvdt)
    ey = v * np.interp(ta, tw, ww)
    # either way: driven backwards, the body still feels (dv/dt, v w) with v signed
    valid = (_near(ta, to) & ok_w & np.isfinite(ex) & np.isfinite(mx) & np.isfinite(my)
             & (np.abs(v) > MOUNT_MIN_SPEED))
    # the same box on both sides keeps m = Rz(-delta) e + b; a window is used only when all of it is valid
    whole = _box(valid.astype(float), SMOOTH_BINS) > 1.0 - 1e-9
    cols = [_box(np.where(valid, a, 0.0), SMOOTH_BINS) for a in (mx, my, ex, ey)]
    idx = np.nonzero(whole)[0]
    if len(idx) < SMOOTH_BINS * MOUNT_MIN_SAMPLES:
        return None
    mx, my, ex, ey = (c[idx] for c in cols)
    n = len(idx)
    # rows: m_x = c e_x + s e_y + b_x ; m_y = -s e_x + c e_y + b_y
    A = np.zeros((2 * n, 4))
    A[:n, 0], A[:n, 1], A[:n, 2] = ex, ey, 1.0
    A[n:, 0], A[n:, 1], A[n:, 3] = ey, -ex, 1.0
    y = np.concatenate([mx, my])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    c, s = float(coef[0]), float(coef[1])
    r2 = c * c + s * s
    expected_rms = float(np.sqrt(np.mean(ex * ex + ey * ey)))
    if r2 <= 0.0 or expected_rms <= 0.0:
        return None
    resid = y - A @ coef
    sigma2 = float(resid @ resid) / max(2 * n - 4, 1)
    # Every window is fitted (one every SMOOTH_BINS-th would make the angle depend on which bin the
    # recording happens to start at), but neighbouring windows share SMOOTH_BINS - 1 of their bins: the
    # fit holds n / SMOOTH_BINS independent samples' information, so the covariance as if they were
    # independent is scaled by SMOOTH_BINS.
    try:
        cov = SMOOTH_BINS * sigma2 * np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:
        return None
    # delta = atan2(s, c): gradient (-s, c) / r2
    var = (s * s * cov[0, 0] + c * c * cov[1, 1] - 2.0 * c * s * cov[0, 1]) / (r2 * r2)
    return MountYaw(math.atan2(s, c), math.sqrt(max(var, 0.0)), math.sqrt(r2), n // SMOOTH_BINS, expected_rms,
                    math.sqrt(sigma2), float(coef[2]))
