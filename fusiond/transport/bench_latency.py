"""Latency benchmark: sensor put -> fused pose at a subscriber, beside the raw Zenoh hop.

One process, two Zenoh sessions on loopback TCP: the daemon's (the same `Daemon`
class `fusiond run` uses: subscribers, queue, worker, core, publishers) and a load
generator's, which publishes synthetic IMU (default 1 kHz) and odometry (100 Hz)
CDR with increasing stamps and subscribes to the fused pose. Each odometry sample
is stamped half an IMU period after the IMU before it, so the pose it triggers
carries its stamp: poses are matched to puts by stamp.

Beside it, every odometry put is followed by a put on a plain echo key: the
daemon's session timestamps it (raw one-way hop) and echoes it straight back to
the generator (raw round trip: the same two hops a fused pose takes, without the
queue, the filter and the encoding in between).

CPU: process time per wall second over the measured window (all threads: both
sessions, the generator and the daemon), and the worker thread and the generator
thread on their own.
"""

from __future__ import annotations

import math
import socket
import struct
import threading
import time
from typing import Any

import msgspec
import numpy as np
import zenoh

from ..codecs import encode_imu_sample, encode_odom_sample
from ..config import loads
from ..errors import TransportError
from ..samples import ImuSample, OdomSample
from .daemon import Daemon, direct
from .session import build_config, open_session, query_health

_STAMP = struct.Struct("<iI").unpack_from
_F64 = struct.Struct("<d")


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
    poses_matched: int
    poses_unmatched: int  # poses whose stamp is not an odometry stamp (the odometry arrived late)
    pose: Stats  # odometry put -> fused pose callback at the generator
    raw_hop: Stats  # put -> callback in the daemon's session (one hop)
    raw_echo: Stats  # put -> daemon session -> echoed back -> generator (two hops)
    raw_hop_idle: Stats  # the same two, measured before the load starts (no worker competing for the GIL)
    raw_echo_idle: Stats
    cpu_process_pct: float  # of one core
    cpu_worker_pct: float
    cpu_generator_pct: float
    queue_drops: int
    core_drops: int
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


