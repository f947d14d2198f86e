"""fusiond as an rmw_zenoh node, tested against an independent implementation of the protocol.

The other end is `zenoh-ros2-sdk` (PyPI, a test dependency): its publishers feed the
daemon, its subscribers receive the daemon's Odometry, pose and TF, its graph query
(`get_topic_names_and_types`, what `ros2 topic list -t` does) lists fusiond's topics.
It computes RIHS01 type hashes itself, from .msg definitions; we give it the
definitions as rosbags knows them (no network), so a hash that differs from rosbags'
would make its keys miss ours.

Beside it, strict checks of what is on the wire against our reading of ros2/rmw_zenoh
(rmw_zenoh_cpp/src/detail: liveliness_utils.cpp, attachment_helpers.cpp,
rmw_publisher_data.cpp, qos.cpp): keys, hashes, the 33-byte attachment with sequence
numbers from 1, GIDs, liveliness tokens. All on loopback.
"""

from __future__ import annotations

import re
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import xxhash
import zenoh

from fusiond.codecs import DIAGNOSTIC_ARRAY, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE, TYPESTORE, type_hash
from fusiond.config import ConfigError, ZenohConfig, loads
from fusiond.health import decode_report
from fusiond.transport.daemon import Daemon
from fusiond.transport.session import build_config, open_session, query_health

from tests.support.configs import sensor_tables
from tests.support.loopback import free_port, wait_until

sdk = pytest.importorskip("zenoh_ros2_sdk", reason="zenoh-ros2-sdk (test extra) not installed")
from zenoh_ros2_sdk import message_registry as sdk_registry  # noqa: E402
from zenoh_ros2_sdk.attachment import Attachment as SdkAttachment  # noqa: E402
from zenoh_ros2_sdk.discovery import get_topic_names_and_types  # noqa: E402

CONFIG = """
[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
[ros]
interop = "rmw_zenoh"
domain_id = {domain}
[output]
ros_diagnostics_period_s = 0.2
""" + sensor_tables(imu_key="imu/data")

DOMAIN = 7
TYPES = {"/odom_combined": POSE_COV_STAMPED, "/odometry/filtered": ODOMETRY, "/tf": TF_MESSAGE,
         "/diagnostics": DIAGNOSTIC_ARRAY}
INPUTS = {"/odom": ODOMETRY, "/imu/data": "sensor_msgs/msg/Imu", "/set_pose": POSE_COV_STAMPED}
V = 0.5  # m/s along x
SMOOTH_LAG = 0.2  # s, the smoothed pose's lag in smoothing_world


def dds(msgtype: str) -> str:
    pkg, sub, name = msgtype.split("/")
    return f"{pkg}::{sub}::dds_::{name}_"


# --------------------------------------------------------------------------- the SDK, fed .msg files


def write_msg_definitions(root: Path, msgtypes: list[str]) -> None:
    """Per-type .msg files (what the SDK reads) from rosbags' definitions of the types and their fields."""
    ts = TYPESTORE
    for typename in msgtypes:
        text, _ = ts.generate_msgdef(typename, ros_version=2)
        parts = re.split(r"\n=+\n", text)
        items = [(typename, parts[0])]
        for part in parts[1:]:
            head, _, body = part.partition("\n")
            name = head.removeprefix("MSG: ").strip()
            if name.count("/") == 1:
                pkg, base = name.split("/")
                name = f"{pkg}/msg/{base}"
            items.append((name, body))
        for name, body in items:
            f = root / f"{name}.msg"
            f.parent.mkdir(parents=True, exist_ok=True)
            f.write_text(body.strip() + "\n")


