"""`fusiond replay --reference TOPIC`: the published trajectory scored against a reference topic that is
never fused, beside the baselines a user could have had with no filter at all.

A filter earns its place only where it beats those baselines on the same recording and the same scorer:
raw wheel odometry, the gyro's heading with the wheels' speed, the raw fixes (interpolated between a fix
and the next, so they know the next one), holding the last fused fix or extrapolating the last two (what
a GPS-only user has at each moment, through an outage too; with fixes thinned by ``--fuse-every N``
scored on the fixes that were not fused). Alignment and RPE use evo's implementations (Umeyama, relative pose error); this module
only reads the bag, builds the tracks and splits the recording into the segments its gaps leave.

Scoring times: every reference stamp, or with ``--fuse-every N`` the stamps of the absolute sensor's
messages that were held back. Each track is read at those times: published poses and dead-reckoned
tracks are interpolated between their own samples (never across more than ``segment_gap_s``), a held
fix is a step. The reference is taken to be in the filter's world frame when the configuration has a
GPS or an absolute pose (ENU at the GPS datum for a NavSatFix reference); without one only aligned
errors mean anything, and only those are shown.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import numpy as np

from ..config import Config
from ..core.layout import absolute_sensor
from ..core.sensors.registry import kind_of
from ..errors import ReplayError
from ..estimator.geodesy import EnuFrame
from ..estimator.rotation import from_rpy, matrix, yaw
from ..samples import Sample
from ..core.sensors import GpsSample, ImuSample, OdomSample

__all__ = ["Evaluation", "Score", "Segment", "Recorder", "evaluate", "format_evaluation", "read_reference"]

REFERENCE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
    "sensor_msgs/msg/NavSatFix",
)


@dataclass
class Track:
    """A trajectory sampled at its own stamps: positions (n, 3) and, when it has one, a heading (n,)."""

    name: str
    t: np.ndarray
    xyz: np.ndarray
    heading: np.ndarray | None
    world: bool  # expressed in the world frame, so that unaligned errors mean something
    held: bool = False  # a held value (the last fix): read as a step, never interpolated
    # per sample: is its heading an estimate? (None: every one is) A pose published while a GPS-referenced
    # heading waits for travel states its yaw as unknown: its yaw is a placeholder, not scored.
    heading_known: np.ndarray | None = None

    @classmethod
    def build(cls, name: str, t, xyz, heading=None, world: bool = False, held: bool = False,
              heading_known=None) -> Track:
        """Sorted by stamp, one sample a stamp (the last one published for it), the heading unwrapped so
        that interpolation never runs the long way round."""
        t = np.asarray(t, dtype=float)
        order = np.argsort(t, kind="stable")
        t = t[order]
        keep = np.append(t[1:] != t[:-1], True) if t.size else np.zeros(0, bool)
        xyz = np.asarray(xyz, dtype=float).reshape(-1, 3)[order][keep]
        h = None if heading is None else np.unwrap(np.asarray(heading, dtype=float)[order][keep])
        known = None if heading_known is None else np.asarray(heading_known, dtype=bool)[order][keep]
        return cls(name, t[keep], xyz, h, world, held, known)

    def at(self, ts: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        """(xyz, heading, valid) at the times ``ts``."""
        n = self.t.size
        m = ts.size
        if n == 0:
            return np.zeros((m, 3)), None if self.heading is None else np.zeros(m), np.zeros(m, bool)
        if self.held:
            i = np.searchsorted(self.t, ts, side="right") - 1
            valid = i >= 0
            i = np.clip(i, 0, n - 1)
            return self.xyz[i], None if self.heading is None else self.heading[i], valid
        hi = np.clip(np.searchsorted(self.t, ts, side="left"), 0, n - 1)
        lo = np.clip(hi - 1, 0, n - 1)
        exact = self.t[hi] == ts
        lo = np.where(exact, hi, lo)
        span = self.t[hi] - self.t[lo]
        valid = exact | ((self.t[lo] <= ts) & (ts <= self.t[hi]) & (span > 0.0) & (span <= max_gap))
        w = np.where(span > 0.0, (ts - self.t[lo]) / np.where(span > 0.0, span, 1.0), 0.0)
        xyz = self.xyz[lo] + w[:, None] * (self.xyz[hi] - self.xyz[lo])
        h = None if self.heading is None else self.heading[lo] + w * (self.heading[hi] - self.heading[lo])
        if h is not None and self.heading_known is not None:
            h = np.where(self.heading_known[lo] & self.heading_known[hi], h, np.nan)
        return xyz, h, valid


@dataclass
class ExtrapolatedFixes:
    """The last two fused fixes extrapolated at their velocity: what a GPS-only tracker with a constant
    velocity model would say between fixes."""

    name: str
    t: np.ndarray
    xyz: np.ndarray
    world: bool = True
    heading = None

    def at(self, ts: np.ndarray, max_gap: float) -> tuple[np.ndarray, None, np.ndarray]:
        n = self.t.size
        i = np.searchsorted(self.t, ts, side="right") - 1  # the last fix at or before each time
        valid = i >= 0
        i = np.clip(i, 0, max(n - 1, 0))
        if n == 0:
            return np.zeros((ts.size, 3)), None, valid
        prev = np.maximum(i - 1, 0)
        dt = self.t[i] - self.t[prev]
        moving = (i >= 1) & (dt > 0.0) & (dt <= max_gap)  # no velocity from one fix, nor across a gap
        v = np.where(moving[:, None], (self.xyz[i] - self.xyz[prev]) / np.where(moving, dt, 1.0)[:, None], 0.0)
        return self.xyz[i] + v * (ts - self.t[i])[:, None], None, valid


class Score(msgspec.Struct):
    """One method on one segment. Errors in metres (horizontal unless said), heading in degrees;
    None where the method or the frame cannot give it."""

    segment: str
    method: str
    n: int
    world_h: float | None = None  # RMS horizontal error in the world frame, unaligned
    world_up: float | None = None  # RMS vertical error in the world frame, unaligned
    aligned_h: float | None = None  # RMS horizontal error after a 2-D rigid (Umeyama) alignment
    heading_deg: float | None = None  # RMS heading error less its mean offset over the segment
    rpe_m: float | None = None  # RMS relative (drift) error over rpe_s, 2-D
    world_offset: tuple[float, float] | None = None  # the mean horizontal error in the world frame (east, north)


class Segment(msgspec.Struct):
    name: str
    start: float  # s since the reference's first stamp
    end: float


class Evaluation(msgspec.Struct):
    reference: str
    reference_type: str
    world: bool  # the configuration defines a world frame (GPS or absolute pose)
    fuse_every: int
    scored_at: str  # "reference stamps" | "held-back <sensor> messages"
    rpe_s: float
    segments: list[Segment]
    scores: list[Score]
    notes: list[str] = msgspec.field(default_factory=list)


@dataclass
class Recorder:
    """Sees every sample of the bag before the core does: keeps what the baselines need and, with
    ``fuse_every`` > 1, holds back all but every Nth message of the absolute sensor (they are scored on)."""

    cfg: Config
    fuse_every: int = 1
    odom: list[tuple[float, ...]] = field(default_factory=list)  # t vx vy wz yaw_of_message world_twist
    gyro: list[tuple[float, float]] = field(default_factory=list)  # t, yaw rate in base_link
    fused_fixes: list[tuple[float, float, float, float, int]] = field(default_factory=list)  # t lat lon alt status
    held_fixes: list[tuple[float, float, float, float, int]] = field(default_factory=list)
    fused_poses: list[tuple[float, float, float, float, float]] = field(default_factory=list)  # t x y z yaw
    held_poses: list[tuple[float, float, float, float, float]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.fuse_every < 1:
            raise ReplayError("--fuse-every must be >= 1")
        sensors = {s.name: s for s in self.cfg.sensors}
        self._odom_world = {n for n, s in sensors.items() if kind_of(s).drives_prediction and s.twist_frame == "world"}
        self._imu_rot = {n: matrix(from_rpy(*s.extrinsic_rpy)) for n, s in sensors.items()
                         if kind_of(s).fuses_gyro(s)}
        self._absolute = next((s.name for s in self.cfg.sensors if absolute_sensor(s)), None)
        # the world frame's sensor is a GPS (fixes in WGS84, their status scored) rather than a pose sensor
        self.geodetic = self._absolute is not None and kind_of(sensors[self._absolute]).geodetic
        self._count = 0

    @property
    def absolute(self) -> str | None:
        return self._absolute

    def filter(self, samples: Iterator[Sample]) -> Iterator[Sample]:
        """The bag's samples, less the held-back ones, in the same order. The baselines see each
        stamp with its sensor's ``stamp_offset_s`` added, as the core does: what the configuration
        knows of a sensor's clock, the baselines know too."""
        offsets = {s.name: s.stamp_offset_s for s in self.cfg.sensors if s.stamp_offset_s}
        for original in samples:
            s = original
            if s.sensor in offsets:
                s = msgspec.structs.replace(s, stamp=s.stamp + offsets[s.sensor])
            if isinstance(s, OdomSample):
                lin, ang = s.linear, s.angular
                self.odom.append((s.stamp, lin[0], lin[1], ang[2], yaw(s.orientation),
                                  1.0 if s.sensor in self._odom_world else 0.0))
            elif isinstance(s, ImuSample):
                rot = self._imu_rot.get(s.sensor)
                if rot is not None and s.angular_velocity_covariance[0] != -1.0:
                    self.gyro.append((s.stamp, float(rot[2] @ np.asarray(s.angular_velocity))))
            elif s.sensor == self._absolute:
                keep = self._count % self.fuse_every == 0
                self._count += 1
                if isinstance(s, GpsSample):
                    (self.fused_fixes if keep else self.held_fixes).append(
                        (s.stamp, s.latitude, s.longitude, s.altitude, s.status))
                else:  # a world frame that is not geodetic is defined by poses (position, orientation)
                    (self.fused_poses if keep else self.held_poses).append((s.stamp, *s.position, yaw(s.orientation)))
                if not keep:
                    continue
            yield original


