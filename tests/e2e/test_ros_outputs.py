"""ROS-facing outputs of a real daemon on loopback Zenoh (bridge mode): TF, ROS diagnostics,
set_pose, and the `starting` health status.

Every message is decoded with rosbags, as a ROS 2 node would see it.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Iterator

import msgspec
import numpy as np
import pytest
import zenoh

from fusiond.codecs import DIAGNOSTIC_ARRAY, POSE_COV_STAMPED, TF_MESSAGE, TYPESTORE, decode_pose_cdr
from fusiond.config import loads
from fusiond.estimator.rotation import from_rpy
from fusiond.health import decode_report
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample
from fusiond.transport.daemon import Daemon
from fusiond.transport.session import query_health, request_set_pose

from tests.support.configs import loopback_daemon_config
from tests.support.loopback import sessions, wait_until  # noqa: F401  (fixture)

ROS_OUTPUTS = """tf_key = "t/tf"
ros_diagnostics_key = "t/ros_diagnostics"
ros_diagnostics_period_s = 0.1
set_pose_key = "t/set_pose"
"""


V = 0.5  # m/s forward, no turn: dead reckoning is a straight line
TWIST_COV = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))


def odom(stamp: float, v: float = V) -> bytes:
    return encode_sample(OdomSample("wheel", stamp, (v, 0.0, 0.0), (0.0, 0.0, 0.0), TWIST_COV), "ros2-cdr")


def imu(stamp: float) -> bytes:
    return encode_sample(ImuSample("imu", stamp, (0.0, 0.0, 0.0, 1.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4),
                                       (0.0, 0.0, 0.0), (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)), "ros2-cdr")


def stamp_of(header) -> float:
    return header.stamp.sec + header.stamp.nanosec * 1e-9


class Collector:
    """Raw payloads per key, in arrival order."""

    def __init__(self, session: zenoh.Session, *keys: str) -> None:
        self.got: dict[str, list[bytes]] = {k: [] for k in keys}
        self._lock = threading.Lock()
        self._subs = [session.declare_subscriber(k, self._cb(k)) for k in keys]

    def _cb(self, key: str):
        def on(sample: zenoh.Sample) -> None:
            with self._lock:
                self.got[key].append(sample.payload.to_bytes())
        return on

    def __getitem__(self, key: str) -> list[bytes]:
        with self._lock:
            return list(self.got[key])


@pytest.fixture
def daemon_factory(sessions) -> Iterator:
    dsession, client = sessions
    started: list[Daemon] = []

    def make(extra: str = "") -> tuple[Daemon, zenoh.Session]:
        d = Daemon(loopback_daemon_config(output=ROS_OUTPUTS + extra), dsession, monitor=False)
        started.append(d)
        return d, client

    yield make
    for d in started:
        d.stop()


def health(client: zenoh.Session):
    answers = query_health(client, "t/health", 1.0)
    return decode_report(answers[0]) if answers else None


# --------------------------------------------------------------------------- TF


def test_tf_once_per_new_pose_stamp_strictly_increasing_and_equal_to_the_pose(daemon_factory):
    daemon, client = daemon_factory()
    out = Collector(client, "t/pose", "t/tf")
    daemon.start()
    pub = client.declare_publisher("t/odom", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_until(lambda: health(client), 10, "the daemon")
    # In order, with every fifth message a late one (an older stamp, as real odometry
    # drivers deliver): a late message is fused at its own stamp and the pose is
    # published again at the newest stamp, already published: no second TF for it.
    stamps: list[float] = []
    for k in range(60):
        stamps.append(100.0 + 0.02 * k)
        if k % 5 == 4:
            stamps.append(100.0 + 0.02 * k - 0.01)
    for st in stamps:
        pub.put(odom(st))
    wait_until(lambda: len(out["t/pose"]) == len(stamps), 10, "one pose per odometry message")
    poses = [decode_pose_cdr(raw) for raw in out["t/pose"]]
    pose_stamps = [stamp_of(p.header) for p in poses]
    advancing = [s for i, s in enumerate(pose_stamps) if i == 0 or s > max(pose_stamps[:i])]
    assert len(advancing) == 60 < len(pose_stamps)  # the late ones repeated a stamp
    # A sentinel instead of a sleep: one more odometry message with a new stamp. The daemon publishes
    # the TF key in order and Zenoh delivers one key in order, so once the sentinel's TF is here every
    # TF published before it is too: a surplus one would be counted below.
    sentinel = 100.0 + 0.02 * 60
    pub.put(odom(sentinel))
    wait_until(lambda: out["t/tf"] and stamp_of(TYPESTORE.deserialize_cdr(out["t/tf"][-1], TF_MESSAGE)
                                                 .transforms[0].header) == sentinel, 10, "the sentinel's TF")
    tfs = [TYPESTORE.deserialize_cdr(raw, TF_MESSAGE) for raw in out["t/tf"]][:-1]
    poses = [decode_pose_cdr(raw) for raw in out["t/pose"]][: len(stamps)]
    assert len(tfs) == len(advancing) == daemon.tf_published - 1  # (the sentinel's own TF aside)
    tf_stamps = [stamp_of(m.transforms[0].header) for m in tfs]
    assert all(b > a for a, b in zip(tf_stamps, tf_stamps[1:])), "TF stamps must strictly increase"
    assert tf_stamps == advancing
    first_pose_at = {}
    for p in poses:
        first_pose_at.setdefault(stamp_of(p.header), p)
    for m in tfs:
        assert len(m.transforms) == 1
        t = m.transforms[0]
        assert (t.header.frame_id, t.child_frame_id) == ("odom", "base_link")
        pose = first_pose_at[stamp_of(t.header)].pose.pose
        tr, rot = t.transform.translation, t.transform.rotation
        assert (tr.x, tr.y, tr.z) == (pose.position.x, pose.position.y, pose.position.z)
        assert (rot.x, rot.y, rot.z, rot.w) == (pose.orientation.x, pose.orientation.y, pose.orientation.z,
                                                pose.orientation.w)


def test_publish_tf_false_publishes_nothing_on_tf(daemon_factory):
    daemon, client = daemon_factory("publish_tf = false")
    out = Collector(client, "t/pose", "t/tf")
    daemon.start()
    pub = client.declare_publisher("t/odom", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_until(lambda: health(client), 10, "the daemon")
    for k in range(30):
        pub.put(odom(100.0 + 0.02 * k))
    wait_until(lambda: len(out["t/pose"]) == 30, 10, "30 poses")
    # The worker counts a TF when it puts one, in the same step as the pose: 30 poses out, none counted.
    assert daemon.tf_published == 0 and out["t/tf"] == []


def test_with_a_gps_the_tf_holds_map_to_odom_and_a_continuous_odom_to_base_link(sessions):
    """Nav2's tree beside a GPS: every TF carries map -> odom and odom -> base_link at the pose's stamp;
    composed they are the published (map-frame) pose, and when a fix moves the estimate sideways the
    odom frame keeps driving straight while map -> odom takes the jump."""
    from fusiond.core.sensors.gps.codec import encode_gps_sample
    from fusiond.core.tf_tree import compose
    from fusiond.core.sensors import GpsSample

    gps = '[[sensors]]\nname = "gps"\nkind = "gps"\nkey = "t/gps"\ndatum = [48.0, 11.0, 500.0]\n' \
          'position_noise = [0.1, 0.1, 1.0]\n'
    cfg = loopback_daemon_config(output=ROS_OUTPUTS, extra=gps)
    dsession, client = sessions
    out = Collector(client, "t/pose", "t/tf")
    daemon = Daemon(cfg, dsession, monitor=False)
    daemon.start()
    try:
        pubs = {k: client.declare_publisher(f"t/{k}", congestion_control=zenoh.CongestionControl.BLOCK)
                for k in ("odom", "imu", "gps")}
        wait_until(lambda: health(client), 10, "the daemon")
        cov = (0.01, 0, 0, 0, 0.01, 0, 0, 0, 1.0)
        north_per_m = 1.0 / 111_200.0  # degrees of latitude per metre at 48 deg
        steps = 100
        for k in range(steps):
            t = 100.0 + 0.02 * k
            pubs["imu"].put(imu(t - 0.005))
            if k in (0, 60):  # the first fix defines the world; the second sits 1 m north of the track
                east = V * 0.02 * k
                lat = 48.0 + (1.0 if k == 60 else 0.0) * north_per_m
                lon = 11.0 + east / (111_200.0 * math.cos(math.radians(48.0)))
                pubs["gps"].put(encode_gps_sample(GpsSample("gps", t - 0.001, lat, lon, 500.0, 0, cov, 2),
                                                  "ros2-cdr"))
            pubs["odom"].put(odom(t))
        last = 100.0 + 0.02 * (steps - 1)
        wait_until(lambda: out["t/tf"] and stamp_of(TYPESTORE.deserialize_cdr(out["t/tf"][-1], TF_MESSAGE)
                                                     .transforms[0].header) == last, 10, "the last odometry's TF")
        # the pose travels on its own key: its last one may come after the last TF
        wait_until(lambda: out["t/pose"] and stamp_of(decode_pose_cdr(out["t/pose"][-1]).header) == last, 10,
                   "the last odometry's pose")
        poses = {}
        for raw in out["t/pose"]:
            p = decode_pose_cdr(raw)
            assert p.header.frame_id == "map"  # the estimate is the world pose
            poses.setdefault(stamp_of(p.header), p.pose.pose)
        tfs = [TYPESTORE.deserialize_cdr(raw, TF_MESSAGE) for raw in out["t/tf"]]
        assert len(tfs) > 0.9 * steps
        odom_track = []
        for m in tfs:
            (mo, ob) = m.transforms
            assert (mo.header.frame_id, mo.child_frame_id) == ("map", "odom")
            assert (ob.header.frame_id, ob.child_frame_id) == ("odom", "base_link")
            assert stamp_of(mo.header) == stamp_of(ob.header)

            def tr(t):
                v, q = t.transform.translation, t.transform.rotation
                return (v.x, v.y, v.z), (q.x, q.y, q.z, q.w)

            (p, q) = compose(tr(mo), tr(ob))
            pose = poses[stamp_of(mo.header)]
            assert max(abs(a - b) for a, b in zip(p, (pose.position.x, pose.position.y, pose.position.z))) < 1e-9
            odom_track.append((stamp_of(ob.header), tr(ob)[0], tr(mo)[0]))
        # The second fix pulled the estimate north; the odom frame drove on along its line, and the
        # jump is in map -> odom.
        before = [y for st, (x, y, z), _ in odom_track if st < 100.0 + 0.02 * 60]
        after = [y for st, (x, y, z), _ in odom_track if st >= 100.0 + 0.02 * 60]
        assert max(abs(y - before[0]) for y in before + after) < 1e-3
        assert odom_track[-1][2][1] > 0.3  # map -> odom moved north by most of the 1 m
        for (t0, a, _), (t1, b, _) in zip(odom_track, odom_track[1:]):
            assert math.dist(a, b) <= V * (t1 - t0) * 1.05 + 1e-9  # continuous: never faster than the wheels
    finally:
        daemon.stop()


# --------------------------------------------------------------------------- ROS diagnostics


def diag_statuses(raw: bytes) -> dict[str, tuple[int, str, dict[str, str]]]:
    msg = TYPESTORE.deserialize_cdr(raw, DIAGNOSTIC_ARRAY)
    return {s.name: (int(s.level), s.message, {kv.key: kv.value for kv in s.values}) for s in msg.status}


def test_ros_diagnostics_decode_and_show_starting_then_a_sensor_going_silent(daemon_factory):
    daemon, client = daemon_factory()
    out = Collector(client, "t/ros_diagnostics")
    daemon.start()
    wait_until(lambda: health(client), 10, "the daemon")

    # Waiting for the first samples: `starting`, a warning, not a failure.
    assert health(client).status == "starting"
    first = wait_until(lambda: out["t/ros_diagnostics"] and diag_statuses(out["t/ros_diagnostics"][-1]), 5,
                       "a DiagnosticArray")
    assert set(first) == {"fusiond: filter", "fusiond: wheel", "fusiond: imu"}
    level, message, _ = first["fusiond: filter"]
    assert level == 1 and message.startswith("starting")
    assert first["fusiond: imu"][:2] == (1, "no sample yet")

    # Both sensors at 50 Hz of wall time (liveness is wall clock), then the IMU stops.
    pub_o = client.declare_publisher("t/odom", congestion_control=zenoh.CongestionControl.BLOCK)
    pub_i = client.declare_publisher("t/imu", congestion_control=zenoh.CongestionControl.BLOCK)
    t0, k = 100.0, 0

    def tick(with_imu: bool) -> None:
        nonlocal k
        if with_imu:
            pub_i.put(imu(t0 + 0.02 * k - 0.005))
        pub_o.put(odom(t0 + 0.02 * k))
        k += 1
        time.sleep(0.02)

    def latest() -> dict:
        raw = out["t/ros_diagnostics"]
        return diag_statuses(raw[-1]) if raw else {}

    deadline = time.monotonic() + 10
    while not (latest().get("fusiond: imu", (None,))[0] == 0 and latest()["fusiond: wheel"][0] == 0):
        assert time.monotonic() < deadline, "both sensors OK"
        tick(True)
    ok = latest()
    assert ok["fusiond: filter"][0] == 0 and ok["fusiond: filter"][2]["status"] == "ok"
    assert ok["fusiond: imu"][2]["alive"] == "true" and float(ok["fusiond: imu"][2]["rate_hz"]) > 0
    assert ok["fusiond: wheel"][2]["received"] != "0"

    # The IMU goes silent. It is silent after max(timeout_s 0.2 s, 3 x its 0.02 s period) = 0.2 s of
    # wall time; the array is refreshed every 0.1 s (period) by a thread polling every 0.1 s.
    deadline = time.monotonic() + 10
    while latest().get("fusiond: imu", (None,))[0] != 2:
        assert time.monotonic() < deadline, "the silent IMU at ERROR"
        tick(False)
    silent = latest()
    level, message, values = silent["fusiond: imu"]
    assert message.startswith("silent for") and values["alive"] == "false" and values["rate_hz"] == "0.00"
    assert float(values["age_s"]) >= 0.2
    assert silent["fusiond: wheel"][0] == 0  # the wheel goes on
    assert silent["fusiond: filter"][0] == 1 and "degraded" in silent["fusiond: filter"][1]
    assert "imu: silent" in silent["fusiond: filter"][1]


def test_garbage_only_is_failed_not_starting(daemon_factory):
    daemon, client = daemon_factory()
    daemon.start()
    wait_until(lambda: health(client), 10, "the daemon")
    client.put("t/odom", b"\x00\x01\x00\x00not odometry")
    rep = wait_until(lambda: (r := health(client)) and r.sensors["wheel"].dropped == 1 and r, 5, "the drop")
    assert rep.status == "failed" and "no sensor alive" in rep.problems


# --------------------------------------------------------------------------- set_pose


def set_pose_json(stamp: float, position, yaw: float, sigma: float = 0.1) -> bytes:
    cov = [0.0] * 36
    for i in range(6):
        cov[7 * i] = sigma**2
    return json.dumps({"stamp": stamp, "position": list(position), "orientation": list(from_rpy(0.0, 0.0, yaw)),
                       "covariance": cov}).encode()


def pose_cdr(x: float, y: float, q=(0.0, 0.0, 0.0, 1.0), stamp: float = 0.0, cov=None) -> bytes:
    T = TYPESTORE.types
    sec, nsec = int(stamp), int(round((stamp - int(stamp)) * 1e9))
    msg = T[POSE_COV_STAMPED](
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), frame_id="odom"),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                             orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2],
                                                                                            w=q[3])),
            covariance=np.zeros(36) if cov is None else np.asarray(cov, dtype=float)))
    return bytes(TYPESTORE.serialize_cdr(msg, POSE_COV_STAMPED))


def test_set_pose_moves_the_estimate_and_dead_reckoning_continues_from_it(daemon_factory):
    daemon, client = daemon_factory()
    out = Collector(client, "t/pose")
    daemon.start()
    pub = client.declare_publisher("t/odom", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_until(lambda: health(client), 10, "the daemon")

    # Before anything is fused, "stamp 0 = the filter's time" has no time to mean.
    ok, errors = request_set_pose(client, "t/set_pose", set_pose_json(0.0, (1.0, 2.0, 0.0), 0.0), 5.0)
    assert ok == [] and len(errors) == 1 and "nothing has been fused yet" in errors[0]

    for k in range(51):
        pub.put(odom(100.0 + 0.02 * k))
    wait_until(lambda: len(out["t/pose"]) == 51, 10, "51 poses")
    before = decode_pose_cdr(out["t/pose"][-1]).pose.pose.position
    assert before.x == pytest.approx(V * 1.0, abs=1e-9)  # 1 s at 0.5 m/s along x

    yaw = 1.0
    ok, errors = request_set_pose(client, "t/set_pose", set_pose_json(0.0, (5.0, -3.0, 0.0), yaw), 5.0)
    assert errors == [] and len(ok) == 1
    answer = decode_report(ok[0])  # the new health
    assert answer.filter.time == pytest.approx(101.0, abs=1e-9) and answer.status in ("ok", "degraded")
    assert daemon.set_poses == 1
    wait_until(lambda: len(out["t/pose"]) == 52, 5, "the pose published at the set pose")
    at = decode_pose_cdr(out["t/pose"][-1])
    q = from_rpy(0.0, 0.0, yaw)
    p = at.pose.pose
    assert stamp_of(at.header) == pytest.approx(101.0, abs=1e-9)
    assert (p.position.x, p.position.y, p.position.z) == (5.0, -3.0, 0.0)
    assert (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w) == pytest.approx(q, abs=1e-12)
    assert at.pose.covariance[0] == pytest.approx(0.01) and at.pose.covariance[35] == pytest.approx(0.01)

    # Odometry goes on: the body-frame twist now drives the robot along yaw = 1 rad from (5, -3).
    # set_pose forgets the held twist (robot_localization zeroes the velocity), so the step from
    # 101.00 to the first new odometry at 101.02 is at rest: 0.5 m/s over 102.00 - 101.02 = 0.98 s.
    for k in range(51, 101):
        pub.put(odom(100.0 + 0.02 * k))
    wait_until(lambda: len(out["t/pose"]) == 102, 10, "the poses after set_pose")
    end = decode_pose_cdr(out["t/pose"][-1]).pose.pose.position
    travelled = V * (102.0 - 101.02)
    assert end.x == pytest.approx(5.0 + travelled * math.cos(yaw), abs=1e-6)
    assert end.y == pytest.approx(-3.0 + travelled * math.sin(yaw), abs=1e-6)

    # The same through CDR, robot_localization's message, with an explicit stamp.
    ok, errors = request_set_pose(client, "t/set_pose", pose_cdr(-1.0, 4.0, stamp=102.0), 5.0)
    assert errors == [] and decode_report(ok[0]).filter.time == pytest.approx(102.0)
    wait_until(lambda: len(out["t/pose"]) == 103, 5, "the pose at the CDR set_pose")
    p = decode_pose_cdr(out["t/pose"][-1]).pose.pose.position
    assert (p.x, p.y) == (-1.0, 4.0)


@pytest.mark.parametrize("payload, problem", [
    (b"", "empty"),
    (b"\x00\x01\x00\x00nonsense", "not a valid geometry_msgs/msg/PoseWithCovarianceStamped"),
    (b'{"position": [1, 2, 0]}', "missing required field `orientation`"),
    (b'{"position": [1, 2], "orientation": [0, 0, 0, 1]}', "position"),
    (b'{"position": [1, 2, 0], "orientation": [0, 0, 0, 0]}', "unit quaternion"),
    (b'{"position": [1, 2, 0], "orientation": [0, 0, 0, 1], "covariance": [-1' + b', 0' * 35 + b"]}",
     "covariance diagonal must not be negative"),
    (b'{"stamp": -5, "position": [1, 2, 0], "orientation": [0, 0, 0, 1]}', "stamp must be finite and >= 0"),
    ("nan", "position[0] is not finite"),
    ("inf-cov", "covariance[7] is not finite"),
])
def test_a_bad_set_pose_gets_an_error_naming_the_problem_and_changes_nothing(daemon_factory, payload, problem):
    if payload == "nan":
        payload = pose_cdr(math.nan, 0.0)
    elif payload == "inf-cov":
        payload = pose_cdr(0.0, 0.0, cov=[math.inf if i == 7 else 0.0 for i in range(36)])
    daemon, client = daemon_factory()
    out = Collector(client, "t/pose")
    daemon.start()
    pub = client.declare_publisher("t/odom", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_until(lambda: health(client), 10, "the daemon")
    for k in range(11):
        pub.put(odom(100.0 + 0.02 * k))
    wait_until(lambda: len(out["t/pose"]) == 11, 10, "11 poses")
    # health's core figures are refreshed every CORE_REFRESH_S: wait for them to count the 11 poses
    wait_until(lambda: health(client).published == 11, 10, "health to count the 11 poses")
    before = health(client)
    ok, errors = request_set_pose(client, "t/set_pose", payload, 5.0)
    assert ok == [] and len(errors) == 1 and problem in errors[0], errors
    after = health(client)
    assert daemon.set_poses == 0 and after.filter.time == before.filter.time and after.published == before.published
    # and the filter goes on from where it was. The next odometry message is the sentinel: the pose key
    # is delivered in order, so a pose published by a wrongly applied set_pose would come before its
    # pose, as the 12th.
    pub.put(odom(100.0 + 0.02 * 11))
    wait_until(lambda: len(out["t/pose"]) >= 12, 5, "the next pose")
    assert decode_pose_cdr(out["t/pose"][11]).pose.pose.position.x == pytest.approx(V * 0.22, abs=1e-9)
    assert decode_pose_cdr(out["t/pose"][11]).header.stamp.sec == 100


def test_set_pose_request_type_is_msgspec_json():
    """`fusiond set-pose` sends SetPoseMessage JSON: the daemon reads exactly that form."""
    from fusiond.codecs import SetPoseMessage, decode_set_pose

    m = SetPoseMessage(stamp=3.5, position=(1.0, 2.0, 3.0), orientation=(0.0, 0.0, 0.0, 1.0))
    req = decode_set_pose(msgspec.json.encode(m))
    assert (req.stamp, req.position, req.orientation, req.covariance) == (3.5, (1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0),
                                                                        (0.0,) * 36)


def test_config_toml_documents_the_ros_keys_with_the_code_defaults():
    from pathlib import Path

    from fusiond.config import Config, load

    documented = load(Path(__file__).resolve().parents[2] / "config.toml")
    assert documented.output == Config().output and documented.ros == Config().ros


def test_migration_guide_examples_are_valid_configs():
    """Every TOML block of docs/MIGRATION.md loads: a migrated config is one the code accepts."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "MIGRATION.md").read_text()
    blocks = re.findall(r"```toml\n(.*?)```", text, re.S)
    assert len(blocks) == 3
    for block in blocks:
        cfg = loads(block, "MIGRATION.md")
        assert cfg.sensors and cfg.output.publish_tf
