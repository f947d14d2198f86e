"""`[metrics] listen`: the daemon's /metrics, scraped and read with prometheus-client's own parser, says
what its health answer says at the same moment; the deploy/ alert rules and dashboard use only families
the daemon exports; `fusiond play` into a daemon that died says so and fails."""

from __future__ import annotations

import json
import re
import signal
import subprocess
import time
import urllib.request
from pathlib import Path

import pytest
import yaml
from prometheus_client.parser import text_string_to_metric_families

from tests.support.daemon import (ROOT, client_session, daemon_process, free_port, fusiond_cmd, log_events,
                                  wait_daemon_ready, wait_until, write_config)
from tests.support.reliability import IMU_KEY, WHEEL_KEY, imu_payload, odom_payload

pytestmark = pytest.mark.e2e


def _scrape(port: int) -> dict[tuple[str, tuple], float]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=5) as r:
        assert r.status == 200 and r.headers["Content-Type"].startswith("text/plain")
        text = r.read().decode()
    out = {}
    for fam in text_string_to_metric_families(text):
        for s in fam.samples:
            out[(s.name, tuple(sorted(s.labels.items())))] = s.value
    return out


def _health(session, key: str = "robot7/fusiond/health") -> dict:
    replies = [json.loads(r.ok.payload.to_bytes()) for r in session.get(key, timeout=2.0) if r.ok is not None]
    assert len(replies) == 1, replies
    return replies[0]


def _answers(session, key: str = "robot7/fusiond/health") -> list:
    return [r for r in session.get(key, timeout=0.5) if r.ok is not None]


def _counts(h: dict) -> tuple:
    return h["published"], {n: (s["received"], s["applied"], s["dropped"], s["rejected"])
                            for n, s in h["sensors"].items()}


def _metrics_config(tmp_path: Path, port: int, metrics_port: int) -> Path:
    config = write_config(tmp_path / "robot7.toml", port)
    text = config.read_text().replace('multicast_scouting = false\n', 'multicast_scouting = false\nnamespace = "robot7"\n',
                                      1)
    config.write_text(text.replace("\n\n", f'\n\n[metrics]\nlisten = "127.0.0.1:{metrics_port}"\n\n', 1))
    return config


def test_the_metrics_say_what_the_health_answer_says(tmp_path):
    port, metrics_port = free_port(), free_port()
    config = _metrics_config(tmp_path, port, metrics_port)
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        wait_until(lambda: proc.poll() is not None or _answers(session), 30, "the daemon's health")
        assert proc.poll() is None, log.read_text()
        odom = session.declare_publisher(f"robot7/{WHEEL_KEY}")  # its namespace is on the wire
        imu = session.declare_publisher(f"robot7/{IMU_KEY}")
        for k in range(300):  # 3 s of a robot at 100 Hz IMU, 50 Hz odometry; one garbage payload
            stamp = 1000.0 + 0.01 * k
            imu.put(imu_payload(stamp))
            if k % 2 == 0:
                odom.put(odom_payload(stamp))
            time.sleep(0.01)
        odom.put(b"\x00\x01 not cdr")
        wait_until(lambda: _health(session)["sensors"]["wheel"]["dropped"] >= 1, 10, "the garbage counted")
        # the same moment: the input stopped and the counts settled, so a scrape and a query see the same
        last: list = [None]

        def settled() -> bool:
            now = _counts(_health(session))
            same = now == last[0]
            last[0] = now
            return same

        wait_until(settled, 10, "the counts to settle", step=0.3)
        m = _scrape(metrics_port)
        h = _health(session)

    def v(name, **labels):
        return m[(name, tuple(sorted({"namespace": "robot7", **labels}.items())))]

    assert h["namespace"] == "robot7" and h["published"] > 100
    assert v("fusiond_poses_published_total") == h["published"]
    assert v("fusiond_daemon_info", zid=h["zid"]) == 1.0
    assert v("fusiond_status", status=h["status"]) == 1.0
    assert sum(v("fusiond_status", status=s) for s in ("ok", "starting", "degraded", "failed")) == 1.0
    for name, s in h["sensors"].items():
        assert v("fusiond_sensor_received_total", sensor=name) == s["received"]
        assert v("fusiond_sensor_applied_total", sensor=name) == s["applied"]
        assert v("fusiond_sensor_rejected_total", sensor=name) == s["rejected"]
        assert v("fusiond_sensor_alive", sensor=name) == float(s["alive"])
        assert v("fusiond_sensor_rate_hz", sensor=name) == pytest.approx(s["rate_hz"])
        assert v("fusiond_sensor_age_seconds", sensor=name) == pytest.approx(s["age_s"], abs=0.5)
        for reason, n in s["dropped_by_reason"].items():
            assert v("fusiond_sensor_dropped_total", sensor=name, reason=reason) == n
    assert sum(n for (k, _), n in m.items() if k == "fusiond_sensor_dropped_total") >= 1
    for key, c in h["consistency"].items():
        sensor, channel = key.split("/", 1)
        if c["nis_mean"] is not None:
            assert v("fusiond_nis_window_mean", sensor=sensor, channel=channel) == pytest.approx(c["nis_mean"])
        if c["nis_bounds"]:
            assert v("fusiond_nis_upper_bound", sensor=sensor, channel=channel) == pytest.approx(c["nis_bounds"][1])
        assert v("fusiond_nis_out_of_bounds", sensor=sensor, channel=channel, verdict=c["verdict"]) == \
            float(c["verdict"] in ("nis_high", "nis_low"))
        assert v("fusiond_nis_rejected_share", sensor=sensor, channel=channel) == pytest.approx(c["rejected_share"])
    assert h["consistency"], "no NIS channel to compare"
    assert v("fusiond_filter_finite") == float(h["filter"]["finite"])
    assert v("fusiond_filter_heading_known") == float(h["filter"]["heading_known"])
    pose = h["pose"]
    assert v("fusiond_pose_stamp_seconds") == pose["stamp"]
    assert [v("fusiond_pose_position_meters", axis=a) for a in "xyz"] == pytest.approx(pose["position"])
    assert v("fusiond_pose_yaw_radians") == pytest.approx(pose["yaw"])
    assert v("fusiond_pose_sigma_xy_meters") == pytest.approx(pose["sigma_xy"])
    assert v("fusiond_pose_sigma_z_meters") == pytest.approx(pose["sigma_z"])
    assert v("fusiond_pose_sigma_yaw_radians") == pytest.approx(pose["sigma_yaw"])
    assert v("fusiond_zenoh_link_up") == float(h["link"] == "connected") == 1.0
    assert v("fusiond_zenoh_reconnections_total") == h["link_stats"]["reconnections"]
    assert all(k.startswith("fusiond_") and dict(labels).get("namespace") == "robot7" for k, labels in m)
    events = log_events(log)
    assert any(e["event"] == "metrics_listening" and str(metrics_port) in e["url"] for e in events)


