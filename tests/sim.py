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
from fusiond.samples import ImuSample, OdomSample


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
    standstill: float = 0.0  # seconds at rest before moving
    imu_yaw_offset: float = 0.0  # the IMU's own yaw reference (magnetic north, ...)
    imu_yaw_wander: float = 0.0  # amplitude (rad) of a slow magnetic disturbance of the IMU's yaw
    seed: int = 3
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)  # t x y yaw


def commanded(t: float, cfg: SimConfig) -> tuple[float, float]:
    if t < cfg.standstill:
        return 0.0, 0.0
    return 1.0, 0.3 * math.sin(0.5 * (t - cfg.standstill))


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
        v, w = commanded(rel, cfg)
        if rel >= next_odom:
            cov = [0.0] * 36
            for i in range(6):
                cov[7 * i] = ws**2
            moving = v != 0.0 or w != 0.0  # encoders read exactly zero when the wheels stand
            out.append(OdomSample("wheel", t, (v + moving * rng.normal(0, ws), 0.0, 0.0),
                                  (0.0, 0.0, cfg.wheel_yaw_scale * w + moving * rng.normal(0, ws)), tuple(cov)))
            next_odom += 1.0 / cfg.odom_rate
            cfg.truth.append((t, x, y, yaw))
        if rel >= next_imu:
            disturbance = cfg.imu_yaw_wander * math.sin(0.4 * rel)
            q = rot.from_rpy(rng.normal(0, os_), rng.normal(0, os_),
                             yaw + cfg.imu_yaw_offset + disturbance + rng.normal(0, os_))
            b = cfg.gyro_bias
            gyro = (b[0] + rng.normal(0, gs), b[1] + rng.normal(0, gs), w + b[2] + rng.normal(0, gs))
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