@pytest.fixture(scope="module")
def msg_dir(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("msg")
    write_msg_definitions(d, [*TYPES.values(), *INPUTS.values()])
    return d


@pytest.fixture
def world(msg_dir) -> Iterator[dict]:
    """A fusiond daemon in rmw_zenoh mode, a plain Zenoh session beside it, and the SDK's session."""
    yield from _world(msg_dir, CONFIG)


@pytest.fixture
def smoothing_world(msg_dir) -> Iterator[dict]:
    """As ``world``, the daemon also publishing the fixed-lag smoothed pose on /odom_smoothed."""
    yield from _world(msg_dir, CONFIG.replace("[output]\n", f"[output]\nsmoothed_key = \"odom_smoothed\"\n"
                                                            f"smooth_lag_s = {SMOOTH_LAG}\n"))


def _world(msg_dir, config: str) -> Iterator[dict]:
    port = free_port()
    cfg = loads(config.format(port=port, domain=DOMAIN))
    dsession = open_session(build_config(cfg.zenoh))
    client = open_session(build_config(ZenohConfig(connect=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False)))
    sdk_registry._registry = sdk_registry.MessageRegistry(str(msg_dir))
    sdk.ZenohSession._instance = None
    daemon = Daemon(cfg, dsession, monitor=False)
    daemon.start()
    sdk_session = sdk.ZenohSession.get_instance("127.0.0.1", port)
    try:
        yield {"port": port, "cfg": cfg, "daemon": daemon, "client": client, "dsession": dsession}
    finally:
        daemon.stop()
        sdk_session.close()
        sdk_registry._registry = None
        client.close()
        dsession.close()


def health(session: zenoh.Session):
    answers = query_health(session, "fusiond/health", 1.0)
    return decode_report(answers[0]) if answers else None


class Received:
    def __init__(self) -> None:
        self.items: list = []
        self._lock = threading.Lock()

    def __call__(self, item) -> None:
        with self._lock:
            self.items.append(item)

    def __len__(self) -> int:
        with self._lock:
            return len(self.items)

    def snapshot(self) -> list:
        with self._lock:
            return list(self.items)


def sdk_odometry(pub, stamp: float) -> None:
    T = pub.session_mgr.store.types
    sec, nsec = int(stamp), round((stamp - int(stamp)) * 1e9)
    cov = [1e-4 if i % 7 == 0 else 0.0 for i in range(36)]
    pub.publish(
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec),
                                        frame_id="odom"),
        child_frame_id="base_link",
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                             orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=np.zeros(36)),
        twist=T["geometry_msgs/msg/TwistWithCovariance"](
            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=V, y=0.0, z=0.0),
                                               angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
            covariance=np.array(cov)),
    )


def parse_token(key: str) -> dict:
    """A liveliness key as rmw_zenoh's `Entity::make(keyexpr)` reads it (liveliness_utils.cpp)."""
    parts = key.split("/")
    assert all(parts), f"empty chunk in {key}"
    names = ["admin", "domain", "zid", "nid", "id", "kind", "enclave", "namespace", "node"]
    if len(parts) > 9:
        names += ["topic", "type", "hash", "qos"]
    assert len(parts) == len(names), key
    d = dict(zip(names, parts))
    for k in ("enclave", "namespace", "node", "topic", "type", "hash"):
        if k in d:
            d[k] = d[k].replace("%", "/")
    return d


# --------------------------------------------------------------------------- tests