def _reference_topic(reader, topic: str) -> str:
    """The bag's name of the reference topic, refused when absent or of a type the scoring cannot read."""
    from .bag import BagError, did_you_mean

    name = topic if topic in reader.topics else "/" + topic.lstrip("/")
    if name not in reader.topics:
        have = ", ".join(sorted(reader.topics)) or "none"
        raise BagError(f"--reference {topic}: no such topic in the bag{did_you_mean(name, reader.topics)}; "
                       f"the bag has: {have}")
    msgtype = reader.topics[name].connections[0].msgtype
    if msgtype not in REFERENCE_TYPES:
        raise BagError(f"--reference {name} has type {msgtype}; expected one of {', '.join(REFERENCE_TYPES)}")
    return name


def check_reference(paths: Sequence[Path], topic: str) -> None:
    """``read_reference``'s checks of the topic itself, made before a replay: a mistyped --reference is refused
    at once, not after the whole recording was fused."""
    from .bag import _open_reader

    reader = _open_reader(list(paths))
    try:
        _reference_topic(reader, topic)
    finally:
        reader.close()


def read_reference(paths: Sequence[Path], topic: str) -> tuple[str, np.ndarray, np.ndarray, np.ndarray | None,
                                                                 tuple[float, float, float] | None]:
    """(message type, stamps, positions, headings or None, first NavSatFix lla or None) of a bag topic,
    by header stamp. A NavSatFix reference is returned as lla in ``positions`` (ENU is taken later, at
    the filter's datum)."""
    from rosbags.highlevel import AnyReader

    from .bag import BagError, _open_reader

    reader: AnyReader = _open_reader(list(paths))
    try:
        name = _reference_topic(reader, topic)
        conns = reader.topics[name].connections
        msgtype = conns[0].msgtype
        t, pos, head = [], [], []
        for c, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, c.msgtype)
            st = msg.header.stamp
            t.append(st.sec + 1e-9 * st.nanosec)
            if msgtype == "sensor_msgs/msg/NavSatFix":
                if msg.status.status < 0:
                    t.pop()
                    continue
                pos.append((msg.latitude, msg.longitude, msg.altitude))
                continue
            pose = msg.pose.pose if msgtype != "geometry_msgs/msg/PoseStamped" else msg.pose
            pos.append((pose.position.x, pose.position.y, pose.position.z))
            o = pose.orientation
            head.append(yaw((o.x, o.y, o.z, o.w)))
    finally:
        reader.close()
    if not t:
        raise BagError(f"--reference {name}: no usable message")
    lla = tuple(pos[0]) if msgtype == "sensor_msgs/msg/NavSatFix" else None
    return msgtype, np.array(t), np.array(pos, dtype=float), (np.array(head) if head else None), lla


