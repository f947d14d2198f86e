"""A small wheeled-robot simulator with known truth, for fusion-core tests.

Planar motion on a tilted plane is overkill here: the robot drives on flat
ground with commanded (v, yaw rate); sensors get noise, a gyro bias and
per-sensor stamp lag, like the real bags.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample


@dataclass
class SimConfig:
    duration: float = 20.0
    odom_rate: float = 50.0
    imu_rate: float = 100.0
    gyro_bias: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gyro_sigma: float = 0.002
    orientation_sigma: float = 0.002
    wheel_sigma: float = 0.01
    wheel_yaw_scale: float = 1.0  # skid-steer wheels misread the turn rate
    wheel_yaw_offset: float = 0.0  # rad/s a driver adds to the wheels' yaw rate while they move
    turn_amplitude: float = 0.3  # rad/s of the commanded weave (0: a straight road)
    standstill: float = 0.0  # seconds at rest before moving
    imu_yaw_offset: float = 0.0  # the IMU's own yaw reference (magnetic north, ...)
    imu_yaw_wander: float = 0.0  # amplitude (rad) of a slow magnetic disturbance of the IMU's yaw
    seed: int = 3
    # traits for the doctor's tests; the defaults leave every other simulation unchanged
    speed: float = 1.0  # m/s while driving
    stops: tuple[tuple[float, float], ...] = ()  # (t0, t1) relative: genuine standstills
    false_stops: tuple[tuple[float, float, float], ...] = ()  # (t0, t1, yaw rate): wheels read 0, robot turns
    dropouts: tuple[tuple[float, float], ...] = ()  # (t0, t1) relative: wheels read 0, the robot drives on
    wheel_yaw_lost: bool = False  # the driver lost the yaw rate: it reports 0 with variance 0
    imu_mount_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the IMU's true mounting in base_link
    imu_axis_sigma: tuple[float, float, float] | None = None  # orientation noise about the IMU's own axes
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)  # t x y yaw


def commanded(t: float, cfg: SimConfig) -> tuple[float, float]:
    v, w, _ = commanded_seen(t, cfg)
    return v, w


def commanded_seen(t: float, cfg: SimConfig) -> tuple[float, float, bool]:
    """(v, yaw rate, the wheels see the motion)."""
    if t < cfg.standstill or any(a <= t < b for a, b in cfg.stops):
        return 0.0, 0.0, True
    for a, b, rate in cfg.false_stops:
        if a <= t < b:
            return 0.0, rate, False
    w = cfg.turn_amplitude * math.sin(0.5 * (t - cfg.standstill))
    return cfg.speed, w, not any(a <= t < b for a, b in cfg.dropouts)


def simulate(cfg: SimConfig) -> list[OdomSample | ImuSample]:
    """Samples in stamp order, covariances stated honestly."""
    rng = np.random.default_rng(cfg.seed)
    dt = 1e-3
    x = y = yaw = 0.0
    next_odom = next_imu = 0.0
    out: list[OdomSample | ImuSample] = []
    t = 1000.0  # stamps start at 1000 s, as a robot clock would
    t_end = t + cfg.duration
    ws, gs, os_ = cfg.wheel_sigma, cfg.gyro_sigma, cfg.orientation_sigma
    while t < t_end:
        rel = t - 1000.0
        v, w, seen = commanded_seen(rel, cfg)
        if rel >= next_odom:
            cov = [0.0] * 36
            for i in range(6):
                cov[7 * i] = ws**2
            moving = seen and (v != 0.0 or w != 0.0)  # encoders read exactly zero when the wheels stand
            wz = (cfg.wheel_yaw_scale * w if seen else 0.0) + moving * (cfg.wheel_yaw_offset + rng.normal(0, ws))
            if cfg.wheel_yaw_lost:
                wz, cov[35] = 0.0, 0.0
            out.append(OdomSample("wheel", t, ((v if seen else 0.0) + moving * rng.normal(0, ws), 0.0, 0.0),
                                  (0.0, 0.0, wz), tuple(cov)))
            next_odom += 1.0 / cfg.odom_rate
            cfg.truth.append((t, x, y, yaw))
        if rel >= next_imu:
            disturbance = cfg.imu_yaw_wander * math.sin(0.4 * rel)
            b = cfg.gyro_bias
            if cfg.imu_axis_sigma is None and cfg.imu_mount_rpy == (0.0, 0.0, 0.0):
                q = rot.from_rpy(rng.normal(0, os_), rng.normal(0, os_),
                                 yaw + cfg.imu_yaw_offset + disturbance + rng.normal(0, os_))
                gyro = (b[0] + rng.normal(0, gs), b[1] + rng.normal(0, gs), w + b[2] + rng.normal(0, gs))
            else:  # q_imu = q_base * q_mount * exp(noise about the IMU's axes); rates in the IMU's axes
                sig = cfg.imu_axis_sigma or (os_, os_, os_)
                q_mount = rot.from_rpy(*cfg.imu_mount_rpy)
                noise = rot.exp(*(rng.normal(0, sk) for sk in sig))
                q = rot.mul(rot.mul(rot.from_rpy(0.0, 0.0, yaw + cfg.imu_yaw_offset + disturbance), q_mount), noise)
                w_imu = rot.matrix(q_mount).T @ np.array([0.0, 0.0, w])
                gyro = tuple(float(w_imu[k] + b[k] + rng.normal(0, gs)) for k in range(3))
            out.append(ImuSample("imu", t, q, (os_**2, 0, 0, 0, os_**2, 0, 0, 0, os_**2), gyro,
                                 (gs**2, 0, 0, 0, gs**2, 0, 0, 0, gs**2)))
            next_imu += 1.0 / cfg.imu_rate
        x += v * math.cos(yaw) * dt
        y += v * math.sin(yaw) * dt
        yaw += w * dt
        t += dt
    return out


def arrival_order(samples, lag: dict[str, float], jitter: float = 0.0, seed: int = 0):
    """Reorder as a transport would deliver them: each sensor's stamps lag by its own delay."""
    rng = np.random.default_rng(seed)
    keyed = [(s.stamp + lag.get(s.sensor, 0.0) + rng.uniform(0, jitter), i, s) for i, s in enumerate(samples)]
    keyed.sort(key=lambda k: (k[0], k[1]))
    return [s for _, _, s in keyed]
