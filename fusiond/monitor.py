"""`fusiond monitor`: a live per-sensor view of running daemons, from any machine.

Daemons are found by their liveliness tokens (`**/fusiond/health/alive`, any
namespace); their diagnostics stream (`**/fusiond/diagnostics`) is aggregated here
per sensor channel into a rate, an age, a windowed NIS against its chi-square
bounds, the innovation RMS per component and the gated count; the doctor turns
it into a verdict line in plain words. `--json` prints the same as JSON lines; with
its output not a terminal (a pipe, a log file) it streams plain text lines as it goes.

A daemon is shown from what is known NOW, never from its last answer: its liveliness token
(followed by a liveliness subscriber) gone, or no health answer for `stale_s`, and it reads
`lost` (with since when and why; its record's health is that state, never the last answer) and
shows no figures; the monitor's own Zenoh link gone (its router died), and every daemon reads
`disconnected`. A restarted daemon comes back
by itself: its token returns, its next answer is shown, and a new Zenoh id restarts its
channel statistics. Health is asked of every daemon by one wildcard query per refresh whose
answers arrive on a callback, so a dead daemon delays nothing. `--fleet` shows one line per
daemon, worst first (``fleet.py``).

A channel's verdict is judged over everything seen since the monitor started (the
doctor's whole-run rule, chi-square bounds for that count) and says when the latest
window differs, exactly as the replay summary does. Every NIS figure of a row comes from
the doctor's statistics of that channel: the whole run's mean, bounds and verdict side by
side, and the latest window's mean, bounds and verdict side by side, each verdict judged
on the very mean and bounds printed beside it (a verdict beside another window's mean
read "ok" next to a NIS outside its bounds).

Given the robot's config (``--config`` with its ``[[sensors]]``), a daemon whose health answer lists those
sensors is judged by a doctor that knows them, as the replay's doctor does (a GPS altitude whose NIS reads
low is what its configured error model expects, not an overstated noise): without it, the same stream read
a warning the offline doctor contradicted. A daemon with other sensors (another robot of the fleet) is
judged without the config.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import msgspec

from .config import Config
from .core.diagnostics import DiagnosticsRecord
from .doctor import ChannelStats, Doctor, Verdict, judge_nis, nis_bounds
from .fleet import STATUS_STYLE
from .presence import Presence, withdrawn

ALIVE_SUFFIX = "/alive"
DIAGNOSTICS_SUFFIX = "fusiond/diagnostics"
RATE_WINDOW_S = 5.0
# discovery asks for the daemons' liveliness tokens once a period at most (a daemon that comes up is seen within
# it): a query with nothing on the link to serve it returns at once, and asked again at once it spins a core
DISCOVER_S = 1.0

# The diagnostics key carries one record or a JSON array of them (the daemon's batches,
# `[output] diagnostics_batch_s`): one decoder for both, no guessing from the first byte.
_DIAGNOSTICS = msgspec.json.Decoder(DiagnosticsRecord | list[DiagnosticsRecord])


def decode_diagnostics(payload: bytes) -> list[DiagnosticsRecord]:
    """The records of one diagnostics payload, in order (raises msgspec.DecodeError on anything else)."""
    out = _DIAGNOSTICS.decode(payload)
    return out if type(out) is list else [out]


@dataclass
class ChannelView:
    sensor: str
    channel: str
    components: list[str]
    window: int
    confidence: float
    arrivals: deque = field(default_factory=lambda: deque(maxlen=4096))  # wall times
    innovations: deque = field(default_factory=deque)
    dof: int = 0
    total: int = 0
    rejected: int = 0
    last_stamp: float | None = None

    def __post_init__(self) -> None:
        self.innovations = deque(maxlen=self.window)

    def add(self, r: DiagnosticsRecord, now: float) -> None:
        self.arrivals.append(now)
        self.total += 1
        self.rejected += r.rejected
        self.last_stamp = r.stamp
        if r.components != self.components:  # the rms columns are per component: one shape at a time
            self.innovations.clear()
            self.components = list(r.components)
        self.dof = r.dof
        self.innovations.append(r.innovation)

    def row(self, now: float) -> dict:
        """Rate, age, the latest window's innovation rms and the counts; the NIS figures are the doctor's
        (:func:`nis_figures`)."""
        recent = [t for t in self.arrivals if now - t <= RATE_WINDOW_S]
        rate = (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 1 and recent[-1] > recent[0] else 0.0
        rms = [math.sqrt(sum(v[i] ** 2 for v in self.innovations) / len(self.innovations))
               for i in range(len(self.components))] if self.innovations else []
        return {
            "sensor": self.sensor, "channel": self.channel, "rate_hz": rate,
            "age_s": now - self.arrivals[-1] if self.arrivals else None, "dof": self.dof,
            "rms": dict(zip(self.components, rms)), "updates": self.total, "gated": self.rejected,
        }


def nis_figures(stats: ChannelStats) -> dict:
    """A channel's NIS columns, all from its doctor statistics: the whole run's mean, bounds and verdict,
    the latest window's mean, bounds and verdict. Each verdict is judged on the mean and bounds beside it
    (the window's on exactly the sums the doctor's window test uses), so neither can read "ok" beside a
    mean outside its bounds, and the window's verdict is the one the "now:" note speaks of."""
    whole = stats.summary()
    out = {"nis_mean": whole["nis_mean"], "nis_bounds": whole["nis_bounds"], "verdict": whole["verdict"],
           "now_note": whole["now_note"], "window_nis_mean": None, "window_nis_bounds": None,
           "window_verdict": whole["verdict"]}  # not_judged / learning: no window test either
    if whole["verdict"] in ("not_judged", "learning"):
        return out
    n = len(stats.recent)
    if n == 0:
        out["window_verdict"] = "no_updates"
        return out
    mean, dof = stats.recent_sum / n, stats.recent_dof / n
    out["window_nis_mean"] = mean
    out["window_nis_bounds"] = list(nis_bounds(n, dof, stats.confidence))
    out["window_verdict"] = judge_nis(mean, n, dof, stats.confidence)
    return out