@pytest.mark.e2e
def test_sdk_publishers_feed_the_daemon_and_sdk_subscribers_get_its_outputs(world):
    client: zenoh.Session = world["client"]
    port = world["port"]
    wait_until(lambda: health(client), 10, "the daemon")

    # raw samples on every rmw_zenoh key of the domain, with their attachments
    raw: Received = Received()
    raw_sub = client.declare_subscriber(f"{DOMAIN}/**", lambda s: raw((str(s.key_expr), s.payload.to_bytes(),
                                                                        None if s.attachment is None
                                                                        else s.attachment.to_bytes(),
                                                                        time.time_ns())))
    odometry, poses, tfs, diagnostics = Received(), Received(), Received(), Received()
    subs = [
        sdk.ROS2Subscriber("/odometry/filtered", ODOMETRY, odometry, node_name="checker", domain_id=DOMAIN,
                           router_port=port),
        sdk.ROS2Subscriber("/odom_combined", POSE_COV_STAMPED, poses, node_name="checker", domain_id=DOMAIN,
                           router_port=port),
        sdk.ROS2Subscriber("/tf", TF_MESSAGE, tfs, node_name="checker", domain_id=DOMAIN, router_port=port),
        sdk.ROS2Subscriber("/diagnostics", DIAGNOSTIC_ARRAY, diagnostics, node_name="checker", domain_id=DOMAIN,
                           router_port=port),
    ]
    wheel = sdk.ROS2Publisher("/odom", ODOMETRY, node_name="wheel_driver", domain_id=DOMAIN, router_port=port)
    # The SDK computed the hashes itself from the .msg definitions: they must be rosbags'.
    for s in subs:
        assert s.type_hash == type_hash(s.msg_type)
    assert wheel.keyexpr == f"{DOMAIN}/odom/{dds(ODOMETRY)}/{type_hash(ODOMETRY)}"

    # the SDK's graph view (ros2 topic list -t) sees fusiond's topics and types
    def graph() -> dict:
        return dict(get_topic_names_and_types(domain_id=DOMAIN, router_port=port, timeout=0.5))

    topics = wait_until(lambda: (g := graph()) and all(t in g for t in [*TYPES, *INPUTS]) and g, 10,
                        "fusiond's topics in the ROS graph")
    for name, msgtype in {**TYPES, **INPUTS}.items():
        assert msgtype in topics[name], (name, topics[name])

    # declarations travel the link in order: once the daemon's health answers after the
    # SDK declared its subscriber, the daemon routes to it; and its subscription is matched
    t_start = time.time_ns()
    n = 50
    for k in range(n):
        sdk_odometry(wheel, 200.0 + 0.02 * k)
        time.sleep(0.005)
    rep = wait_until(lambda: (r := health(client)) and r.sensors["wheel"].applied == n and r, 10,
                     "the daemon to fuse the SDK's odometry")
    assert rep.sensors["wheel"].received == n and rep.sensors["wheel"].dropped == 0
    wait_until(lambda: len(odometry) >= n and len(poses) >= n, 10, "the SDK subscribers to get n poses")
    t_end = time.time_ns()
    last = odometry.snapshot()[-1]
    assert last.header.stamp.sec == 200 and last.child_frame_id == "base_link"
    assert last.pose.pose.position.x == pytest.approx(V * 0.02 * (n - 1), abs=1e-9)  # 0.5 m/s x 0.98 s
    assert poses.snapshot()[-1].pose.pose.position.x == pytest.approx(V * 0.02 * (n - 1), abs=1e-9)
    assert len(tfs) >= 1 and tfs.snapshot()[-1].transforms[0].child_frame_id == "base_link"

    # -- strict: keys, hashes, attachments
    samples = raw.snapshot()
    odom_key = f"{DOMAIN}/odometry/filtered/{dds(ODOMETRY)}/{type_hash(ODOMETRY)}"
    pose_key = f"{DOMAIN}/odom_combined/{dds(POSE_COV_STAMPED)}/{type_hash(POSE_COV_STAMPED)}"
    tf_key = f"{DOMAIN}/tf/{dds(TF_MESSAGE)}/{type_hash(TF_MESSAGE)}"
    assert odom_key == ("7/odometry/filtered/nav_msgs::msg::dds_::Odometry_/"
                        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0")
    tokens = [str(r.ok.key_expr) for r in client.liveliness().get(f"@ros2_lv/{DOMAIN}/**", timeout=1.0)
              if r.ok is not None]
    zid = str(world["dsession"].zid())
    ours = {t: parse_token(t) for t in tokens if parse_token(t)["zid"] == zid}
    mp = {d["topic"]: (t, d) for t, d in ours.items() if d["kind"] == "MP"}
    for key in (odom_key, pose_key, tf_key):
        mine = [s for s in samples if s[0] == key]
        assert mine, f"nothing on {key}"
        seqs, stamps_ns, gids = [], [], set()
        for _, payload, att, arrived in mine:
            assert att is not None and len(att) == 33, "rmw_zenoh's attachment: int64, int64, LEB128 16, 16 bytes"
            seq, ts_ns, n16 = struct.unpack_from("<qqB", att)
            assert n16 == 16
            seqs.append(seq)
            stamps_ns.append(ts_ns)
            gids.add(att[17:])
            # the SDK's own attachment reader agrees (u64, u64, u8 length, gid)
            other = SdkAttachment.from_bytes(att)
            assert (other.sequence_id, other.timestamp_ns, other.gid) == (seq, ts_ns, att[17:])
            assert t_start - 5e9 <= ts_ns <= arrived  # the system clock at publication, before arrival
            assert payload[:4] == b"\x00\x01\x00\x00"
        assert seqs == list(range(1, len(seqs) + 1)), f"{key}: sequence numbers from 1, +1 per sample"
        assert stamps_ns == sorted(stamps_ns)
        (gid,) = gids
        topic = "/" + key.split("/")[1] if key != odom_key else "/odometry/filtered"
        token, _ = mp[topic]
        v = xxhash.xxh3_128_intdigest(token.encode())
        assert gid == (v & (2**64 - 1)).to_bytes(8, "little") + (v >> 64).to_bytes(8, "little")
    assert max(s[3] for s in samples) <= t_end

    # /diagnostics (every 0.2 s here) through the SDK: odometry at 50 Hz of wall time until an array
    # shows the wheel alive; the IMU never sent, so the filter is degraded (WARN) and the IMU WARN
    def wheel_ok() -> list:
        return [d for d in diagnostics.snapshot() if any(st.name == "fusiond: wheel" and st.level == 0
                                                         for st in d.status)]

    k, deadline = n, time.monotonic() + 10
    while not wheel_ok():
        assert time.monotonic() < deadline, "a DiagnosticArray with the wheel OK"
        sdk_odometry(wheel, 200.0 + 0.02 * k)
        k += 1
        time.sleep(0.02)
    levels = {st.name: int(st.level) for st in wheel_ok()[-1].status}
    assert levels == {"fusiond: filter": 1, "fusiond: wheel": 0, "fusiond: imu": 1}
    raw_sub.undeclare()
    for s in subs:
        s.close()
    wheel.close()


@pytest.mark.e2e
def test_liveliness_tokens_are_rmw_zenohs(world):
    client: zenoh.Session = world["client"]
    wait_until(lambda: health(client), 10, "the daemon")
    zid = str(world["dsession"].zid())
    tokens = [str(r.ok.key_expr) for r in client.liveliness().get(f"@ros2_lv/{DOMAIN}/**", timeout=1.0)
              if r.ok is not None]
    ours = sorted((parse_token(t) for t in tokens if t.split("/")[2] == zid), key=lambda d: int(d["id"]))
    node = ours[0]
    assert node["kind"] == "NN" and node["nid"] == node["id"] == "0"
    assert (node["admin"], node["domain"], node["enclave"], node["namespace"], node["node"]) == (
        "@ros2_lv", str(DOMAIN), "/", "/", "fusiond")
    assert f"@ros2_lv/{DOMAIN}/{zid}/0/0/NN/%/%/fusiond" in tokens
    endpoints = ours[1:]
    ids = [int(d["id"]) for d in endpoints]
    assert len(set(ids)) == len(ids) and all(i > 0 for i in ids) and all(d["nid"] == "0" for d in endpoints)
    pubs = {d["topic"]: d for d in endpoints if d["kind"] == "MP"}
    subs = {d["topic"]: d for d in endpoints if d["kind"] == "MS"}
    assert set(pubs) == set(TYPES) and set(subs) == set(INPUTS)
    for table, kinds in ((pubs, TYPES), (subs, INPUTS)):
        for topic, d in table.items():
            assert d["type"] == dds(kinds[topic]) and d["hash"] == type_hash(kinds[topic])
            # reliable, volatile, keep-last: 10 deep (tf: 100), every other field rmw_zenoh's default
            assert d["qos"] == ("::,100:,:,:,," if topic == "/tf" else "::,10:,:,:,,")
            assert (d["enclave"], d["namespace"], d["node"]) == ("/", "/", "fusiond")
    # the token of the pose publisher in full
    pose_id = next(d["id"] for d in endpoints if d["topic"] == "/odom_combined")
    expected = (f"@ros2_lv/{DOMAIN}/{zid}/0/{pose_id}/MP/%/%/fusiond/%odom_combined/"
                f"geometry_msgs::msg::dds_::PoseWithCovarianceStamped_/{type_hash(POSE_COV_STAMPED)}/::,10:,:,:,,")
    assert expected in tokens
    # stopping the daemon withdraws them all
    world["daemon"].stop()
    wait_until(lambda: not [r for r in client.liveliness().get(f"@ros2_lv/{DOMAIN}/{zid}/**", timeout=0.5)
                            if r.ok is not None], 5, "the tokens to go")


@pytest.mark.e2e
def test_set_pose_topic_from_an_rmw_zenoh_publisher(world):
    client: zenoh.Session = world["client"]
    port = world["port"]
    wait_until(lambda: health(client), 10, "the daemon")
    wheel = sdk.ROS2Publisher("/odom", ODOMETRY, node_name="wheel_driver", domain_id=DOMAIN, router_port=port)
    setter = sdk.ROS2Publisher("/set_pose", POSE_COV_STAMPED, node_name="operator", domain_id=DOMAIN,
                               router_port=port)
    poses = Received()
    sub = sdk.ROS2Subscriber("/odom_combined", POSE_COV_STAMPED, poses, node_name="checker", domain_id=DOMAIN,
                             router_port=port)
    wait_until(lambda: health(client), 10, "the declarations to reach the daemon")
    for k in range(11):
        sdk_odometry(wheel, 300.0 + 0.02 * k)
    wait_until(lambda: (r := health(client)) and r.sensors["wheel"].applied == 11, 10, "11 odometry messages")
    T = setter.session_mgr.store.types
    setter.publish(
        header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=300, nanosec=200_000_000),
                                        frame_id="odom"),
        pose=T["geometry_msgs/msg/PoseWithCovariance"](
            pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=3.0, y=4.0, z=0.0),
                                             orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
            covariance=np.eye(6).ravel() * 0.01),
    )
    wait_until(lambda: world["daemon"].set_poses == 1, 10, "the set_pose topic to be applied")
    got = wait_until(lambda: [p for p in poses.snapshot() if p.pose.pose.position.x == 3.0], 10,
                     "the pose at (3, 4) on /odom_combined")
    assert got[0].pose.pose.position.y == 4.0 and got[0].header.stamp.nanosec == 200_000_000
    sub.close()
    wheel.close()
    setter.close()


