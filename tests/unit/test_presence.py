"""What a remote tool may say of a daemon (presence.py), the fleet rows built on it (fleet.py), the link
watch's transitions (transport/link.py), and the config keys of this layer ([metrics], zenoh retry)."""

from __future__ import annotations

import math

import pytest

from fusiond.config import ConfigError, loads
from fusiond.fleet import fleet_rows, worst_channel
from fusiond.presence import Presence, rank
from fusiond.transport.link import LinkWatch
from fusiond.transport.session import build_config

from tests.support.recordings import DATA

OK = {"status": "ok", "zid": "a"}


def test_a_current_answer_is_shown_and_a_stale_one_never_is():
    p = Presence()
    p.token_up(now=10.0, wall=1000.0)
    assert p.state(10.5, 1000.5, 2.0, True, None).status == "waiting"
    p.answered(now=11.0, wall=1001.0)
    s = p.state(12.0, 1002.0, 2.0, True, OK)
    assert (s.status, s.current, s.health_age_s) == ("ok", True, 1.0)
    s = p.state(13.5, 1003.5, 2.0, True, OK)  # 2.5 s without an answer
    assert (s.status, s.current, s.since) == ("lost", False, 1001.0) and "no health answer" in s.reason


def test_a_withdrawn_token_is_lost_at_once_whatever_the_last_answer_said():
    p = Presence()
    p.token_up(10.0, 1000.0)
    p.answered(10.1, 1000.1)
    p.token_down(wall=1000.2)
    s = p.state(10.3, 1000.3, math.inf, True, OK)
    assert (s.status, s.current, s.since) == ("lost", False, 1000.2) and "token" in s.reason


def test_a_restart_waits_for_its_own_first_answer_not_the_dead_runs_last():
    p = Presence()
    p.token_up(10.0, 1000.0)
    p.answered(10.1, 1000.1)
    p.token_down(1000.2)
    p.token_up(20.0, 1010.0)  # back: the answer at 10.1 belongs to the old run
    assert p.state(20.1, 1010.1, 5.0, True, OK).status == "waiting"
    assert p.state(26.0, 1016.0, 5.0, True, OK).status == "lost"  # found 6 s ago, never answered
    p.answered(26.5, 1016.5)
    assert p.state(26.6, 1016.6, 5.0, True, OK).status == "ok"


def test_without_a_link_of_its_own_the_tool_says_disconnected_since_it_was_cut():
    p = Presence()
    p.token_up(10.0, 1000.0)
    p.answered(10.0, 1000.0)
    assert p.state(11.0, 1001.0, 5.0, False, OK).status == "disconnected"
    assert p.state(12.0, 1002.0, 5.0, False, OK).since == 1001.0
    assert p.state(12.5, 1002.5, 5.0, True, OK).status == "ok"


def _snap(daemon, status, consistency=None, dropped=0):
    health = None if status in ("lost", "disconnected") else {
        "status": status, "consistency": consistency or {},
        "sensors": {"wheel": {"alive": True, "dropped": dropped}, "imu": {"alive": status == "ok", "dropped": 0}}}
    return {"daemon": daemon, "namespace": daemon, "zid": "z", "status": status, "since": None,
            "reason": "gone" if health is None else None, "link": "connected" if health else None,
            "health_age_s": 0.2, "health": health}


def test_fleet_rows_put_the_worst_first():
    high = {"imu/orientation": {"nis_mean": 9.0, "nis_bounds": [1.5, 2.6], "verdict": "nis_high"}}
    fine = {"imu/orientation": {"nis_mean": 2.0, "nis_bounds": [1.5, 2.6], "verdict": "ok"}}
    rows = fleet_rows([_snap("a", "ok", fine), _snap("b", "lost"), _snap("c", "degraded", dropped=3),
                       _snap("d", "ok", high), _snap("e", "failed")])
    assert [r["daemon"] for r in rows] == ["b", "e", "c", "d", "a"]
    assert rows[0]["dropped"] is None and rows[0]["worst_nis"] is None  # a lost robot shows no figures
    assert rows[2]["dropped"] == 3 and rows[2]["sensors_alive"] == "1/2"
    assert rows[3]["worst_nis"]["channel"] == "imu/orientation" and rows[3]["worst_nis"]["outside"] > 3
    assert rank("lost") < rank("failed") < rank("degraded") < rank("ok")


