"""A fleet as an operator runs it, through the real CLI: `fusiond router`, daemons in client mode with a
namespace each, `fusiond monitor`, `fusiond health`, `fusiond play`, and the daemons' /metrics.

A dead robot never reads `ok`; a lost link is seen on both ends; every answer names its robot; the
metrics say what the health answer says."""

from __future__ import annotations

import json
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.support.daemon import ROOT, free_port, fusiond_cmd, log_events, wait_until
from tests.support.fleet import Feeder, MonitorLines, client, processes, robot_config, start_daemon, start_router

pytestmark = pytest.mark.e2e

LOST_WITHIN_S = 10.0  # the acceptance bound: SIGKILL -> `lost` in the monitor's records


def _health(session, key: str, timeout: float = 2.0) -> list[dict]:
    return [json.loads(reply.ok.payload.to_bytes()) for reply in session.get(key, timeout=timeout)
            if reply.ok is not None]


def _not_current(rec: dict, status: str) -> bool:
    """A record that shows no answer of the daemon: its health is the monitor's state, nothing else."""
    return (rec["status"] == status and not rec["current"]
            and rec["health"] == {"status": status, "since": rec["since"], "reason": rec["reason"]})


def _robots(tmp_path, started, router_port: int, names=("robot1", "robot2"), metrics: dict | None = None):
    """Daemons and feeders for ``names``; (configs, daemon processes, feeders) by name."""
    configs, procs, feeders = {}, {}, {}
    for name in names:
        configs[name] = robot_config(tmp_path / f"{name}.toml", router_port, name, (metrics or {}).get(name))
        procs[name] = start_daemon(configs[name], tmp_path / f"{name}.log")
        started.append(procs[name])
    for name in names:
        feeders[name] = Feeder(router_port, name)
        started.append(feeders[name])
    return configs, procs, feeders


def test_a_killed_daemon_reads_lost_within_the_bound_never_ok_again_and_comes_back_restarted(tmp_path):
    port = free_port()
    with processes() as started:
        started.append(start_router(port, tmp_path / "router.log"))
        configs, procs, _ = _robots(tmp_path, started, port)
        mon = MonitorLines("--connect", f"tcp/127.0.0.1:{port}", "--no-multicast", "--interval", "0.5",
                           "--timeout", "20")
        started.append(mon)
        fleet = MonitorLines("--connect", f"tcp/127.0.0.1:{port}", "--no-multicast", "--interval", "0.5",
                             "--timeout", "20", "--fleet")
        started.append(fleet)
        plain = MonitorLines("--connect", f"tcp/127.0.0.1:{port}", "--no-multicast", "--interval", "0.5",
                             "--timeout", "20", json_lines=False)  # the terminal view's text, into a pipe
        started.append(plain)
        for name in ("robot1", "robot2"):
            plain.wait_line(f"daemon {name} status ok", 30)
            fleet.wait(name, "ok", 30)
            _, rec = mon.wait(name, "ok", 30)
            assert rec["namespace"] == name and rec["zid"] and rec["health"]["namespace"] == name
        first_zid = mon.of("robot2")[-1]["zid"]

        procs["robot2"].send_signal(signal.SIGKILL)
        killed = time.monotonic()
        procs["robot2"].wait(5)
        seen, lost = mon.wait("robot2", "lost", LOST_WITHIN_S + 5, after=killed)
        assert seen - killed <= LOST_WITHIN_S, f"lost shown {seen - killed:.1f} s after the kill"
        assert _not_current(lost, "lost") and lost["channels"] == [] and lost["since"] is not None
        assert "token" in lost["reason"] or "no health answer" in lost["reason"], lost
        shown, line = plain.wait_line("daemon robot2 status lost since", LOST_WITHIN_S + 5, after=killed)
        assert shown - killed <= LOST_WITHIN_S, line
        # never ok again while it is dead: a few more refreshes, every one of them lost, robot1 still ok
        later = time.monotonic()
        wait_until(lambda: len(mon.of("robot2", after=later)) >= 4, 10, "more records of robot2")
        after_kill = mon.of("robot2", after=seen)
        assert after_kill and all(_not_current(r, "lost") for r in after_kill), after_kill
        with plain.lock:
            printed = [ln for t, ln in plain.lines if t >= shown and "daemon robot2 status" in ln]
        assert printed and all("status lost since" in ln for ln in printed), printed
        assert mon.of("robot1", after=later)[-1]["status"] == "ok"

        # the fleet view (started before the kill) puts it first; --namespace watches one robot only
        fleet.wait("robot2", "lost", 10, after=killed)
        last = fleet.records[-1][1]["time"]
        rows = [r for _, r in fleet.records if r["time"] == last]
        assert [(r["daemon"], r["status"]) for r in rows] == [("robot2", "lost"), ("robot1", "ok")], rows
        assert rows[1]["link"] == "connected" and rows[1]["sensors_alive"] == "2/2" and rows[1]["dropped"] == 0
        one = subprocess.run(fusiond_cmd("monitor", "--connect", f"tcp/127.0.0.1:{port}", "--no-multicast",
                                         "--namespace", "robot1", "--json", "--duration", "1.5", "--interval", "0.5"),
                             cwd=ROOT, capture_output=True, text=True, timeout=60)
        recs = [json.loads(line) for line in one.stdout.splitlines() if line.startswith("{")]
        assert recs and {r["daemon"] for r in recs} == {"robot1"}, one.stdout + one.stderr

        # restarted, it comes back by itself, a new session
        restarted_at = time.monotonic()
        procs["robot2"] = start_daemon(configs["robot2"], tmp_path / "robot2.log")
        started.append(procs["robot2"])
        _, back = mon.wait("robot2", "ok", 30, after=restarted_at)
        assert back["zid"] != first_zid and back["health"]["namespace"] == "robot2"
        assert mon.proc.poll() is None  # one monitor all along


