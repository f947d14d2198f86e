"""Security of `fusiond run`: Zenoh mutual TLS and access control, configured through
`zenoh.config_file` (native Zenoh JSON5), against real daemon subprocesses on loopback.

Certificates are generated in the test with the `openssl` CLI (skipped without it). The JSON5
keys are zenoh 1.x's (DEFAULT_CONFIG.json5): `transport.link.tls.{root_ca_certificate,
listen_private_key, listen_certificate, enable_mtls, connect_private_key, connect_certificate}`
and `access_control.{enabled, default_permission, rules, subjects, policies}`.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest
import zenoh

from fusiond.config import ZenohConfig, load
from fusiond.transport.session import build_config, open_session, query_health

from tests.support.daemon import ROOT, daemon_process, free_port, fusiond_cmd, wait_until
from tests.support.reliability import IMU_KEY, WHEEL_KEY, Poses, imu_payload, odom_payload

OPENSSL = shutil.which("openssl")
needs_openssl = pytest.mark.skipif(OPENSSL is None, reason="openssl CLI not found")


# --------------------------------------------------------------------------- certificates


def _openssl(*args: str, cwd: Path) -> None:
    subprocess.run([OPENSSL, *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def _ca(d: Path, name: str) -> None:
    _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes", "-days", "2",
             "-keyout", f"{name}.key", "-out", f"{name}.pem", "-subj", f"/CN={name}",
             "-addext", "basicConstraints=critical,CA:TRUE", "-addext", "keyUsage=critical,keyCertSign,cRLSign",
             cwd=d)


def _leaf(d: Path, name: str, ca: str, san: str, eku: str) -> None:
    _openssl("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
             "-keyout", f"{name}.key", "-out", f"{name}.csr", "-subj", f"/CN={name}", cwd=d)
    (d / f"{name}.ext").write_text(f"basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n"
                                   f"extendedKeyUsage={eku}\nsubjectAltName={san}\n")
    _openssl("x509", "-req", "-in", f"{name}.csr", "-CA", f"{ca}.pem", "-CAkey", f"{ca}.key", "-CAcreateserial",
             "-days", "2", "-out", f"{name}.pem", "-extfile", f"{name}.ext", cwd=d)


@pytest.fixture(scope="module")
def pki(tmp_path_factory) -> Path:
    """ca (trusted): fusiond (server, 127.0.0.1/localhost), operator and viewer (clients); rogue CA: intruder."""
    if OPENSSL is None:
        pytest.skip("openssl CLI not found")
    d = tmp_path_factory.mktemp("pki")
    _ca(d, "ca")
    _leaf(d, "fusiond", "ca", "IP:127.0.0.1,DNS:localhost", "serverAuth,clientAuth")
    _leaf(d, "operator", "ca", "DNS:operator", "clientAuth")
    _leaf(d, "viewer", "ca", "DNS:viewer", "clientAuth")  # trusted, but not the operator
    _ca(d, "rogue")
    _leaf(d, "intruder", "rogue", "DNS:intruder", "clientAuth")
    return d


def tls_json5(pki: Path) -> str:
    """The daemon's native Zenoh config: listen with mutual TLS, trusting only our CA."""
    return f"""{{
  // fusiond daemon: TLS listener, clients must present a certificate signed by ca.pem
  transport: {{
    link: {{
      tls: {{
        root_ca_certificate: "{pki / 'ca.pem'}",
        listen_private_key: "{pki / 'fusiond.key'}",
        listen_certificate: "{pki / 'fusiond.pem'}",
        enable_mtls: true,
      }},
    }},
  }},
}}
"""


def tls_client(pki: Path, port: int, cert: str | None, ca: str = "ca") -> zenoh.Session:
    conf = build_config(ZenohConfig(mode="peer", connect=[f"tls/127.0.0.1:{port}"], multicast_scouting=False))
    conf.insert_json5("transport/link/tls/root_ca_certificate", json.dumps(str(pki / f"{ca}.pem")))
    if cert is not None:
        conf.insert_json5("transport/link/tls/connect_private_key", json.dumps(str(pki / f"{cert}.key")))
        conf.insert_json5("transport/link/tls/connect_certificate", json.dumps(str(pki / f"{cert}.pem")))
        conf.insert_json5("transport/link/tls/enable_mtls", "true")
    return open_session(conf)