@pytest.mark.e2e
def test_smoothed_key_is_an_rmw_zenoh_topic_with_the_pose_of_the_lag_ago(smoothing_world):
    """``[output] smoothed_key`` in rmw_zenoh mode: a ROS topic of the node (its liveliness token, its key
    with the type hash, rmw_zenoh's attachment), which an rmw_zenoh subscriber receives; each pose is the one
    of ``smooth_lag_s`` before the newest (odometry alone at constant speed: no later evidence moves it, so
    it is where the wheels put it then)."""
    world = smoothing_world
    client: zenoh.Session = world["client"]
    port = world["port"]
    wait_until(lambda: health(client), 10, "the daemon")
    key = f"{DOMAIN}/odom_smoothed/{dds(POSE_COV_STAMPED)}/{type_hash(POSE_COV_STAMPED)}"
    zid = str(world["dsession"].zid())
    tokens = [str(r.ok.key_expr) for r in client.liveliness().get(f"@ros2_lv/{DOMAIN}/{zid}/**", timeout=1.0)
              if r.ok is not None]
    mine = [parse_token(t) for t in tokens if "%odom_smoothed" in t]
    assert len(mine) == 1 and mine[0]["kind"] == "MP" and mine[0]["hash"] == type_hash(POSE_COV_STAMPED)
    raw: Received = Received()
    raw_sub = client.declare_subscriber(key, lambda s: raw((s.payload.to_bytes(), None if s.attachment is None
                                                            else s.attachment.to_bytes())))
    smoothed, poses = Received(), Received()
    subs = [sdk.ROS2Subscriber("/odom_smoothed", POSE_COV_STAMPED, smoothed, node_name="mapper", domain_id=DOMAIN,
                               router_port=port),
            sdk.ROS2Subscriber("/odom_combined", POSE_COV_STAMPED, poses, node_name="mapper", domain_id=DOMAIN,
                               router_port=port)]
    wheel = sdk.ROS2Publisher("/odom", ODOMETRY, node_name="wheel_driver", domain_id=DOMAIN, router_port=port)
    wait_until(lambda: health(client), 10, "the declarations to reach the daemon")
    n, t0, dt = 40, 400.0, 0.02
    for k in range(n):
        sdk_odometry(wheel, t0 + dt * k)
    wait_until(lambda: (r := health(client)) and r.sensors["wheel"].applied == n, 10, f"{n} odometry messages")
    newest = t0 + dt * (n - 1)
    got = wait_until(lambda: (g := smoothed.snapshot()) and abs(_msg_stamp(g[-1]) - (newest - SMOOTH_LAG)) < 1e-6
                     and g, 10, "the smoothed pose of the newest stamp minus the lag")
    assert len(got) >= n - SMOOTH_LAG / dt - 2
    for msg in got:
        t = _msg_stamp(msg)
        assert t0 <= t <= newest - SMOOTH_LAG + 1e-6
        assert msg.pose.pose.position.x == pytest.approx(V * (t - t0), abs=1e-9)
        assert msg.header.frame_id == poses.snapshot()[-1].header.frame_id
    wait_until(lambda: len(raw) >= len(got), 5, "the raw samples on the smoothed key")
    seqs = []
    for payload, att in raw.snapshot():
        assert att is not None and len(att) == 33 and payload[:4] == b"\x00\x01\x00\x00"
        seqs.append(struct.unpack_from("<q", att)[0])
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs)
    raw_sub.undeclare()
    for s in subs:
        s.close()
    wheel.close()


