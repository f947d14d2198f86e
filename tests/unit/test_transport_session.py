"""Transport pieces without the daemon: the struct CDR encoders of the outputs against rosbags,
and the Zenoh session built from `[zenoh]` (real sessions on loopback, namespace included)."""

from __future__ import annotations

import json
import socket
import time

import numpy as np
import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond.codecs import encode_odometry_cdr, encode_pose_cdr, encode_tf_cdr, encode_tf_tree_cdr
from fusiond.config import ConfigError, ZenohConfig, check_endpoint
from fusiond.transport.session import (
    build_config,
    client_config,
    client_endpoints,
    loopback,
    open_session,
    zenoh_error_text,
)

from tests.support.cdr_reference import (
    encode_odometry_cdr_rosbags, encode_pose_cdr_rosbags, encode_tf_cdr_rosbags, encode_tf_tree_cdr_rosbags,
)

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
frames = st.text(alphabet=st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=20)


@settings(max_examples=200, deadline=None)
@given(stamp=st.floats(min_value=0.0, max_value=2.0e9), frame=frames, child=frames,
       values=st.lists(finite, min_size=85, max_size=85))
def test_struct_encoders_are_byte_identical_to_rosbags(stamp, frame, child, values):
    p, q, cov, lin, ang, tcov = values[0:3], values[3:7], values[7:43], values[43:46], values[46:49], values[49:85]
    assert encode_pose_cdr(stamp, frame, p, q, cov) == encode_pose_cdr_rosbags(stamp, frame, p, q, cov)
    assert encode_tf_cdr(stamp, frame, child, p, q) == encode_tf_cdr_rosbags(stamp, frame, child, p, q)
    assert (encode_odometry_cdr(stamp, frame, child, np.array(p), tuple(q), np.array(cov), lin, ang, tcov)
            == encode_odometry_cdr_rosbags(stamp, frame, child, p, q, cov, lin, ang, tcov))


@settings(max_examples=200, deadline=None)
@given(stamp=st.floats(min_value=0.0, max_value=2.0e9), names=st.lists(frames, min_size=2, max_size=6),
       values=st.lists(finite, min_size=21, max_size=21))
def test_the_tf_tree_encoder_is_byte_identical_to_rosbags(stamp, names, values):
    """Any frame names (their lengths move the padding before each transform's doubles), 1-3 transforms."""
    transforms = [(names[i], names[i + 1], values[7 * i:7 * i + 3], values[7 * i + 3:7 * i + 7])
                  for i in range(min(len(names) - 1, 3))]
    assert encode_tf_tree_cdr(stamp, transforms) == encode_tf_tree_cdr_rosbags(stamp, transforms)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_bad_values_are_one_line_config_errors(tmp_path):
    with pytest.raises(ConfigError, match=r"^zenoh.listen: Endpoints must be of the form") as e:
        build_config(ZenohConfig(listen=["nonsense"]))
    assert "\n" not in str(e.value) and ".rs:" not in str(e.value)
    with pytest.raises(ConfigError, match=r"^zenoh.namespace: Invalid Key Expr"):
        build_config(ZenohConfig(namespace="robot*"))
    with pytest.raises(ConfigError, match=r"^zenoh.config_file: no such file .*missing.json5"):
        build_config(ZenohConfig(config_file="missing.json5"), base_dir=tmp_path)
    (tmp_path / "bad.json5").write_text('{ mode: "mesh" }')
    with pytest.raises(ConfigError, match=r"zenoh.config_file: .*bad.json5: unknown variant `mesh`"):
        build_config(ZenohConfig(config_file="bad.json5"), base_dir=tmp_path)
    assert zenoh_error_text(zenoh.ZError("x at /root/a/b.rs:12.")) == "x"


def test_config_file_is_layered_under_the_toml_keys(tmp_path):
    (tmp_path / "z.json5").write_text('{ mode: "client", connect: { endpoints: ["tcp/127.0.0.1:7000"] } }')
    conf = build_config(ZenohConfig(config_file="z.json5"), base_dir=tmp_path)
    # defaults in the TOML do not override what the file says
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:7000"]
    conf = build_config(ZenohConfig(config_file=str(tmp_path / "z.json5"), mode="peer", connect=["tcp/10.0.0.1:1"],
                                    multicast_scouting=False, namespace="r1"))
    assert json.loads(conf.get_json("mode")) == "client"  # "peer" is the default: the file wins
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/10.0.0.1:1"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    assert json.loads(conf.get_json("namespace")) == "r1"


