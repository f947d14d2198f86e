"""The real recordings as another recording of the same kind would differ: fusiond beside the plain
baselines on each variant.

A recording fusiond is judged on starts elsewhere (a car already at speed when the heading is
searched for), loses its GPS for a while, gets its fixes less often, or sees a multipath burst.
Each variant here is written from a recording in ../shared/data (a ROS 2 bag: its messages are
copied, the fixes edited through rosbags' own CDR codec), then replayed and scored exactly as
`fusiond replay BAG --config CFG --reference /ground_truth` does. A benchmark, not a test: it
asserts nothing and prints the table; with --write it puts it into docs/RESULTS.md between its
markers ("Variants of the real recordings"). Beside fusiond, the plain EKF (scripts/plain_ekf.py) is
scored on every variant by the same evaluation.

"fusiond tuned": on the variants --tuned names, the same replay and evaluation with the config
`fusiond tune` fits to that variant's bag (scripts/real_recordings.py's ``tune_cached``: the fit
bounded by --maxfev-per-param replays per fitted parameter, never by wall time, cached under
out/tuned/variants/, --retune to refresh; a variant with --fuse-every N is tuned on the fixes the
Recorder lets through, what a robot with 1 fix in N records). Its verdict column compares it with
fusiond's default config, allowing the reference's own noise (scripts/real_recordings.py's
``reference_noise``, with 0.1 s of clock difference at the median speed for an unaligned error on
the highway car, as there).

    .venv/bin/python scripts/recording_variants.py [--data ../shared/data] [--only NAME] [--write]
        [--tuned REGEX] [--retune] [--maxfev-per-param N]

A variant that starts later keeps the original's world frame (the reference is ENU at the
original first fix): its config names that fix as the GPS datum.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- variants table: begin -->", "<!-- variants table: end -->"
EARTH_RADIUS = 6378137.0  # m, WGS84 equatorial: a burst's metres turned into degrees


@dataclass(frozen=True)
class Variant:
    name: str
    recording: str  # under the data folder
    config: str  # under examples/
    what: str
    # (topic, seconds after the first message, message) -> the message to write, or None to drop it;
    # the message is deserialised only for the topics in ``edits``
    edit: Callable[[str, float, object], object | None]
    edits: tuple[str, ...] = ()
    metrics: tuple[str, ...] = ("world_h", "aligned_h")
    # the raw fixes know the next fix (read between two) and are scored only where there are fixes; holding
    # or extrapolating the last one is what a GPS-only user has at each moment, through an outage too
    baselines: tuple[str, ...] = ("raw fixes", "hold last fused fix", "fixes at constant velocity")
    segment: str = "all"
    segments: tuple[str, ...] = ()  # several segments scored (default: ``segment`` alone)
    keep_datum: bool = False  # name the original's first fix as the datum (a variant that starts later)
    fuse_every: int = 1  # as `replay --fuse-every N`: every Nth fix fused, scored at the others
    odom_keys: tuple[tuple[str, object], ...] = ()  # keys set in the config's odometry table (what `init` writes)
    gps_keys: tuple[tuple[str, object], ...] = ()  # keys set in the config's GPS table (a receiver's antenna)
    # a [[sensors]] table added to the config (key = value lines): the sensor of a topic the edit adds (``added``)
    sensor: str = ""


def _keep(topic: str, rel: float, msg: object) -> object:
    return msg


def _start_at(t0: float) -> Callable:
    return lambda topic, rel, msg: msg if rel >= t0 else None


def _outage(t0: float, seconds: float) -> Callable:
    return lambda topic, rel, msg: None if topic == "/fix" and t0 <= rel < t0 + seconds else msg


def _every_nth_fix(n: int) -> Callable:
    count = {"fixes": 0}

    def edit(topic: str, rel: float, msg: object) -> object | None:
        if topic != "/fix":
            return msg
        count["fixes"] += 1
        return msg if (count["fixes"] - 1) % n == 0 else None
    return edit


def _burst(t0: float, fixes: int, east: float, north: float) -> Callable:
    """``fixes`` fixes from t0 on moved by (east, north) m: a multipath burst."""
    left = {"n": None}

    def edit(topic: str, rel: float, msg) -> object | None:
        if topic != "/fix" or rel < t0:
            return msg
        if left["n"] is None:
            left["n"] = fixes
        if left["n"] > 0:
            left["n"] -= 1
            msg.latitude += math.degrees(north / EARTH_RADIUS)
            msg.longitude += math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(msg.latitude))))
        return msg
    return edit


def _shift(msg, east: float, north: float) -> None:
    msg.latitude += math.degrees(north / EARTH_RADIUS)
    msg.longitude += math.degrees(east / (EARTH_RADIUS * math.cos(math.radians(msg.latitude))))


def _step(t0: float, east: float, north: float) -> Callable:
    """Every fix from t0 on moved by (east, north) m: a persistent shift of the receiver's error (a
    re-acquisition, or a multipath lock), to the end of the run. The reference is cut for the 1.5 s
    before t0, so that the evaluation's segments are a (before the step) and b (from the step on)."""
    def edit(topic: str, rel: float, msg) -> object | None:
        if topic == "/ground_truth" and t0 - 1.5 <= rel < t0:
            return None
        if topic == "/fix" and rel >= t0:
            _shift(msg, east, north)
        return msg
    return edit