class DaemonView:
    """One daemon (one namespace prefix): its channels and a doctor fed from the stream, and whether it
    is there (``presence``)."""

    def __init__(self, prefix: str, window: int = 50, confidence: float = 0.95, cfg: Config | None = None) -> None:
        self.prefix = prefix
        self.window = window
        self.confidence = confidence
        self.channels: dict[tuple[str, str], ChannelView] = {}
        # the robot's config (module doc), while the daemon's health does not say it has other sensors
        self.cfg = cfg if cfg is not None and cfg.sensors else None
        self.doctor = Doctor(self.cfg, window, confidence)
        self.health: dict | None = None  # the latest health answer (shown only while presence says current)
        self.presence = Presence()
        self.lock = threading.Lock()

    def on_health(self, health: dict, now: float, wall: float) -> None:
        """A health answer arrived: a daemon with a new Zenoh id is a new run (restarted): its channel
        statistics start again."""
        with self.lock:
            zid = health.get("zid") if isinstance(health, dict) else None
            sensors = health.get("sensors") if isinstance(health, dict) else None
            theirs = set(sensors) if isinstance(sensors, dict) else None
            if self.cfg is not None and theirs is not None and theirs != {sc.name for sc in self.cfg.sensors}:
                self.cfg = None  # another robot's sensors: its records are judged without the config from now on
                self.doctor = Doctor(None, self.window, self.confidence)
            if zid and self.health is not None and self.health.get("zid") not in (None, "", zid):
                self.channels.clear()
                self.doctor = Doctor(self.cfg, self.window, self.confidence)
            self.health = health
            self.presence.answered(now, wall)

    def add(self, r: DiagnosticsRecord, now: float) -> None:
        with self.lock:
            key = (r.sensor, r.channel)
            ch = self.channels.get(key)
            if ch is None:
                ch = self.channels[key] = ChannelView(r.sensor, r.channel, list(r.components), self.window,
                                                      self.confidence)
            ch.add(r, now)
            self.doctor.add(r)

    def snapshot(self, now: float, wall: float | None = None, stale_s: float = math.inf,
                 link_up: bool = True) -> dict:
        """What is known of the daemon now: its state (``Presence.state``); as ``health`` its answer while it
        is current, else only ``{"status", "since", "reason"}`` of that state (`lost`, ...: never its last
        answer, and a reader of ``health["status"]`` reads the state); the channels and verdicts unless the
        daemon is lost or out of reach (then none)."""
        wall = time.time() if wall is None else wall
        with self.lock:
            state = self.presence.state(now, wall, stale_s, link_up, self.health)
            current = state.current
            rows = []
            verdicts: list = []
            if state.status not in ("lost", "disconnected"):  # the stream's figures carry their own ages
                for key, ch in sorted(self.channels.items()):
                    row = ch.row(now)
                    row.update(nis_figures(self.doctor.channels[key]))  # every record reached both
                    rows.append(row)
                verdicts = self.doctor.verdicts()
            answer = (self.health or {}) if current else {}
            verdicts = as_of_silence(verdicts, answer.get("sensors"))
        health = answer if current else {"status": state.status, "since": state.since, "reason": state.reason}
        return {"daemon": self.prefix or "(no namespace)", "namespace": answer.get("namespace", self.prefix),
                "zid": answer.get("zid") or None, "status": state.status, "current": current, "since": state.since,
                "reason": state.reason, "link": answer.get("link") or None, "health_age_s": state.health_age_s,
                "health": health, "channels": rows, "verdicts": [msgspec.to_builtins(v) for v in verdicts]}


