"""`[state] path`: a restarted `fusiond run` resumes where it stopped (real processes, loopback Zenoh).

The daemon is fed at real-time pace (stamps advance as the wall clock does), so a save interval
in wall time is the same span of stamps: a kill -9 must lose at most about one interval of them.
"""

from __future__ import annotations

import math
import signal
import time
from pathlib import Path

import pytest
import zenoh

from fusiond.codecs import decode_pose_cdr
from fusiond.config import load
from fusiond.core.resume import state_fingerprint
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample
from fusiond.transport.state_file import load_state

from tests.support.configs import sensor_tables
from tests.support.daemon import client_session, daemon_process, free_port, log_events, wait_daemon_ready, wait_until

pytestmark = pytest.mark.e2e

SAVE_S = 0.5
RATE = 50.0  # Hz of odometry and IMU, stamps at real-time pace
V = 1.0  # m/s straight ahead
TWIST_COV = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
IMU_COV = (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4)
GYRO_COV = (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)
# What the worker's loop adds to the save interval: it looks at the timer between passes, at least
# every 0.1 s (CORE_REFRESH_S), and the saver thread's write (an fsync) follows.
SAVE_SLACK_S = 0.15
SENSORS = sensor_tables('orientation = "roll_pitch"\nangular_velocity = true', imu_key="imu/data")


def write_config(path: Path, port: int, state: Path, max_age_s: float = 60.0) -> Path:
    path.write_text(f"""
[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false

[state]
path = "{state.name}"
save_interval_s = {SAVE_S}
max_age_s = {max_age_s}

{SENSORS}
""")
    return path


class Feed:
    """Odometry + IMU at RATE with stamps that keep the wall clock's pace; poses collected."""

    def __init__(self, session: zenoh.Session) -> None:
        self.poses: list[tuple[float, float]] = []  # (stamp, x)
        self.sub = session.declare_subscriber("odom_combined", self._on_pose)
        block = zenoh.CongestionControl.BLOCK
        self.odom = session.declare_publisher("odom", congestion_control=block)
        self.imu = session.declare_publisher("imu/data", congestion_control=block)
        self.last_stamp = 0.0

    def _on_pose(self, sample: zenoh.Sample) -> None:
        p = decode_pose_cdr(sample.payload.to_bytes())
        self.poses.append((p.header.stamp.sec + p.header.stamp.nanosec * 1e-9, p.pose.pose.position.x))

    def run(self, t0: float, seconds: float, v: float = V) -> float:
        """Publish for ``seconds`` of wall time from stamp ``t0``; returns the last stamp sent."""
        start = time.monotonic()
        k = 0
        while True:
            due = start + k / RATE
            if due - start > seconds:
                break
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)  # pacing the publisher, not waiting for a result
            stamp = t0 + k / RATE
            self.imu.put(encode_sample(ImuSample("imu", stamp - 0.003, (0.0, 0.0, 0.0, 1.0), IMU_COV,
                                                     (0.0, 0.0, 0.0), GYRO_COV), "ros2-cdr"))
            self.odom.put(encode_sample(OdomSample("wheel", stamp, (v, 0.0, 0.0), (0.0, 0.0, 0.0), TWIST_COV),
                                             "ros2-cdr"))
            self.last_stamp = stamp
            k += 1
        return self.last_stamp

    def pose_at(self, stamp: float) -> float | None:
        for st, x in reversed(self.poses):
            if st == stamp:
                return x
        return None