def _multipath_arc(t0: float, seconds: float, metres: float) -> Callable:
    """The fixes from t0 for ``seconds`` moved by ``metres`` x sin(pi s / seconds) along a direction that turns
    from east to north meanwhile, their covariance as recorded: a slow multipath wander off a row of buildings
    that the filter follows, then returns."""
    def edit(topic: str, rel: float, msg) -> object | None:
        if topic == "/fix" and t0 <= rel < t0 + seconds:
            s = (rel - t0) / seconds
            off, turn = metres * math.sin(math.pi * s), 0.5 * math.pi * s
            _shift(msg, off * math.cos(turn), off * math.sin(turn))
        return msg
    return edit


def _pose_only(topic: str, rel: float, msg: object) -> object:
    """The odometry's twist zeroed, its pose as recorded: a driver that fills the pose only (robot_pose_ekf's
    input)."""
    if topic == "/odom":
        tw = msg.twist.twist
        tw.linear.x = tw.linear.y = tw.linear.z = tw.angular.x = tw.angular.y = tw.angular.z = 0.0
    return msg


def _odom_pauses(every: float, pause: float) -> Callable:
    """No odometry message in the last ``pause`` s of every ``every`` s: a logger or a CAN bridge that pauses
    briefly and often (shorter than the filter's gap_s)."""
    return lambda topic, rel, msg: None if topic == "/odom" and rel % every >= every - pause else msg


def _wheel_yaw_offset(offset: float) -> Callable:
    """Every odometry message's yaw rate (twist.angular.z) read ``offset`` rad/s high: a driver's offset, which
    a road that hardly turns shows alone (no scale to part it from)."""
    def edit(topic: str, rel: float, msg) -> object | None:
        if topic == "/odom":
            msg.twist.twist.angular.z += offset
        return msg
    return edit


class _NoisyRest:
    """Gaussian noise (sigma m/s, seeded) added to the wheel speed (twist.linear.x) of every odometry
    message stamped where the reference says the vehicle is at rest: the reference's displacement between
    0.25 s before and after the stamp below 0.05 m/s (read across the reference's own pauses of up to 2 s:
    the F1/10 car's particle filter stops publishing while the car stands, and resumes where it stopped).
    A drive whose speed reads a few cm/s at rest, never exactly 0."""

    def __init__(self, sigma: float, seed: int, rest_speed: float = 0.05, half: float = 0.25,
                 max_gap: float = 2.0) -> None:
        self.sigma, self.seed, self.rest_speed, self.half, self.max_gap = sigma, seed, rest_speed, half, max_gap
        self.noised = 0

    def prepare(self, src: Path) -> None:
        import numpy as np
        from rosbags.highlevel import AnyReader

        rows = []
        with AnyReader([src]) as reader:
            conns = [c for c in reader.connections if c.topic == "/ground_truth"]
            for c, _, raw in reader.messages(connections=conns):
                m = reader.deserialize(raw, c.msgtype)
                pose = m.pose.pose if hasattr(m.pose, "pose") else m.pose
                rows.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, pose.position.x, pose.position.y))
        self.ref = np.array(sorted(rows))
        self.rng = np.random.default_rng(self.seed)
        self.noised = 0

    def at_rest(self, t: float) -> bool:
        import numpy as np

        rt = self.ref[:, 0]
        a, b = t - self.half, t + self.half
        if a < rt[0] or b > rt[-1]:
            return False
        lo, hi = np.searchsorted(rt, a, side="right") - 1, np.searchsorted(rt, b, side="left")
        if np.max(np.diff(rt[lo:hi + 1]), initial=0.0) > self.max_gap:
            return False
        pa = [np.interp(a, rt, self.ref[:, k]) for k in (1, 2)]
        pb = [np.interp(b, rt, self.ref[:, k]) for k in (1, 2)]
        return math.hypot(pb[0] - pa[0], pb[1] - pa[1]) / (b - a) < self.rest_speed

    def __call__(self, topic: str, rel: float, msg) -> object | None:
        if topic == "/odom" and self.at_rest(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec):
            msg.twist.twist.linear.x += float(self.rng.normal(0.0, self.sigma))
            self.noised += 1
        return msg


