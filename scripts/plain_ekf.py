"""A plain error-state EKF over a bag: the textbook filter that fusiond's benchmark rows are compared with.

The same states as fusiond's core: position (3), orientation (a unit quaternion with a 3-D error
angle), gyro bias (3): nine error states. Nothing else: no gates, no timeouts, no history or late-data
logic (every message is processed once, in header-stamp order), no rest detection, no special cases.

- Prediction: the odometry's twist is the input, held from one odometry message to the next:
  ``p += R(q) v dt`` (body twist; ``p += v dt`` for ``twist_frame = "world"``). The attitude rate is the
  IMU's gyro less the estimated bias when the configuration fuses the gyro (``angular_velocity``),
  otherwise the odometry's angular twist. The input's own covariance (the odometry's twist covariance,
  the IMU's gyro covariance) enters as input noise, plus a fixed process noise per second (PROCESS_NOISE).
- Updates: the IMU's orientation as the configuration's mode says (``absolute``; ``relative``: absolute
  less the yaw difference at the first sample; ``roll_pitch``: roll and pitch only; ``off``), GPS
  positions in ENU at the first fix (or the configured datum), and a pose sensor's poses (a marker
  system, a map localiser) with the sensor at its extrinsic in base_link, each with the message's own
  covariance. A ``differential`` pose sensor (visual odometry, whose origin drifts) is fused as
  robot_localization's differential mode first did it: the change since its previous message, put on
  the filter's own pose at that message, as a pose measurement with this message's covariance (a
  tracking reset is then a jump like any other: nothing here looks at silences or outliers).
- The configuration (fusiond.config.load) is read only for topic names, sensor kinds, the orientation
  mode, the gyro switch, the IMU's and the pose sensors' extrinsics, the twist frame, a GPS datum and a
  pose sensor's ``differential``.

Covariance floors, the only departures from the messages (in variances):
- a diagonal element <= 0 (a message that states 0, or -1 for "absent" on a channel that is used) is
  taken as MIN_VARIANCE (1e-6: 1 mm/s, 1 mrad/s, 1 mrad, 1 mm);
- a twist element >= 1e6 (the "not measured" convention) is taken as UNMEASURED_VARIANCE (1.0: 1 m/s,
  1 rad/s) so that one such input does not swamp the state;
- a GPS fix with covariance type UNKNOWN is taken to be UNKNOWN_GPS_SIGMA = 1 m on each axis: the plain
  user's choice for a receiver that states nothing;
- a pose's axis stated at >= 1e6 (the "not measured" convention) is not fused; a pose message without a
  covariance (PoseStamped) is taken at UNKNOWN_POSE_SIGMA (0.1 m, 0.05 rad).

    .venv/bin/python scripts/plain_ekf.py BAG [BAG ...] --config examples/jackal_rl.toml [--tum OUT.tum]
                                          [--fuse-every N]
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# Process noise per second (variances/s, the covariance grows by Q dt): robot_localization's default
# process_noise_covariance for x y z (m^2/s) and roll pitch yaw (rad^2/s); gyro bias random walk
# (1e-4 rad/s per sqrt(s)) ^ 2.
PROCESS_NOISE = np.array([0.05, 0.05, 0.06, 0.03, 0.03, 0.06, 1e-8, 1e-8, 1e-8])
MIN_VARIANCE = 1e-6
UNMEASURED_VARIANCE = 1.0
UNKNOWN_GPS_SIGMA = 1.0  # m
UNKNOWN_POSE_SIGMA = (0.1, 0.05)  # m, rad
# Initial standard deviations: a position unknown to 100 m with a GPS (its first fix sets it), else
# exactly the origin (1 mm); heading unknown (pi) with a GPS and no absolute orientation, else 0.01 rad;
# roll and pitch 0.01 rad; gyro bias 0.01 rad/s.
INITIAL_POSITION_SIGMA_GPS, INITIAL_POSITION_SIGMA = 100.0, 1e-3
INITIAL_YAW_SIGMA_UNKNOWN, INITIAL_ANGLE_SIGMA, INITIAL_BIAS_SIGMA = math.pi, 0.01, 0.01

WGS84_A, WGS84_E2 = 6378137.0, 6.69437999014e-3


# --- quaternions (x, y, z, w), rotations --------------------------------------------------------------

def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz])


def quat_conj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def quat_exp(phi: np.ndarray) -> np.ndarray:
    """The unit quaternion of the rotation vector ``phi``."""
    a = float(np.linalg.norm(phi))
    if a < 1e-12:
        return np.array([0.5 * phi[0], 0.5 * phi[1], 0.5 * phi[2], 1.0]) / math.sqrt(1.0 + 0.25 * a * a)
    s = math.sin(0.5 * a) / a
    return np.array([s * phi[0], s * phi[1], s * phi[2], math.cos(0.5 * a)])


def quat_log(q: np.ndarray) -> np.ndarray:
    """The rotation vector of the unit quaternion ``q`` (the shorter way: q and -q are one rotation)."""
    if q[3] < 0.0:
        q = -q
    n = float(np.linalg.norm(q[:3]))
    if n < 1e-12:
        return 2.0 * q[:3]
    return 2.0 * math.atan2(n, q[3]) * q[:3] / n


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """R(q): body -> world."""
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def quat_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Fixed-axis roll, pitch, yaw (URDF, tf2): Rz(yaw) Ry(pitch) Rx(roll)."""
    return quat_mul(quat_mul(quat_exp(np.array([0.0, 0.0, yaw])), quat_exp(np.array([0.0, pitch, 0.0]))),
                    quat_exp(np.array([roll, 0.0, 0.0])))