def test_the_worst_channel_is_the_one_furthest_outside_either_bound():
    c = {"a/x": {"nis_mean": 0.5, "nis_bounds": [1.0, 3.0], "verdict": "nis_low"},  # 2x below
         "b/y": {"nis_mean": 4.5, "nis_bounds": [1.0, 3.0], "verdict": "nis_high"},  # 1.5x above
         "c/z": {"nis_mean": None, "nis_bounds": None, "verdict": "warming_up"}}
    assert worst_channel(c)["channel"] == "a/x"
    assert worst_channel({"c/z": c["c/z"]}) is None


class _Counts:
    def __init__(self):
        self.value = (0, 0)

    def __call__(self, _session):
        return self.value


def test_the_link_watch_counts_losses_and_reconnections_not_a_lonely_start():
    counts, clock = _Counts(), [0.0]
    w = LinkWatch(None, counts=counts, clock=lambda: clock[0])
    w.poll()
    assert w.health().state == "disconnected" and w.losses == 0  # nobody to talk to yet: no loss
    counts.value, clock[0] = (1, 0), 1.0
    w.poll()
    h = w.health()
    assert (h.state, h.routers, h.losses, h.reconnections) == ("connected", 1, 0, 0)
    counts.value, clock[0] = (0, 0), 5.0
    w.poll()
    counts.value, clock[0] = (0, 2), 8.0
    w.poll()
    clock[0] = 9.0
    h = w.health()
    assert (h.state, h.peers, h.losses, h.reconnections, h.since_s) == ("connected", 2, 1, 1, 1.0)


def test_metrics_listen_and_the_retry_keys_are_checked_and_reach_zenoh():
    assert loads("").metrics.listen == ""
    assert loads('[metrics]\nlisten = "[::1]:9108"').metrics.listen == "[::1]:9108"
    for bad in ('[metrics]\nlisten = "9108"', '[metrics]\nlisten = "host:http"', '[metrics]\nlisten = ":9108"'):
        with pytest.raises(ConfigError, match="metrics.listen"):
            loads(bad)
    with pytest.raises(ConfigError, match="zenoh.connect_retry_max_s"):
        loads("[zenoh]\nconnect_retry_init_s = 2.0\nconnect_retry_max_s = 1.0")
    with pytest.raises(ConfigError, match="zenoh.connect_retry_init_s"):
        loads("[zenoh]\nconnect_retry_init_s = 0.0")
    cfg = loads("[zenoh]\nconnect_retry_init_s = 0.1\nconnect_retry_max_s = 2.0\nconnect_retry_factor = 3.0")
    import json

    retry = json.loads(build_config(cfg.zenoh).get_json("connect/retry"))
    assert retry == {"period_init_ms": 100, "period_max_ms": 2000, "period_increase_factor": 3.0}


def test_the_terminal_view_of_a_lost_daemon_says_lost_and_since_and_shows_no_table():
    from rich.console import Console

    from fusiond.monitor import DaemonView, render

    view = DaemonView("robot2")
    view.presence.token_up(10.0, 1000.0)
    view.on_health({"status": "ok", "zid": "a", "sensors": {"wheel": {"alive": True, "received": 5}}}, 10.1, 1000.1)
    assert view.snapshot(10.2, 1000.2, 5.0)["status"] == "ok"
    view.presence.token_down(1000.3)
    snap = view.snapshot(10.4, 1000.4, 5.0)
    assert (snap["status"], snap["current"], snap["channels"]) == ("lost", False, [])
    assert snap["health"] == {"status": "lost", "since": 1000.3, "reason": snap["reason"]}
    console = Console(record=True, width=200, force_terminal=False)
    console.print(render([snap]))
    text = console.export_text()
    assert "daemon robot2  status lost since" in text and "token" in text
    assert "wheel" not in text and " ok" not in text


def test_a_listening_peer_reports_its_sessions_but_counts_no_tool_leaving_as_a_loss():
    counts = _Counts()
    w = LinkWatch(None, watched=False, counts=counts)
    for value in ((1, 0), (0, 0), (0, 1), (0, 0)):  # tools dialling the daemon and leaving
        counts.value = value
        w.poll()
    h = w.health()
    # listening, not disconnected: a tool dialling it in client mode is no router or peer of its session
    assert (h.state, h.losses, h.reconnections) == ("listening", 0, 0)
    counts.value = (0, 1)
    w.poll()
    assert w.health().state == "connected"


