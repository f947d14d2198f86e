"""What a recording holds, as fusiond sees it: `fusiond info BAG` and the facts `fusiond init` builds a config from.

`ros2 bag info` lists topics, types and counts. A new user also needs what robot_localization's
tracker keeps being asked: which topic is the odometry, does the IMU publish an orientation
(covariance[0] = -1 says it does not), in which frame, at what rate, what do the messages claim
their noise is, where is the IMU mounted (`/tf_static`), and what would fusiond do with each topic.
This module reads that once, from the bag's index and a sample of each topic's messages (the first
`SAMPLE` of each, plus the counts and receive times of all), into plain Structs; `format_info`
prints them. Reading only: no fusion, no config.
"""

from __future__ import annotations

import math
import statistics
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec

from .core.sensors.odom.pose_twist import POSE_PATH_M
from .core.sensors.registry import kind_reading
from .replay.bag import open_reader, same_definition

__all__ = ["BagInfo", "StaticTransform", "TopicInfo", "format_info", "inspect_bags", "is_reference", "print_info",
           "topic_use"]

SAMPLE = 400  # messages of each topic deserialized to read frames, covariances and motion
ODOMETRY = "nav_msgs/msg/Odometry"
IMU = "sensor_msgs/msg/Imu"
NAVSATFIX = "sensor_msgs/msg/NavSatFix"
POSES = ("geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs/msg/PoseStamped")
TF = "tf2_msgs/msg/TFMessage"
REFERENCE_WORDS = ("ground_truth", "groundtruth", "ground_true", "gt_pose", "mocap_reference")


class StaticTransform(msgspec.Struct, frozen=True):
    """One `/tf_static` transform: parent -> child, translation (m), rotation (x y z w)."""

    parent: str
    child: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]


class TopicInfo(msgspec.Struct, kw_only=True):
    """One topic of the recording, with what a sample of its messages says."""

    topic: str
    msgtype: str
    count: int
    recorded_as: str = ""  # another type name with msgtype's definition (ROS 1 MD5), as the bag names it
    rate_hz: float  # by receive time over the recording (count - 1 over the span)
    frame_id: str = ""
    child_frame_id: str = ""  # odometry
    covariance: str = ""  # the stated covariances in brief
    # IMU
    orientation_valid: bool | None = None  # None: not an IMU; False: covariance[0] = -1 (no orientation)
    gyro_measured: bool | None = None
    orientation_zero_covariance: bool | None = None  # every sampled orientation variance exactly 0
    gyro_zero_covariance: bool | None = None  # every sampled angular-velocity variance exactly 0
    # odometry
    lateral_body: float | None = None  # median |vy| / speed of the moving samples, as stated
    lateral_rotated: float | None = None  # ... with the twist turned from the pose's frame into the body
    yaw_rate_zero: bool | None = None  # every sampled angular.z exactly 0 (a driver that lost its yaw rate)
    twist_zero_covariance: bool | None = None
    # the pose travels while every sampled twist reads exactly 0: a driver that fills the pose only
    pose_only: bool | None = None
    # GPS
    covariance_type: int | None = None


class BagInfo(msgspec.Struct, kw_only=True):
    paths: list[str]
    ros2: bool
    duration_s: float
    topics: list[TopicInfo]
    static: list[StaticTransform] = []


def is_reference(topic: str) -> bool:
    """A topic named as a reference (ground truth): never fused by `init`, scored against by `replay --reference`."""
    name = topic.lower()
    return any(w in name for w in REFERENCE_WORDS)


def topic_use(t: TopicInfo) -> str:
    """What fusiond would use this topic for, in a few words."""
    if is_reference(t.topic) and t.msgtype in (*POSES, ODOMETRY, NAVSATFIX):
        return "reference: never fused; replay --reference scores against it"
    if t.msgtype == ODOMETRY:
        return "odom sensor: its twist drives the prediction"
    if t.msgtype == IMU:
        parts = ["imu sensor:"]
        parts.append("gyro drives heading" if t.gyro_measured else "no gyro")
        parts.append("+ roll/pitch" if t.orientation_valid else "(no orientation: covariance[0] = -1)")
        return " ".join(parts)
    if t.msgtype == NAVSATFIX:
        return "gps sensor: position fixes (ENU at the datum)"
    if t.msgtype in POSES:
        return "pose sensor (absolute or differential), if it measures this robot"
    if t.msgtype == TF and t.topic.endswith("tf_static"):
        return "mounts: extrinsic_rpy / extrinsic_xyz of the sensors"
    kind = kind_reading(t.msgtype)  # a kind an installed package adds (docs/SENSOR_KINDS.md)
    if kind is not None:
        return f'{kind.name} sensor: kind = "{kind.name}", from an installed package'
    return "not used"


