"""IMU noise calibration from a static recording: the noise a user should state.

Message covariances lie; the honest numbers come from the IMU itself standing
still. Orientation noise is the spread of roll/pitch/yaw after removing a linear
drift (a slowly settling filter is not noise), gyro noise the per-sample spread of
each axis, gyro bias its mean. The result prints as a ready-to-paste snippet.

Numbers from a robot that moved are not noise: a robot driving straight for a
minute looks quiet to a mean-rate test. So the recording is checked against what a
static IMU can show (its gyro and accelerometer spread against static floors) and,
when the config has an odometry sensor, against the wheels: clear motion refuses
(the CLI exits 1), borderline spread warns loudly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import ImuSensor, OdomSensor
from .errors import CalibrationError
from .estimator import rotation as rot
from .core.sensors import ImuSample, OdomSample

STATIC_RATE = 0.05  # rad/s: a mean rate above this is motion, not bias
# Static floors. A MEMS gyro at rest spreads by 0.001-0.01 rad/s and an accelerometer by 0.01-0.04 m/s^2
# (noise densities of 0.005-0.05 deg/s/sqrt(Hz) and 150-400 ug/sqrt(Hz) over a 100 Hz bandwidth). Above
# the warn floors the recording is suspect; above the refuse floors it is motion (a robot driving on a
# floor shakes its accelerometer by 0.3-1 m/s^2).
GYRO_WARN_SIGMA, GYRO_REFUSE_SIGMA = 0.02, 0.1  # rad/s
ACCEL_WARN_SIGMA, ACCEL_REFUSE_SIGMA = 0.15, 0.3  # m/s^2
ODOM_STATIC_SPEED = 0.01  # m/s: wheels faster than this (on average, or 5x in any sample) moved
ODOM_STATIC_RATE = 0.02  # rad/s


@dataclass
class Calibration:
    samples: int
    duration_s: float
    rate_hz: float
    orientation_sigma: tuple[float, float, float] | None  # roll pitch yaw, rad
    orientation_drift: tuple[float, float, float] | None  # rad/s, removed before the spread
    gyro_sigma: tuple[float, float, float] | None
    gyro_bias: tuple[float, float, float] | None
    stated_orientation_sigma: tuple[float, float, float] | None
    stated_gyro_sigma: tuple[float, float, float] | None
    static: bool
    accel_sigma: tuple[float, float, float] | None = None
    motion: tuple[str, ...] = ()  # why the recording looks like motion (empty: static)
    refuse: bool = False  # clear motion: the numbers must not be used

    def snippet(self, sensor: str = "imu") -> str:
        """What to paste into the config: comments, then for each table a "# paste into ..." line and
        its key = value lines only (no table header: a second [[sensors]] header would add a sensor,
        a second [filter] header is a TOML error), each to go inside the user's existing table."""
        lines = [f"# measured by fusiond calibrate-imu: {self.samples} samples over {self.duration_s:.1f} s "
                 f"({self.rate_hz:.1f} Hz)"]
        if not self.static:
            why = "; ".join(self.motion) or "mean rate above 0.05 rad/s"
            lines.append(f"# WARNING: the IMU was not static ({why}): numbers overstate the noise")
        keys = []
        if self.orientation_sigma:
            r, p, y = (max(v, 1e-4) for v in self.orientation_sigma)
            stated = ""
            if self.stated_orientation_sigma:
                sr, sp, sy = self.stated_orientation_sigma
                stated = f"; the messages state [{sr:.5f}, {sp:.5f}, {sy:.5f}]"
            keys.append(("orientation_noise", f"orientation_noise = [{r:.5f}, {p:.5f}, {y:.5f}]  # rad{stated}"))
        if self.gyro_sigma:
            g = max(max(self.gyro_sigma), 1e-5)
            stated = f"; the messages state {max(self.stated_gyro_sigma):.5f}" if self.stated_gyro_sigma else ""
            keys.append(("gyro_noise", f"gyro_noise = {g:.5f}  # rad/s, the largest axis{stated}"))
        if keys:
            lines.append(f'# paste into the [[sensors]] table named "{sensor}" (in place of any '
                         f'{" or ".join(k for k, _ in keys)} it has)')
            lines.extend(line for _, line in keys)
        if self.gyro_bias:
            b = max(abs(v) for v in self.gyro_bias)
            lines.append("")
            lines.append("# paste into the [filter] table (in place of any gyro_bias_sigma it has; "
                         "a config without one: a [filter] line first)")
            lines.append(f"gyro_bias_sigma = {max(2.0 * b, 1e-4):.5f}  # rad/s, twice the largest bias seen; "
                         f"bias was [{self.gyro_bias[0]:+.5f}, {self.gyro_bias[1]:+.5f}, {self.gyro_bias[2]:+.5f}]")
        return "\n".join(lines)


