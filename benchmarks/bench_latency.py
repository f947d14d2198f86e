"""Latency and CPU benchmark: sensor put -> fused pose, beside the raw Zenoh hop and a bare subscriber.

Three processes, three Zenoh sessions on loopback TCP:

- the daemon's (a child process running the same `Daemon` class `fusiond run` uses:
  subscribers, queue, worker, core, publishers);
- a bare zenoh-python subscriber's (a child process: the two sensor keys with
  zenoh-python's default callback, each payload copied to bytes and counted: the
  least any consumer of this traffic does) -- the yardstick of the daemon's CPU;
- the load generator's (this process), connected to both, which publishes synthetic
  IMU (default 1 kHz) and odometry (100 Hz) CDR with increasing stamps ("live
  stamps") and subscribes to the fused pose. Each odometry sample is stamped half
  an IMU period after the IMU before it, so the pose it triggers carries its stamp:
  poses are matched to puts by stamp.

Separate processes because Zenoh's runtime threads are per process: CPU time of one
process is exactly one party's cost (its session, its Python threads), so the two
are comparable in the same run, on the same traffic, under the same machine load.

Beside it, every odometry put is followed by a put on a plain echo key: the
daemon's session timestamps it (raw one-way hop) and echoes it straight back to
the generator (raw round trip: the same two hops a fused pose takes, without the
queue, the filter and the encoding in between).

CPU: process time per wall second over the measured window (each child reads its
own `process_time()` at the window's start and end, asked over a pipe), for the
daemon, the bare subscriber, and the daemon's worker thread (its timers: samples are
fused on the threads that receive them) and the generator thread on their own. The
daemon's process also carries the echo (100 Hz, a few us each): counted against it,
not the yardstick.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import socket
import struct
import threading
import time
from collections.abc import Callable
from statistics import median
from typing import Any

import msgspec
import numpy as np
import zenoh

from fusiond.config import ZenohConfig, loads
from fusiond.errors import TransportError
from fusiond.estimator.backend import from_environment
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample
from fusiond.health import decode_report, encode_report
from fusiond.logs import configure
from fusiond.transport.daemon import Daemon, direct
from fusiond.transport.session import build_config, open_session, query_health

_STAMP = struct.Struct("<iI").unpack_from
_F64 = struct.Struct("<d")
BARE_READY_KEY = "bench/bare/ready"


class Stats(msgspec.Struct):
    n: int
    p50_us: float
    p90_us: float
    p99_us: float
    max_us: float
    mean_us: float


class BenchResult(msgspec.Struct):
    seconds: float
    imu_hz: float
    odom_hz: float
    express: bool
    imu_sent: int
    odom_sent: int
    sent_total: int  # sensor messages of the whole run (warm-up included)
    poses_matched: int
    poses_unmatched: int  # poses whose stamp is not an odometry stamp (the odometry arrived late)
    pose: Stats  # odometry put -> fused pose callback at the generator
    raw_hop: Stats  # put -> callback in the daemon's session (one hop)
    raw_echo: Stats  # put -> daemon session -> echoed back -> generator (two hops)
    raw_hop_idle: Stats  # the same two, measured before the load starts (no worker competing for the GIL)
    raw_echo_idle: Stats
    cpu_daemon_pct: float  # the daemon's process, of one core
    cpu_bare_pct: float  # the bare subscriber's process on the same traffic, same window
    cpu_ratio: float  # daemon / bare
    cpu_worker_pct: float  # the daemon's worker thread alone (its timers: samples are fused where they arrive)
    cpu_generator_pct: float
    passes: int  # the daemon's passes that fused samples, in the measured window (each one sample or more)
    messages_in_window: int  # sensor messages sent in the measured window
    bare_received: int  # sensor messages the bare subscriber got (whole run: = sent_total)
    daemon_received: int  # the same at the daemon (health's `received`)
    queue_drops: int
    core_drops: int
    diagnostics_batch_s: float | None  # the daemon's [output] diagnostics_batch_s (None: its default)
    zenoh_version: str


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _stats(values_s: list[float]) -> Stats:
    if not values_s:
        return Stats(0, math.nan, math.nan, math.nan, math.nan, math.nan)
    a = np.asarray(values_s) * 1e6
    p50, p90, p99 = np.percentile(a, [50, 90, 99])
    return Stats(len(a), float(p50), float(p90), float(p99), float(a.max()), float(a.mean()))


def _config_text(port: int, diagnostics_batch_s: float | None = None) -> str:
    batch = "" if diagnostics_batch_s is None else f"diagnostics_batch_s = {diagnostics_batch_s!r}\n"
    return f"""
