"""`fusiond run` (and `play`, `health`) as real processes on real Zenoh sessions over loopback.

The daemon is a subprocess listening on a free loopback port with multicast off;
the test is a Zenoh client of it. Every wait has a deadline and every process is
killed in a `finally`, so nothing can hang CI.
"""

from __future__ import annotations

import json
import math
import re
import signal
import subprocess
import threading
import time

import msgspec
import pytest
import zenoh

from fusiond.config import load
from fusiond.core.fusion import FusionCore
from fusiond.replay.bag import open_bag_samples
from fusiond.replay.run import replay
from fusiond.core.sensors import OdomSample, encode_sample, make_decoder
from fusiond.codecs import decode_odometry_cdr, decode_pose_cdr

from tests.support.daemon import (
    ROOT,
    client_session,
    daemon_process,
    free_port,
    fusiond_cmd,
    health,
    log_events,
    sensor_publishers,
    wait_daemon_ready,
    wait_until,
    write_config,
)

PACE = 10.0  # x real time for the whole-bag test: 61 s of bag in ~6 s


class Collector:
    """Raw payloads on the outputs, appended by Zenoh callbacks."""

    def __init__(self, session: zenoh.Session) -> None:
        self.poses: list[bytes] = []
        self.odometry: list[bytes] = []
        self.diagnostics: list[bytes] = []
        self.subs = [
            session.declare_subscriber("odom_combined", lambda s: self.poses.append(s.payload.to_bytes())),
            session.declare_subscriber("odometry/filtered", lambda s: self.odometry.append(s.payload.to_bytes())),
            session.declare_subscriber("fusiond/diagnostics",
                                       lambda s: self.diagnostics.append(s.payload.to_bytes())),
        ]


class DiagnosticsSchema(msgspec.Struct):
    """The documented diagnostics record (README, "Diagnostics record"; extra fields allowed)."""

    stamp: float
    sensor: str
    components: list[str]
    innovation: list[float]
    innovation_var: list[float]
    nis: float
    dof: int
    rejected: bool