def as_of_silence(verdicts: list[Verdict], sensors: object) -> list[Verdict]:
    """``verdicts`` with those of a sensor the health answer reports silent (``sensors``: its ``sensors``
    table) said to be as of its last sample, after one line that says it is silent: the doctor judges the
    records it was sent, and a sensor that stopped sends none, so its last "ok" would read as now."""
    if not isinstance(sensors, dict):
        return verdicts
    silent = {name: s for name, s in sensors.items() if isinstance(s, dict) and s.get("alive") is False}
    if not silent:
        return verdicts
    out: list[Verdict] = []
    for name, s in silent.items():
        age = s.get("age_s")
        since = f"for {age:.1f} s" if isinstance(age, (int, float)) else "with no sample yet"
        out.append(Verdict(name, "input", "warn", f"silent {since} (timeout {s.get('timeout_s', 0.0):.2f} s): "
                           "its verdicts below are as of its last sample, not now"))
    for v in verdicts:
        if v.sensor in silent:
            v = msgspec.structs.replace(v, message=f"as of its last sample: {v.message}")
        out.append(v)
    return out


def prefix_of(key: str, suffix: str) -> str:
    """The namespace part of a key: `robot1/fusiond/diagnostics` -> `robot1`."""
    key = str(key)
    return key[: -len(suffix)].rstrip("/") if key.endswith(suffix) else key