def quat_rpy(q: np.ndarray) -> tuple[float, float, float]:
    x, y, z, w = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def right_jacobian(phi: np.ndarray) -> np.ndarray:
    """J_r(phi): Exp(phi + d) = Exp(phi) Exp(J_r(phi) d) to first order."""
    a = float(np.linalg.norm(phi))
    k = skew(phi)
    if a < 1e-6:
        return np.eye(3) - 0.5 * k + k @ k / 6.0
    return np.eye(3) - (1 - math.cos(a)) / a**2 * k + (a - math.sin(a)) / a**3 * k @ k


def euler_rate_rows(roll: float, pitch: float) -> np.ndarray:
    """d(roll, pitch) / d(theta) for a body-frame (right) perturbation q Exp(theta)."""
    sr, cr, tp = math.sin(roll), math.cos(roll), math.tan(pitch)
    return np.array([[1.0, sr * tp, cr * tp], [0.0, cr, -sr]])


def wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


# --- the filter ----------------------------------------------------------------------------------------

@dataclass
class State:
    p: np.ndarray  # position, world
    q: np.ndarray  # orientation body -> world (x, y, z, w)
    b: np.ndarray  # gyro bias, body, rad/s


def propagate(s: State, v: np.ndarray, w: np.ndarray, dt: float, world_twist: bool = False,
              gyro: bool = True) -> State:
    """The nominal state after dt with body twist ``v`` and rate ``w`` (the gyro's, less the bias when
    ``gyro``; else the wheels', taken as it is)."""
    rate = w - s.b if gyro else w
    p = s.p + (v if world_twist else quat_matrix(s.q) @ v) * dt
    q = quat_mul(s.q, quat_exp(rate * dt))
    return State(p, q / np.linalg.norm(q), s.b.copy())


def transition(s: State, v: np.ndarray, w: np.ndarray, dt: float, world_twist: bool = False,
               gyro: bool = True) -> np.ndarray:
    """F = d(error after the step) / d(error before), errors (dp, dtheta, db) with q_true = q Exp(dtheta)."""
    rate = (w - s.b if gyro else w) * dt
    f = np.eye(9)
    if not world_twist:
        f[0:3, 3:6] = -quat_matrix(s.q) @ skew(v) * dt
    f[3:6, 3:6] = quat_matrix(quat_exp(rate)).T
    if gyro:
        f[3:6, 6:9] = -right_jacobian(rate) * dt
    return f


def boxplus(s: State, dx: np.ndarray) -> State:
    q = quat_mul(s.q, quat_exp(dx[3:6]))
    return State(s.p + dx[0:3], q / np.linalg.norm(q), s.b + dx[6:9])


def boxminus(a: State, b: State) -> np.ndarray:
    """The error dx with a = b [+] dx."""
    return np.concatenate((a.p - b.p, quat_log(quat_mul(quat_conj(b.q), a.q)), a.b - b.b))