def test_metrics_are_off_by_default_and_an_address_in_use_fails_the_start(tmp_path):
    port = free_port()
    config = write_config(tmp_path / "plain.toml", port)
    log = tmp_path / "plain.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log)
        assert not any(e["event"] == "metrics_listening" for e in log_events(log))
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    import socket

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        busy = _metrics_config(tmp_path, free_port(), taken.getsockname()[1])
        out = subprocess.run(fusiond_cmd("run", "--config", str(busy)), cwd=ROOT, capture_output=True, text=True,
                             timeout=60)
    assert out.returncode == 1 and "metrics.listen" in out.stderr, out.stderr


def test_the_alert_rules_and_the_dashboard_use_only_exported_families():
    """Every fusiond_* name in deploy/'s rules and dashboard is one the daemon exports (``families``)."""
    from fusiond.health import FilterHealth, HealthReport, QueueHealth, SensorHealth
    from fusiond.transport.answer import answer
    from fusiond.transport.link import LinkHealth
    from fusiond.transport.metrics import families

    rep = HealthReport(status="ok", sensors={"imu": SensorHealth(alive=True, age_s=0.1, rate_hz=100.0, received=9,
                                                                  dropped=1, rejected=0,
                                                                  dropped_by_reason={"too_old": 1})},
                       problems=[], filter=FilterHealth(time=1.0), queue=QueueHealth(),
                       consistency={"imu/orientation": {"nis_mean": 2.0, "nis_bounds": [1.0, 3.0], "verdict": "ok",
                                                        "updates": 60}})
    exported = set()
    for fam in families(answer(rep, "r", "z", LinkHealth(state="connected", routers=1, peers=0))):
        exported.add(fam.name)
        exported.update(s.name for s in fam.samples)
    rules = yaml.safe_load((ROOT / "deploy" / "prometheus-alerts.yml").read_text())
    exprs = [r["expr"] for g in rules["groups"] for r in g["rules"]]
    names = {r["alert"] for g in rules["groups"] for r in g["rules"]}
    assert {"FusiondLost", "FusiondSensorDead", "FusiondNisOutOfBounds", "FusiondZenohLinkDown"} <= names
    dashboard = json.loads((ROOT / "deploy" / "grafana-dashboard.json").read_text())
    targets = [t["expr"] for p in dashboard["panels"] for t in p.get("targets", [])]
    assert targets
    used = {n for e in exprs + targets for n in re.findall(r"\bfusiond_[a-z_]+", e)}
    assert used and used <= exported, used - exported


def test_play_into_a_daemon_that_died_says_so_and_fails(jackal_bag, tmp_path):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log)
        play = subprocess.Popen(fusiond_cmd("play", str(jackal_bag), "--config", str(config), "--rate", "1",
                                            "--duration", "6"), cwd=ROOT, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        try:
            wait_until(lambda: (_h := [json.loads(r.ok.payload.to_bytes()) for r in
                                       session.get("fusiond/health", timeout=0.5) if r.ok is not None])
                       and _h[0]["published"] > 0, 20, "the daemon to publish what play sends")
            proc.send_signal(signal.SIGKILL)
            out, err = play.communicate(timeout=60)
        finally:
            if play.poll() is None:
                play.kill()
                play.wait(5)
    assert play.returncode == 1, (out, err)
    assert "stopped answering" in err and "liveliness token went" in err, err