class Monitor:
    """Zenoh side: liveliness discovery and its changes, the diagnostics subscription, health queries.

    ``namespace`` (a prefix) watches that daemon alone; by default every daemon in any namespace.
    """

    def __init__(self, session, health_key: str = "fusiond/health", diagnostics_key: str = DIAGNOSTICS_SUFFIX,
                 window: int = 50, namespace: str = "", cfg: Config | None = None) -> None:
        self.session = session
        self.cfg = cfg  # the robot's config, for the doctors of the daemons that have its sensors (module doc)
        self.health_key = health_key
        self.diagnostics_key = diagnostics_key
        self.window = window
        self.namespace = namespace.strip("/")
        self.daemons: dict[str, DaemonView] = {}
        self.undecodable = 0
        self._lock = threading.Lock()
        self._subs = []

    def _scope(self, key: str) -> str:
        """A key of every daemon (``**/key``), or of the one namespace watched."""
        return f"{self.namespace}/{key}" if self.namespace else f"**/{key}"

    def _daemon(self, prefix: str) -> DaemonView:
        with self._lock:
            d = self.daemons.get(prefix)
            if d is None:
                d = self.daemons[prefix] = DaemonView(prefix, self.window, cfg=self.cfg)
            return d

    def start(self) -> None:
        # `**` also matches no chunk at all: one subscriber sees every namespace and none
        self._subs.append(self.session.declare_subscriber(self._scope(self.diagnostics_key), self._on_diagnostics))
        # the tokens now (history) and every change after: a daemon's death is seen as it happens
        self._subs.append(self.session.liveliness().declare_subscriber(
            self._scope(f"{self.health_key}{ALIVE_SUFFIX}"), self._on_token, history=True))

    def _on_diagnostics(self, sample) -> None:
        try:
            records = decode_diagnostics(sample.payload.to_bytes())
        except msgspec.DecodeError:
            self.undecodable += 1
            return
        view, now = self._daemon(prefix_of(sample.key_expr, self.diagnostics_key)), time.monotonic()
        for rec in records:
            view.add(rec, now)

    def _on_token(self, sample) -> None:
        view = self._daemon(prefix_of(sample.key_expr, f"{self.health_key}{ALIVE_SUFFIX}"))
        with view.lock:
            if withdrawn(sample):
                view.presence.token_down(time.time())
            else:
                view.presence.token_up(time.monotonic(), time.time())

    def discover(self, timeout: float) -> list[str]:
        """Prefixes of the daemons whose liveliness token is up."""
        found = set()
        alive = f"{self.health_key}{ALIVE_SUFFIX}"
        for reply in self.session.liveliness().get(self._scope(alive), timeout=timeout):
            if reply.ok is not None:
                found.add(prefix_of(reply.ok.key_expr, alive))
        for p in found:
            view = self._daemon(p)
            with view.lock:
                if view.presence.token is None:  # the subscriber has not spoken of it yet
                    view.presence.token_up(time.monotonic(), time.time())
        return sorted(found)

    def _on_health(self, reply) -> None:
        if reply.ok is None:
            return
        try:
            health = msgspec.json.decode(reply.ok.payload.to_bytes())
        except msgspec.DecodeError:
            self.undecodable += 1
            return
        if not isinstance(health, dict):
            self.undecodable += 1
            return
        self._daemon(prefix_of(reply.ok.key_expr, self.health_key)).on_health(health, time.monotonic(), time.time())

    def refresh_health(self, timeout: float = 1.0) -> None:
        """Ask, and wait for the answers (up to ``timeout``)."""
        for reply in self.session.get(self._scope(self.health_key), timeout=timeout):
            self._on_health(reply)

    def link_up(self) -> bool:
        """This monitor's own session has a router or a peer."""
        info = self.session.info
        return bool(list(info.routers_zid()) or list(info.peers_zid()))

    def snapshot(self, stale_s: float = math.inf, link_up: bool = True) -> list[dict]:
        now, wall = time.monotonic(), time.time()
        with self._lock:
            views = sorted(self.daemons.items())
        return [d.snapshot(now, wall, stale_s, link_up) for _, d in views]

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()


# -- rendering --------------------------------------------------------------
def _fmt(v: float | None, spec: str = ".2f") -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else format(v, spec)


# a NIS mean and its bounds in one format: rounding both alike never shows a mean inside its bounds
# beside a verdict that found it outside, nor the reverse
NIS_FORMAT = ".3f"
_VERDICT_STYLE = {"nis_high": "red", "nis_low": "yellow", "ok": "green"}


def _bounds(b: list[float] | None) -> str:
    return f"[{b[0]:{NIS_FORMAT}}, {b[1]:{NIS_FORMAT}}]" if b else "-"




def _clock(wall: float | None) -> str:
    return "-" if wall is None else time.strftime("%H:%M:%S", time.localtime(wall))


def state_note(snap: dict) -> str:
    """What follows the status word: since when and why it is not the daemon's own status, or its link."""
    if snap.get("reason") and snap.get("since") is not None:
        return f" since {_clock(snap['since'])} ({snap['reason']})"
    if snap.get("reason"):
        return f" ({snap['reason']})"
    return f"  link {snap['link']}" if snap.get("link") else ""


