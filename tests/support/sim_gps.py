"""A wheeled robot with GPS and pose sensors, with known truth.

Planar robot in an ENU world starting at an unknown position and heading. The
wheels misread distance (``wheel_scale``: true speed = wheel_scale * reported),
the gyro has a bias and a yaw-axis scale error (true rate = gyro_scale *
(reading - bias)), so the filter's scale states should converge to exactly these
values. GPS fixes carry white noise, optionally a slowly wandering Gauss-Markov
error and frozen stretches, a lever arm and dropouts; a pose sensor
(motion capture, or visual odometry with a drifting origin for `differential`)
sees the sensor's pose through a lever arm. A hand-turn phase rotates the
robot while its wheels read zero.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fusiond.estimator import rotation as rot
from fusiond.estimator.geodesy import EnuFrame, enu_to_geodetic
from fusiond.core.sensors.pose import PoseSample
from fusiond.core.sensors import GpsSample, ImuSample, OdomSample

T0 = 1000.0


@dataclass
class World:
    duration: float = 60.0
    odom_rate: float = 20.0
    imu_rate: float = 50.0
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)  # x y yaw in the world (ENU or pose frame)
    standstill: float = 2.0  # seconds at rest first
    speed: float = 1.0
    wheel_scale: float = 1.0
    wheel_sigma: float = 0.02
    gyro_scale: float = 1.0
    gyro_bias: float = 0.0  # z, rad/s
    gyro_sigma: float = 0.002
    hand_turn: tuple[float, float, float] | None = None  # (t0, t1, rate): wheels at rest, robot turned
    # (t0, t1, rate) relative: when given, the robot drives straight but for these arcs of constant yaw
    # rate (instead of the weave below): curvature that starts and stops, as a skid-steer's turns
    arcs: tuple[tuple[float, float, float], ...] = ()
    # GPS
    gps_rate: float = 0.0  # 0: no GPS
    gps_sigma: float = 0.3
    gps_lever: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gps_dropout: tuple[float, float] | None = None  # no fixes in [t0, t1) (relative seconds)
    gps_bad_every: int = 0  # every n-th fix has status -1 and garbage coordinates
    datum: tuple[float, float, float] = (48.137, 11.575, 520.0)
    gps_error_tau: float = 0.0  # > 0: a first-order Gauss-Markov error (per axis) on top of the white noise
    gps_error_sigma: float = 0.0  # its steady-state std dev, m
    gps_freeze: tuple[tuple[float, float], ...] = ()  # the receiver repeats its last fix in [t0, t1)
    gps_freeze_jitter: float = 0.0  # m (std dev per axis) of noise on those repeats: republished with rounding noise
    gps_alt_error_tau: float = 0.0  # > 0: the altitude alone wanders (Gauss-Markov) beyond the stated sigma
    gps_alt_error_sigma: float = 0.0  # its steady-state std dev, m
    gps_alt_jump: tuple[float, float, float] | None = None  # (t0, t1, m): the altitude off by m in [t0, t1)
    # an absolute IMU yaw (a magnetometer): off by default (yaw "not measured", as before)
    imu_yaw_offset: float | None = None  # not None: the IMU reports yaw = truth + this + disturbance + noise
    imu_yaw_disturbance: tuple[float, float] = (0.0, 60.0)  # (amplitude rad, period s) of a slow sinusoid
    imu_yaw_sigma: float = 0.02  # its noise and stated std dev, rad
    imu_yaw_steps: tuple[tuple[float, float, float], ...] = ()  # (t0, t1, rad): a disturbance switched on
    imu_mount_pitch: float = 0.0  # rad: the IMU pitched in its mount (level ground: its pitch reads this)
    # pose sensor
    pose_rate: float = 0.0  # 0: no pose sensor
    pose_sigma: tuple[float, float] = (0.01, 0.005)  # position m, orientation rad
    pose_lever: tuple[float, float, float] = (0.0, 0.0, 0.0)
    pose_mount_yaw: float = 0.0  # the sensor's axes turned by this about base_link's z (a camera looking sideways)
    pose_origin_drift: float = 0.0  # the pose sensor's origin creeps along x, m/s
    pose_origin_jump: tuple[float, float, float, float] | None = None  # (t, dx, dy, dyaw): a relocalisation
    pose_increment_noise: bool = False  # visual odometry: pose_sigma is per message increment, and accumulates
    # an IMU that also reports an absolute (magnetometer) yaw: offset + slow disturbance
    seed: int = 5
    truth: list[tuple[float, float, float, float]] = field(default_factory=list)  # t x y yaw (every odom stamp)
    fixes: list[tuple[float, float, float]] = field(default_factory=list)  # t east north of every valid fix


HAND_STOP_S = 0.5  # s: a robot about to be turned by hand brakes to rest first (not in one message)


def commanded(rel: float, w: World) -> tuple[float, float, bool]:
    """(v, yaw rate, wheels see it)."""
    if w.hand_turn is not None and w.hand_turn[0] <= rel < w.hand_turn[1]:
        return 0.0, w.hand_turn[2], False
    if rel < w.standstill:
        return 0.0, 0.0, True
    v = w.speed
    if w.hand_turn is not None and w.hand_turn[0] - HAND_STOP_S <= rel < w.hand_turn[0]:
        v *= (w.hand_turn[0] - rel) / HAND_STOP_S  # the robot stops before it is picked up
    if w.arcs:
        return v, next((rate for a, b, rate in w.arcs if a <= rel < b), 0.0), True
    return v, 0.25 * math.sin(0.3 * (rel - w.standstill)) + 0.05, True


def simulate(w: World) -> list:
    rng = np.random.default_rng(w.seed)
    enu = EnuFrame(*w.datum)
    dt = 1e-3
    x, y, yaw = w.start
    nxt = {"odom": 0.0, "imu": 0.0, "gps": 0.0, "pose": 0.0}
    out: list = []
    n_fix = 0
    gm_rng = np.random.default_rng(w.seed + 1000)  # own stream: worlds without it draw as before
    gm = gm_rng.normal(0, w.gps_error_sigma, 3) if w.gps_error_tau > 0 else np.zeros(3)
    gm_t = 0.0
    yaw_rng = np.random.default_rng(w.seed + 3000)
    alt_rng = np.random.default_rng(w.seed + 2000)  # own stream: worlds without it draw as before
    jitter_rng = np.random.default_rng(w.seed + 4000)  # own stream: worlds without it draw as before
    alt_err = alt_rng.normal(0, w.gps_alt_error_sigma) if w.gps_alt_error_tau > 0 else 0.0
    last_fix = None
    vo_err = [0.0, 0.0, 0.0, 0.0]  # accumulated visual-odometry error: x y z yaw
    rel = 0.0
    while rel < w.duration:
        t = T0 + rel
        v, wz, wheels = commanded(rel, w)
        if rel >= nxt["odom"]:
            nxt["odom"] += 1.0 / w.odom_rate
            moving = wheels and (v != 0.0 or wz != 0.0)
            cov = tuple(w.wheel_sigma**2 if i % 7 == 0 else 0.0 for i in range(36))
            vm = (v / w.wheel_scale + rng.normal(0, w.wheel_sigma)) if moving else 0.0
            wm = (wz + rng.normal(0, w.wheel_sigma)) if moving else 0.0
            out.append(OdomSample("wheel", t, (vm, 0.0, 0.0), (0.0, 0.0, wm), cov))
            w.truth.append((t, x, y, yaw))
        if rel >= nxt["imu"]:
            nxt["imu"] += 1.0 / w.imu_rate
            gs = w.gyro_sigma
            gz = wz / w.gyro_scale + w.gyro_bias + rng.normal(0, gs)
            imu_yaw, yaw_var = 0.0, 1e6
            if w.imu_yaw_offset is not None:  # own stream: worlds without it draw as before
                amp, period = w.imu_yaw_disturbance
                imu_yaw = (yaw + w.imu_yaw_offset + amp * math.sin(2 * math.pi * rel / period)
                           + yaw_rng.normal(0, w.imu_yaw_sigma)
                           + sum(d for t0, t1, d in w.imu_yaw_steps if t0 <= rel < t1))
                yaw_var = w.imu_yaw_sigma**2
            # a pitched mount turns the body's z rate onto the IMU's x axis: R_y(p)^T (0, 0, w)
            # (the draws in the order worlds without a mount have always made them)
            mp = w.imu_mount_pitch
            q = rot.from_rpy(rng.normal(0, 0.002), rng.normal(0, 0.002) + mp, imu_yaw)
            gx, gy = rng.normal(0, gs) - math.sin(mp) * gz, rng.normal(0, gs)
            out.append(ImuSample("imu", t, q, (4e-6, 0, 0, 0, 4e-6, 0, 0, 0, yaw_var), (gx, gy, math.cos(mp) * gz),
                                 (gs**2, 0, 0, 0, gs**2, 0, 0, 0, gs**2)))
        if w.gps_rate > 0 and rel >= nxt["gps"]:
            nxt["gps"] += 1.0 / w.gps_rate
            n_fix += 1
            lx, ly, _ = w.gps_lever
            c, s = math.cos(yaw), math.sin(yaw)
            e = x + c * lx - s * ly + rng.normal(0, w.gps_sigma)
            n = y + s * lx + c * ly + rng.normal(0, w.gps_sigma)
            u = w.gps_lever[2] + rng.normal(0, w.gps_sigma)
            if w.gps_error_tau > 0:  # exact discretisation of db = -b/tau dt + noise
                a = math.exp(-(rel - gm_t) / w.gps_error_tau)
                gm = a * gm + math.sqrt(1.0 - a * a) * gm_rng.normal(0, w.gps_error_sigma, 3)
                gm_t = rel
                e, n, u = e + gm[0], n + gm[1], u + gm[2]
            if w.gps_alt_error_tau > 0:
                a = math.exp(-(1.0 / w.gps_rate) / w.gps_alt_error_tau)
                alt_err = a * alt_err + math.sqrt(1.0 - a * a) * alt_rng.normal(0, w.gps_alt_error_sigma)
                u += alt_err
            if w.gps_alt_jump is not None and w.gps_alt_jump[0] <= rel < w.gps_alt_jump[1]:
                u += w.gps_alt_jump[2]  # a receiver switching its height reference (geoid, ellipsoid) and back
            if any(f0 <= rel < f1 for f0, f1 in w.gps_freeze) and last_fix is not None:
                e, n, u = last_fix  # a stuck receiver: same position, new stamp
                if w.gps_freeze_jitter > 0.0:  # ... republished with noise (the stuck position stays the same)
                    de, dn, du = jitter_rng.normal(0, w.gps_freeze_jitter, 3)
                    e, n, u = e + de, n + dn, u + du
            else:
                last_fix = (e, n, u)
            dropped = w.gps_dropout is not None and w.gps_dropout[0] <= rel < w.gps_dropout[1]
            var = w.gps_sigma**2
            if w.gps_bad_every and n_fix % w.gps_bad_every == 0:
                out.append(GpsSample("gps", t, math.nan, 0.0, 0.0, -1, (var, 0, 0, 0, var, 0, 0, 0, var), 2))
            elif not dropped:
                lat, lon, alt = enu_to_geodetic(enu, e, n, u)
                out.append(GpsSample("gps", t, lat, lon, alt, 0, (var, 0, 0, 0, var, 0, 0, 0, var), 2))
                w.fixes.append((t, e, n))
        if w.pose_rate > 0 and rel >= nxt["pose"]:
            nxt["pose"] += 1.0 / w.pose_rate
            ps, os_ = w.pose_sigma
            lx, ly, lz = w.pose_lever
            c, s = math.cos(yaw), math.sin(yaw)
            sx, sy = x + c * lx - s * ly, y + s * lx + c * ly  # sensor origin in the world
            # the sensor's own frame: its origin drifts away from the world's
            ox, oy, oyaw = w.pose_origin_drift * rel, 0.0, 0.0
            if w.pose_origin_jump is not None and rel >= w.pose_origin_jump[0]:
                ox, oy, oyaw = ox + w.pose_origin_jump[1], w.pose_origin_jump[2], w.pose_origin_jump[3]
            co, so = math.cos(-oyaw), math.sin(-oyaw)
            px, py = co * (sx - ox) - so * (sy - oy), so * (sx - ox) + co * (sy - oy)
            if w.pose_increment_noise:
                for k in range(3):
                    vo_err[k] += rng.normal(0, ps)
                vo_err[3] += rng.normal(0, os_)
                err = vo_err
            else:
                err = [rng.normal(0, ps), rng.normal(0, ps), rng.normal(0, ps), rng.normal(0, os_)]
            q = rot.from_rpy(rng.normal(0, 0.002), rng.normal(0, 0.002), yaw + w.pose_mount_yaw - oyaw + err[3])
            cov = tuple((ps**2 if i < 3 else os_**2) if j == i else 0.0 for i in range(6) for j in range(6))
            out.append(PoseSample("pose", t, (px + err[0], py + err[1], lz + err[2]), q, cov))
        x += v * math.cos(yaw) * dt
        y += v * math.sin(yaw) * dt
        yaw += wz * dt
        rel += dt
    return out


def truth_at(w: World, t: float) -> tuple[float, float, float]:
    """Truth (x, y, yaw) at the odometry stamp nearest t."""
    i = min(range(len(w.truth)), key=lambda k: abs(w.truth[k][0] - t))
    return w.truth[i][1:]
