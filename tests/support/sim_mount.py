"""A robot that speeds up, slows down and turns, with an IMU mounted at a known rotation and an accelerometer.

For the doctor's mounting check: the accelerometer reads the body's specific force,
(dv/dt, v w, g) in base_link on flat ground (REP-103: x forward, y left, z up; the
centripetal acceleration of a left turn points left), turned into the IMU's own axes
by its true mounting; the IMU's orientation and gyro are in its own axes as well.
Speed and yaw rate are smooth (no step in dv/dt), so the truth is exact:

    v(t) = speed (1 - cos(a t)),   w(t) = turn sin(b t),   t from the end of the standstill.
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
class MountWorld:
    duration: float = 60.0
    standstill: float = 2.0
    speed: float = 1.0  # m/s: the speed swings between 0 and 2 x this
    speed_rate: float = 0.4  # a (rad/s): dv/dt peaks at speed * a
    turn: float = 0.35  # rad/s: yaw-rate amplitude
    turn_rate: float = 0.23  # b (rad/s)
    imu_mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the IMU's true mounting in base_link
    odom_rate: float = 50.0
    imu_rate: float = 100.0
    wheel_sigma: float = 0.01
    gyro_sigma: float = 0.002
    orientation_sigma: float = 0.002
    accel_sigma: float = 0.05  # m/s^2 per sample (white: vibration and noise)
    accel_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m/s^2, IMU axes
    accel_scale: float = 1.0  # 1 / 9.80665: a driver reporting in g
    orientation_absent: bool = False  # orientation_covariance[0] = -1: the IMU gives no orientation
    seed: int = 17
    direction: float = 1.0  # -1: the same manoeuvres in reverse gear (v <= 0, dv/dt and v w signed with it)
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)  # t x y yaw


def motion(rel: float, w: MountWorld) -> tuple[float, float, float]:
    """(v, dv/dt, yaw rate) at rel seconds from the start."""
    if rel < w.standstill:
        return 0.0, 0.0, 0.0
    t = rel - w.standstill
    a, b = w.speed_rate, w.turn_rate
    v = w.direction * w.speed
    return v * (1.0 - math.cos(a * t)), v * a * math.sin(a * t), w.turn * math.sin(b * t)


def simulate(w: MountWorld) -> list[OdomSample | ImuSample]:
    rng = np.random.default_rng(w.seed)
    dt = 1e-3
    x = y = yaw = 0.0
    out: list[OdomSample | ImuSample] = []
    q_mount = rot.from_rpy(*w.imu_mount_rpy)
    R_mount_T = rot.matrix(q_mount).T  # base -> IMU
    ws, gs, os_, sa = w.wheel_sigma, w.gyro_sigma, w.orientation_sigma, w.accel_sigma
    odom_cov = tuple(ws**2 if i % 7 == 0 else 0.0 for i in range(36))
    next_odom = next_imu = 0.0
    rel = 0.0
    while rel < w.duration:
        v, dv, wz = motion(rel, w)
        if rel >= next_odom:
            moving = v != 0.0 or wz != 0.0  # encoders read exactly zero when the wheels stand
            out.append(OdomSample("wheel", T0 + rel, (v + moving * rng.normal(0, ws), 0.0, 0.0),
                                  (0.0, 0.0, wz + moving * rng.normal(0, ws)), odom_cov))
            w.truth.append((T0 + rel, x, y, yaw))
            next_odom += 1.0 / w.odom_rate
        if rel >= next_imu:
            noise = rot.exp(*(rng.normal(0, os_) for _ in range(3)))
            q = rot.mul(rot.mul(rot.from_rpy(0.0, 0.0, yaw), q_mount), noise)
            gyro = R_mount_T @ np.array([0.0, 0.0, wz])
            f = R_mount_T @ np.array([dv, v * wz, GRAVITY])
            ocov = (-1.0,) + (0.0,) * 8 if w.orientation_absent else (os_**2, 0, 0, 0, os_**2, 0, 0, 0, os_**2)
            out.append(ImuSample(
                "imu", T0 + rel, q, ocov,
                tuple(float(gyro[k] + rng.normal(0, gs)) for k in range(3)), (gs**2, 0, 0, 0, gs**2, 0, 0, 0, gs**2),
                tuple(w.accel_scale * float(f[k] + w.accel_bias[k] + rng.normal(0, sa)) for k in range(3)),
                (sa**2, 0, 0, 0, sa**2, 0, 0, 0, sa**2)))
            next_imu += 1.0 / w.imu_rate
        x += v * math.cos(yaw) * dt
        y += v * math.sin(yaw) * dt
        yaw += wz * dt
        rel += dt
    return out


def mount_imu(samples: list, mount_rpy: tuple[float, float, float], motion, accel_sigma: float = 0.05,
              seed: int = 23) -> list:
    """Another simulator's run with its IMU mounted at ``mount_rpy`` and given an accelerometer.

    ``motion(t)`` is the truth's (v, dv/dt, yaw rate) at stamp t. The IMU's orientation becomes
    q_base * q_mount, its gyro and specific force (dv/dt, v w, g) are turned into its axes; the rest
    of the samples pass unchanged."""
    rng = np.random.default_rng(seed)
    q_mount = rot.from_rpy(*mount_rpy)
    R_T = rot.matrix(q_mount).T
    sa = accel_sigma
    out = []
    for s in samples:
        if isinstance(s, ImuSample):
            v, dv, wz = motion(s.stamp)
            gyro = R_T @ np.array(s.angular_velocity)
            f = R_T @ np.array([dv, v * wz, GRAVITY])
            s = ImuSample(s.sensor, s.stamp, rot.mul(s.orientation, q_mount), s.orientation_covariance,
                          tuple(float(g) for g in gyro), s.angular_velocity_covariance,
                          tuple(float(f[k] + rng.normal(0, sa)) for k in range(3)),
                          (sa**2, 0, 0, 0, sa**2, 0, 0, 0, sa**2))
        out.append(s)
    return out