def test_the_fleet_lines_and_table_say_lost_with_since_and_the_rest_with_their_figures():
    from rich.console import Console

    from fusiond.fleet import fleet_lines, render_fleet

    high = {"imu/orientation": {"nis_mean": 9.0, "nis_bounds": [1.5, 2.6], "verdict": "nis_high"}}
    lost = _snap("robot2", "lost")
    lost["since"] = 1000.0
    rows = fleet_rows([_snap("robot1", "ok", high, dropped=4), lost])
    lines = fleet_lines(rows, 1001.0)
    assert lines[0].split()[1:3] == ["robot2", "lost"] and "since" in lines[0] and ": gone" in lines[0]
    assert "link=connected" in lines[1] and "nis=imu/orientation 9.00 [1.50, 2.60] nis_high" in lines[1]
    assert "dropped=4" in lines[1] and "sensors=2/2" in lines[1]
    console = Console(record=True, width=200, force_terminal=False)
    console.print(render_fleet(rows))
    text = console.export_text().splitlines()
    assert text[1].split()[:2] == ["robot2", "lost"] and text[2].split()[:3] == ["robot1", "ok", "connected"]


def test_a_silent_sensors_verdicts_are_said_to_be_as_of_its_last_sample():
    """The IMU stopped 28 s ago (the health answer says so) while the doctor's verdicts, judged on the records it
    was sent, still read ok: they are said to be as of its last sample, after a line that says it is silent."""
    from fusiond.core.diagnostics import DiagnosticsRecord
    from fusiond.monitor import DaemonView

    view = DaemonView("robot2", window=10)
    view.presence.token_up(10.0, 1000.0)
    for k in range(60):
        view.add(DiagnosticsRecord(float(k), "imu", ["roll", "pitch"], [0.01, -0.01], [1e-4, 1e-4], 2.0, 2, False,
                                   channel="orientation"), now=10.0 + 0.02 * k)
    sensors = {"imu": {"alive": False, "age_s": 28.6, "timeout_s": 0.2, "received": 60},
               "wheel": {"alive": True, "age_s": 0.01, "timeout_s": 0.2, "received": 90}}
    view.on_health({"status": "degraded", "zid": "a", "sensors": sensors}, 11.3, 1001.3)
    verdicts = view.snapshot(11.4, 1001.4, 5.0)["verdicts"]
    imu = [v for v in verdicts if v["sensor"] == "imu"]
    assert imu[0]["channel"] == "input" and imu[0]["level"] == "warn" and "silent for 28.6 s" in imu[0]["message"]
    assert len(imu) > 1 and all(v["message"].startswith("as of its last sample: ") for v in imu[1:]), imu
    sensors["imu"] = {**sensors["imu"], "alive": True, "age_s": 0.01}
    view.on_health({"status": "ok", "zid": "a", "sensors": sensors}, 11.5, 1001.5)
    assert not [v for v in view.snapshot(11.6, 1001.6, 5.0)["verdicts"] if "last sample" in v["message"]]


@pytest.mark.e2e
@pytest.mark.skipif(not (DATA / "comma2k19_ex1").exists(), reason="needs ../shared/data/comma2k19_ex1 (the highway car)")
def test_the_monitor_judges_a_daemon_with_the_robots_config_as_the_replay_does():
    """The highway car's records (its example config) as its daemon streams them: without the config, the monitor's doctor read the
    GPS altitude's low NIS as an overstated noise (a warning with no value); with the robot's config it knows
    the altitude's error model, as the replay's doctor does, and agrees with it. A daemon whose health lists
    other sensors is judged without the config."""
    from pathlib import Path

    from fusiond.config import load
    from fusiond.monitor import DaemonView
    from fusiond.replay.bag import open_bag_samples
    from fusiond.replay.run import run_samples

    cfg = load(Path(__file__).resolve().parents[2] / "examples" / "comma2k19.toml")
    with open_bag_samples([DATA / "comma2k19_ex1"], cfg.sensors) as bag:
        samples = list(bag)
    records: list = []
    result = run_samples(samples, cfg, records=records)
    replayed = next(v for v in result.verdicts() if (v.sensor, v.channel) == ("gps", "altitude"))

    def altitude(view: DaemonView) -> dict:
        for r in records:
            view.add(r, 0.0)
        return next(v for v in view.snapshot(1.0, 1.0)["verdicts"] if (v["sensor"], v["channel"]) == ("gps", "altitude"))

    blind = altitude(DaemonView("car", cfg=None))
    assert blind["level"] == "warn" and replayed.level == "ok", (blind, replayed)
    assert altitude(DaemonView("car", cfg=cfg))["message"] == replayed.message
    other = DaemonView("rover", cfg=cfg)
    other.on_health({"status": "ok", "zid": "b", "sensors": {"wheels": {"alive": True}}}, 0.5, 0.5)
    assert altitude(other)["level"] == "warn"
