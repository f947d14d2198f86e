"""`fusiond monitor` against a daemon in another process, over real Zenoh on loopback."""

from __future__ import annotations

import json
import subprocess
import threading
import time

import pytest

from fusiond.config import load
from fusiond.monitor import DaemonView, prefix_of
from fusiond.core.diagnostics import DiagnosticsRecord
from fusiond.replay.bag import open_bag_samples

from tests.support.daemon import (
    ROOT,
    client_session,
    daemon_process,
    free_port,
    fusiond_cmd,
    sensor_publishers,
    wait_daemon_ready,
    write_config,
)


def test_prefix_of_namespaced_keys():
    assert prefix_of("robot1/fusiond/diagnostics", "fusiond/diagnostics") == "robot1"
    assert prefix_of("fusiond/diagnostics", "fusiond/diagnostics") == ""
    assert prefix_of("fleet/r2/fusiond/health/alive", "fusiond/health/alive") == "fleet/r2"


def test_daemon_view_aggregates_a_channel():
    view = DaemonView("", window=10)
    for k in range(30):
        view.add(DiagnosticsRecord(float(k), "imu", ["roll", "pitch"], [0.01, -0.01], [1e-4, 1e-4], 2.0, 2, k % 10 == 0,
                                   channel="orientation"), now=100.0 + 0.02 * k)
    snap = view.snapshot(now=100.6)
    row = snap["channels"][0]
    assert row["sensor"] == "imu" and row["updates"] == 30 and row["gated"] == 3
    assert row["rate_hz"] == pytest.approx(50.0, rel=0.01)
    assert row["nis_mean"] == pytest.approx(2.0) and row["verdict"] == "ok"
    assert row["rms"] == pytest.approx({"roll": 0.01, "pitch": 0.01})


@pytest.mark.e2e
def test_monitor_sees_a_running_daemon(jackal_bag, tmp_path):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    cfg = load(config)
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        messages = list(bag.raw_cdr())[:2500]
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        wait_daemon_ready(session, proc, log)
        pubs = sensor_publishers(session, cfg)
        stop = threading.Event()

        def stream():  # ~5x real time, looping: the daemon keeps flowing while the monitor watches
            t0 = messages[0][0]
            while not stop.is_set():
                start = time.monotonic()
                for bag_ns, sensor, raw in messages:
                    if stop.is_set():
                        return
                    delay = start + (bag_ns - t0) * 1e-9 / 5.0 - time.monotonic()
                    if delay > 0:
                        time.sleep(delay)
                    pubs[sensor.name].put(raw)
                return

        feeder = threading.Thread(target=stream, daemon=True)
        feeder.start()
        try:
            # off a TTY without --json: plain lines, streamed while the monitor runs (not one frame at exit)
            plain = subprocess.Popen(
                fusiond_cmd("monitor", "--connect", f"tcp/127.0.0.1:{port}", "--no-multicast",
                            "--duration", "30", "--interval", "0.5", "--timeout", "10"),
                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            mon = subprocess.run(
                fusiond_cmd("monitor", "--connect", f"tcp/127.0.0.1:{port}", "--no-multicast", "--json",
                            "--duration", "4", "--interval", "1.5", "--timeout", "10"),
                cwd=ROOT, capture_output=True, text=True, timeout=60)
            try:
                streamed = []
                deadline = time.monotonic() + 25
                while time.monotonic() < deadline and not any("imu/orientation" in line for line in streamed):
                    line = plain.stdout.readline()
                    if not line:
                        break
                    streamed.append(line)
                still_running = plain.poll() is None
            finally:
                plain.terminate()
                plain.communicate(timeout=20)
        finally:
            stop.set()
            feeder.join(10)
    assert mon.returncode == 0, mon.stderr
    lines = [json.loads(line) for line in mon.stdout.splitlines() if line.startswith("{")]
    assert lines, mon.stdout
    last = lines[-1]
    # each view shows the health of its moment: asked just before it is shown, not an interval (1.5 s) earlier
    assert all(rec["health_age_s"] is not None and rec["health_age_s"] < 0.75 for rec in lines), \
        [rec["health_age_s"] for rec in lines]
    assert last["daemon"] == "(no namespace)"
    assert last["health"]["status"] in ("ok", "degraded")
    assert set(last["health"]["sensors"]) == {"wheel", "imu"}
    chans = {(c["sensor"], c["channel"]): c for c in last["channels"]}
    ori = chans[("imu", "orientation")]
    assert ori["rate_hz"] > 50 and ori["updates"] > 100 and ori["nis_mean"] is not None
    assert set(ori["rms"]) == {"roll", "pitch"}
    assert any(v["channel"] == "yaw_rate" for v in last["verdicts"])  # the doctor speaks live too
    # the same key spelling as the replay: the TOML path
    assert all(v["key"] == "" or v["key"].startswith(("sensors.", "filter.")) for v in last["verdicts"])
    assert any(v["key"] == "sensors.wheel.slip_threshold" for v in last["verdicts"]), last["verdicts"]
    assert still_running and any("daemon (no namespace) status" in line for line in streamed), streamed
    assert any("imu/orientation" in line and "->" in line for line in streamed), streamed
    assert not any("\x1b[" in line for line in streamed)  # plain text: no terminal escapes


def test_monitor_without_a_daemon_says_so_and_fails(tmp_path):
    port = free_port()  # nobody listens here
    proc = subprocess.run(fusiond_cmd("monitor", "--connect", f"tcp/127.0.0.1:{port}", "--no-multicast",
                                      "--timeout", "2", "--json"), cwd=ROOT, capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode != 0
    assert "no fusiond daemon reachable" in proc.stderr or "cannot open" in proc.stderr


def test_monitor_waiting_for_a_daemon_asks_once_a_discovery_period_not_in_a_busy_loop(monkeypatch):
    """Nothing on the link: each liveliness query returns at once, so discovery must pace itself
    (``DISCOVER_S``) rather than spin a core until its timeout; a real session on a port nobody serves."""
    import zenoh

    import fusiond.monitor as monitor

    calls = []
    real = monitor.Monitor.discover

    def counted(self, timeout):
        calls.append(time.monotonic())
        return real(self, timeout)

    monkeypatch.setattr(monitor.Monitor, "discover", counted)
    monkeypatch.setattr(monitor, "DISCOVER_S", 0.5)
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer"))
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{free_port()}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(conf)
    try:
        code = monitor.run(session, timeout=2.0, duration=0.0, as_json=True)
    finally:
        session.close()
    assert code == 1
    assert 1 <= len(calls) <= 8, len(calls)  # about 2.0 / 0.5 queries, not thousands
