"""IMU noise calibration from a static recording: the noise a user should state.

Message covariances lie; the honest numbers come from the IMU itself standing
still. Orientation noise is the spread of roll/pitch/yaw after removing a linear
drift (a slowly settling filter is not noise), gyro noise the per-sample spread of
each axis, gyro bias its mean. The result prints as a ready-to-paste snippet.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .config import ImuSensor
from .errors import CalibrationError
from .estimator import rotation as rot
from .samples import ImuSample

STATIC_RATE = 0.05  # rad/s: a mean rate above this is motion, not bias


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

    def snippet(self, sensor: str = "imu") -> str:
        lines = [f"# measured by fusiond calibrate-imu: {self.samples} samples over {self.duration_s:.1f} s "
                 f"({self.rate_hz:.1f} Hz)"]
        if not self.static:
            lines.append("# WARNING: the IMU was not static (mean rate above 0.05 rad/s): numbers overstate the noise")
        lines.append(f"[[sensors]]  # {sensor}: add these keys to its table")
        if self.orientation_sigma:
            r, p, y = (max(v, 1e-4) for v in self.orientation_sigma)
            lines.append(f"orientation_noise = [{r:.5f}, {p:.5f}, {y:.5f}]  # rad")
            if self.stated_orientation_sigma:
                sr, sp, sy = self.stated_orientation_sigma
                lines.append(f"#   the messages state [{sr:.5f}, {sp:.5f}, {sy:.5f}]")
        if self.gyro_sigma:
            g = max(max(self.gyro_sigma), 1e-5)
            lines.append(f"gyro_noise = {g:.5f}  # rad/s, the largest axis")
            if self.stated_gyro_sigma:
                lines.append(f"#   the messages state {max(self.stated_gyro_sigma):.5f}")
        if self.gyro_bias:
            b = max(abs(v) for v in self.gyro_bias)
            lines.append("")
            lines.append("[filter]")
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


def calibrate(samples: list[ImuSample], cfg: ImuSensor | None = None) -> Calibration:
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
    static = True
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
        static = max(abs(v) for v in gyro_bias) < STATIC_RATE
    return Calibration(len(samples), duration, rate, orientation_sigma, drift, gyro_sigma, gyro_bias, stated_ori,
                       stated_gyro, static)


def record_imu(session, sensor: ImuSensor, duration: float) -> list[ImuSample]:
    """Collect a sensor's samples from Zenoh for ``duration`` seconds (undecodable ones skipped)."""
    import threading
    import time

    from .codecs import DecodeError, make_decoder

    decode = make_decoder("imu", sensor.encoding, sensor.name)
    samples: list[ImuSample] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        try:
            s = decode(sample.payload.to_bytes())
        except DecodeError:
            return
        with lock:
            samples.append(s)

    sub = session.declare_subscriber(sensor.key, on_sample)
    try:
        time.sleep(duration)
    finally:
        sub.undeclare()
    with lock:
        return list(samples)