def render(snapshots: list[dict]):
    """A rich renderable of the snapshots (imported lazily: --json needs no rich)."""
    from rich.console import Group
    from rich.table import Table
    from rich.text import Text

    parts = []
    for snap in snapshots:
        health = snap.get("health") or {}
        status = snap.get("status") or health.get("status", "?")
        colour = STATUS_STYLE.get(status, "white")
        parts.append(Text(f"daemon {snap['daemon']}  status ", style="bold") + Text(status, style=f"bold {colour}")
                     + Text(state_note(snap)))
        sensors = health.get("sensors", {})
        if sensors:
            t = Table(show_header=True, header_style="bold", box=None)
            for col in ("sensor", "alive", "age s", "rate Hz", "received", "dropped", "rejected"):
                t.add_column(col)
            for name, s in sensors.items():
                t.add_row(name, "yes" if s.get("alive") else "NO", _fmt(s.get("age_s")), _fmt(s.get("rate_hz"), ".1f"),
                          str(s.get("received")), str(s.get("dropped")), str(s.get("rejected")))
            parts.append(t)
        t = Table(show_header=True, header_style="bold", box=None)
        for col in ("sensor/channel", "rate Hz", "age s", "NIS mean", "bounds", "verdict", "window NIS",
                    "window bounds", "window", "window rms", "gated"):
            t.add_column(col)
        for r in snap["channels"]:
            rms = " ".join(f"{k} {v:.4f}" for k, v in r["rms"].items())
            t.add_row(f"{r['sensor']}/{r['channel']}", _fmt(r["rate_hz"], ".1f"), _fmt(r["age_s"]),
                      _fmt(r["nis_mean"], NIS_FORMAT), _bounds(r["nis_bounds"]),
                      Text(r["verdict"], style=_VERDICT_STYLE.get(r["verdict"], "")),
                      _fmt(r["window_nis_mean"], NIS_FORMAT), _bounds(r["window_nis_bounds"]),
                      Text(r["window_verdict"], style=_VERDICT_STYLE.get(r["window_verdict"], "")),
                      rms, f"{r['gated']}/{r['updates']}")
        parts.append(t)
        for v in snap["verdicts"]:
            style = {"ok": "green", "warn": "yellow", "problem": "bold red"}[v["level"]]
            key = f"  [{v['key']}]" if v["key"] else ""
            parts.append(Text(f"  {v['level'].upper():7} {v['sensor']}/{v['channel']}: {v['message']}{key}",
                              style=style))
        parts.append(Text(""))
    return Group(*parts)


def plain_lines(snapshots: list[dict], wall: float) -> list[str]:
    """The same content as the terminal view, as plain lines (for a pipe or a log file)."""
    stamp = time.strftime("%H:%M:%S", time.localtime(wall))
    out = []
    for snap in snapshots:
        health = snap.get("health") or {}
        out.append(f"{stamp} daemon {snap['daemon']} status {snap.get('status') or health.get('status', '?')}"
                   f"{state_note(snap)}")
        for name, s in health.get("sensors", {}).items():
            out.append(f"{stamp}   sensor {name} alive={'yes' if s.get('alive') else 'NO'} age={_fmt(s.get('age_s'))}s "
                       f"rate={_fmt(s.get('rate_hz'), '.1f')}Hz received={s.get('received')} "
                       f"dropped={s.get('dropped')} rejected={s.get('rejected')}")
        for r in snap["channels"]:
            rms = " ".join(f"{k}={v:.4f}" for k, v in r["rms"].items())
            now = f" ({r['now_note']})" if r.get("now_note") else ""
            out.append(f"{stamp}   {r['sensor']}/{r['channel']} rate={_fmt(r['rate_hz'], '.1f')}Hz "
                       f"nis={_fmt(r['nis_mean'], NIS_FORMAT)} {_bounds(r['nis_bounds'])} -> {r['verdict']}{now} "
                       f"window_nis={_fmt(r['window_nis_mean'], NIS_FORMAT)} {_bounds(r['window_nis_bounds'])} "
                       f"-> {r['window_verdict']} rms[{rms}] gated={r['gated']}/{r['updates']}")
        for v in snap["verdicts"]:
            key = f"  [{v['key']}]" if v["key"] else ""
            out.append(f"{stamp}   {v['level'].upper():7} {v['sensor']}/{v['channel']}: {v['message']}{key}")
    return out