def test_tools_dial_the_daemons_listen_endpoints_and_never_take_its_port():
    zc = ZenohConfig(mode="router", listen=["tcp/0.0.0.0:7447", "tcp/[::]:7448", "udp/10.1.2.3:9"])
    assert client_endpoints(zc, None) == ["tcp/127.0.0.1:7447", "tcp/[::1]:7448", "udp/10.1.2.3:9"]
    assert client_endpoints(zc, ["tcp/h:1"]) == ["tcp/h:1"]
    assert loopback("tcp/localhost:1") == "tcp/localhost:1"
    conf = client_config(zc)
    assert json.loads(conf.get_json("listen/endpoints"))["peer"] == ["tcp/[::]:0"]  # Zenoh's own: a random port
    assert json.loads(conf.get_json("mode")) == "peer"
    assert json.loads(conf.get_json("connect/endpoints"))[0] == "tcp/127.0.0.1:7447"
    assert json.loads(client_config(zc, listen=["tcp/127.0.0.1:9"]).get_json("listen/endpoints")) == ["tcp/127.0.0.1:9"]


def test_two_tools_that_dial_one_peer_daemon_hear_each_other():
    """``play`` publishing a bag and a live ``calibrate-imu`` listening, both dialling the daemon (a peer, no
    router, no multicast): a peer routes nothing between two other peers, so they must connect to each other,
    at the locators the daemon's gossip passes on. Each tool's session is ``client_config``'s; the IMU key
    put by one reaches the other within the deadline."""
    port = free_port()
    zc = ZenohConfig(listen=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False)
    daemon = open_session(build_config(zc))
    player = open_session(client_config(zc))
    listener = open_session(client_config(zc))
    try:
        heard: list[bytes] = []
        sub = listener.declare_subscriber("imu", lambda s: heard.append(s.payload.to_bytes()))
        deadline = time.monotonic() + 10
        while not heard and time.monotonic() < deadline:
            player.put("imu", b"x")
            time.sleep(0.05)
        assert heard == [b"x"] * len(heard) and heard
        sub.undeclare()
    finally:
        for s in (listener, player, daemon):
            s.close()


def test_namespace_prefixes_keys_on_the_wire_only():
    """Zenoh's native namespace (checked supported here): robot1's local `odom_combined` is
    `robot1/odom_combined` for everyone else, and a remote put on `robot1/odom` reaches its `odom`."""
    port = free_port()
    robot = open_session(build_config(ZenohConfig(listen=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False,
                                                  namespace="robot1")))
    other = open_session(build_config(ZenohConfig(connect=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False)))
    try:
        seen_other: list[str] = []
        seen_robot: list[str] = []
        s1 = other.declare_subscriber("*/odom_combined", lambda s: seen_other.append(str(s.key_expr)))
        s2 = robot.declare_subscriber("odom", lambda s: seen_robot.append(str(s.key_expr)))
        deadline = time.monotonic() + 5
        while not (seen_other and seen_robot) and time.monotonic() < deadline:
            robot.put("odom_combined", b"x")
            other.put("robot1/odom", b"y")
            time.sleep(0.05)
        assert seen_other and set(seen_other) == {"robot1/odom_combined"}
        assert seen_robot and set(seen_robot) == {"odom"}
        s1.undeclare()
        s2.undeclare()
    finally:
        other.close()
        robot.close()


@pytest.mark.parametrize("endpoint, ok", [
    ("tcp/127.0.0.1:7447", True), ("tcp/[::1]:0", True), ("udp/10.0.0.2:65535", True),
    ("tcp/localhost:7447?iface=eth0", True), ("unixsock-stream//tmp/zenoh.sock", True), ("serial//dev/ttyUSB0", True),
    ("tcp/127.0.0.1:99999", False), ("tcp/127.0.0.1", False), ("tcp/:7447", False), ("quic/host:port", False),
])
def test_an_ip_endpoint_needs_a_host_and_a_port_in_range(endpoint, ok):
    if ok:
        check_endpoint(endpoint, "zenoh.listen")
    else:
        with pytest.raises(ConfigError, match=r"^zenoh.listen: a \w+ endpoint is \w+/HOST:PORT"):
            check_endpoint(endpoint, "zenoh.listen")