def _msg_stamp(msg) -> float:
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def test_rmw_zenoh_mode_refuses_a_zenoh_namespace_and_non_cdr_sensors():
    with pytest.raises(ConfigError, match="zenoh.namespace: not used with ros.interop"):
        loads('[ros]\ninterop = "rmw_zenoh"\n[zenoh]\nnamespace = "robot1"\n')
    with pytest.raises(ConfigError, match="sensor \"w\": encoding: rmw_zenoh carries ROS 2 CDR only"):
        loads('[ros]\ninterop = "rmw_zenoh"\n[[sensors]]\nname = "w"\nkind = "odom"\nkey = "odom"\nencoding = "json"\n')
    with pytest.raises(ConfigError, match="ros.node_name"):
        loads('[ros]\nnode_name = "my-node"\n')


def test_attachment_is_zenohs_serialisation_of_int64_int64_and_a_16_byte_sequence():
    """zenoh-cpp serialises std::array<uint8_t, 16> as a sequence: LEB128 length, then the bytes
    (serialization.hxx), after the two little-endian int64 (attachment_helpers.cpp)."""
    from fusiond.transport.rmw_zenoh import attachment, gid_of

    gid = gid_of("@ros2_lv/0/abc/0/1/MP/%/%/fusiond/%tf/tf2_msgs::msg::dds_::TFMessage_/RIHS01_x/::,100:,:,:,,")
    raw = attachment(1, 1_700_000_000_123_456_789, gid)
    assert raw == struct.pack("<qqB", 1, 1_700_000_000_123_456_789, 16) + gid and len(raw) == 33
    assert attachment(2**40, -5, gid)[:16] == struct.pack("<qq", 2**40, -5)