def _stamp(msg: Any) -> float | None:
    h = getattr(msg, "header", None)
    return None if h is None else h.stamp.sec + h.stamp.nanosec * 1e-9


def _diag(cov: Sequence[float], n: int) -> list[float]:
    return [float(cov[i * (n + 1)]) for i in range(n)]


def _sigmas(values: list[float]) -> str:
    return "[" + ", ".join("-" if v < 0 else f"{math.sqrt(v):.3g}" for v in values) + "]"


def _read_odometry(t: TopicInfo, msgs: list[Any]) -> None:
    t.child_frame_id = msgs[0].child_frame_id
    twist = [_diag(m.twist.covariance, 6) for m in msgs]
    median = [statistics.median(col) for col in zip(*twist)]
    t.twist_zero_covariance = all(v == 0.0 for row in twist for v in row)
    t.covariance = f"twist sigma {_sigmas(median)} (vx vy vz wx wy wz, median)"
    body, rotated, yaw_rates = [], [], []
    for m in msgs:
        v = m.twist.twist.linear
        yaw_rates.append(m.twist.twist.angular.z)
        speed = math.hypot(v.x, v.y)
        if speed < 0.2:
            continue
        q = m.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        body.append(abs(v.y) / speed)
        rotated.append(abs(-math.sin(yaw) * v.x + math.cos(yaw) * v.y) / speed)
    if body:
        t.lateral_body, t.lateral_rotated = statistics.median(body), statistics.median(rotated)
    t.yaw_rate_zero = bool(body) and all(w == 0.0 for w in yaw_rates)
    still = all(m.twist.twist.linear.x == m.twist.twist.linear.y == m.twist.twist.linear.z == 0.0
                and m.twist.twist.angular.x == m.twist.twist.angular.y == m.twist.twist.angular.z == 0.0 for m in msgs)
    path = sum(math.dist((a.pose.pose.position.x, a.pose.pose.position.y, a.pose.pose.position.z),
                         (b.pose.pose.position.x, b.pose.pose.position.y, b.pose.pose.position.z))
               for a, b in zip(msgs, msgs[1:]))
    t.pose_only = still and path >= POSE_PATH_M  # the sampled poses travel while every twist reads 0


def _read_imu(t: TopicInfo, msgs: list[Any]) -> None:
    first = [m.orientation_covariance[0] for m in msgs]
    q = [(m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w) for m in msgs]
    t.orientation_valid = not any(c == -1.0 for c in first) and any(sum(c * c for c in x) > 0.5 for x in q)
    t.gyro_measured = not any(m.angular_velocity_covariance[0] == -1.0 for m in msgs)
    t.orientation_zero_covariance = t.orientation_valid and all(
        v == 0.0 for m in msgs for v in _diag(m.orientation_covariance, 3))
    t.gyro_zero_covariance = t.gyro_measured and all(v == 0.0 for m in msgs for v in _diag(m.angular_velocity_covariance, 3))
    parts = []
    if t.orientation_valid:
        parts.append(f"orientation sigma {_sigmas(_diag(msgs[0].orientation_covariance, 3))} rad")
    else:
        parts.append("no orientation (covariance[0] = -1)")
    if t.gyro_measured:
        parts.append(f"gyro sigma {_sigmas(_diag(msgs[0].angular_velocity_covariance, 3))} rad/s")
    t.covariance = ", ".join(parts)


def _read_fix(t: TopicInfo, msgs: list[Any]) -> None:
    t.covariance_type = int(msgs[0].position_covariance_type)
    kind = {0: "UNKNOWN", 1: "APPROXIMATED", 2: "DIAGONAL_KNOWN", 3: "KNOWN"}.get(t.covariance_type, "?")
    t.covariance = f"position sigma {_sigmas(_diag(msgs[0].position_covariance, 3))} m (type {kind})"