def _enu(frame: EnuFrame, rows) -> np.ndarray:
    return np.array([frame.enu(lat, lon, alt) for lat, lon, alt in rows], dtype=float).reshape(-1, 3)


def _dead_reckoned(name: str, odom: np.ndarray, heading_at, max_gap: float) -> Track:
    """Integrate the wheels' speed along a heading (zero-order hold, no step longer than ``max_gap``:
    across a logging gap nothing moves)."""
    t = odom[:, 0]
    h = heading_at(t)
    xyz = np.zeros((t.size, 3))
    dt = np.diff(t)
    dt = np.where(dt <= max_gap, dt, 0.0)
    world = odom[:-1, 5] > 0.5  # a world-frame twist is integrated as it is
    c, s = np.cos(h[:-1]), np.sin(h[:-1])
    vx, vy = odom[:-1, 1], odom[:-1, 2]
    dx = np.where(world, vx, c * vx - s * vy) * dt
    dy = np.where(world, vy, s * vx + c * vy) * dt
    xyz[1:, 0] = np.cumsum(dx)
    xyz[1:, 1] = np.cumsum(dy)
    return Track.build(name, t, xyz, h)


class InterpolatedFixes:
    """The fused fixes interpolated linearly between each and the next: what a user has after the fact
    with no filter (the smoother's plain rival), read across the fused fixes' own spacing."""

    world = True
    heading = None

    def __init__(self, name: str, t: np.ndarray, xyz: np.ndarray, spacing: float) -> None:
        self.name = name
        self.track = Track.build(name, t, xyz, world=True)
        self.spacing = spacing  # the longest span interpolated: a longer one is a gap, not a fix missed

    def at(self, ts: np.ndarray, max_gap: float) -> tuple[np.ndarray, None, np.ndarray]:
        xyz, _, valid = self.track.at(ts, self.spacing)
        return xyz, None, valid