[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
[output]
pose_key = "bench/pose"
odometry_key = "bench/odometry"
diagnostics_key = "bench/diagnostics"
health_key = "bench/health"
{batch}[[sensors]]
name = "wheel"
kind = "odom"
key = "bench/odom"
[[sensors]]
name = "imu"
kind = "imu"
key = "bench/imu"
orientation = "roll_pitch"
angular_velocity = true
"""


def _schedule(seconds: float, imu_hz: float, odom_hz: float, t0: float = 1000.0
              ) -> list[tuple[float, str, bytes, tuple[int, int]]]:
    """(offset s, "imu"|"odom", CDR, stamp) pre-encoded, so the generator spends no time encoding."""
    every = max(int(round(imu_hz / odom_hz)), 1)
    v, w = 0.5, 0.2  # driving a circle
    cov_o = (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4)
    cov_g = (1e-5, 0, 0, 0, 1e-5, 0, 0, 0, 1e-5)
    twist_cov = tuple(float(x) for x in np.diag([1e-3] * 3 + [1e-3] * 3).ravel())
    out = []
    n = int(seconds * imu_hz)
    for k in range(n):
        t = k / imu_hz
        yaw = w * t
        q = (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
        stamp = t0 + t
        out.append((t, "imu", encode_sample(ImuSample("imu", stamp, q, cov_o, (0.0, 0.0, w), cov_g), "ros2-cdr"),
                    _ros(stamp)))
        if k % every == 0:
            ts = t + 0.5 / imu_hz
            out.append((ts, "odom", encode_sample(
                OdomSample("wheel", t0 + ts, (v, 0.0, 0.0), (0.0, 0.0, w), twist_cov), "ros2-cdr"), _ros(t0 + ts)))
    return out


def _ros(stamp: float) -> tuple[int, int]:
    sec = math.floor(stamp)
    return sec, round((stamp - sec) * 1e9)


def _thread_cpu(ident: int | None) -> float:
    try:
        return time.clock_gettime(time.pthread_getcpuclockid(ident))  # type: ignore[arg-type]
    except (OSError, AttributeError, TypeError):
        return math.nan


def _wait(cond, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.01)
    return True


def thread_timed(fn: Callable[..., Any], acc: dict[str, float], key: str) -> Callable[..., Any]:
    """``fn`` adding the calling thread's CPU time it takes to ``acc[key]`` (a daemon worker's share per part)."""
    clock = time.thread_time

    def wrapper(*args: Any) -> Any:
        t = clock()
        try:
            return fn(*args)
        finally:
            acc[key] += clock() - t

    return wrapper


def feed_daemon(daemon: Daemon, cfg: Any, port: int, seconds: float) -> int:
    """Feed a started in-process ``daemon`` (listening on ``port``) ``seconds`` of 1 kHz IMU and 100 Hz odometry
    at their real pace from a second session, wait (5 s at most) until it applied them, then stop it; the
    messages sent. Its worker's CPU (``daemon.worker_cpu_s``) is then the run's."""
    g_session = open_session(build_config(msgspec.structs.replace(
        cfg.zenoh, listen=[], connect=[f"tcp/127.0.0.1:{port}"])))
    block = zenoh.CongestionControl.BLOCK
    pubs = {k: g_session.declare_publisher(f"bench/{k}", express=True, congestion_control=block).put
            for k in ("imu", "odom")}
    if not _wait(lambda: query_health(g_session, cfg.output.health_key, 0.5), 10.0):
        raise SystemExit("the daemon did not answer its health query within 10 s")
    schedule = _schedule(seconds, 1000.0, 100.0)
    start = time.perf_counter()
    for offset, kind, payload, _ in schedule:
        delay = start + offset - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        pubs[kind](payload)
    _wait(lambda: sum(s.applied for s in daemon.report().sensors.values()) >= len(schedule), 5.0)
    daemon.stop()
    g_session.close()
    return len(schedule)


def _ping(put: Any, echo: list[float], seconds: float, hz: float = 500.0) -> list[float]:
    """Echo pings alone (no sensor load): the round trip of this machine at rest (the hops are the daemon's)."""
    echo.clear()
    start = time.perf_counter()
    for k in range(int(seconds * hz)):
        delay = start + k / hz - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        put(_F64.pack(time.perf_counter()))
    _wait(lambda: len(echo) >= int(seconds * hz), 1.0)
    out = list(echo)
    echo.clear()
    return out


def _take(values: list[float]) -> list[float]:
    """Move out what a callback thread has appended so far (it may append meanwhile: nothing is lost)."""
    n = len(values)
    out = values[:n]
    del values[:n]
    return out


def _daemon_child(conn: Any, config_text: str, express: bool) -> None:
    """Child process: the daemon (as `fusiond run` builds it) plus the echo; answers the parent's commands."""
    configure("warning")  # a spawned child starts unconfigured: logs on stderr, stdout stays the table/JSON
    cfg = loads(config_text, "<bench>")
    session = open_session(build_config(cfg.zenoh))
    # the estimator's backend as `fusiond run` would take it (FUSIOND_KERNELS)
    daemon = Daemon(cfg, session, express=express, monitor=False, backend=from_environment(os.environ))
    hop: list[float] = []
    perf = time.perf_counter  # CLOCK_MONOTONIC: comparable with the parent's stamps
    objs: list[Any] = []
    try:
        daemon.start()
        echo_pub = session.declare_publisher("bench/echo_back", express=True,
                                             congestion_control=zenoh.CongestionControl.BLOCK)

        def on_echo(sample: zenoh.Sample) -> None:
            t = perf()
            raw = sample.payload.to_bytes()
            hop.append(t - _F64.unpack(raw)[0])
            echo_pub.put(raw)

        objs += [echo_pub, session.declare_subscriber("bench/echo", direct(on_echo))]
        worker = daemon._worker.ident if daemon._worker else None
        conn.send("ready")
        while (cmd := conn.recv()) != "stop":
            if cmd == "mark":
                conn.send((time.process_time(), _thread_cpu(worker), daemon.passes))
            elif cmd == "hops":
                conn.send(_take(hop))
            elif cmd == "drained":
                conn.send(daemon.queued() == 0)
            elif cmd == "report":
                conn.send(encode_report(daemon.report()))
    finally:
        for o in objs:
            try:
                o.undeclare()
            except zenoh.ZError:
                pass
        daemon.stop()
        session.close()


def _bare_child(conn: Any, port: int, keys: list[str]) -> None:
    """Child process: the yardstick. A plain subscriber per sensor key (zenoh-python's default
    callback), each payload copied to bytes and counted; then a queryable that proves them declared."""
    session = open_session(build_config(ZenohConfig(mode="peer", listen=[f"tcp/127.0.0.1:{port}"],
                                                    multicast_scouting=False)))
    counts = [0] * len(keys)  # one slot per subscriber: each is written by its own callback thread only

    def counter(i: int) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            sample.payload.to_bytes()
            counts[i] += 1
        return on_sample

    objs = [session.declare_subscriber(k, counter(i)) for i, k in enumerate(keys)]
    objs.append(session.declare_queryable(BARE_READY_KEY, lambda q: q.reply(BARE_READY_KEY, b"ready")))
    try:
        conn.send("ready")
        while conn.recv() != "stop":
            conn.send((time.process_time(), sum(counts)))
    finally:
        for o in objs:
            o.undeclare()
        session.close()


def _ask(conn: Any, cmd: str, timeout: float = 10.0) -> Any:
    conn.send(cmd)
    if not conn.poll(timeout):
        raise TransportError(f"a benchmark child did not answer {cmd!r} within {timeout:g} s")
    return conn.recv()


def _answered(session: zenoh.Session, key: str) -> bool:
    return any(r.ok is not None for r in session.get(key, timeout=0.5))


def run_bench(seconds: float = 10.0, imu_hz: float = 1000.0, odom_hz: float = 100.0, *, express: bool = False,
              warmup_s: float = 1.0, idle_s: float = 1.0, diagnostics_batch_s: float | None = None) -> BenchResult:
    port, bare_port = free_port(), free_port()
    text = _config_text(port, diagnostics_batch_s)
    cfg = loads(text, "<bench>")
    schedule = _schedule(seconds + warmup_s, imu_hz, odom_hz)
    ctx = multiprocessing.get_context("spawn")  # no fork of a process that may hold Zenoh threads
    d_conn, d_end = ctx.Pipe()
    b_conn, b_end = ctx.Pipe()
    children = [ctx.Process(target=_daemon_child, args=(d_end, text, express), name="bench-daemon", daemon=True),
                ctx.Process(target=_bare_child, args=(b_end, bare_port, [s.key for s in cfg.sensors]),
                            name="bench-bare-subscriber", daemon=True)]
    for p in children:
        p.start()
    g_session = None
    echo: list[float] = []
    pose_arrival: dict[tuple[int, int], float] = {}
    perf = time.perf_counter
    try:
        for conn, p in zip((d_conn, b_conn), children):
            if not _wait(lambda: conn.poll() or not p.is_alive(), 60.0) or not conn.poll():
                raise TransportError(f"{p.name} did not start within 60 s (exit code {p.exitcode}; a script "
                                     "calling run_bench needs `if __name__ == '__main__':`, children are spawned)")
            conn.recv()
        g_session = open_session(build_config(msgspec.structs.replace(
            cfg.zenoh, listen=[], connect=[f"tcp/127.0.0.1:{port}", f"tcp/127.0.0.1:{bare_port}"])))

        def on_echo_back(sample: zenoh.Sample) -> None:
            echo.append(perf() - _F64.unpack(sample.payload.to_bytes())[0])

        def on_pose(sample: zenoh.Sample) -> None:
            t = perf()
            pose_arrival[_STAMP(sample.payload.to_bytes(), 4)] = t

        block = zenoh.CongestionControl.BLOCK  # as the bridge publishes reliable topics: no silent loss
        g_session.declare_subscriber("bench/echo_back", direct(on_echo_back))
        g_session.declare_subscriber("bench/pose", direct(on_pose))
        imu_put = g_session.declare_publisher("bench/imu", express=True, congestion_control=block).put
        odom_put = g_session.declare_publisher("bench/odom", express=True, congestion_control=block).put
        echo_put = g_session.declare_publisher("bench/echo", express=True, congestion_control=block).put
        if not _wait(lambda: query_health(g_session, cfg.output.health_key, 0.5), 10.0):
            raise TransportError("the daemon did not answer its health query within 10 s")
        if not _wait(lambda: _answered(g_session, BARE_READY_KEY), 10.0):
            raise TransportError("the bare subscriber did not answer within 10 s")
        time.sleep(0.2)
        echo_idle = _ping(echo_put, echo, idle_s)
        hop_idle = _ask(d_conn, "hops")

        put_time: dict[tuple[int, int], float] = {}
        main_ident = threading.get_ident()
        sleep = time.sleep
        start = perf()
        measuring = False
        marks: dict[str, Any] = {}
        for offset, kind, payload, stamp in schedule:
            if not measuring and offset >= warmup_s:
                measuring = True
                _ask(d_conn, "hops")
                echo.clear()
                marks = {"wall": perf(), "daemon": _ask(d_conn, "mark"), "bare": _ask(b_conn, "mark"),
                         "main": _thread_cpu(main_ident), "first_stamp": stamp}
            delay = start + offset - perf()
            if delay > 0:
                sleep(delay)
            if kind == "imu":
                imu_put(payload)
            else:
                t = perf()
                odom_put(payload)
                echo_put(_F64.pack(perf()))
                if measuring:
                    put_time[stamp] = t
        _wait(lambda: all(k in pose_arrival for k in put_time) and _ask(d_conn, "drained"), 2.0)
        wall = perf() - marks["wall"]
        (d_cpu1, w_cpu1, passes1), (b_cpu1, bare_received) = _ask(d_conn, "mark"), _ask(b_conn, "mark")
        main_cpu = _thread_cpu(main_ident) - marks["main"]
        (d_cpu0, w_cpu0, passes0), (b_cpu0, _) = marks["daemon"], marks["bare"]
        hop = _ask(d_conn, "hops")
        _wait(lambda: _ask(b_conn, "mark")[1] >= len(schedule), 1.0)  # the last puts may be in flight
        bare_received = _ask(b_conn, "mark")[1]
        rep = decode_report(_ask(d_conn, "report"))
        lat = [pose_arrival[s] - t for s, t in put_time.items() if s in pose_arrival]
        first = marks["first_stamp"]
        unmatched = sum(1 for s in list(pose_arrival) if s >= first and s not in put_time)
        n_imu = sum(1 for o, k, *_ in schedule if k == "imu" and o >= warmup_s)
        daemon_pct, bare_pct = 100.0 * (d_cpu1 - d_cpu0) / wall, 100.0 * (b_cpu1 - b_cpu0) / wall
        return BenchResult(
            seconds=seconds, imu_hz=imu_hz, odom_hz=odom_hz, express=express,
            imu_sent=n_imu, odom_sent=len(put_time), sent_total=len(schedule),
            poses_matched=len(lat), poses_unmatched=unmatched,
            pose=_stats(lat), raw_hop=_stats(hop), raw_echo=_stats(echo),
            raw_hop_idle=_stats(hop_idle), raw_echo_idle=_stats(echo_idle),
            cpu_daemon_pct=daemon_pct, cpu_bare_pct=bare_pct,
            cpu_ratio=daemon_pct / bare_pct if bare_pct > 0 else math.nan,
            cpu_worker_pct=100.0 * (w_cpu1 - w_cpu0) / wall,
            cpu_generator_pct=100.0 * main_cpu / wall,
            passes=passes1 - passes0,
            messages_in_window=sum(1 for o, *_ in schedule if o >= warmup_s),
            bare_received=bare_received, daemon_received=sum(s.received for s in rep.sensors.values()),
            queue_drops=rep.queue.dropped,
            core_drops=sum(s.dropped for s in rep.sensors.values()) - rep.queue.dropped,
            diagnostics_batch_s=diagnostics_batch_s,
            zenoh_version=_zenoh_version(),
        )
    finally:
        for conn in (d_conn, b_conn):
            try:
                conn.send("stop")
            except (OSError, ValueError):
                pass
        for p in children:
            p.join(10.0)
            if p.is_alive():
                p.kill()
                p.join(5.0)
        if g_session is not None:
            g_session.close()


def _zenoh_version() -> str:
    try:
        from importlib.metadata import version

        return version("eclipse-zenoh")
    except Exception:
        return "unknown"


def format_runs(results: list[BenchResult]) -> str:
    """One line a run and the CPU ratio's median over them: the bare subscriber's own share moves with where
    the system places its threads (each run starts its processes afresh), so one run's ratio is one draw."""
    out = [f"{'run':>4}{'ratio':>8}{'daemon %':>10}{'bare %':>8}{'worker %':>10}{'pose p50 us':>13}{'p99 us':>9}"]
    for i, r in enumerate(results, 1):
        out.append(f"{i:>4}{r.cpu_ratio:>8.2f}{r.cpu_daemon_pct:>10.1f}{r.cpu_bare_pct:>8.1f}{r.cpu_worker_pct:>10.1f}"
                   f"{r.pose.p50_us:>13.0f}{r.pose.p99_us:>9.0f}")
    ratios = [r.cpu_ratio for r in results]
    out.append(f"CPU ratio daemon / bare subscriber over {len(results)} runs: median {median(ratios):.2f} "
               f"({min(ratios):.2f}-{max(ratios):.2f}); the daemon's process median "
               f"{median([r.cpu_daemon_pct for r in results]):.1f} %, the bare subscriber's "
               f"{median([r.cpu_bare_pct for r in results]):.1f} %")
    return "\n".join(out)


def format_table(r: BenchResult) -> str:
    rows = [("fused pose (odom put -> pose)", r.pose), ("raw hop (put -> callback)", r.raw_hop),
            ("raw echo (put -> echo back)", r.raw_echo), ("raw hop, no load", r.raw_hop_idle),
            ("raw echo, no load", r.raw_echo_idle)]
    out = [f"fusiond bench-latency: {r.seconds:g} s, IMU {r.imu_hz:g} Hz + odometry {r.odom_hz:g} Hz, "
           f"loopback TCP, express={r.express}, zenoh {r.zenoh_version}",
           f"{'latency (us)':<32}{'n':>7}{'p50':>9}{'p90':>9}{'p99':>9}{'max':>9}"]
    for name, s in rows:
        out.append(f"{name:<32}{s.n:>7}{s.p50_us:>9.0f}{s.p90_us:>9.0f}{s.p99_us:>9.0f}{s.max_us:>9.0f}")
    ratio_hop = r.pose.p99_us / r.raw_hop.p99_us if r.raw_hop.p99_us else math.nan
    ratio_echo = r.pose.p99_us / r.raw_echo.p99_us if r.raw_echo.p99_us else math.nan
    out.append(f"p99 ratio: fused/raw hop {ratio_hop:.2f}x, fused/raw echo {ratio_echo:.2f}x")
    out.append(f"poses matched {r.poses_matched}/{r.odom_sent} (unmatched {r.poses_unmatched}); "
               f"queue drops {r.queue_drops}, core drops {r.core_drops}")
    out.append(f"CPU (% of one core): daemon process {r.cpu_daemon_pct:.1f}, bare subscriber process "
               f"{r.cpu_bare_pct:.1f} -> ratio {r.cpu_ratio:.2f}x; daemon worker thread (timers) "
               f"{r.cpu_worker_pct:.1f}, load generator thread {r.cpu_generator_pct:.1f}")
    out.append(f"passes that fused {r.passes} for {r.messages_in_window} messages "
               f"({r.passes / max(r.messages_in_window, 1):.2f} a message)")
    batch = "default" if r.diagnostics_batch_s is None else f"{r.diagnostics_batch_s:g} s"
    out.append(f"received (whole run, {r.sent_total} sent): daemon {r.daemon_received}, bare subscriber "
               f"{r.bare_received}; diagnostics batch {batch}")
    return "\n".join(out)