def test_a_router_outage_reads_disconnected_and_recovers_and_the_daemon_logs_both(tmp_path):
    port = free_port()
    with processes() as started:
        router = start_router(port, tmp_path / "router.log")
        started.append(router)
        _, procs, _ = _robots(tmp_path, started, port, names=("robot1",))
        mon = MonitorLines("--connect", f"tcp/127.0.0.1:{port}", "--no-multicast", "--interval", "0.5",
                           "--timeout", "20")
        started.append(mon)
        mon.wait("robot1", "ok", 30)

        router.kill()
        router.wait(5)
        cut = time.monotonic()
        seen, rec = mon.wait("robot1", "disconnected", 10, after=cut)
        assert _not_current(rec, "disconnected") and rec["since"] is not None
        assert not [r for r in mon.of("robot1", after=seen) if r["status"] == "ok"]
        wait_until(lambda: any(e["event"] == "zenoh_link_lost" for e in log_events(tmp_path / "robot1.log")), 10,
                   "the daemon to log the lost link")

        started.append(start_router(port, tmp_path / "router.log"))  # back on the same port
        back_at = time.monotonic()
        mon.wait("robot1", "ok", 20, after=back_at)
        events = log_events(tmp_path / "robot1.log")
        restored = [e for e in events if e["event"] == "zenoh_link_restored"]
        assert restored and restored[0]["outage_s"] > 0, [e["event"] for e in events]
        assert procs["robot1"].poll() is None
        with client(port) as session:
            (h,) = _health(session, "robot1/fusiond/health")
        assert h["link"] == "connected" and h["link_stats"]["reconnections"] >= 1 and h["link_stats"]["losses"] >= 1