def baseline_tracks(rec: Recorder, frame: EnuFrame | None, max_gap: float, after_the_fact: bool = False) -> list:
    """The tracks a user could have had with no filter, from the same samples. ``after_the_fact``
    (a smoothed trajectory is scored): with thinned fixes, also the fused fixes interpolated, the
    non-causal baseline a smoother must beat."""
    tracks: list = []
    if rec.odom:
        odom = np.array(sorted(rec.odom), dtype=float)
        t = odom[:, 0]
        dt = np.where(np.diff(t) <= max_gap, np.diff(t), 0.0)
        wheel_h = np.concatenate(([0.0], np.cumsum(odom[:-1, 3] * dt)))
        tracks.append(_dead_reckoned("wheel odometry", odom, lambda ts: np.interp(ts, t, wheel_h), max_gap))
        if rec.gyro:
            g = np.array(sorted(rec.gyro), dtype=float)
            gdt = np.where(np.diff(g[:, 0]) <= max_gap, np.diff(g[:, 0]), 0.0)
            gh = np.concatenate(([0.0], np.cumsum(g[:-1, 1] * gdt)))
            tracks.append(_dead_reckoned("gyro + wheel speed", odom, lambda ts: np.interp(ts, g[:, 0], gh), max_gap))
    if frame is not None:
        fused = sorted(f for f in rec.fused_fixes if f[4] >= 0)
        held = sorted(f for f in rec.held_fixes if f[4] >= 0)
        every = sorted(fused + held)
        if every:
            tracks.append(Track.build("raw fixes", [f[0] for f in every], _enu(frame, [f[1:4] for f in every]),
                                      world=True))
        if fused:  # causal, unlike the raw fixes (read between a fix and the next): what a GPS-only user has
            ft = np.array([f[0] for f in fused])
            fx = _enu(frame, [f[1:4] for f in fused])
            tracks.append(Track.build("hold last fused fix", ft, fx, world=True, held=True))
            tracks.append(ExtrapolatedFixes("fixes at constant velocity", ft, fx))
            if after_the_fact and rec.fuse_every > 1:
                tracks.append(InterpolatedFixes("fused fixes interpolated", ft, fx, rec.fuse_every * max_gap))
    poses = sorted(rec.fused_poses + rec.held_poses)
    if poses and rec.absolute is not None and not rec.geodetic:
        p = np.array(poses)
        tracks.append(Track.build("raw poses", p[:, 0], p[:, 1:4], p[:, 4], world=True))
        if rec.fused_poses:
            q = np.array(sorted(rec.fused_poses))
            tracks.append(Track.build("hold last fused pose", q[:, 0], q[:, 1:4], q[:, 4], world=True, held=True))
    return tracks