def test_a_restart_resumes_the_saved_pose_and_kill_9_loses_at_most_one_interval(tmp_path):
    port = free_port()
    state = tmp_path / "fusiond.state"
    config = write_config(tmp_path / "robot.toml", port, state)
    cfg = load(config)
    fingerprint = state_fingerprint(cfg)
    log1, log2 = tmp_path / "first.log", tmp_path / "second.log"

    # -- first run: no file yet, 3 s of driving, the file appears; SIGTERM writes the last state
    with daemon_process(config, log1) as proc, client_session(port) as session:
        feed = Feed(session)
        wait_daemon_ready(session, proc, log1)
        last = feed.run(1000.0, 3.0)
        x_last = wait_until(lambda: feed.pose_at(last), 10, "the pose of the last odometry")
        assert x_last == pytest.approx(V * (last - 1000.0), abs=0.2)
        wait_until(state.exists, 5, "the state file")
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    events = [e for e in log_events(log1) if e["event"].startswith("state_")]
    assert events[0]["event"] == "state_resume_refused" and events[0]["reason"] == "missing"
    saved = load_state(state, fingerprint, 60.0, time.time()).state
    assert saved.stamp == last  # a clean stop saves the state after the last sample
    assert saved.x[0] == pytest.approx(x_last, abs=1e-9)

    # -- second run: resumes there; fed on (at rest first), the pose starts at the saved one
    with daemon_process(config, log2) as proc, client_session(port) as session:
        feed = Feed(session)
        wait_daemon_ready(session, proc, log2)
        resumed = [e for e in log_events(log2) if e["event"] in ("state_resumed", "state_resume_refused")]
        assert [e["event"] for e in resumed] == ["state_resumed"], resumed
        t1 = last + 2.0
        feed.run(t1, 0.2, v=0.0)
        first = wait_until(lambda: feed.poses and feed.poses[0], 10, "a pose after the restart")
        # where it stopped, not the origin, carried on by the twist held there as across a logging gap
        # (core/resume.py): through filter.gap_s, 0.5 s (longer than its timeout_s and 3 periods at 50 Hz)
        assert first[1] == pytest.approx(x_last + V * 0.5, abs=0.05)
        assert abs(first[1]) > 2.0
        # drive on, stop feeding, let the last pose arrive, then kill -9 at once
        last2 = feed.run(t1 + 0.22, 2.5)
        x2 = wait_until(lambda: feed.pose_at(last2), 10, "the pose of the last odometry")
        proc.kill()
        proc.wait(5)
    assert x2 == pytest.approx(first[1] + V * (last2 - t1 - 0.22), abs=0.3)  # on from the resumed pose
    killed = load_state(state, fingerprint, 60.0, time.time()).state
    lost = last2 - killed.stamp
    assert 0.0 <= lost <= SAVE_S + SAVE_SLACK_S, f"the file is {lost:.3f} s of stamps behind the last input"
    assert math.isfinite(killed.x[0]) and killed.x[0] > x_last

    # -- third run, the file now older than max_age_s: started fresh, and the log says why
    log3 = tmp_path / "third.log"
    write_config(config, port, state, max_age_s=0.0)
    with daemon_process(config, log3) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log3)
        events = [e for e in log_events(log3) if e["event"] in ("state_resumed", "state_resume_refused")]
        assert [(e["event"], e["reason"]) for e in events] == [("state_resume_refused", "stale")]


def test_a_daemon_stopped_after_idling_does_not_pass_its_old_state_off_as_fresh(tmp_path):
    """Fed for a second, idle for 2.5 s (the robot may be carried off meanwhile), then stopped cleanly: the
    state written at the stop is as old as its newest sample, so a restart with max_age_s = 2 s refuses it
    as stale instead of resuming a pose 2.5 s out of date."""
    port = free_port()
    state = tmp_path / "fusiond.state"
    config = write_config(tmp_path / "robot.toml", port, state, max_age_s=2.0)
    log1, log2 = tmp_path / "first.log", tmp_path / "second.log"
    with daemon_process(config, log1) as proc, client_session(port) as session:
        feed = Feed(session)
        wait_daemon_ready(session, proc, log1)
        last = feed.run(1000.0, 1.0)
        wait_until(lambda: feed.pose_at(last), 10, "the pose of the last odometry")
        idle_until = time.monotonic() + 2.5
        while time.monotonic() < idle_until:
            time.sleep(0.05)  # the robot stands unobserved: no input for 2.5 s
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    with daemon_process(config, log2) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log2)
        events = [e for e in log_events(log2) if e["event"] in ("state_resumed", "state_resume_refused")]
        assert [(e["event"], e["reason"]) for e in events] == [("state_resume_refused", "stale")], events