def daemon_config(tmp_path: Path, listen: str, json5: str, name: str) -> Path:
    (tmp_path / f"{name}.json5").write_text(json5)
    config = tmp_path / f"{name}.toml"
    config.write_text(f'[zenoh]\nmode = "peer"\nlisten = ["{listen}"]\nmulticast_scouting = false\n'
                      f'config_file = "{name}.json5"\n\n' + (ROOT / "examples" / "jackal.toml").read_text())
    return config


def answers(session: zenoh.Session, timeout: float = 1.0) -> list[bytes]:
    return query_health(session, "fusiond/health", timeout)


@needs_openssl
@pytest.mark.e2e
def test_mutual_tls_only_a_client_with_a_valid_certificate_gets_anything(pki, tmp_path, reliability_log):
    port = free_port()
    config = daemon_config(tmp_path, f"tls/127.0.0.1:{port}", tls_json5(pki), "tls")
    log = tmp_path / "daemon.log"
    sessions: list[zenoh.Session] = []
    with daemon_process(config, log) as proc:
        try:
            good = tls_client(pki, port, "operator")
            sessions.append(good)
            wait_until(lambda: proc.poll() is None and answers(good, 0.5), 30, "a health answer over mutual TLS")
            poses = Poses(good)
            # the ones that must get nothing: no client certificate, a certificate of another CA, plain TCP
            intruders = {
                "TLS client without a certificate": tls_client(pki, port, None),
                "TLS client with a certificate of another CA": tls_client(pki, port, "intruder", ca="ca"),
                "plain TCP client on the TLS port": open_session(build_config(ZenohConfig(
                    mode="peer", connect=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False))),
            }
            sessions += intruders.values()
            seen = {name: Poses(s) for name, s in intruders.items()}
            pub = good.declare_publisher(WHEEL_KEY)
            imu = good.declare_publisher(IMU_KEY)
            for k in range(40):
                stamp = 1000.0 + 0.02 * k
                imu.put(imu_payload(stamp - 0.005))
                pub.put(odom_payload(stamp))
                time.sleep(0.02)
            wait_until(lambda: len(poses) >= 40, 10, "40 poses over mutual TLS")
            got = {name: (len(p), len(answers(s, 0.5))) for (name, s), p in zip(intruders.items(), seen.values())}
            # an intruder's put on a sensor key must not reach the daemon either
            before = json.loads(answers(good)[0])["sensors"]["wheel"]["received"]
            for s in intruders.values():
                s.put(WHEEL_KEY, odom_payload(2000.0))
            # Not sleep-and-hope: a session whose info lists no peer and no router has no link to
            # anyone, so nothing it puts can reach the daemon; the daemon's counter confirms it.
            for name, s in intruders.items():
                assert not list(s.info.peers_zid()) and not list(s.info.routers_zid()), name
            after = json.loads(answers(good)[0])["sensors"]["wheel"]["received"]
        finally:
            for s in sessions:
                s.close()
        alive = proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    reliability_log.record(
        group="security", sensor="zenoh", input="mutual TLS listener (tls/127.0.0.1), client with a certificate "
                                                "of the trusted CA",
        expected="health answers, sensor data in, poses out",
        observed=f"{len(poses)} poses received over TLS; health answered", passed=len(poses) >= 40 and alive,
        crashed=not alive, test="test_mutual_tls")
    for name, (n_poses, n_answers) in got.items():
        reliability_log.record(
            group="security", sensor="zenoh", input=name, expected="gets nothing: no pose, no health answer",
            observed=f"{n_poses} poses, {n_answers} health answers", passed=n_poses == 0 and n_answers == 0,
            crashed=not alive, test="test_mutual_tls")
    reliability_log.record(
        group="security", sensor="zenoh", input="those three clients put odometry on the sensor key",
        expected="never reaches the daemon", observed=f"wheel received {before} -> {after}",
        passed=after == before, crashed=not alive, test="test_mutual_tls")
    assert alive
    for name, (n_poses, n_answers) in got.items():
        assert (n_poses, n_answers) == (0, 0), name
    assert after == before


# --------------------------------------------------------------------------- access control