def _rpe(ref_xy, ref_h, est_xy, est_h, ts, rpe_s: float) -> float | None:
    """evo's RPE (translation part) between planar poses rpe_s apart (in frames of the scoring times)."""
    if ts.size < 3:
        return None
    step = float(np.median(np.diff(ts)))
    delta = max(int(round(rpe_s / step)), 1) if step > 0 else 1
    if delta >= ts.size:
        return None
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    def traj(xy, h):
        xyz = np.column_stack((xy, np.zeros(len(xy))))
        wxyz = np.column_stack((np.cos(h / 2), np.zeros(len(h)), np.zeros(len(h)), np.sin(h / 2)))
        return PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=wxyz, timestamps=ts)

    rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=delta, delta_unit=metrics.Unit.frames,
                      all_pairs=False)
    rpe.process_data((traj(ref_xy, ref_h), traj(est_xy, est_h)))
    return float(rpe.get_statistic(metrics.StatisticsType.rmse))


def _aligned_rms(est: np.ndarray, ref: np.ndarray) -> float:
    """RMS error after evo's 2-D rigid Umeyama alignment; a track that does not move (a vehicle parked
    through the segment) has no rotation to fit and is aligned by its mean alone."""
    from evo.core.geometry import GeometryException, umeyama_alignment

    try:
        r, tr, _ = umeyama_alignment(est.T, ref.T, with_scale=False)
    except GeometryException:
        r, tr = np.eye(2), ref.mean(axis=0) - est.mean(axis=0)
    aligned = (r @ est.T).T + tr
    return float(np.sqrt(np.mean(np.sum((aligned - ref) ** 2, axis=1))))


def _timelines(t: np.ndarray) -> list[slice]:
    """The runs of ``t`` between its jumps back (a clock reset starts a timeline of its own), in order."""
    cuts = [0, *(np.flatnonzero(np.diff(t) < 0) + 1).tolist(), len(t)]
    return [slice(a, b) for a, b in zip(cuts, cuts[1:])]


def _known_by_then(published: np.ndarray, known: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    """Per stamp of another track of the same publish moments (the smoothed one), whether the heading of the
    last pose published by then was known: looked up within the same timeline (its k-th run between jumps back
    against the published poses' k-th), so that a clock reset does not send a stamp to the other run's poses."""
    out = np.zeros(len(stamps), dtype=bool)
    mine, theirs = _timelines(published), _timelines(stamps)
    for pub, run in zip(mine, theirs):
        i = np.searchsorted(published[pub], stamps[run], side="right") - 1
        out[run] = (i >= 0) & known[pub][np.clip(i, 0, None)]
    return out


def _score(segment: str, track, ts, ref_xyz, ref_h, world: bool, max_gap: float, rpe_s: float) -> Score | None:
    xyz, h, valid = track.at(ts, max_gap)
    valid = valid & np.all(np.isfinite(xyz), axis=1)
    n = int(valid.sum())
    if n == 0:
        return None
    xyz, ts_v, rx = xyz[valid], ts[valid], ref_xyz[valid]
    sc = Score(segment, track.name, n)
    if world and track.world:
        d = xyz - rx
        sc.world_h = float(np.sqrt(np.mean(d[:, 0] ** 2 + d[:, 1] ** 2)))
        sc.world_offset = (float(np.mean(d[:, 0])), float(np.mean(d[:, 1])))
        sc.world_up = float(np.sqrt(np.mean(d[:, 2] ** 2)))
    if n >= 2:
        sc.aligned_h = _aligned_rms(xyz[:, :2], rx[:, :2])
    if h is not None and ref_h is not None:
        hv, rh, ts_h, rxy = h[valid], ref_h[valid], ts_v, rx[:, :2]
        xy = xyz[:, :2]
        known = np.isfinite(hv)
        if not known.all():  # scored where the track's heading is an estimate (Track.heading_known)
            hv, rh, ts_h, rxy, xy = hv[known], rh[known], ts_h[known], rxy[known], xy[known]
        if hv.size == 0:
            return sc
        err = np.angle(np.exp(1j * (hv - rh)))
        offset = np.angle(np.mean(np.exp(1j * err)))  # the segment's heading alignment: its mean offset
        sc.heading_deg = float(np.degrees(np.sqrt(np.mean(np.angle(np.exp(1j * (err - offset))) ** 2))))
        sc.rpe_m = _rpe(rxy, rh, xy, hv, ts_h, rpe_s)
    return sc


def _segments(t: np.ndarray, gap: float) -> list[tuple[float, float]]:
    """The spans of the reference between its gaps longer than ``gap``."""
    cuts = np.flatnonzero(np.diff(t) > gap)
    starts = np.concatenate(([0], cuts + 1))
    ends = np.concatenate((cuts, [t.size - 1]))
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends)]


