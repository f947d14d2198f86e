"""The health answer carries the latest pose, says honestly whether the heading is known, and `fusiond
set-pose` answers with the pose it set: through the real `fusiond run` on loopback Zenoh and the real CLI."""

from __future__ import annotations

import json
import math
import subprocess

import pytest

from fusiond.codecs import decode_pose_cdr
from fusiond.config import load
from fusiond.estimator.rotation import yaw as yaw_of
from fusiond.replay.bag import open_bag_samples
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample
from tests.support.daemon import (
    ROOT, client_session, daemon_process, free_port, fusiond_cmd, health, sensor_publishers, wait_daemon_ready,
    wait_until, write_config,
)

pytestmark = pytest.mark.e2e

GPS = """
[[sensors]]
name = "gps"
kind = "gps"
key = "gps/fix"
"""


def test_health_carries_the_latest_published_pose_and_set_pose_answers_with_the_pose_it_set(jackal_bag, tmp_path):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    cfg = load(config)
    log = tmp_path / "daemon.log"
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        messages = [m for m in bag.raw_cdr()][:600]  # ~6 s of the bag
    with daemon_process(config, log) as proc, client_session(port) as session:
        poses: list[bytes] = []
        sub = session.declare_subscriber("odom_combined", lambda s: poses.append(s.payload.to_bytes()))
        first = wait_daemon_ready(session, proc, log)
        assert first["pose"] is None  # nothing fused yet: no pose to show
        assert first["filter"]["heading_known"] is True  # no GPS: the odom frame's heading is known by definition
        pubs = sensor_publishers(session, cfg)
        for _, sensor, raw in messages:
            pubs[sensor.name].put(raw)
        n_wheel = sum(s.name == "wheel" for _, s, _ in messages)
        wait_until(lambda: len(poses) >= n_wheel, 15, "a pose per odometry message")
        last = decode_pose_cdr(poses[-1])
        stamp = last.header.stamp.sec + last.header.stamp.nanosec * 1e-9
        h = wait_until(lambda: (h := health(session)) and h["pose"] and h["pose"]["stamp"] == pytest.approx(stamp)
                       and h, 5, "health to show the last published pose")
        p = h["pose"]
        position = last.pose.pose.position
        assert p["position"] == pytest.approx([position.x, position.y, position.z], abs=1e-9)
        q = last.pose.pose.orientation
        assert p["yaw"] == pytest.approx(yaw_of((q.x, q.y, q.z, q.w)), abs=1e-9)
        assert p["frame_id"] == "odom"
        cov = last.pose.covariance
        assert p["sigma_yaw"] == pytest.approx(math.sqrt(cov[35]), rel=1e-9)
        assert math.sqrt(max(cov[0], cov[7])) <= p["sigma_xy"] <= math.sqrt(cov[0] + cov[7])

        proc_cli = subprocess.run(fusiond_cmd("set-pose", "3.5", "-2.25", "0.75", "--config", str(config),
                                              "--connect", f"tcp/127.0.0.1:{port}", "--timeout", "5"),
                                  capture_output=True, text=True, timeout=60, cwd=ROOT)
        assert proc_cli.returncode == 0, proc_cli.stderr
        answer = json.loads(proc_cli.stdout)
        assert answer["pose"]["position"] == [3.5, -2.25, 0.0]
        assert answer["pose"]["yaw"] == pytest.approx(0.75, abs=1e-12)
        assert answer["pose"]["stamp"] == pytest.approx(stamp)  # stamp 0: at the filter's time
        sub.undeclare()


def test_with_a_gps_configured_the_heading_is_not_known_before_a_fix(tmp_path):
    port = free_port()
    config = write_config(tmp_path / "gps.toml", port)
    config.write_text(config.read_text() + GPS)
    cfg = load(config)
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        first = wait_daemon_ready(session, proc, log)
        assert first["filter"]["heading_known"] is False and first["pose"] is None
        pubs = sensor_publishers(session, cfg)
        cov = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
        for k in range(50):
            t = 100.0 + 0.02 * k
            pubs["wheel"].put(encode_sample(OdomSample("wheel", t, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), cov),
                                                 "ros2-cdr"))
            pubs["imu"].put(encode_sample(ImuSample("imu", t + 0.01, (0.0, 0.0, 0.0, 1.0), (1e-4, 0, 0, 0, 1e-4, 0,
                                                        0, 0, 1e-4), (0.0, 0.0, 0.0), (1e-6, 0, 0, 0, 1e-6, 0, 0, 0,
                                                                                      1e-6)), "ros2-cdr"))
        h = wait_until(lambda: (h := health(session)) and h["filter"]["initialised"] and h, 10,
                       "the filter to start on odometry and IMU")
        assert h["filter"]["heading_known"] is False  # odometry and IMU, no fix: nothing references the heading
        assert h["pose"] is None  # the world frame waits for the first fix: nothing published, nothing shown