def _diag_floor(var: np.ndarray, unmeasured: bool = False) -> np.ndarray:
    var = np.where(var <= 0.0, MIN_VARIANCE, var)
    return np.where(var >= 1e6, UNMEASURED_VARIANCE, var) if unmeasured else var


class PlainEkf:
    def __init__(self, placed_by: bool, absolute_yaw: bool, gyro: bool, world_twist: bool) -> None:
        """``placed_by``: a sensor (a GPS, an absolute pose) places the robot in its world frame: the position
        starts unknown, and the heading too unless the IMU's yaw is absolute."""
        self.x = State(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.zeros(3))
        pos = INITIAL_POSITION_SIGMA_GPS if placed_by else INITIAL_POSITION_SIGMA
        yaw = INITIAL_YAW_SIGMA_UNKNOWN if placed_by and not absolute_yaw else INITIAL_ANGLE_SIGMA
        self.P = np.diag(np.array([pos, pos, pos, INITIAL_ANGLE_SIGMA, INITIAL_ANGLE_SIGMA, yaw,
                                   INITIAL_BIAS_SIGMA, INITIAL_BIAS_SIGMA, INITIAL_BIAS_SIGMA]) ** 2)
        self.gyro, self.world_twist = gyro, world_twist
        self.t: float | None = None
        self.v = np.zeros(3)
        self.v_var = np.full(3, MIN_VARIANCE)
        self.w = np.zeros(3)
        self.w_var = np.full(3, MIN_VARIANCE)

    def predict(self, t: float) -> None:
        if self.t is None:
            self.t = t
            return
        dt = t - self.t
        if dt <= 0.0:
            return
        f = transition(self.x, self.v, self.w, dt, self.world_twist, self.gyro)
        g = np.zeros((9, 6))  # input noise: d(error) / d(v, w)
        g[0:3, 0:3] = (np.eye(3) if self.world_twist else quat_matrix(self.x.q)) * dt
        g[3:6, 3:6] = np.eye(3) * dt
        q = g @ np.diag(np.concatenate((self.v_var, self.w_var))) @ g.T + np.diag(PROCESS_NOISE * dt)
        self.x = propagate(self.x, self.v, self.w, dt, self.world_twist, self.gyro)
        self.P = f @ self.P @ f.T + q
        self.t = t

    def update(self, residual: np.ndarray, h: np.ndarray, r: np.ndarray) -> None:
        s = h @ self.P @ h.T + r
        k = np.linalg.solve(s, h @ self.P).T  # P H^T S^-1 (S and P symmetric)
        dx = k @ residual
        i_kh = np.eye(9) - k @ h
        self.P = i_kh @ self.P @ i_kh.T + k @ r @ k.T  # Joseph form
        self.P = 0.5 * (self.P + self.P.T)
        self.x = boxplus(self.x, dx)

    def update_position(self, z: np.ndarray, r: np.ndarray) -> None:
        h = np.zeros((3, 9))
        h[:, 0:3] = np.eye(3)
        self.update(z - self.x.p, h, r)

    def update_orientation(self, q_meas: np.ndarray, r_world: np.ndarray) -> None:
        """Full orientation; ``r_world`` about the fixed axes (ROS's convention), turned into the body's."""
        rot = quat_matrix(self.x.q)
        h = np.zeros((3, 9))
        h[:, 3:6] = np.eye(3)
        self.update(quat_log(quat_mul(quat_conj(self.x.q), q_meas)), h, rot.T @ r_world @ rot)

    def update_pose(self, p_meas: np.ndarray, q_meas: np.ndarray, cov: np.ndarray, lever: np.ndarray) -> None:
        """A sensor at ``lever`` (base_link) whose pose reads: the sensor's origin ``p_meas`` (h = p + R(q) t) and
        base_link's orientation ``q_meas``; ``cov`` 6x6 about the world's axes (ROS's convention), its rows of
        variance >= 1e6 not fused."""
        rot = quat_matrix(self.x.q)
        h = np.zeros((6, 9))
        h[0:3, 0:3] = np.eye(3)
        h[0:3, 3:6] = -rot @ skew(lever)  # q_true = q Exp(dtheta): R_true t = R t + R (dtheta x t)
        h[3:6, 3:6] = np.eye(3)
        y = np.concatenate((p_meas - self.x.p - rot @ lever, quat_log(quat_mul(quat_conj(self.x.q), q_meas))))
        r = cov.copy()
        r[3:6, 3:6] = rot.T @ r[3:6, 3:6] @ rot  # the attitude error is about the body's axes
        r[0:3, 3:6] = r[0:3, 3:6] @ rot
        r[3:6, 0:3] = rot.T @ r[3:6, 0:3]
        rows = [i for i in range(6) if cov[i, i] < 1e6]
        if rows:
            self.update(y[rows], h[rows], r[np.ix_(rows, rows)])

    def update_roll_pitch(self, q_meas: np.ndarray, r_rp: np.ndarray) -> None:
        roll, pitch, _ = quat_rpy(self.x.q)
        mr, mp, _ = quat_rpy(q_meas)
        h = np.zeros((2, 9))
        h[:, 3:6] = euler_rate_rows(roll, pitch)
        self.update(wrap(np.array([mr - roll, mp - pitch])), h, r_rp)