@pytest.mark.e2e
def test_daemon_fuses_the_jackal_bag_over_zenoh_like_replay(jackal_bag, tmp_path):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    cfg = load(config)
    log = tmp_path / "daemon.log"
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        messages = list(bag.raw_cdr())
    last_wheel = max(i for i, (_, s, _) in enumerate(messages) if s.name == "wheel")
    flow, final = messages[:last_wheel], messages[last_wheel]
    sent = {"wheel": sum(s.name == "wheel" for _, s, _ in flow), "imu": sum(s.name == "imu" for _, s, _ in flow)}

    with daemon_process(config, log) as proc, client_session(port) as session:
        # the offline answer, computed while the daemon starts
        tum = tmp_path / "replay.tum"
        replay([jackal_bag], cfg, tum=tum, keep_trace=False, progress=False)
        expected = [float(v) for v in tum.read_text().splitlines()[-1].split()]

        # Subscribe first: the health answer then proves the daemon has seen these declarations
        # (one link, in order), so no early pose is published to nobody.
        out = Collector(session)
        first = wait_daemon_ready(session, proc, log)
        assert first["status"] == "starting" and "starting: waiting for the first samples" in first["problems"]
        # a HEALTHCHECK's probe: a daemon that has published nothing yet is not healthy, though it answers
        for min_status, code in (("degraded", 1), ("starting", 0)):
            probe = subprocess.run(fusiond_cmd("health", "--config", str(config), "--min-status", min_status),
                                   cwd=ROOT, capture_output=True, text=True, timeout=30)
            assert probe.returncode == code and json.loads(probe.stdout)["status"] == "starting", probe
        pubs = sensor_publishers(session, cfg)

        # -- the whole bag (but its last odometry message) at PACE x, health sampled meanwhile
        samples: list[tuple[float, str, list[str]]] = []
        flowing = threading.Event()
        done = threading.Event()

        def poll_health():
            while not done.is_set():
                t = time.monotonic()
                h = health(session, 1.0)
                if h is not None and flowing.is_set() and not done.is_set():
                    samples.append((t, h["status"], h["problems"]))
                done.wait(0.2)

        poller = threading.Thread(target=poll_health, daemon=True)
        poller.start()
        t0_bag = flow[0][0]
        t0 = time.monotonic()
        for bag_ns, sensor, raw in flow:
            delay = t0 + (bag_ns - t0_bag) * 1e-9 / PACE - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            pubs[sensor.name].put(raw)
            if not flowing.is_set() and time.monotonic() - t0 > 0.5:
                flowing.set()
        done.set()
        poller.join(5)
        assert len(samples) >= 10, samples
        assert all(status == "ok" for _, status, _ in samples), [s for s in samples if s[1] != "ok"]

        # -- everything processed, then the last odometry message: its pose must be replay's last TUM line
        last: list[dict] = []

        def drained():
            h = health(session)
            last[:] = [h, len(out.poses)]
            return (h and h["queue"]["depth"] == 0 and h["published"] == len(out.poses)
                    and {k: h["sensors"][k]["received"] for k in sent} == sent
                    and sum(h["sensors"][k]["applied"] + h["sensors"][k]["dropped"] for k in sent) == sum(sent.values())
                    and h)

        try:
            h = wait_until(drained, 15, "the daemon to process the bag", step=0.1)
        except AssertionError:
            raise AssertionError(f"not drained: sent {sent}, last health/poses {last}") from None
        for name in sent:
            assert h["sensors"][name]["dropped"] == 0, h["sensors"][name]
        assert h["queue"]["dropped"] == 0
        n_poses = len(out.poses)
        pubs["wheel"].put(final[2])
        wait_until(lambda: len(out.poses) > n_poses, 5, "the final pose")
        pose = decode_pose_cdr(out.poses[-1])
        p = pose.pose.pose.position
        stamp = pose.header.stamp.sec + pose.header.stamp.nanosec * 1e-9
        assert stamp == pytest.approx(expected[0], abs=1e-9)
        assert math.dist((p.x, p.y, p.z), expected[1:4]) < 1e-6, ((p.x, p.y, p.z), expected)
        q = pose.pose.pose.orientation
        assert max(abs(a - b) for a, b in zip((q.x, q.y, q.z, q.w), expected[4:8])) < 1e-6
        assert pose.header.frame_id == "odom"

        # one decodable PoseWithCovarianceStamped (and Odometry) per odometry message
        wheel_total = sent["wheel"] + 1
        wait_until(lambda: len(out.odometry) >= len(out.poses), 2, "odometry outputs")
        good = 0
        for raw in out.poses:
            msg = decode_pose_cdr(raw)
            good += len(msg.pose.covariance) == 36 and all(map(math.isfinite, msg.pose.covariance))
        assert good >= 0.99 * wheel_total, (good, wheel_total)
        odo = decode_odometry_cdr(out.odometry[-1])
        assert (odo.header.frame_id, odo.child_frame_id) == ("odom", "base_link")
        assert (odo.pose.pose.position.x, odo.pose.pose.position.y) == (p.x, p.y)
        assert len(out.odometry) >= 0.99 * wheel_total

        # diagnostics: JSON records of the schema, one per update, in batches (a JSON array per put)
        def decoded() -> list:
            return [msgspec.json.decode(raw, type=DiagnosticsSchema | list[DiagnosticsSchema])
                    for raw in list(out.diagnostics)]

        # at least one orientation record per IMU message (the last batch follows within diagnostics_batch_s)
        batches = wait_until(lambda: (b := decoded()) and sum(map(len, b)) >= sent["imu"] and b, 5,
                             "a diagnostics record per IMU message")
        assert all(isinstance(b, list) for b in batches)  # config default: diagnostics_batch_s = 0.05
        records = [r for b in batches for r in b]
        for r in records:
            assert r.sensor in ("wheel", "imu")
            assert len(r.components) == len(r.innovation) == len(r.innovation_var) == r.dof >= 1
        assert {r.sensor for r in records} == {"wheel", "imu"}

        # -- both flowing again (stamps go on from the bag's end), then the IMU stops
        dec_w = make_decoder("odom", "ros2-cdr", "wheel")
        dec_i = make_decoder("imu", "ros2-cdr", "imu")
        w = dec_w(final[2])
        i = dec_i(next(raw for _, s, raw in reversed(messages) if s.name == "imu"))
        t_base = max(w.stamp, i.stamp)
        ok_seen = False
        imu_stopped_at = None
        degraded = None
        for k in range(1, 200):
            w = OdomSample("wheel", t_base + 0.02 * k, w.linear, w.angular, w.twist_covariance)
            pubs["wheel"].put(encode_sample(w, "ros2-cdr"))
            if imu_stopped_at is None:
                i = msgspec.structs.replace(i, stamp=t_base + 0.02 * k + 0.01)
                pubs["imu"].put(encode_sample(i, "ros2-cdr"))
            if k == 30:
                ok_seen = health(session)["status"] == "ok"
                imu_stopped_at = time.monotonic()
            if imu_stopped_at is not None:
                h = health(session, 0.5)
                if h["status"] == "degraded":
                    degraded = (time.monotonic() - imu_stopped_at, h)
                    break
            time.sleep(0.02)
        assert ok_seen
        assert degraded is not None, "never degraded after the IMU stopped"
        elapsed, h = degraded
        # silent after the timeout in force: 0.2 s for an even 50 Hz stream, longer only by this loop's own stalls
        # (1.5 x the longest recent interval, core.inputs), plus the health's publishing latency
        timeout = h["sensors"]["imu"]["timeout_s"]
        assert timeout < 1.0 and elapsed <= max(0.5, timeout + 0.3), (elapsed, timeout)
        assert h["sensors"]["imu"]["alive"] is False and h["sensors"]["wheel"]["alive"] is True
        assert any(p.startswith("imu:") for p in h["problems"])

        # -- SIGTERM: clean stop, exit 0
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    events = log_events(log)
    names = [e["event"] for e in events]
    assert names[-1] == "daemon_stopped" and "daemon_started" in names and "sensor_subscribed" in names
    assert "health_changed" in names
    stopped = events[-1]
    assert stopped["sensors"]["wheel"]["received"] >= wheel_total