def test_every_health_answer_and_log_line_names_its_robot(tmp_path):
    port = free_port()
    with processes() as started:
        started.append(start_router(port, tmp_path / "router.log"))
        configs, procs, _ = _robots(tmp_path, started, port)
        with client(port) as session:
            answers = wait_until(lambda: (lambda a: a if len(a) == 2 else None)(
                _health(session, "*/fusiond/health", 1.0)), 30, "both robots' health")
        by_ns = {a["namespace"]: a for a in answers}
        assert set(by_ns) == {"robot1", "robot2"}
        assert all(a["zid"] and a["link"] == "connected" and a["link_stats"]["routers"] == 1 for a in answers)
        assert by_ns["robot1"]["zid"] != by_ns["robot2"]["zid"]

        # the CLI prints them, one per robot, each naming it
        out = subprocess.run(fusiond_cmd("health", "--connect", f"tcp/127.0.0.1:{port}", "--no-multicast",
                                         "--key", "*/fusiond/health", "--min-status", "failed"),
                             cwd=ROOT, capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        assert sorted(json.loads(line)["namespace"] for line in out.stdout.splitlines()) == ["robot1", "robot2"]
        # asking a robot that is not there: the error names the namespace asked
        ghost = robot_config(tmp_path / "robot9.toml", port, "robot9")
        miss = subprocess.run(fusiond_cmd("health", "--config", str(ghost), "--timeout", "1"), cwd=ROOT,
                              capture_output=True, text=True, timeout=60)
        assert miss.returncode == 1 and "'robot9'" in miss.stderr and "fusiond/health" in miss.stderr, miss.stderr

        for name, proc in procs.items():
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(15) == 0
            events = log_events(tmp_path / f"{name}.log")
            assert len(events) > 3 and {e.get("namespace") for e in events} == {name}, \
                [e for e in events if e.get("namespace") != name]


def test_a_frozen_daemon_whose_answers_stopped_reads_lost_before_its_lease_ends_and_comes_back(tmp_path):
    """SIGSTOP: the token stays up until Zenoh's lease (10 s) ends, but no answer comes: the last one is
    not shown as current past --stale; SIGCONT and it is back, the same session."""
    port = free_port()
    with processes() as started:
        started.append(start_router(port, tmp_path / "router.log"))
        _, procs, _ = _robots(tmp_path, started, port, names=("robot1",))
        mon = MonitorLines("--connect", f"tcp/127.0.0.1:{port}", "--no-multicast", "--interval", "0.5",
                           "--timeout", "20", "--stale", "1.5")
        started.append(mon)
        _, before = mon.wait("robot1", "ok", 30)
        proc = procs["robot1"]
        proc.send_signal(signal.SIGSTOP)
        try:
            frozen = time.monotonic()
            seen, lost = mon.wait("robot1", "lost", 8, after=frozen)
            assert seen - frozen < 5.0 and _not_current(lost, "lost"), lost
            assert "no health answer" in lost["reason"], lost  # the token is still up: the answers said it
            assert all(not r["current"] or r["health_age_s"] <= 1.5 for r in mon.of("robot1", after=frozen))
        finally:
            proc.send_signal(signal.SIGCONT)
        thawed = time.monotonic()
        _, back = mon.wait("robot1", "ok", 30, after=thawed)
        assert back["zid"] == before["zid"] and proc.poll() is None


def test_the_router_unit_runs_fusiond_router_as_its_command_line_reads_it(tmp_path):
    """deploy/fusiond-router.service's ExecStart, parsed by fusiond's own parser, and that command on loopback
    serving a daemon-to-tool route (a health answer crosses it)."""
    import shlex

    from fusiond.cli import build_parser

    text = (ROOT / "deploy" / "fusiond-router.service").read_text()
    keys = dict(line.split("=", 1) for line in text.splitlines() if "=" in line and not line.startswith("#"))
    argv = shlex.split(keys["ExecStart"])
    args = build_parser().parse_args(argv[1:])
    assert Path(argv[0]).name == "fusiond" and args.command == "router" and args.listen == ["tcp/0.0.0.0:7447"]
    assert keys["KillSignal"] == "SIGTERM" and keys.get("DynamicUser") == "yes"
    port = free_port()
    with processes() as started:
        router = start_router(port, tmp_path / "router.log")
        started.append(router)
        _robots(tmp_path, started, port, names=("robot1",))
        with client(port) as session:
            wait_until(lambda: _health(session, "robot1/fusiond/health", 0.5), 30, "an answer across the router")
        router.send_signal(signal.SIGTERM)
        assert router.wait(15) == 0


def test_a_peer_tool_asks_a_daemon_behind_a_router_right_after_opening_and_is_answered(tmp_path):
    """The README's rmw_zenoh setup: the daemon and the tools are peers that dial a router. A tool's session
    learns the router's routes a moment after it opens; its health query, asked at once, found nothing serving
    it about half the time and `fusiond health` failed. Each of ten fresh peer sessions is answered."""
    from fusiond.config import ZenohConfig
    from fusiond.transport.session import client_config, open_session, query_health

    port = free_port()
    with processes() as started:
        started.append(start_router(port, tmp_path / "router.log"))
        config = tmp_path / "peer.toml"
        config.write_text(f'[zenoh]\nconnect = ["tcp/127.0.0.1:{port}"]\nmulticast_scouting = false\n\n'
                          + (ROOT / "examples" / "jackal.toml").read_text())
        started.append(start_daemon(config, tmp_path / "daemon.log"))
        probe = client(port)
        started.append(probe)
        wait_until(lambda: _health(probe, "fusiond/health", 0.5), 30, "the daemon's first health answer")
        tool = ZenohConfig(connect=[f"tcp/127.0.0.1:{port}"], multicast_scouting=False)
        for _ in range(10):
            session = open_session(client_config(tool))
            try:
                assert query_health(session, "fusiond/health", 2.0), "a fresh peer session was not answered"
            finally:
                session.close()