# --- geodesy -------------------------------------------------------------------------------------------

def _ecef(lat_deg: float, lon_deg: float, alt: float) -> np.ndarray:
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * math.sin(lat) ** 2)
    return np.array([(n + alt) * math.cos(lat) * math.cos(lon), (n + alt) * math.cos(lat) * math.sin(lon),
                     (n * (1.0 - WGS84_E2) + alt) * math.sin(lat)])


class Enu:
    """Local east-north-up at a WGS84 origin."""

    def __init__(self, lat: float, lon: float, alt: float) -> None:
        self.origin = _ecef(lat, lon, alt)
        la, lo = math.radians(lat), math.radians(lon)
        self.rows = np.array([[-math.sin(lo), math.cos(lo), 0.0],
                              [-math.sin(la) * math.cos(lo), -math.sin(la) * math.sin(lo), math.cos(la)],
                              [math.cos(la) * math.cos(lo), math.cos(la) * math.sin(lo), math.sin(la)]])

    def __call__(self, lat: float, lon: float, alt: float) -> np.ndarray:
        return self.rows @ (_ecef(lat, lon, alt) - self.origin)


# --- the bag -------------------------------------------------------------------------------------------

def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def _pose_of(msg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A pose message's (position, orientation, 6x6 covariance, diagonal floored) whatever its type."""
    pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose  # Odometry, PoseWithCovarianceStamped
    if hasattr(msg.pose, "covariance"):
        cov = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)
        cov = cov + np.diag(_diag_floor(cov.diagonal()) - cov.diagonal())
    else:  # PoseStamped
        cov = np.diag([UNKNOWN_POSE_SIGMA[0] ** 2] * 3 + [UNKNOWN_POSE_SIGMA[1] ** 2] * 3)
    p, o = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z]), np.array([o.x, o.y, o.z, o.w]), cov


def _fuse_pose(f: PlainEkf, msg, sensor: dict) -> None:
    """One pose message: the sensor's pose as base_link's (absolute), or the change since the sensor's previous
    message put on the filter's pose at it (differential)."""
    p_s, q_s, cov = _pose_of(msg)
    q_ext, t_ext = sensor["q_ext"], sensor["t_ext"]
    q_base = quat_mul(q_s, quat_conj(q_ext))  # the sensor's frame is base_link turned by q_ext
    if not sensor["differential"]:  # its covariance is about the world's axes already (ROS's convention)
        f.update_pose(p_s, q_base, cov, t_ext)
        return
    last = sensor["last"]
    if last is None:
        sensor["last"] = (p_s, q_base, f.x.p.copy(), f.x.q.copy())
        return
    p0, q0, fp, fq = last
    # base_link's motion between the two messages, in base_link's axes at the first: the sensor's origin moved
    # by R0^T (p1 - p0); base_link's origin is t_ext behind it in either pose
    dq = quat_mul(quat_conj(q0), q_base)
    dp = quat_matrix(q0).T @ (p_s - p0) + t_ext - quat_matrix(dq) @ t_ext
    q_meas = quat_mul(fq, dq)
    p_meas = fp + quat_matrix(fq) @ dp + quat_matrix(q_meas) @ t_ext  # the sensor's origin, as update_pose reads
    # the message's covariance as the change's noise, about the sensor's axes: turned into the world's (a pose
    # measured in part is fused about its own axes: turning would mix the unmeasured ones in)
    if (cov.diagonal() < 1e6).all():
        turn = np.zeros((6, 6))
        turn[0:3, 0:3] = turn[3:6, 3:6] = quat_matrix(quat_mul(fq, q_ext))
        cov = turn @ cov @ turn.T
    f.update_pose(p_meas, q_meas, cov, t_ext)
    sensor["last"] = (p_s, q_base, f.x.p.copy(), f.x.q.copy())  # the filter's pose at it: after its update