def _config(port: int) -> Any:
    return loads(f"""
[zenoh]
mode = "peer"
listen = ["tcp/127.0.0.1:{port}"]
multicast_scouting = false
[output]
pose_key = "bench/pose"
odometry_key = "bench/odometry"
diagnostics_key = "bench/diagnostics"
health_key = "bench/health"
[[sensors]]
name = "wheel"
kind = "odom"
key = "bench/odom"
[[sensors]]
name = "imu"
kind = "imu"
key = "bench/imu"
orientation = "roll_pitch"
angular_velocity = true
""", "<bench>")


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
        out.append((t, "imu", encode_imu_sample(ImuSample("imu", stamp, q, cov_o, (0.0, 0.0, w), cov_g), "ros2-cdr"),
                    _ros(stamp)))
        if k % every == 0:
            ts = t + 0.5 / imu_hz
            out.append((ts, "odom", encode_odom_sample(
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


def _ping(put: Any, hop: list[float], echo: list[float], seconds: float, hz: float = 500.0
          ) -> tuple[list[float], list[float]]:
    """Echo pings alone (no sensor load): the raw hop and round trip of this machine at rest."""
    hop.clear()
    echo.clear()
    start = time.perf_counter()
    for k in range(int(seconds * hz)):
        delay = start + k / hz - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
        put(_F64.pack(time.perf_counter()))
    _wait(lambda: len(echo) >= int(seconds * hz), 1.0)
    out = list(hop), list(echo)
    hop.clear()
    echo.clear()
    return out


def run_bench(seconds: float = 10.0, imu_hz: float = 1000.0, odom_hz: float = 100.0, *, express: bool = False,
              warmup_s: float = 1.0, idle_s: float = 1.0) -> BenchResult:
    port = free_port()
    cfg = _config(port)
    schedule = _schedule(seconds + warmup_s, imu_hz, odom_hz)
    d_session = open_session(build_config(cfg.zenoh))
    daemon = Daemon(cfg, d_session, express=express, monitor=False)
    g_conf = build_config(msgspec.structs.replace(cfg.zenoh, listen=[], connect=[f"tcp/127.0.0.1:{port}"]))
    g_session = open_session(g_conf)
    hop: list[float] = []
    echo: list[float] = []
    pose_arrival: dict[tuple[int, int], float] = {}
    perf = time.perf_counter
    objs: list[Any] = []
    try:
        daemon.start()
        block = zenoh.CongestionControl.BLOCK  # as the bridge publishes reliable topics: no silent loss
        echo_pub = d_session.declare_publisher("bench/echo_back", express=True, congestion_control=block)

        def on_echo(sample: zenoh.Sample) -> None:
            t = perf()
            raw = sample.payload.to_bytes()
            hop.append(t - _F64.unpack(raw)[0])
            echo_pub.put(raw)

        def on_echo_back(sample: zenoh.Sample) -> None:
            echo.append(perf() - _F64.unpack(sample.payload.to_bytes())[0])

        def on_pose(sample: zenoh.Sample) -> None:
            t = perf()
            pose_arrival[_STAMP(sample.payload.to_bytes(), 4)] = t

        objs += [echo_pub, d_session.declare_subscriber("bench/echo", direct(on_echo)),
                 g_session.declare_subscriber("bench/echo_back", direct(on_echo_back)),
                 g_session.declare_subscriber("bench/pose", direct(on_pose))]
        pubs = {"imu": g_session.declare_publisher("bench/imu", express=True, congestion_control=block),
                "odom": g_session.declare_publisher("bench/odom", express=True, congestion_control=block)}
        echo_put = g_session.declare_publisher("bench/echo", express=True, congestion_control=block).put
        objs += list(pubs.values())
        if not _wait(lambda: query_health(g_session, cfg.output.health_key, 0.5), 10.0):
            raise TransportError("the daemon did not answer its health query within 10 s")
        time.sleep(0.2)
        hop_idle, echo_idle = _ping(echo_put, hop, echo, idle_s)

        put_time: dict[tuple[int, int], float] = {}
        imu_put, odom_put = pubs["imu"].put, pubs["odom"].put
        worker_ident = daemon._worker.ident if daemon._worker else None
        main_ident = threading.get_ident()
        sleep = time.sleep
        start = perf()
        measuring = False
        marks: dict[str, float] = {}
        for offset, kind, payload, stamp in schedule:
            if not measuring and offset >= warmup_s:
                measuring = True
                hop.clear()
                echo.clear()
                marks = {"wall": perf(), "proc": time.process_time(), "worker": _thread_cpu(worker_ident),
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
        _wait(lambda: all(k in pose_arrival for k in put_time) and daemon.queue.empty(), 2.0)
        wall = perf() - marks["wall"]
        cpu = time.process_time() - marks["proc"]
        worker_cpu = _thread_cpu(worker_ident) - marks["worker"]
        main_cpu = _thread_cpu(main_ident) - marks["main"]
        time.sleep(0.1)
        lat = [pose_arrival[s] - t for s, t in put_time.items() if s in pose_arrival]
        first = marks["first_stamp"]
        unmatched = sum(1 for s in pose_arrival if s >= first and s not in put_time)
        rep = daemon.report()
        n_imu = sum(1 for o, k, *_ in schedule if k == "imu" and o >= warmup_s)
        return BenchResult(
            seconds=seconds, imu_hz=imu_hz, odom_hz=odom_hz, express=express,
            imu_sent=n_imu, odom_sent=len(put_time), poses_matched=len(lat), poses_unmatched=unmatched,
            pose=_stats(lat), raw_hop=_stats(hop), raw_echo=_stats(echo),
            raw_hop_idle=_stats(hop_idle), raw_echo_idle=_stats(echo_idle),
            cpu_process_pct=100.0 * cpu / wall, cpu_worker_pct=100.0 * worker_cpu / wall,
            cpu_generator_pct=100.0 * main_cpu / wall,
            queue_drops=rep.queue.dropped,
            core_drops=sum(s.dropped for s in rep.sensors.values()) - rep.queue.dropped,
            zenoh_version=_zenoh_version(),
        )
    finally:
        for o in objs:
            try:
                o.undeclare()
            except zenoh.ZError:
                pass
        daemon.stop()
        g_session.close()
        d_session.close()


def _zenoh_version() -> str:
    try:
        from importlib.metadata import version

        return version("eclipse-zenoh")
    except Exception:
        return "unknown"


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
    out.append(f"CPU (% of one core): process {r.cpu_process_pct:.1f}, worker thread {r.cpu_worker_pct:.1f}, "
               f"load generator thread {r.cpu_generator_pct:.1f}")
    return "\n".join(out)