class _RtkFixes:
    """Every fix rebuilt as an RTK receiver's (fixed solution) would give it: the reference's position at the fix's
    stamp (interpolated), the antenna at ``lever`` in base_link turned by the reference's direction of travel
    (over +-0.25 s), plus a seeded white noise of 1.2 cm horizontal and 2.5 cm vertical, stating 1.5 cm and 3 cm
    (DIAGONAL_KNOWN) and a GBAS fix. In the reference's frame: ENU at the original first fix, which the variant's
    config names as its datum (``keep_datum``)."""

    def __init__(self, lever: tuple[float, float, float], seed: int = 1) -> None:
        self.lever, self.seed = lever, seed

    def prepare(self, src: Path) -> None:
        import numpy as np
        from rosbags.highlevel import AnyReader

        from fusiond.estimator.geodesy import EnuFrame

        rows, first = [], None
        with AnyReader([src]) as reader:
            conns = [c for c in reader.connections if c.topic in ("/ground_truth", "/fix")]
            for c, _, raw in reader.messages(connections=conns):
                m = reader.deserialize(raw, c.msgtype)
                if c.topic == "/fix":
                    if first is None and m.status.status >= 0:
                        first = (m.latitude, m.longitude, m.altitude)
                    continue
                pose = m.pose.pose if hasattr(m.pose, "pose") else m.pose
                p = pose.position
                rows.append((m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec, p.x, p.y, p.z))
        self.ref = np.array(sorted(rows))
        self.frame = EnuFrame(*first)
        self.rng = np.random.default_rng(self.seed)

    def __call__(self, topic: str, rel: float, msg) -> object | None:
        import numpy as np

        from fusiond.estimator.geodesy import enu_to_geodetic

        if topic != "/fix":
            return msg
        rt = self.ref[:, 0]
        t = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if not rt[0] + 0.25 <= t <= rt[-1] - 0.25:
            return None
        e, n, u = (float(np.interp(t, rt, self.ref[:, k])) for k in (1, 2, 3))
        (e0, n0), (e1, n1) = ([float(np.interp(s, rt, self.ref[:, k])) for k in (1, 2)] for s in (t - 0.25, t + 0.25))
        yaw = math.atan2(n1 - n0, e1 - e0)
        c, s = math.cos(yaw), math.sin(yaw)
        lx, ly, lz = self.lever
        e += c * lx - s * ly + float(self.rng.normal(0.0, 0.012))
        n += s * lx + c * ly + float(self.rng.normal(0.0, 0.012))
        u += lz + float(self.rng.normal(0.0, 0.025))
        msg.latitude, msg.longitude, msg.altitude = enu_to_geodetic(self.frame, e, n, u)
        msg.status.status = 2  # GBAS_FIX: an RTK solution
        msg.position_covariance = np.array([0.015**2, 0.0, 0.0, 0.0, 0.015**2, 0.0, 0.0, 0.0, 0.03**2])
        msg.position_covariance_type = 2  # DIAGONAL_KNOWN
        return msg