def _detrended_std(t: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """(std after removing a linear fit, slope)."""
    if len(t) < 3:
        return math.nan, 0.0
    A = np.vstack([t - t[0], np.ones_like(t)]).T
    coef, *_ = np.linalg.lstsq(A, values, rcond=None)
    resid = values - A @ coef
    return float(np.std(resid, ddof=2)), float(coef[0])


def calibrate(samples: list[ImuSample], cfg: ImuSensor | None = None,
              odom: list[OdomSample] | None = None) -> Calibration:
    """``odom``: the odometry over the same span, when an odometry sensor is configured."""
    if len(samples) < 10:
        raise CalibrationError(f"need at least 10 IMU samples to calibrate, got {len(samples)}")
    samples = sorted(samples, key=lambda s: s.stamp)
    t = np.array([s.stamp for s in samples])
    duration = float(t[-1] - t[0])
    rate = (len(t) - 1) / duration if duration > 0 else math.nan
    ori = [s for s in samples if s.orientation_covariance and s.orientation_covariance[0] != -1.0]
    orientation_sigma = drift = stated_ori = None
    if len(ori) >= 10:
        to = np.array([s.stamp for s in ori])
        rpy = np.unwrap(np.array([rot.to_rpy(rot.normalize(s.orientation)) for s in ori]), axis=0)
        fits = [_detrended_std(to, rpy[:, k]) for k in range(3)]
        orientation_sigma = tuple(f[0] for f in fits)
        drift = tuple(f[1] for f in fits)
        oc = np.array([[s.orientation_covariance[0], s.orientation_covariance[4], s.orientation_covariance[8]]
                       for s in ori])
        stated_ori = tuple(float(v) for v in np.sqrt(np.clip(oc.mean(axis=0), 0.0, None)))
    gyro_sigma = gyro_bias = stated_gyro = None
    gy = [s for s in samples if s.angular_velocity_covariance and s.angular_velocity_covariance[0] != -1.0]
    if len(gy) >= 10:
        w = np.array([s.angular_velocity for s in gy])
        if cfg is not None and any(cfg.extrinsic_rpy):
            R = rot.matrix(rot.from_rpy(*cfg.extrinsic_rpy))
            w = w @ R.T  # base_link axes, as the filter sees them
        gyro_bias = tuple(float(v) for v in w.mean(axis=0))
        gyro_sigma = tuple(float(v) for v in w.std(axis=0, ddof=1))
        gc = np.array([[s.angular_velocity_covariance[0], s.angular_velocity_covariance[4],
                        s.angular_velocity_covariance[8]] for s in gy])
        stated_gyro = tuple(float(v) for v in np.sqrt(np.clip(gc.mean(axis=0), 0.0, None)))
    motion: list[str] = []
    refuse = False
    if gyro_bias is not None:
        mean_rate = max(abs(v) for v in gyro_bias)
        if mean_rate >= STATIC_RATE:
            motion.append(f"mean gyro rate {mean_rate:.3f} rad/s, above {STATIC_RATE}")
            refuse = True
        spread = max(gyro_sigma)
        if spread > GYRO_WARN_SIGMA:
            motion.append(f"gyro spread {spread:.4f} rad/s, above a static IMU's {GYRO_WARN_SIGMA}")
            refuse = refuse or spread > GYRO_REFUSE_SIGMA
    acc = [s for s in samples if len(s.linear_acceleration_covariance) == 9
           and s.linear_acceleration_covariance[0] != -1.0 and any(s.linear_acceleration)]
    accel_sigma = None
    if len(acc) >= 10:
        a = np.array([s.linear_acceleration for s in acc])
        accel_sigma = tuple(float(v) for v in a.std(axis=0, ddof=1))
        spread = max(accel_sigma)
        if spread > ACCEL_WARN_SIGMA:
            motion.append(f"accelerometer spread {spread:.3f} m/s^2, above a static IMU's {ACCEL_WARN_SIGMA}")
            refuse = refuse or spread > ACCEL_REFUSE_SIGMA
    if odom:
        v = np.array([s.linear for s in odom])
        w = np.array([s.angular for s in odom])
        speed = np.linalg.norm(v, axis=1)
        turn = np.abs(w[:, 2])
        if speed.mean() > ODOM_STATIC_SPEED or speed.max() > 5 * ODOM_STATIC_SPEED or \
                turn.mean() > ODOM_STATIC_RATE or turn.max() > 5 * ODOM_STATIC_RATE:
            motion.append(f"the odometry moved (mean speed {speed.mean():.3f} m/s, max {speed.max():.3f}; "
                          f"mean turn {turn.mean():.3f} rad/s)")
            refuse = True
    return Calibration(len(samples), duration, rate, orientation_sigma, drift, gyro_sigma, gyro_bias, stated_ori,
                       stated_gyro, not motion, accel_sigma, tuple(motion), refuse)


def record_imu(session, sensor: ImuSensor, duration: float, odom: OdomSensor | None = None):
    """Collect a sensor's samples from Zenoh for ``duration`` seconds (undecodable ones skipped).
    With ``odom``, its samples too: returns (imu samples, odometry samples) then."""
    import threading
    import time

    from .codecs import DecodeError
    from .core.sensors import make_decoder

    lock = threading.Lock()

    def collector(kind: str, cfg):
        decode = make_decoder(kind, cfg.encoding, cfg.name)
        out: list = []

        def on_sample(sample) -> None:
            try:
                s = decode(sample.payload.to_bytes())
            except DecodeError:
                return
            with lock:
                out.append(s)

        return out, session.declare_subscriber(cfg.key, on_sample)

    samples, sub = collector("imu", sensor)
    odom_samples, odom_sub = collector("odom", odom) if odom is not None else ([], None)
    try:
        time.sleep(duration)
    finally:
        sub.undeclare()
        if odom_sub is not None:
            odom_sub.undeclare()
    with lock:
        return (list(samples), list(odom_samples)) if odom is not None else list(samples)