def _read_pose(t: TopicInfo, msgs: list[Any]) -> None:
    cov = getattr(getattr(msgs[0], "pose", None), "covariance", None)
    t.covariance = f"pose sigma {_sigmas(_diag(cov, 6))}" if cov is not None else "no covariance (PoseStamped)"


_READERS = {ODOMETRY: _read_odometry, IMU: _read_imu, NAVSATFIX: _read_fix, POSES[0]: _read_pose,
            POSES[1]: _read_pose}


def inspect_bags(paths: Sequence[Path | str]) -> BagInfo:
    """Read the recording's topics (BagError for what is no readable bag; the same checks as `replay`)."""
    reader = open_reader([Path(p) for p in paths])
    try:
        topics: list[TopicInfo] = []
        static: list[StaticTransform] = []
        for name, info in sorted(reader.topics.items()):
            conns = list(info.connections)
            msgtype = recorded = info.msgtype or ""
            if msgtype not in _READERS and conns:  # a known type re-registered under another name: read as it
                msgtype = next((k for k in _READERS if same_definition(conns[0], k, reader.is2)), msgtype)
            times: list[int] = []
            sample: list[Any] = []
            wanted = msgtype in _READERS or msgtype == TF and name.endswith("tf_static")
            for conn, bag_ns, raw in reader.messages(connections=conns):
                times.append(bag_ns)
                if wanted and (len(sample) < SAMPLE or name.endswith("tf_static")):
                    try:
                        sample.append(reader.deserialize(raw, conn.msgtype))
                    except Exception:  # noqa: BLE001 - a message rosbags cannot read: counted, not read
                        pass
            span = (times[-1] - times[0]) * 1e-9 if len(times) > 1 else 0.0
            t = TopicInfo(topic=name, msgtype=msgtype, count=len(times),
                          rate_hz=(len(times) - 1) / span if span > 0.0 else 0.0,
                          recorded_as=recorded if recorded != msgtype else "")
            if sample and getattr(sample[0], "header", None) is not None:
                t.frame_id = sample[0].header.frame_id
            if sample and msgtype in _READERS:
                _READERS[msgtype](t, sample)
            if msgtype == TF and name.endswith("tf_static"):
                for msg in sample:
                    for tr in msg.transforms:
                        v, r = tr.transform.translation, tr.transform.rotation
                        static.append(StaticTransform(tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"),
                                                      (v.x, v.y, v.z), (r.x, r.y, r.z, r.w)))
            topics.append(t)
        duration = reader.duration * 1e-9 if reader.message_count else 0.0
        return BagInfo(paths=[str(p) for p in paths], ros2=bool(reader.is2), duration_s=duration, topics=topics,
                       static=static)
    finally:
        reader.close()


def format_info(info: BagInfo) -> str:
    """`fusiond info`'s text: one block per topic, then the static transforms."""
    kind = "ROS 2" if info.ros2 else "ROS 1"
    out = [f"bag         {', '.join(info.paths)} ({kind}, {info.duration_s:.1f} s, {len(info.topics)} topics)"]
    for t in info.topics:
        frame = f" frame {t.frame_id}" if t.frame_id else ""
        if t.child_frame_id:
            frame += f" -> {t.child_frame_id}"
        recorded = f" (recorded as {t.recorded_as}, its definition)" if t.recorded_as else ""
        out.append(f"{t.topic}  {t.msgtype}{recorded}  {t.count} msgs  {t.rate_hz:.1f} Hz{frame}")
        if t.covariance:
            out.append(f"    stated: {t.covariance}")
        out.append(f"    use:    {topic_use(t)}")
    for s in info.static:
        out.append(f"tf_static   {s.parent} -> {s.child}: xyz {list(round(v, 4) for v in s.translation)} "
                   f"xyzw {list(round(v, 4) for v in s.rotation)}")
    return "\n".join(out)


def print_info(bags: Sequence[str]) -> int:
    """`fusiond info`: the text on stdout, 0; a bag that cannot be read: one line on stderr, 2."""
    from .errors import BagError

    try:
        info = inspect_bags(bags)
    except BagError as err:
        print(f"fusiond: {err}", file=sys.stderr)
        return 2
    print(format_info(info))
    return 0