class _VisualOdometry:
    """A camera's visual odometry made from the reference (``added``: the topic /vo/odom, nav_msgs/Odometry at the
    reference's rate): the camera's pose (``lever`` ahead of base_link, its axes turned by ``mount`` yaw) in a frame
    at its first pose, plus a seeded white noise of 1.5 cm and 0.2 deg, stating 2 cm and 0.01 rad. ``reset``: (t,
    seconds) after the first message: silent for that long, then it starts again from its own origin (a tracking
    loss). The reference's own orientation is the camera's as recorded (the highway car's INS sits 0.9 deg from its
    direction of travel: the doctor's vo/mount)."""

    def __init__(self, lever: float = 0.0, mount: float = 0.0, reset: tuple[float, float] | None = None,
                 seed: int = 1) -> None:
        self.lever, self.mount, self.reset, self.seed = lever, mount, reset, seed

    def prepare(self, src: Path) -> None:
        self.src = src

    def __call__(self, topic: str, rel: float, msg) -> object | None:
        return msg

    def added(self, store, t_first: int) -> tuple[str, str, list[tuple[int, bytes]]]:
        import numpy as np
        from rosbags.highlevel import AnyReader

        from fusiond.estimator import rotation as rot

        rng = np.random.default_rng(self.seed)
        rows = []
        with AnyReader([self.src]) as reader:
            for c, t, raw in reader.messages(connections=[c for c in reader.connections if c.topic == "/ground_truth"]):
                m = reader.deserialize(raw, c.msgtype)
                pose = m.pose.pose if hasattr(m.pose, "pose") else m.pose
                p, o = pose.position, pose.orientation
                rows.append((t, m.header, (p.x, p.y, p.z), (o.x, o.y, o.z, o.w)))
        mount_q = rot.from_rpy(0.0, 0.0, self.mount)
        msgtype = "nav_msgs/msg/Odometry"
        Odometry = store.types[msgtype]
        cov = np.diag([0.02**2] * 3 + [0.01**2] * 3).ravel()
        out, origin = [], None
        for t, header, p, q in rows:
            rel = (t - t_first) / 1e9
            if self.reset is not None and self.reset[0] <= rel < self.reset[0] + self.reset[1]:
                continue
            lever = rot.matrix9(q)
            cam = (p[0] + lever[0] * self.lever, p[1] + lever[3] * self.lever, p[2] + lever[6] * self.lever)
            cq = rot.mul(q, mount_q)
            restart = self.reset is not None and rel >= self.reset[0] + self.reset[1] and origin[2] == 0
            if origin is None or restart:
                origin = (cam, cq, 1 if origin is not None else 0)
            r0 = rot.matrix9(origin[1])
            d = (cam[0] - origin[0][0], cam[1] - origin[0][1], cam[2] - origin[0][2])
            local = tuple(r0[k] * d[0] + r0[k + 3] * d[1] + r0[k + 6] * d[2] + float(rng.normal(0.0, 0.015))
                          for k in range(3))
            turn = rot.from_rpy(*(float(v) for v in rng.normal(0.0, math.radians(0.2), 3)))
            lq = rot.normalize(rot.mul(turn, rot.mul(rot.conj(origin[1]), cq)))
            msg = Odometry(header=header, child_frame_id="camera", pose=store.types[
                "geometry_msgs/msg/PoseWithCovariance"](pose=store.types["geometry_msgs/msg/Pose"](
                    position=store.types["geometry_msgs/msg/Point"](x=local[0], y=local[1], z=local[2]),
                    orientation=store.types["geometry_msgs/msg/Quaternion"](x=lq[0], y=lq[1], z=lq[2], w=lq[3])),
                    covariance=cov), twist=store.types["geometry_msgs/msg/TwistWithCovariance"](
                    twist=store.types["geometry_msgs/msg/Twist"](
                        linear=store.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                        angular=store.types["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                    covariance=np.zeros(36)))
            msg.header.frame_id = "vo"
            out.append((t, store.serialize_cdr(msg, msgtype)))
        return "/vo/odom", msgtype, out


VO = 'name = "vo"\nkind = "pose"\nkey = "vo/odom"\nmsgtype = "nav_msgs/msg/Odometry"\ndifferential = true'
COMMA, F110 = "comma2k19_ex1", "f110_ds2"
F110_BASELINES = ("gyro + wheel speed", "wheel odometry")
VARIANTS = (
    Variant("comma_copy", COMMA, "comma2k19.toml", "highway car, as recorded (the control)", _keep),
    Variant("comma_start10", COMMA, "comma2k19.toml", "highway car, starting 10 s in (at 15 m/s)", _start_at(10.0),
            keep_datum=True),
    Variant("comma_start20", COMMA, "comma2k19.toml", "highway car, starting 20 s in (at 19 m/s)", _start_at(20.0),
            keep_datum=True),
    Variant("comma_start30", COMMA, "comma2k19.toml", "highway car, starting 30 s in", _start_at(30.0),
            keep_datum=True),
    Variant("comma_outage20", COMMA, "comma2k19.toml", "highway car, no fix for 20 s from 25 s", _outage(25.0, 20.0)),
    Variant("comma_1hz", COMMA, "comma2k19.toml", "highway car, fixes at 1 Hz", _every_nth_fix(10)),
    Variant("comma_burst", COMMA, "comma2k19.toml", "highway car, 20 fixes 15 m east from 30 s", _burst(30.0, 20, 15.0, 0.0),
            edits=("/fix",)),
    Variant("comma_burst_early", COMMA, "comma2k19.toml", "highway car, 5 fixes 15 m east from 0.5 s (heading unknown)",
            _burst(0.5, 5, 15.0, 0.0), edits=("/fix",)),
    Variant("comma_burst3", COMMA, "comma2k19.toml", "highway car, 3 fixes 7 m east from 30 s (an outlier burst)",
            _burst(30.0, 3, 7.0, 0.0), edits=("/fix",)),
    Variant("comma_step_east", COMMA, "comma2k19.toml",
            "highway car, every fix from 30 s on 7 m east (the receiver's error steps and stays)",
            _step(30.0, 7.0, 0.0), edits=("/fix",), segments=("all", "a", "b")),
    Variant("comma_step_north", COMMA, "comma2k19.toml",
            "highway car, every fix from 20 s on 7 m north (the receiver's error steps and stays)",
            _step(20.0, 0.0, 7.0), edits=("/fix",), segments=("all", "a", "b")),
    Variant("comma_step_east_1in10", COMMA, "comma2k19.toml",
            "the same step, 1 fix in 10 fused (scored at the other 9, against the reference)",
            _step(30.0, 7.0, 0.0), edits=("/fix",), segments=("all", "a", "b"), fuse_every=10,
            baselines=("hold last fused fix", "fixes at constant velocity")),
    Variant("comma_multipath_arc", COMMA, "comma2k19.toml",
            "highway car, the fixes from 5 s to 25 s wandering up to 8 m off along a slow arc (multipath)",
            _multipath_arc(5.0, 20.0, 8.0), edits=("/fix",)),
    Variant("comma_odom_pauses", COMMA, "comma2k19.toml",
            "highway car, no odometry for 0.4 s every 2 s (a logger pausing briefly and often)", _odom_pauses(2.0, 0.4)),
    Variant("comma_odom_pauses_no_gps", COMMA, "comma2k19_odom_imu.toml",
            "the same pauses, wheels and gyro alone", _odom_pauses(2.0, 0.4), metrics=("aligned_h", "heading_deg"),
            baselines=("gyro + wheel speed", "wheel odometry")),
    Variant("comma_wz_offset", COMMA, "comma2k19.toml",
            "highway car, the wheels' yaw rate read 0.05 rad/s high (a driver's offset; the gyro fused)",
            _wheel_yaw_offset(0.05), edits=("/odom",)),
    Variant("comma_rtk", COMMA, "comma2k19.toml", "highway car, an RTK receiver's fixes (1.2 cm) at the base",
            _RtkFixes((0.0, 0.0, 0.0)), ("/fix",), keep_datum=True),
    Variant("comma_rtk_lever", COMMA, "comma2k19.toml",
            "highway car, an RTK receiver's fixes (1.2 cm), its antenna 0.5 m behind the base, stated",
            _RtkFixes((-0.5, 0.0, 0.0)), ("/fix",), keep_datum=True, gps_keys=(("extrinsic_xyz", (-0.5, 0.0, 0.0)),)),
    Variant("comma_vo", COMMA, "comma2k19_odom_imu.toml",
            "highway car, wheels + gyro + a camera's visual odometry (the reference's, as mounted), no GPS",
            _VisualOdometry(), metrics=("aligned_h", "heading_deg"), baselines=("gyro + wheel speed", "wheel odometry"),
            sensor=VO),
    Variant("comma_vo_stated", COMMA, "comma2k19_odom_imu.toml",
            "the same, the doctor's vo/mount line pasted (its yaw, 0.82 deg, in extrinsic_rpy)",
            _VisualOdometry(), metrics=("aligned_h", "heading_deg"), baselines=("gyro + wheel speed", "wheel odometry"),
            sensor=VO + "\nextrinsic_rpy = [0.0, 0.0, 0.0143]"),
    Variant("comma_vo_mount", COMMA, "comma2k19_odom_imu.toml",
            "the camera 0.3 m ahead, turned 90 deg left, stated (extrinsic_xyz, and extrinsic_rpy as the doctor's "
            "vo/mount line on it: 90.82 deg)", _VisualOdometry(lever=0.3, mount=math.pi / 2),
            metrics=("aligned_h", "heading_deg"), baselines=("gyro + wheel speed", "wheel odometry"),
            sensor=VO + "\nextrinsic_xyz = [0.3, 0.0, 0.0]\nextrinsic_rpy = [0.0, 0.0, 1.5851]"),
    Variant("comma_vo_reset", COMMA, "comma2k19_odom_imu.toml",
            "the stated camera, silent 3 s from 18 s, then starting again from its own origin",
            _VisualOdometry(reset=(18.0, 3.0)), metrics=("aligned_h", "heading_deg"),
            baselines=("gyro + wheel speed", "wheel odometry"), sensor=VO + "\nextrinsic_rpy = [0.0, 0.0, 0.0143]"),
    Variant("f110_vo_reset", F110, "f110.toml",
            "F1/10 car, a camera's visual odometry silent 3 s from 50 s, then from its own origin",
            _VisualOdometry(reset=(50.0, 3.0)), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES,
            segments=("a", "c", "d"), sensor=VO),
    Variant("f110_copy", F110, "f110.toml", "F1/10 car, orientation off, as recorded (the control)", _keep,
            metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segments=("a", "c", "d")),
    Variant("f110_noisy_rest", F110, "f110.toml",
            "F1/10 car, orientation off, wheel speed + N(0, 0.03 m/s) where the reference is at rest",
            _NoisyRest(0.03, seed=0), edits=("/odom",), metrics=("aligned_h", "heading_deg"),
            baselines=F110_BASELINES, segments=("a", "c", "d")),
    Variant("f110_new_user", F110, "f110_new_user.toml",
            "F1/10 car, the config a new user writes (no twist_measured, no [filter])", _keep,
            metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segments=("a", "c", "d")),
    Variant("f110_pose_only", F110, "f110_new_user.toml",
            "F1/10 car, the driver's twist zeroed (it fills the pose only), twist_from_pose as `fusiond init` writes it",
            _pose_only, edits=("/odom",), metrics=("aligned_h", "heading_deg"), baselines=(), segments=("a", "c", "d"),
            odom_keys=(("twist_from_pose", True),)),
    Variant("f110_start20", F110, "f110_imu_yaw.toml", "F1/10 car, IMU yaw relative, starting 20 s in",
            _start_at(20.0), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segment="a"),
    Variant("f110_start60", F110, "f110_imu_yaw.toml", "F1/10 car, IMU yaw relative, starting 60 s in",
            _start_at(60.0), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segment="a"),
    Variant("f110_off_start60", F110, "f110.toml", "F1/10 car, orientation off, starting 60 s in",
            _start_at(60.0), metrics=("aligned_h", "heading_deg"), baselines=F110_BASELINES, segment="a"),
)
UNITS = {"world_h": "m world", "aligned_h": "m aligned", "heading_deg": "deg heading"}
# the variants given a tuned column by default (--tuned): the F1/10 car's faults and the GPS steps
TUNED = "f110_copy|f110_noisy_rest|f110_new_user|comma_step_.*"
# how far the reference's clock may be from the sensors' (the recordings' README), as in real_recordings.py
TIME_BASE_S = {COMMA: 0.1, F110: 0.0}


def write_variant(src: Path, out: Path, v: Variant) -> tuple[float, float, float] | None:
    """Write ``v`` of the ROS 2 bag ``src`` to ``out``; the original's first fix (lat, lon, alt), if any."""
    from rosbags.rosbag2 import Reader, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    if hasattr(v.edit, "prepare"):
        v.edit.prepare(src)
    first_fix = None
    with Reader(src) as reader, Writer(out, version=8) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=store) for c in reader.connections}
        t0 = reader.start_time
        for c, t, raw in reader.messages():
            rel = (t - t0) / 1e9
            decoded = c.topic in v.edits or (c.topic == "/fix" and first_fix is None)
            msg = store.deserialize_cdr(raw, c.msgtype) if decoded else raw
            if c.topic == "/fix" and first_fix is None and msg.status.status >= 0:
                first_fix = (msg.latitude, msg.longitude, msg.altitude)
            kept = v.edit(c.topic, rel, msg)
            if kept is None:
                continue
            writer.write(conns[c.id], t, store.serialize_cdr(kept, c.msgtype) if c.topic in v.edits else raw)
        if hasattr(v.edit, "added"):
            topic, msgtype, rows = v.edit.added(store, t0)
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for t, raw in rows:
                writer.write(conn, t, raw)
    return first_fix


def _real_recordings():
    """scripts/real_recordings.py as a module (this script is also loaded by file, off sys.path)."""
    import importlib.util

    if "real_recordings" not in sys.modules:
        spec = importlib.util.spec_from_file_location("real_recordings", ROOT / "scripts" / "real_recordings.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[spec.name] = module
        spec.loader.exec_module(module)
    return sys.modules["real_recordings"]


def _plain_evaluation(bag: Path, cfg, rec):
    return _real_recordings().plain_evaluation([bag], cfg, rec)


def score(data: Path, v: Variant, work: Path, tuned: dict | None = None
          ) -> list[tuple[str, str, tuple | None, tuple | None, list, tuple | None]]:
    """Per segment and metric: fusiond's (value, points scored), the plain EKF's, each baseline's
    (name, value, points scored), and the tuned config's (value, points scored; None unless ``tuned``,
    a dict of tune_cached's options to which the Tuned config is added under the variant's name)."""
    import msgspec

    from fusiond.config import load
    from fusiond.core.sensors import kind_of
    from fusiond.replay.evaluate import Recorder, evaluate
    from fusiond.replay.run import replay

    bag = work / v.name
    first_fix = write_variant(data / v.recording, bag, v)
    cfg = load(ROOT / "examples" / v.config)
    if v.sensor:  # the example's own text with the table added: checked as a user's config is
        from fusiond.config import loads

        cfg = loads((ROOT / "examples" / v.config).read_text() + "\n[[sensors]]\n" + v.sensor)
    if v.odom_keys:
        cfg = msgspec.structs.replace(cfg, sensors=[msgspec.structs.replace(s, **dict(v.odom_keys))
                                                    if kind_of(s).drives_prediction else s for s in cfg.sensors])
    if v.gps_keys:
        cfg = msgspec.structs.replace(cfg, sensors=[msgspec.structs.replace(s, **dict(v.gps_keys))
                                                    if kind_of(s).geodetic else s for s in cfg.sensors])
    if v.keep_datum and first_fix is not None:
        cfg = msgspec.structs.replace(cfg, sensors=[msgspec.structs.replace(s, datum=first_fix)
                                                    if kind_of(s).geodetic else s for s in cfg.sensors])
    rec = Recorder(cfg, v.fuse_every)
    result = replay([bag], cfg, keep_trace=False, progress=False, doctor=False, through=rec.filter)
    ev = evaluate([bag], cfg, "/ground_truth", result.trajectory, rec, heading_known=result.heading_known)
    pev = _plain_evaluation(bag, cfg, rec)
    tev = None
    if tuned is not None:
        rr = _real_recordings()
        # the cache is that of this variant of this config: the variant's edit is named by its name and
        # description, the config by its full encoding (the datum a later start names is in it)
        source = f"{v.name}\n{v.what}\n{msgspec.json.encode(cfg).decode()}"
        options = {k: val for k, val in tuned.items() if k in ("retune", "maxfev_per_param")}
        t = rr.tune_cached([bag], cfg, source, f"{v.name} ({v.recording}, {v.config}"
                           f"{f', --fuse-every {v.fuse_every}' if v.fuse_every > 1 else ''})", v.name,
                           fuse_every=v.fuse_every, cache=rr.TUNED_DIR / "variants", **options)
        tuned.setdefault("runs", []).append(t)
        tev, _ = rr.fusiond_evaluation([bag], t.cfg, v.fuse_every)
    out = []
    for segment in v.segments or (v.segment,):
        by = {sc.method: sc for sc in ev.scores if sc.segment == segment}
        pby = {sc.method: sc for sc in pev.scores if sc.segment == segment}
        tby = {sc.method: sc for sc in tev.scores if sc.segment == segment} if tev is not None else {}
        span = next((f"{s.start:.0f}-{s.end:.0f} s" for s in ev.segments if s.name == segment), "")
        for metric in v.metrics:
            ours = (getattr(by["fusiond"], metric), by["fusiond"].n) if "fusiond" in by else None
            plain = (getattr(pby["fusiond"], metric), pby["fusiond"].n) if "fusiond" in pby else None
            base = [(m, getattr(by[m], metric), by[m].n) for m in v.baselines
                    if m in by and getattr(by[m], metric) is not None]
            tv = (getattr(tby["fusiond"], metric), tby["fusiond"].n) if "fusiond" in tby else None
            out.append((f"{segment} ({span})" if span else segment, metric, ours, plain, base, tv))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"), help="the recordings' folder")
    ap.add_argument("--only", help="variants by name (a regular expression matched in full)")
    ap.add_argument("--write", action="store_true", help="write the table into docs/RESULTS.md")
    ap.add_argument("--tuned", default=TUNED, help=f"variants given a tuned column (a regular expression matched "
                    f"in full; default {TUNED!r}; '' for none)")
    ap.add_argument("--retune", action="store_true", help="tune every variant again (ignore out/tuned/variants/)")
    ap.add_argument("--maxfev-per-param", type=int, default=None,
                    help="tune's fit replays per fitted parameter (default: scripts/real_recordings.py's)")
    args = ap.parse_args()
    data = Path(args.data)
    from fusiond.logs import configure

    configure("warning")
    if not (data / COMMA).exists():
        print(f"recording_variants: no recordings in {data}", file=sys.stderr)
        return 2
    chosen = [v for v in VARIANTS if args.only is None or re.fullmatch(args.only, v.name)]
    if not chosen:
        print(f"recording_variants: no variant {args.only!r}; one of {', '.join(v.name for v in VARIANTS)}",
              file=sys.stderr)
        return 2
    started = time.perf_counter()
    rr = _real_recordings()
    per_param = args.maxfev_per_param or rr.MAXFEV_PER_PARAM
    options = {"retune": args.retune, "maxfev_per_param": per_param}
    runs: list = []
    lines = ["| variant | case | segment | metric | fusiond (points scored) | fusiond tuned (points scored) | "
             "plain EKF (points scored) | plain baselines (points scored) | reference noise | "
             "tuned not worse than default (within reference noise) |", "|---|---|---|---|---|---|---|---|---|---|"]
    print("\n".join(lines))
    with tempfile.TemporaryDirectory(prefix="fusiond-variants-") as tmp:
        for v in chosen:
            tuned = dict(options) if args.tuned and re.fullmatch(args.tuned, v.name) else None
            noise_m, noise_deg, speed = rr.reference_noise(data, v.recording)
            for segment, metric, ours, plain, base, tv in score(data, v, Path(tmp), tuned):
                noise = noise_deg if metric == "heading_deg" else \
                    max(noise_m, TIME_BASE_S[v.recording] * speed if metric == "world_h" else 0.0)
                ours_s = "-" if ours is None else f"{ours[0]:.3f} {UNITS[metric]} ({ours[1]})"
                tuned_s = "-" if tv is None or tv[0] is None else f"{tv[0]:.3f} ({tv[1]})"
                plain_s = "-" if plain is None or plain[0] is None else f"{plain[0]:.3f} ({plain[1]})"
                base_s = "; ".join(f"{name} {value:.3f} ({n})" for name, value, n in base) or "-"
                verdict = rr.not_worse(None if tv is None else tv[0], None if ours is None else ours[0], noise)
                lines.append(f"| {v.name} | {v.what} | {segment} | {metric} | {ours_s} | {tuned_s} | {plain_s} | "
                             f"{base_s} | {noise:.3f} | {verdict} |")
                print(lines[-1], flush=True)
            if hasattr(v.edit, "noised"):
                print(f"({v.name}: {v.edit.noised} odometry messages noised)", file=sys.stderr)
            if tuned is not None:
                runs += tuned["runs"]
                t = tuned["runs"][-1]
                print(f"\n{t.label} ({t.path}):\n{t.table}\n", file=sys.stderr, flush=True)
    if runs:
        lines += ["", f"`fusiond tune` per variant (maxfev {per_param} replays per fitted parameter, no wall-time "
                  "bound; seconds on this shared machine):", ""]
        lines += rr.tune_lines(runs)
        print("\n" + "\n".join(lines[-len(runs) - 4:]))
    print(f"({time.perf_counter() - started:.0f} s)", file=sys.stderr)
    if args.write:
        if args.only is not None:
            print("recording_variants: --write writes the whole table; run it without --only", file=sys.stderr)
            return 2
        path = ROOT / "docs" / "RESULTS.md"
        doc = path.read_text()
        if BEGIN not in doc:
            print(f"recording_variants: no {BEGIN} in {path}", file=sys.stderr)
            return 2
        head, rest = doc.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        path.write_text(head + BEGIN + "\n" + "\n".join(lines) + "\n" + END + tail)
    return 0


if __name__ == "__main__":
    sys.exit(main())
