"""A robot driven through a schedule of segments, for standstill and gyro-bias tests.

Each segment has a duration, a true speed and yaw rate, and what the odometry
reports: the truth (plus noise), or exactly zero (a drive that reads zero while
the vehicle still coasts or turns). The gyro reads the true body rates plus a
constant per-axis bias and white noise; the IMU's roll/pitch may drift (an IMU
whose own attitude filter wanders), which makes the filter's x/y bias wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

T0 = 1000.0
GRAVITY = 9.80665


@dataclass
class Segment:
    duration: float
    speed: float = 0.0
    yaw_rate: float = 0.0
    odom_reads_zero: bool = False  # the drive reports exactly zero although the vehicle moves
    ramp_s: float | None = None  # this segment's speed is reached over this long (None: the world's ramp_s)


@dataclass
class RestWorld:
    segments: list[Segment]
    odom_rate: float = 50.0
    imu_rate: float = 100.0
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_bias_drift: float = 0.0  # rad/s per s: the z bias drifts steadily (temperature)
    wheel_yaw_lost: bool = False  # the driver sends its yaw rate as exactly 0 with variance 0 (it has none)
    gyro_sigma: float = 0.002
    gyro_stated_sigma: float | None = None  # the covariance the driver states (None: the true sigma)
    ramp_s: float = 0.0  # > 0: each segment's speed is reached over this long (the accelerometer feels it)
    orientation_sigma: float = 0.002
    roll_drift: float = 0.0  # rad/s: the IMU's reported roll wanders away from the truth
    wheel_sigma: float = 0.01
    rest_noise: float = 0.0  # > 0: at rest the odometry reads white noise of this sigma, not exactly 0 (a car's wheels)
    accel_sigma: float | None = None  # the IMU reports its specific force with this noise (m/s^2)
    orientation_absent: bool = False  # orientation_covariance[0] = -1: the IMU gives no orientation
    accel_scale: float = 1.0  # 1 / 9.80665: a driver reporting in g
    accel_gravity_removed: bool = False  # a driver publishing linear acceleration without gravity
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s^2, added to the specific force
    settle_s: float = 0.0  # > 0: for this long after the vehicle stops, it rocks on its suspension: the gyro ...
    settle_sigma: float = 0.0  # ... reads this much more white noise on every axis (its drive reads zero throughout)
    seed: int = 11
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)  # t x y yaw

    @property
    def duration(self) -> float:
        return sum(s.duration for s in self.segments)


def simulate(w: RestWorld) -> list[OdomSample | ImuSample]:
    rng = np.random.default_rng(w.seed)
    dt = 1e-3
    x = y = yaw = 0.0
    out: list[OdomSample | ImuSample] = []
    ws, gs, os_ = w.wheel_sigma, w.gyro_sigma, w.orientation_sigma
    odom_cov = tuple(ws**2 if i % 7 == 0 and not (w.wheel_yaw_lost and i == 35) else 0.0 for i in range(36))
    next_odom = next_imu = 0.0
    t = 0.0
    v_prev = 0.0  # speed at the end of the previous segment
    for seg in w.segments:
        t_seg, t_end = t, t + seg.duration
        while t < t_end - 1e-9:
            # speed now, and the forward acceleration: steps, or ramps of ramp_s into each segment
            ramp_s = w.ramp_s if seg.ramp_s is None else seg.ramp_s
            ramping = ramp_s > 0.0 and t - t_seg < ramp_s
            accel = (seg.speed - v_prev) / ramp_s if ramping else 0.0
            speed = v_prev + accel * (t - t_seg) if ramping else seg.speed
            if t >= next_odom:
                moving = (speed != 0.0 or seg.yaw_rate != 0.0) and not seg.odom_reads_zero
                v = speed + rng.normal(0, ws) if moving else 0.0
                wz = seg.yaw_rate + rng.normal(0, ws) if moving else 0.0
                if w.rest_noise > 0.0 and not moving and not seg.odom_reads_zero:
                    v, wz = rng.normal(0, w.rest_noise), rng.normal(0, w.rest_noise)
                if w.wheel_yaw_lost:
                    wz = 0.0
                out.append(OdomSample("wheel", T0 + t, (v, 0.0, 0.0), (0.0, 0.0, wz), odom_cov))
                w.truth.append((T0 + t, x, y, yaw))
                next_odom += 1.0 / w.odom_rate
            if t >= next_imu:
                q = rot.from_rpy(w.roll_drift * t + rng.normal(0, os_), rng.normal(0, os_), yaw + rng.normal(0, os_))
                b = w.gyro_bias
                if w.gyro_bias_drift:
                    b = (b[0], b[1], b[2] + w.gyro_bias_drift * t)
                gyro = (b[0] + rng.normal(0, gs), b[1] + rng.normal(0, gs), seg.yaw_rate + b[2] + rng.normal(0, gs))
                stopped_for = t - t_seg - max(ramp_s, 0.0)  # since the vehicle stopped, in a rest after a drive
                if (w.settle_sigma > 0.0 and seg.speed == 0.0 and seg.yaw_rate == 0.0 and v_prev != 0.0
                        and 0.0 <= stopped_for < w.settle_s):
                    gyro = tuple(g + rng.normal(0, w.settle_sigma) for g in gyro)
                ocov = (-1.0,) + (0.0,) * 8 if w.orientation_absent else (os_**2, 0, 0, 0, os_**2, 0, 0, 0, os_**2)
                acc, acov = (0.0, 0.0, 0.0), (-1.0,) + (0.0,) * 8
                if w.accel_sigma is not None:  # flat ground: gravity up, centripetal v w to the left
                    sa = w.accel_sigma
                    g = 0.0 if w.accel_gravity_removed else GRAVITY
                    ab = w.accel_bias
                    acc = tuple(w.accel_scale * a for a in (accel + ab[0] + rng.normal(0, sa), speed * seg.yaw_rate
                                                            + ab[1] + rng.normal(0, sa), g + ab[2] + rng.normal(0, sa)))
                    acov = (sa**2, 0, 0, 0, sa**2, 0, 0, 0, sa**2)
                sv = (gs if w.gyro_stated_sigma is None else w.gyro_stated_sigma) ** 2
                out.append(ImuSample("imu", T0 + t, q, ocov, gyro, (sv, 0, 0, 0, sv, 0, 0, 0, sv), acc, acov))
                next_imu += 1.0 / w.imu_rate
            x += speed * math.cos(yaw) * dt
            y += speed * math.sin(yaw) * dt
            yaw += seg.yaw_rate * dt
            t += dt
        v_prev = seg.speed
    out.sort(key=lambda s: (s.stamp, isinstance(s, ImuSample)))
    return out