def test_qos_chunk_and_names_as_rmw_zenoh_writes_them():
    from fusiond.transport.rmw_zenoh import mangle, qos_keyexpr, topic_key, topic_name

    assert qos_keyexpr(42) == "::,:,:,:,,"  # everything rmw_zenoh's default (qos.cpp): all elided
    assert qos_keyexpr(10) == "::,10:,:,:,,"
    assert mangle("/robot1/odom") == "%robot1%odom" and mangle("/") == "%"
    assert topic_name("robot1/odom") == "/robot1/odom"
    assert topic_key(0, "/robot1/odom/", ODOMETRY) == f"0/robot1/odom/{dds(ODOMETRY)}/{type_hash(ODOMETRY)}"


def test_type_hashes_do_not_depend_on_the_rosbags_store():
    """type_hash uses rosbags' Jazzy store; the messages fusiond uses hash the same in Humble's and Kilted's."""
    from rosbags.typesys import Stores, get_typestore

    types = [*TYPES.values(), *INPUTS.values(), "sensor_msgs/msg/NavSatFix", "geometry_msgs/msg/PoseStamped"]
    for store in (Stores.ROS2_HUMBLE, Stores.ROS2_KILTED):
        ts = get_typestore(store)
        assert [ts.hash_rihs01(t) for t in types] == [type_hash(t) for t in types], store