def daemon_rules(outputs: list[str], sensor_keys: list[str], health: list[str]) -> list[dict]:
    """The ACL rules every fusiond deployment needs: publish its outputs (and let them be subscribed
    to), subscribe to and receive its sensors, answer health queries and liveliness."""
    return [
        {"id": "publish-outputs", "permission": "allow", "flows": ["egress"], "messages": ["put"],
         "key_exprs": outputs},
        {"id": "outputs-subscribers", "permission": "allow", "flows": ["ingress"],
         "messages": ["declare_subscriber"], "key_exprs": outputs},
        {"id": "subscribe-sensors", "permission": "allow", "flows": ["egress"],
         "messages": ["declare_subscriber"], "key_exprs": sensor_keys},
        {"id": "receive-sensors", "permission": "allow", "flows": ["ingress"], "messages": ["put"],
         "key_exprs": sensor_keys},
        {"id": "health", "permission": "allow", "flows": ["ingress", "egress"],
         "messages": ["declare_queryable", "query", "reply", "liveliness_token", "liveliness_query",
                      "declare_liveliness_subscriber"], "key_exprs": health},
    ]


def acl_json5(sensor_keys: list[str]) -> str:
    """fusiond's least privilege: publish only its outputs, subscribe only to its sensors, answer health."""
    outputs = ["odom_combined", "odometry/filtered", "fusiond/**"]
    return json.dumps({
        "access_control": {
            "enabled": True,
            "default_permission": "deny",
            "rules": daemon_rules(outputs, sensor_keys, ["fusiond/**"]),
            "subjects": [{"id": "every-peer"}],
            "policies": [{"rules": ["publish-outputs", "outputs-subscribers", "subscribe-sensors", "receive-sensors",
                                    "health"], "subjects": ["every-peer"]}],
        }
    }, indent=2)


@pytest.mark.e2e
def test_access_control_lets_fusiond_publish_only_its_own_keys(tmp_path, reliability_log):
    port = free_port()
    sensor_keys = [WHEEL_KEY, IMU_KEY]
    config = daemon_config(tmp_path, f"tcp/127.0.0.1:{port}", acl_json5(sensor_keys), "acl")
    cfg = load(config)
    log = tmp_path / "daemon.log"
    sessions: list[zenoh.Session] = []
    with daemon_process(config, log) as proc:
        try:
            operator = open_session(build_config(ZenohConfig(mode="peer", connect=[f"tcp/127.0.0.1:{port}"],
                                                             multicast_scouting=False)))
            sessions.append(operator)
            everything: list[str] = []
            for key in ("odom_combined", "odometry/filtered", "fusiond/**"):
                operator.declare_subscriber(key, lambda s: everything.append(str(s.key_expr)))
            poses = Poses(operator)
            wait_until(lambda: proc.poll() is None and answers(operator, 0.5), 30, "a health answer with ACL on")
            pub, imu = operator.declare_publisher(WHEEL_KEY), operator.declare_publisher(IMU_KEY)
            for k in range(30):
                stamp = 1000.0 + 0.02 * k
                imu.put(imu_payload(stamp - 0.005))
                pub.put(odom_payload(stamp))
                time.sleep(0.02)
            wait_until(lambda: len(poses) >= 30, 10, "poses with ACL on")
            daemon_keys = sorted(set(everything))

            # A session with the daemon's own Zenoh config (same JSON5, so the same ACL) tries what
            # fusiond never does: publish on a foreign key, subscribe to a foreign key.
            port2 = free_port()
            as_daemon = open_session(build_config(cfg.zenoh, base_dir=tmp_path,
                                                  listen=[f"tcp/127.0.0.1:{port2}"]))
            sessions.append(as_daemon)
            peer = open_session(build_config(ZenohConfig(mode="peer", connect=[f"tcp/127.0.0.1:{port2}"],
                                                         multicast_scouting=False)))
            sessions.append(peer)
            at_peer: list[str] = []
            at_daemon: list[str] = []
            for key in ("odom_combined", "cmd_vel"):  # (a `**` subscription is not an allowed declaration)
                peer.declare_subscriber(key, lambda s: at_peer.append(f"{s.key_expr}:{s.payload.to_bytes().decode()}"))
            as_daemon.declare_subscriber("cmd_vel", lambda s: at_daemon.append(s.payload.to_bytes().decode()))
            witness: list[bytes] = []  # an allowed key, received by the daemon-config session
            as_daemon.declare_subscriber(WHEEL_KEY, lambda s: witness.append(s.payload.to_bytes()))

            def probe() -> bool:  # polled until the allowed key arrives: declarations have propagated
                as_daemon.put("cmd_vel", b"from-daemon")
                as_daemon.put("odom_combined", b"from-daemon")
                peer.put("cmd_vel", b"from-peer")
                return "odom_combined:from-daemon" in at_peer

            wait_until(probe, 10, "the allowed key at the peer", step=0.1)
            # cmd_vel from the daemon-config session was put before odom_combined on the same link,
            # so it would have arrived first. For the other direction, the peer puts cmd_vel and then
            # an allowed key on the same link: once that arrives, a permitted cmd_vel would have too.
            def witnessed() -> bool:
                peer.put("cmd_vel", b"from-peer")
                peer.put(WHEEL_KEY, b"witness")
                return bool(witness)

            wait_until(witnessed, 10, "the peer's allowed put at the daemon-config session", step=0.1)
        finally:
            for s in sessions:
                s.close()
        alive = proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    allowed = {"odom_combined", "odometry/filtered", "fusiond/diagnostics"}
    reliability_log.record(
        group="security", sensor="zenoh", input="access_control: default deny; fusiond may put only "
                                                "odom_combined, odometry/filtered, fusiond/**",
        expected="the daemon works: sensors in, pose/odometry/diagnostics out, health answers",
        observed=f"{len(poses)} poses; keys received from it: {', '.join(daemon_keys)}; health answered",
        passed=set(daemon_keys) == allowed and len(poses) >= 30, crashed=not alive,
        test="test_access_control")
    reliability_log.record(
        group="security", sensor="zenoh", input="a session with the daemon's Zenoh config puts on cmd_vel "
                                                "and subscribes to cmd_vel",
        expected="denied: the put never leaves, the subscription never receives",
        observed=(f"the peer received {sorted(set(k for k in at_peer if k.endswith('from-daemon')))}; the "
                  f"daemon-config session's cmd_vel subscription received {at_daemon.count('from-peer')} of the "
                  f"peer's puts"),
        passed="cmd_vel:from-daemon" not in at_peer and "from-peer" not in at_daemon, crashed=not alive,
        test="test_access_control")
    assert alive and len(poses) >= 30
    assert set(daemon_keys) == allowed, daemon_keys
    assert "cmd_vel:from-daemon" not in at_peer and "odom_combined:from-daemon" in at_peer
    assert "from-peer" not in at_daemon