def evaluate(paths: Sequence[Path], cfg: Config, reference: str, trajectory, rec: Recorder,
             segment_gap_s: float = 1.0, rpe_s: float = 1.0, heading_known=None, smoothed=None) -> Evaluation:
    """Score the published ``trajectory`` (8 doubles a pose: t x y z qx qy qz qw) and the baselines
    ``rec`` gathered during the replay. ``heading_known`` (one flag a pose, ReplayResult's): the heading
    and RPE of the poses published before the filter knew its heading are not scored. ``smoothed``
    (the same layout, ReplayResult.smoothed): scored too, as "fusiond smoothed", beside the fused fixes
    interpolated when they are thinned."""
    msgtype, rt, rpos, rhead, ref_lla = read_reference(paths, reference)
    world = rec.absolute is not None
    notes: list[str] = []
    fused_keys = {s.key.lstrip("/") for s in cfg.sensors if s.name != rec.absolute or rec.fuse_every == 1}
    if reference.lstrip("/") in fused_keys:
        raise ReplayError(f"--reference {reference} is a fused sensor's topic: a reference must never be fused "
                          "(an absolute sensor's own topic can be, with --fuse-every N > 1: the held-back messages)")
    # The world frame: ENU at the GPS's datum (configured, or its first valid fused fix in stamp order).
    gps = next((s for s in cfg.sensors if kind_of(s).geodetic), None)
    frame = None
    if gps is not None:
        datum = kind_of(gps).datum(gps)
        if datum is not None:
            frame = EnuFrame(*datum)
        else:
            first = min((f for f in rec.fused_fixes if f[4] >= 0), default=None)
            frame = EnuFrame(*first[1:4]) if first is not None else None
    if msgtype == "sensor_msgs/msg/NavSatFix":
        if frame is None:
            frame = EnuFrame(*ref_lla)
            notes.append("reference fixes in ENU at their own first fix (no GPS configured)")
        rpos = _enu(frame, rpos)
    ref = Track.build("reference", rt, rpos, rhead)
    if ref.t.size < 2:
        raise ReplayError(f"--reference {reference}: fewer than two poses")
    spans = _segments(ref.t, segment_gap_s)
    if rec.fuse_every > 1:
        held = rec.held_fixes if rec.geodetic else rec.held_poses
        ts_all = np.array(sorted(h[0] for h in held if not rec.geodetic or h[4] >= 0))
        scored_at = f"the {ts_all.size} held-back {rec.absolute} messages"
    else:
        ts_all = ref.t
        scored_at = "reference stamps"
    tr = np.asarray(trajectory, dtype=float).reshape(-1, 8)
    known = None
    if heading_known is not None and len(heading_known) == len(tr) and not all(heading_known):
        known = np.asarray(heading_known, dtype=bool)
        unknown_until = float(tr[~known, 0].max() - tr[0, 0])
        notes.append(f"fusiond's heading and RPE skip the {int((~known).sum())} poses published before its heading "
                     f"was known (their yaw variance says unknown; the last of them {unknown_until:.1f} s after the "
                     "first)")
    fused = Track.build("fusiond", tr[:, 0], tr[:, 1:4],
                        np.array([yaw(tuple(q)) for q in tr[:, 4:8]]) if tr.size else None, world=world,
                        heading_known=known)
    tracks = [fused]
    if smoothed is not None:
        sm = np.asarray(smoothed, dtype=float).reshape(-1, 8)
        sm_known = None
        if known is not None:  # a smoothed pose's heading is scored where the last pose published by then was
            sm_known = _known_by_then(tr[:, 0], known, sm[:, 0])
        tracks.append(Track.build("fusiond smoothed", sm[:, 0], sm[:, 1:4],
                                  np.array([yaw(tuple(q)) for q in sm[:, 4:8]]) if sm.size else None, world=world,
                                  heading_known=sm_known))
    tracks += baseline_tracks(rec, frame, segment_gap_s, after_the_fact=smoothed is not None)
    t0 = float(ref.t[0])
    segments = [Segment("all", 0.0, spans[-1][1] - t0)]
    if len(spans) > 1:
        segments += [Segment(chr(ord("a") + i) if i < 26 else str(i), a - t0, b - t0) for i, (a, b) in enumerate(spans)]
    scores: list[Score] = []
    for seg in segments:
        inside = (ts_all >= seg.start + t0) & (ts_all <= seg.end + t0)
        ts = ts_all[inside]
        rxyz, rh, rvalid = ref.at(ts, segment_gap_s)
        ts, rxyz = ts[rvalid], rxyz[rvalid]
        rh = rh[rvalid] if rh is not None else None
        for track in tracks:
            sc = _score(seg.name, track, ts, rxyz, rh, world, segment_gap_s, rpe_s)
            if sc is not None:
                scores.append(sc)
    whole = next((sc for sc in scores if sc.segment == "all" and sc.method == "fusiond"), None)
    if whole is not None and whole.world_offset is not None and whole.world_h:
        east, north = whole.world_offset
        if east * east + north * north > 0.5 * whole.world_h**2:  # the larger part of its mean square error
            notes.append(f"fusiond's world error is mostly one constant offset ({east:+.1f} m east, {north:+.1f} m "
                         "north): the reference's origin is not the filter's world origin (a GPS's datum: its "
                         "first fix unless `datum` is set), or the receiver's own bias")
    return Evaluation(reference=ref_name(reference), reference_type=msgtype, world=world, fuse_every=rec.fuse_every,
                      scored_at=scored_at, rpe_s=rpe_s, segments=segments, scores=scores, notes=notes)