def run(bags: Sequence[Path | str], cfg, fuse_fix: Callable[[float, int], bool] | None = None) -> np.ndarray:
    """The plain EKF over ``bags`` with fusiond's config ``cfg``: one pose per odometry message (with a GPS,
    from its first fix on), (n, 8) rows t x y z qx qy qz qw. ``fuse_fix(stamp, index)`` (index: the fix's position in bag order) says
    whether a GPS fix is fused; default: every fix."""
    from rosbags.highlevel import AnyReader

    # each [[sensors]] table is a msgspec Struct tagged with its kind ("odom", "imu", "gps")
    by_topic = {"/" + s.key.lstrip("/"): (type(s).__struct_config__.tag, s) for s in cfg.sensors}
    odom_cfg = next(s for k, s in by_topic.values() if k == "odom")
    imu_cfg = next((s for k, s in by_topic.values() if k == "imu"), None)
    gps_cfg = next((s for k, s in by_topic.values() if k == "gps"), None)
    gyro = imu_cfg is not None and imu_cfg.angular_velocity
    mode = imu_cfg.orientation if imu_cfg is not None else "off"
    ext = quat_from_rpy(*imu_cfg.extrinsic_rpy) if imu_cfg is not None else np.array([0.0, 0.0, 0.0, 1.0])
    ext_rot = quat_matrix(ext)
    # a pose sensor: its extrinsic (rotation, lever arm), and for a differential one the previous message's
    # pose and the filter's at it
    poses = {topic: {"q_ext": quat_from_rpy(*sc.extrinsic_rpy), "t_ext": np.array(sc.extrinsic_xyz, dtype=float),
                     "differential": sc.differential, "last": None}
             for topic, (kind, sc) in by_topic.items() if kind == "pose"}

    events = []  # (stamp, bag order, kind, message)
    fixes = 0
    with AnyReader([Path(b) for b in bags]) as reader:
        conns = [c for c in reader.connections if c.topic in by_topic]
        for order, (c, _, raw) in enumerate(reader.messages(connections=conns)):
            kind, _s = by_topic[c.topic]
            msg = reader.deserialize(raw, c.msgtype)
            if kind == "gps":  # counted in bag order, every fix (as fusiond's --fuse-every counts them)
                keep = fuse_fix(_stamp(msg), fixes) if fuse_fix is not None else True
                fixes += 1
                if not keep or msg.status.status < 0:  # STATUS_NO_FIX: no position
                    continue
            events.append((_stamp(msg), order, kind, msg, c.topic))
    events.sort(key=lambda e: (e[0], e[1]))  # header-stamp order

    placing = gps_cfg is not None or any(not ps["differential"] for ps in poses.values())
    f = PlainEkf(placed_by=placing, absolute_yaw=mode in ("absolute", "relative"), gyro=gyro,
                 world_twist=odom_cfg.twist_frame == "world")
    enu = Enu(*gps_cfg.datum) if gps_cfg is not None and gps_cfg.datum is not None else None
    yaw_offset = None  # orientation = "relative": filter yaw less the IMU's yaw at the first sample
    # with a GPS (an absolute pose), a pose is published once its first fix (pose) has placed the robot (as
    # fusiond does): before it, the filter's position is the datum's (the origin), which a recording that
    # starts away from it puts far off
    placed = not placing
    out = []
    from_pose = getattr(odom_cfg, "twist_from_pose", False)
    last_pose = None  # twist_from_pose: the previous odometry message's (t, p, q)
    for t, _, kind, msg, topic in events:
        f.predict(t)
        if kind == "odom":
            tw = msg.twist.twist
            cov = np.asarray(msg.twist.covariance, dtype=float).reshape(6, 6).diagonal()
            v = np.array([tw.linear.x, tw.linear.y, tw.linear.z])
            w = np.array([tw.angular.x, tw.angular.y, tw.angular.z])
            if from_pose:  # the driver fills the pose only: its change since the last message, in the body
                pp, pq = msg.pose.pose.position, msg.pose.pose.orientation
                p, q = np.array([pp.x, pp.y, pp.z]), np.array([pq.x, pq.y, pq.z, pq.w])
                v, w, cov = np.zeros(3), np.zeros(3), np.zeros(6)
                if last_pose is not None and 0.0 < t - last_pose[0] <= cfg.filter.gap_s:
                    dt = t - last_pose[0]
                    v = quat_matrix(last_pose[2]).T @ (p - last_pose[1]) / dt
                    w = quat_log(quat_mul(quat_conj(last_pose[2]), q)) / dt
                last_pose = (t, p, q)
            f.v = v
            f.v_var = _diag_floor(cov[:3], unmeasured=True)
            if not gyro:
                f.w = w
                f.w_var = _diag_floor(cov[3:], unmeasured=True)
            if placed:
                out.append((t, *f.x.p, *f.x.q))
        elif kind == "imu":
            if gyro and msg.angular_velocity_covariance[0] != -1.0:
                av = msg.angular_velocity
                f.w = ext_rot @ np.array([av.x, av.y, av.z])
                cov = np.asarray(msg.angular_velocity_covariance, dtype=float).reshape(3, 3)
                f.w_var = _diag_floor((ext_rot @ cov @ ext_rot.T).diagonal())
            if mode == "off" or msg.orientation_covariance[0] == -1.0:
                continue
            o = msg.orientation
            q_meas = quat_mul(np.array([o.x, o.y, o.z, o.w]), quat_conj(ext))  # base_link in world
            cov = np.asarray(msg.orientation_covariance, dtype=float).reshape(3, 3)
            cov = ext_rot @ cov @ ext_rot.T
            cov = cov + np.diag(_diag_floor(cov.diagonal()) - cov.diagonal())
            if mode == "roll_pitch":
                f.update_roll_pitch(q_meas, cov[:2, :2])
                continue
            if mode == "relative":
                if yaw_offset is None:
                    yaw_offset = quat_rpy(f.x.q)[2] - quat_rpy(q_meas)[2]
                q_meas = quat_mul(quat_exp(np.array([0.0, 0.0, yaw_offset])), q_meas)
            f.update_orientation(q_meas, cov)
        elif kind == "gps":
            if enu is None:
                enu = Enu(msg.latitude, msg.longitude, msg.altitude)
            z = enu(msg.latitude, msg.longitude, msg.altitude)
            if msg.position_covariance_type == 0:  # UNKNOWN
                r = np.eye(3) * UNKNOWN_GPS_SIGMA**2
            else:
                r = np.asarray(msg.position_covariance, dtype=float).reshape(3, 3)
                r = r + np.diag(_diag_floor(r.diagonal()) - r.diagonal())
            f.update_position(z, r)
            placed = True
        elif kind == "pose":
            _fuse_pose(f, msg, poses[topic])
            placed = placed or not poses[topic]["differential"]
    return np.array(out, dtype=float).reshape(-1, 8)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bags", nargs="+")
    ap.add_argument("--config", required=True, help="fusiond's TOML config (topics, kinds, modes, extrinsics)")
    ap.add_argument("--tum", help="write the trajectory as TUM lines (stamp x y z qx qy qz qw)")
    ap.add_argument("--fuse-every", type=int, default=1,
                    help="fuse only every Nth GPS fix (bag order, the first one fused)")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from fusiond.config import load

    cfg = load(args.config)
    n = max(args.fuse_every, 1)
    traj = run(args.bags, cfg, fuse_fix=lambda stamp, i: i % n == 0)
    if args.tum:
        np.savetxt(args.tum, traj, fmt="%.9f")
    t, x, y, z = traj[-1, :4]
    yaw = quat_rpy(traj[-1, 4:8])[2]
    print(f"{traj.shape[0]} poses; final t {t:.3f}  x {x:.4f} y {y:.4f} z {z:.4f}  yaw {math.degrees(yaw):.2f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