@pytest.mark.e2e
def test_play_speaks_rmw_zenoh_to_a_daemon_that_does(jackal_bag, tmp_path):
    """With `[ros] interop = "rmw_zenoh"` the daemon subscribes on rmw_zenoh's keys and drops a sample without its
    attachment: `play` of the same config publishes as an rmw_zenoh node (it published on the bridge's keys, and
    not one sample was fused). Every sample it sends is received."""
    port = free_port()
    config = write_config(tmp_path / "rmw.toml", port)
    config.write_text(config.read_text() + '\n[ros]\ninterop = "rmw_zenoh"\n')
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log)
        play = subprocess.run(fusiond_cmd("play", str(jackal_bag), "--config", str(config), "--rate", "4",
                                          "--duration", "4"), cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert play.returncode == 0, play.stderr
        m = re.search(r"played (\d+) messages \(wheel=(\d+) imu=(\d+)\)", play.stdout)
        assert m and int(m.group(2)) > 0, play.stdout
        sent = {"wheel": int(m.group(2)), "imu": int(m.group(3))}
        h = wait_until(lambda: (lambda h: h if h and all(h["sensors"][n]["received"] >= k for n, k in sent.items())
                                else None)(health(session)), 30, "every played sample received")
        assert {n: h["sensors"][n]["received"] for n in sent} == sent


@pytest.mark.e2e
def test_play_feeds_run_like_the_bridge_would(jackal_bag, tmp_path):
    """`fusiond play` and `fusiond run` as two processes: the first 10 s of the bag at 4x."""
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    cfg = load(config)
    log = tmp_path / "daemon.log"
    duration, rate = 10.0, 4.0
    # what play sends: the configured topics up to 10 s of bag time, in bag order
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        rows = list(bag.raw_cdr())
    rows = [(s.name, raw) for t, s, raw in rows if (t - rows[0][0]) * 1e-9 <= duration]
    core = FusionCore(cfg)
    decoders = {s.name: make_decoder("odom" if s.name == "wheel" else "imu", "ros2-cdr", s.name) for s in cfg.sensors}
    last_pose = None
    for name, raw in rows:
        if core.ingest(decoders[name](raw)).publish:
            last_pose = core.pose()[1][0:3].tolist()
    n_wheel = sum(name == "wheel" for name, _ in rows)

    with daemon_process(config, log) as proc, client_session(port) as session:
        out = Collector(session)
        wait_daemon_ready(session, proc, log)
        t0 = time.monotonic()
        play = subprocess.run(fusiond_cmd("play", str(jackal_bag), "--config", str(config), "--rate", str(rate),
                                          "--duration", str(duration)),
                              cwd=ROOT, capture_output=True, text=True, timeout=60)
        wall = time.monotonic() - t0
        assert play.returncode == 0, play.stderr
        m = re.search(r"played (\d+) messages \(wheel=(\d+) imu=(\d+)\)", play.stdout)
        assert m, play.stdout
        assert int(m.group(1)) == len(rows) and int(m.group(2)) == n_wheel
        assert wall >= duration / rate  # paced by bag time
        assert "play_finished" in play.stderr

        # a deadline, not a speed check: a loaded CI machine may need a while to drain
        h = wait_until(lambda: (lambda h: h if h and h["published"] >= n_wheel else None)(health(session)), 30,
                       "all poses")
        for name in ("wheel", "imu"):
            assert h["sensors"][name]["received"] == sum(n == name for n, _ in rows)
            assert h["sensors"][name]["dropped"] == 0
        wait_until(lambda: len(out.poses) >= n_wheel, 15, "pose messages")
        p = decode_pose_cdr(out.poses[-1]).pose.pose.position
        assert math.dist((p.x, p.y, p.z), last_pose) < 1e-6

        # the health command a HEALTHCHECK runs: connects to the config's listen endpoint
        probe = subprocess.run(fusiond_cmd("health", "--config", str(config), "--min-status", "failed"), cwd=ROOT,
                               capture_output=True, text=True, timeout=30)
        assert probe.returncode == 0, probe.stderr
        assert json.loads(probe.stdout)["sensors"]["wheel"]["received"] == n_wheel
        strict = subprocess.run(fusiond_cmd("health", "--config", str(config), "--min-status", "ok"), cwd=ROOT,
                                capture_output=True, text=True, timeout=30)
        assert strict.returncode == 1  # the bag is over: no sensor alive, status failed

        proc.send_signal(signal.SIGINT)
        assert proc.wait(15) == 0
    assert log_events(log)[-1]["event"] == "daemon_stopped"


@pytest.mark.parametrize("zenoh_toml, needle", [
    ('mode = "mesh"', "zenoh.mode"),
    ('listen = ["nonsense"]', "zenoh.listen: Endpoints must be of the form"),
    ('listen = ["tcp/127.0.0.1:99999"]', "zenoh.listen: a tcp endpoint is tcp/HOST:PORT with a port in 0-65535"),
    ('config_file = "nowhere.json5"', "zenoh.config_file: no such file"),
])
def test_run_with_a_bad_config_exits_2_with_one_line(tmp_path, zenoh_toml, needle):
    config = tmp_path / "bad.toml"
    config.write_text(f"[zenoh]\n{zenoh_toml}\nmulticast_scouting = false\n\n"
                      + (ROOT / "examples" / "jackal.toml").read_text())
    proc = subprocess.run(fusiond_cmd("run", "--config", str(config)), cwd=ROOT, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2
    assert needle in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_health_without_a_daemon_exits_1(tmp_path):
    port = free_port()
    proc = subprocess.run(fusiond_cmd("health", "--connect", f"tcp/127.0.0.1:{port}", "--timeout", "0.5"), cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines()[-1].startswith("fusiond:")


def test_a_listening_daemon_tells_the_tool_that_dials_it_listening_not_disconnected(tmp_path):
    """A peer daemon that only listens, queried by `fusiond health` alone: it dials nothing, so with no session seen
    it reads "listening" ("disconnected" would be said to the very tool it answers); the tool's own session may
    already be among its peers (polled every 0.2 s), "connected" then. Never a loss."""
    port = free_port()
    config = write_config(tmp_path / "fusiond.toml", port)
    with daemon_process(config, tmp_path / "daemon.log"):
        def probe():
            p = subprocess.run(fusiond_cmd("health", "--config", str(config), "--min-status", "failed",
                                           "--timeout", "2"), cwd=ROOT, capture_output=True, text=True, timeout=60)
            return json.loads(p.stdout) if p.returncode == 0 and p.stdout.strip() else None
        answer = wait_until(probe, 60.0, "the daemon's health answer")
    assert answer["link"] in ("listening", "connected") and answer["link_stats"]["losses"] == 0, answer