def ref_name(topic: str) -> str:
    return "/" + topic.lstrip("/")


def _cell(v: float | None, fmt: str = "{:.3f}") -> str:
    return "-" if v is None else fmt.format(v)


def format_evaluation(ev: Evaluation) -> str:
    """The evaluation as a plain-text table (the replay summary prints it)."""
    out = [f"reference   {ev.reference} ({ev.reference_type}), scored at {ev.scored_at}"
           + (f", fixes fused 1 in {ev.fuse_every}" if ev.fuse_every > 1 else "")
           + ("; unaligned errors in the filter's world frame" if ev.world
              else "; no world frame: aligned errors only")
           + "; head deg: the heading's RMS error less its mean offset over the segment"]
    out += [f"note        {n}" for n in ev.notes]
    header = f"{'segment':<14} {'method':<26} {'n':>6} {'world m':>8} {'up m':>7} {'aligned m':>9} " \
             f"{'head deg':>8} {'RPE/' + format(ev.rpe_s, 'g') + 's m':>10}"
    out.append(header)
    spans = {s.name: s for s in ev.segments}
    for sc in ev.scores:
        s = spans[sc.segment]
        label = f"{sc.segment} {s.start:.0f}-{s.end:.0f}s"
        out.append(f"{label:<14} {sc.method:<26} {sc.n:>6} {_cell(sc.world_h):>8} {_cell(sc.world_up):>7} "
                   f"{_cell(sc.aligned_h):>9} {_cell(sc.heading_deg, '{:.2f}'):>8} {_cell(sc.rpe_m):>10}")
    return "\n".join(out)