# --------------------------------------------------------------------------- set_pose for the operator only


def set_pose_acl_json5(pki: Path, sensor_keys: list[str]) -> str:
    """Mutual TLS, and an ACL in which only the certificate with CN "operator" may call set_pose."""
    tls = json.loads(json.dumps({"root_ca_certificate": str(pki / "ca.pem"),
                                 "listen_private_key": str(pki / "fusiond.key"),
                                 "listen_certificate": str(pki / "fusiond.pem"), "enable_mtls": True}))
    outputs = ["odom_combined", "odometry/filtered", "tf", "diagnostics", "fusiond/diagnostics"]
    health = ["fusiond/health", "fusiond/health/**"]
    return json.dumps({
        "transport": {"link": {"tls": tls}},
        "access_control": {
            "enabled": True,
            "default_permission": "deny",
            "rules": [
                *daemon_rules(outputs, sensor_keys, health),
                {"id": "set-pose", "permission": "allow", "flows": ["ingress", "egress"],
                 "messages": ["declare_queryable", "query", "reply"], "key_exprs": ["fusiond/set_pose"]},
            ],
            "subjects": [{"id": "every-peer"}, {"id": "operator", "cert_common_names": ["operator"]}],
            "policies": [
                {"rules": ["publish-outputs", "outputs-subscribers", "subscribe-sensors", "receive-sensors", "health"],
                 "subjects": ["every-peer"]},
                {"rules": ["set-pose"], "subjects": ["operator"]},
            ],
        },
    }, indent=2)


def tls_tool_config(tmp_path: Path, pki: Path, port: int, cert: str) -> Path:
    """A client tool's TOML (fusiond set-pose / health) dialling the daemon with a client certificate."""
    (tmp_path / f"{cert}.json5").write_text(json.dumps({"transport": {"link": {"tls": {
        "root_ca_certificate": str(pki / "ca.pem"), "connect_private_key": str(pki / f"{cert}.key"),
        "connect_certificate": str(pki / f"{cert}.pem"), "enable_mtls": True}}}}))
    path = tmp_path / f"{cert}.toml"
    path.write_text(f'[zenoh]\nmode = "peer"\nconnect = ["tls/127.0.0.1:{port}"]\nmulticast_scouting = false\n'
                    f'config_file = "{cert}.json5"\n')
    return path