def run(session, *, timeout: float, duration: float | None, as_json: bool, interval: float = 1.0,
        health_key: str = "fusiond/health", diagnostics_key: str = DIAGNOSTICS_SUFFIX, window: int = 50,
        stop: threading.Event | None = None, out=sys.stdout, fleet: bool = False, namespace: str = "",
        stale_s: float | None = None, cfg: Config | None = None) -> int:
    """Discover daemons (up to ``timeout``), then show them until ``duration`` or Ctrl-C.

    ``stale_s`` (default ``max(3 x interval, 2 s)``): a health answer older than this is not current and
    the daemon reads `lost`. ``fleet``: one line per daemon, worst first. ``namespace``: that daemon only.
    Exit 1, with a message naming what was looked for, when no daemon answers.
    """
    from .fleet import fleet_lines, fleet_rows, render_fleet

    mon = Monitor(session, health_key, diagnostics_key, window, namespace=namespace, cfg=cfg)
    mon.start()
    stale = max(3.0 * interval, 2.0) if stale_s is None else stale_s
    stop = stop or threading.Event()
    deadline = time.monotonic() + timeout
    found: list[str] = []
    while not found and time.monotonic() < deadline and not stop.is_set():
        asked = time.monotonic()
        period = min(DISCOVER_S, max(deadline - asked, 0.1))
        found = mon.discover(timeout=period)
        if not found:  # a query ends at once when nothing on the link serves it: the next one a period on
            stop.wait(max(asked + period - time.monotonic(), 0.0))
    if not found:
        mon.close()
        where = f"{namespace}/{health_key}{ALIVE_SUFFIX}" if namespace else \
            f"{health_key}{ALIVE_SUFFIX} in any namespace"
        print(f"fusiond monitor: no fusiond daemon reachable within {timeout:g} s "
              f"(no liveliness token on {where}); check --connect and that `fusiond run` is up", file=sys.stderr)
        return 1
    end = None if duration is None else time.monotonic() + duration
    enc = msgspec.json.Encoder()
    live = None
    plain = not as_json and not (hasattr(out, "isatty") and out.isatty())
    if not as_json and not plain:
        from rich.console import Console
        from rich.live import Live

        live = Live(render([]), console=Console(file=out), refresh_per_second=4, transient=False)
        live.start()
    try:
        while not stop.is_set() and (end is None or time.monotonic() < end):
            asked = time.monotonic()
            # asked, and the answers waited for, just before they are shown: each view shows the daemons' health
            # of that moment (shown an interval after it was asked, it read an interval old)
            mon.refresh_health(timeout=max(min(interval, stale), 0.1))
            snaps = mon.snapshot(stale, mon.link_up())
            wall = time.time()
            if fleet:
                rows = fleet_rows(snaps)
                if as_json:
                    for r in rows:
                        out.write(enc.encode({"time": wall, **r}).decode() + "\n")
                    out.flush()
                elif plain:
                    out.write("\n".join(fleet_lines(rows, wall)) + "\n")
                    out.flush()
                else:
                    live.update(render_fleet(rows))
            elif as_json:
                for s in snaps:
                    out.write(enc.encode({"time": wall, **s}).decode() + "\n")
                out.flush()
            elif plain:
                out.write("\n".join(plain_lines(snaps, wall)) + "\n")
                out.flush()
            else:
                live.update(render(snaps))
            if stop.wait(max(asked + interval - time.monotonic(), 0.0)):
                break
    except KeyboardInterrupt:
        pass
    finally:
        if live is not None:
            live.stop()
        mon.close()
    return 0


__all__ = ["Monitor", "DaemonView", "ChannelView", "Verdict", "as_of_silence", "decode_diagnostics", "nis_figures",
           "plain_lines", "render", "run", "state_note"]