@needs_openssl
@pytest.mark.e2e
def test_only_the_operator_identity_may_set_the_pose(pki, tmp_path, reliability_log):
    """The ACL of docs/SECURITY.md: a session whose certificate is not the operator's cannot reset the
    filter (its query never reaches the daemon); the operator's `fusiond set-pose` does."""
    port = free_port()
    config = daemon_config(tmp_path, f"tls/127.0.0.1:{port}", set_pose_acl_json5(pki, [WHEEL_KEY, IMU_KEY]),
                           "setpose")
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc:
        viewer = tls_client(pki, port, "viewer")
        try:
            wait_until(lambda: proc.poll() is None and answers(viewer, 0.5), 30, "a health answer for the viewer")
            poses = Poses(viewer)
            pub = viewer.declare_publisher(WHEEL_KEY)
            for k in range(20):
                pub.put(odom_payload(1000.0 + 0.02 * k))
            wait_until(lambda: len(poses) >= 20, 10, "20 poses")
            last = 1000.0 + 0.02 * 19
            before = wait_until(lambda: (h := json.loads(answers(viewer)[0]))["filter"]["time"] == last and h, 10,
                                "health at the last stamp")

            # the viewer (trusted certificate, other identity) asks, directly and through the CLI
            from fusiond.transport.session import request_set_pose

            request = json.dumps({"stamp": 0, "position": [9.0, 9.0, 0.0], "orientation": [0, 0, 0, 1]}).encode()
            viewer_ok, viewer_err = request_set_pose(viewer, "fusiond/set_pose", request, 2.0)
            cli_viewer = subprocess.run(fusiond_cmd("set-pose", "9", "9", "--config",
                                                    str(tls_tool_config(tmp_path, pki, port, "viewer"))),
                                        cwd=ROOT, capture_output=True, text=True, timeout=60)
            after_denied = json.loads(answers(viewer)[0])
            pub.put(odom_payload(1000.0 + 0.02 * 20))
            wait_until(lambda: len(poses) >= 21, 10, "the next pose")
            x_after_denied = poses.items[-1][2][0]

            # the operator's certificate is allowed
            cli_operator = subprocess.run(fusiond_cmd("set-pose", "9", "9", "0.5", "--config",
                                                      str(tls_tool_config(tmp_path, pki, port, "operator"))),
                                          cwd=ROOT, capture_output=True, text=True, timeout=60)
            wait_until(lambda: any(x[0] == 9.0 and x[1] == 9.0 for _, _, x, _ in poses.items), 10,
                       "the pose at (9, 9)")
        finally:
            viewer.close()
        alive = proc.poll() is None
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    # A circle at 0.5 m/s from the origin: after 0.4 s, x = sin(0.2 * 0.4) / 0.2 * 0.5 = 0.1999 m, nowhere near 9.
    denied = (not viewer_ok and not viewer_err and cli_viewer.returncode == 1
              and after_denied["filter"]["time"] == before["filter"]["time"] and x_after_denied < 1.0)
    reliability_log.record(
        group="security", sensor="set_pose", input="ACL: set_pose allowed to cert CN 'operator' only; a trusted "
                                                   "'viewer' certificate sends set_pose (query and CLI)",
        expected="no answer, filter unchanged",
        observed=f"answers {len(viewer_ok)}, errors {len(viewer_err)}, CLI exit {cli_viewer.returncode}, "
                 f"x after {x_after_denied:.4f}",
        passed=denied, crashed=not alive, test="test_only_the_operator_identity_may_set_the_pose")
    reliability_log.record(
        group="security", sensor="set_pose", input="the operator's certificate: fusiond set-pose 9 9 0.5",
        expected="applied, health answered", observed=f"CLI exit {cli_operator.returncode}",
        passed=cli_operator.returncode == 0, crashed=not alive,
        test="test_only_the_operator_identity_may_set_the_pose")
    assert alive
    assert viewer_ok == [] and viewer_err == []
    assert cli_viewer.returncode == 1 and "no daemon answered" in cli_viewer.stderr, cli_viewer.stderr
    assert after_denied["filter"]["time"] == before["filter"]["time"] and x_after_denied < 1.0
    assert cli_operator.returncode == 0, cli_operator.stderr
    # its answer is the new health: the filter re-initialised at its current time (stamp 0), the
    # last odometry's 1000.40; the sensors have been quiet since, so the status itself is whatever it is
    answer = json.loads(cli_operator.stdout.splitlines()[0])
    assert answer["filter"]["time"] == pytest.approx(1000.0 + 0.02 * 20, abs=1e-9) and "wheel" in answer["sensors"]
