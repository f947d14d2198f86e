#!/usr/bin/env python3
"""Soak test of `fusiond run`: a daemon subprocess fed 1 kHz IMU + 100 Hz odometry for N minutes.

    python scripts/soak.py [--minutes 10] [--imu-hz 1000] [--odom-hz 100] [--sample-s 5]
                           [--warmup-s 30] [--slope-threshold 1.0] [--json out/soak.json] [--state]

The daemon runs as its own process (`python -m fusiond run`, the Jackal sensor setup of
examples/jackal.toml on a free loopback port, multicast off); this script is a Zenoh peer
of it that publishes the sensors (CDR, stamps = wall clock, in stamp order) and
subscribes to the fused pose. Every `--sample-s` seconds it records:

- the daemon's RSS (VmRSS of /proc/PID/status),
- end-to-end latency percentiles of that window: odometry put -> its pose's arrival
  (matched by header stamp; every pose stamp is the stamp of the odometry that made it),
- the daemon's health: published poses, queue depth, queue_full and other drops.

At the end it prints a table and a summary and writes everything as JSON. The memory
verdict is a least-squares line through the RSS samples after `--warmup-s` (allocator
and import warm-up): a slope above `--slope-threshold` MiB/min is flagged ("GROWING",
exit status 1); otherwise "flat" (exit 0). Exit 2 when the daemon dies or never answers.

Not part of CI (minutes long); tests/e2e/test_soak.py runs it for ~10 s to keep it working.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from array import array
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import zenoh  # noqa: E402

from fusiond.config import ZenohConfig  # noqa: E402
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample  # noqa: E402
from fusiond.transport.session import build_config, open_session, query_health  # noqa: E402

_STAMP = struct.Struct("<iI")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rss_mib(pid: int) -> float:
    """VmRSS of a process, MiB (nan when it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return math.nan


def memory_slope(minutes: list[float], mib: list[float]) -> float:
    """Least-squares slope of RSS over time, MiB/min (0 with fewer than 2 points)."""
    pts = [(t, m) for t, m in zip(minutes, mib) if math.isfinite(m)]
    n = len(pts)
    if n < 2:
        return 0.0
    mt = sum(t for t, _ in pts) / n
    mm = sum(m for _, m in pts) / n
    var = sum((t - mt) ** 2 for t, _ in pts)
    if var == 0.0:
        return 0.0
    return sum((t - mt) * (m - mm) for t, m in pts) / var


def percentile(sorted_values, q: float) -> float:
    if not sorted_values:
        return math.nan
    k = min(len(sorted_values) - 1, max(0, round(q / 100.0 * (len(sorted_values) - 1))))
    return sorted_values[k]


def _cov(n: int, values: list[float]) -> tuple[float, ...]:
    c = [0.0] * (n * n)
    for i, v in enumerate(values):
        c[(n + 1) * i] = v
    return tuple(c)


class Templates:
    """Pre-encoded CDR messages whose stamp is patched in place (encoding each one would cost more
    than the daemon's work). The robot drives straight at 0.5 m/s, level, gyro at rest + noise-free."""

    def __init__(self) -> None:
        self.odom = bytearray(encode_sample(
            OdomSample("wheel", 1.0, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), _cov(6, [1e-3, 1e-3, 1e-3, 1e6, 1e6, 1e-2])),
            "ros2-cdr"))
        self.imu = bytearray(encode_sample(
            ImuSample("imu", 1.0, (0.0, 0.0, 0.0, 1.0), _cov(3, [1e-4, 1e-4, 1e-2]), (0.0, 0.0, 0.0),
                      _cov(3, [1e-5] * 3)), "ros2-cdr"))

    @staticmethod
    def stamped(buf: bytearray, sec: int, nsec: int) -> bytes:
        _STAMP.pack_into(buf, 4, sec, nsec)
        return bytes(buf)


def write_config(path: Path, port: int, state: Path | None = None) -> None:
    """The soak's config; with ``state``, the daemon also persists its filter state there every second."""
    saved = f'[state]\npath = "{state}"\nsave_interval_s = 1.0\n\n' if state is not None else ""
    path.write_text(f'[zenoh]\nmode = "peer"\nlisten = ["tcp/127.0.0.1:{port}"]\nmulticast_scouting = false\n\n'
                    + saved + (ROOT / "examples" / "jackal.toml").read_text())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="duration of the load (default 10)")
    ap.add_argument("--imu-hz", type=float, default=1000.0)
    ap.add_argument("--odom-hz", type=float, default=100.0)
    ap.add_argument("--sample-s", type=float, default=5.0, help="RSS/health/latency sampling period (default 5 s)")
    ap.add_argument("--warmup-s", type=float, default=30.0, help="samples before this are left out of the memory fit")
    ap.add_argument("--slope-threshold", type=float, default=1.0, help="MiB/min above which memory is flagged")
    ap.add_argument("--json", default="out/soak.json", help="where to write the results (default out/soak.json)")
    ap.add_argument("--quiet", action="store_true", help="no per-sample lines while running")
    ap.add_argument("--state", action="store_true", help="the daemon persists its state every second ([state])")
    args = ap.parse_args(argv)

    duration = args.minutes * 60.0
    tmp = Path(tempfile.mkdtemp(prefix="fusiond-soak-"))
    port = free_port()
    config = tmp / "soak.toml"
    write_config(config, port, tmp / "state" if args.state else None)
    log_path = tmp / "daemon.log"
    with open(log_path, "wb") as err:
        proc = subprocess.Popen([sys.executable, "-m", "fusiond", "run", "--config", str(config)], cwd=ROOT,
                                stdout=subprocess.DEVNULL, stderr=err, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    session = None
    samples: list[dict] = []
    latencies = array("d")  # seconds, all poses
    window: list[float] = []
    lock = threading.Lock()
    put_times: dict[bytes, float] = {}
    sent = {"imu": 0, "wheel": 0}
    exit_code = None
    try:
        session = open_session(build_config(ZenohConfig(mode="peer", connect=[f"tcp/127.0.0.1:{port}"],
                                                        multicast_scouting=False)))

        def on_pose(sample: zenoh.Sample) -> None:
            now = time.monotonic()
            key = bytes(sample.payload.to_bytes()[4:12])
            t = put_times.pop(key, None)
            if t is not None:
                with lock:
                    latencies.append(now - t)
                    window.append(now - t)

        sub = session.declare_subscriber("odom_combined", on_pose)
        deadline = time.monotonic() + 60.0
        while not query_health(session, "fusiond/health", 0.5):
            if proc.poll() is not None or time.monotonic() > deadline:
                print(f"soak: the daemon did not start (log: {log_path})", file=sys.stderr)
                return 2
        block = zenoh.CongestionControl.BLOCK
        pub_imu = session.declare_publisher("imu/data", congestion_control=block)
        pub_odom = session.declare_publisher("jackal_velocity_controller/odom", congestion_control=block)
        tpl = Templates()
        imu_dt, odom_dt = 1.0 / args.imu_hz, 1.0 / args.odom_hz
        stamp0 = 1000.0
        t0 = time.monotonic()
        next_sample = t0
        k_imu = k_odom = 0
        print(f"soak: daemon pid {proc.pid}, {args.imu_hz:g} Hz IMU + {args.odom_hz:g} Hz odometry for "
              f"{args.minutes:g} min, sampling every {args.sample_s:g} s; log {log_path}", flush=True)
        if not args.quiet:
            print(f"{'t_s':>7} {'rss_MiB':>8} {'published':>9} {'q_depth':>7} {'q_full':>7} {'dropped':>7} "
                  f"{'lat_p50_ms':>10} {'lat_p99_ms':>10} {'lat_max_ms':>10}", flush=True)
        while True:
            now = time.monotonic()
            el = now - t0
            if el >= duration:
                break
            # everything due by now, in stamp order (odometry 0.5 ms after the IMU of its tick)
            while True:
                t_imu = k_imu * imu_dt
                t_odom = k_odom * odom_dt + 0.0005
                if min(t_imu, t_odom) > el:
                    break
                if t_imu <= t_odom:
                    s = stamp0 + t_imu
                    sec = math.floor(s)
                    pub_imu.put(tpl.stamped(tpl.imu, sec, round((s - sec) * 1e9)))
                    k_imu += 1
                    sent["imu"] += 1
                else:
                    s = stamp0 + t_odom
                    sec = math.floor(s)
                    payload = tpl.stamped(tpl.odom, sec, round((s - sec) * 1e9))
                    put_times[payload[4:12]] = time.monotonic()
                    pub_odom.put(payload)
                    k_odom += 1
                    sent["wheel"] += 1
            if now >= next_sample:
                next_sample += args.sample_s
                samples.append(take_sample(session, proc, el, window, lock))
                if not args.quiet:
                    print(row(samples[-1]), flush=True)
                if proc.poll() is not None:
                    print(f"soak: the daemon exited with {proc.returncode} (log: {log_path})", file=sys.stderr)
                    return 2
            time.sleep(0.001)
        time.sleep(1.0)  # the last poses
        samples.append(take_sample(session, proc, time.monotonic() - t0, window, lock))
        if not args.quiet:
            print(row(samples[-1]), flush=True)
        sub.undeclare()
        proc.send_signal(signal.SIGTERM)
        try:
            exit_code = proc.wait(20)
        except subprocess.TimeoutExpired:
            exit_code = None
    finally:
        if session is not None:
            session.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)

    fit = [s for s in samples if s["t_s"] >= args.warmup_s] or samples
    slope = memory_slope([s["t_s"] / 60.0 for s in fit], [s["rss_mib"] for s in fit])
    lat = sorted(latencies)
    last = samples[-1]["health"] if samples else {}
    summary = {
        "minutes": args.minutes,
        "imu_hz": args.imu_hz,
        "odom_hz": args.odom_hz,
        "sent": sent,
        "rate_achieved_hz": {k: v / duration for k, v in sent.items()},
        "poses_matched": len(lat),
        "latency_ms": {f"p{q}": 1e3 * percentile(lat, q) for q in (50, 90, 99, 99.9)} | {"max": 1e3 * (lat[-1] if lat else math.nan)},
        "rss_mib": {"first": samples[0]["rss_mib"] if samples else math.nan,
                    "last": samples[-1]["rss_mib"] if samples else math.nan,
                    "max": max((s["rss_mib"] for s in samples), default=math.nan)},
        "rss_slope_mib_per_min": slope,
        "slope_fit_samples": len(fit),
        "slope_threshold_mib_per_min": args.slope_threshold,
        "memory": "GROWING" if slope > args.slope_threshold else "flat",
        "queue_full": last.get("queue_full", 0),
        "dropped": last.get("dropped", {}),
        "published": last.get("published", 0),
        "daemon_exit_code": exit_code,
        "machine": f"{os.uname().machine}, {os.cpu_count()} CPUs",
    }
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"summary": summary, "samples": samples}, indent=1))
    print()
    print(f"sent          imu {sent['imu']}  odometry {sent['wheel']}  "
          f"({summary['rate_achieved_hz']['imu']:.0f} / {summary['rate_achieved_hz']['wheel']:.0f} Hz)")
    print(f"poses         {summary['published']} published, {len(lat)} matched to their odometry put")
    print("latency ms    " + "  ".join(f"{k} {v:.2f}" for k, v in summary["latency_ms"].items()))
    print(f"drops         queue_full {summary['queue_full']}  by sensor {summary['dropped']}")
    print(f"RSS MiB       first {summary['rss_mib']['first']:.1f}  last {summary['rss_mib']['last']:.1f}  "
          f"max {summary['rss_mib']['max']:.1f}")
    print(f"RSS slope     {slope:+.3f} MiB/min over {len(fit)} samples after {args.warmup_s:g} s "
          f"(threshold {args.slope_threshold:g}): {summary['memory']}")
    print(f"daemon exit   {exit_code}")
    print(f"json          {out}")
    if exit_code != 0:
        return 2
    return 1 if summary["memory"] == "GROWING" else 0


def take_sample(session, proc, t: float, window: list[float], lock: threading.Lock) -> dict:
    with lock:
        w = sorted(window)
        window.clear()
    h = {}
    answers = query_health(session, "fusiond/health", 2.0)
    if answers:
        rep = json.loads(answers[0])
        h = {"status": rep["status"], "published": rep["published"], "queue_depth": rep["queue"]["depth"],
             "queue_full": rep["queue"]["dropped"],
             "dropped": {n: s["dropped_by_reason"] for n, s in rep["sensors"].items() if s["dropped"]}}
    return {"t_s": round(t, 2), "rss_mib": rss_mib(proc.pid), "health": h, "poses_in_window": len(w),
            "latency_ms": {"p50": 1e3 * percentile(w, 50), "p99": 1e3 * percentile(w, 99),
                           "max": 1e3 * (w[-1] if w else math.nan)}}


def row(s: dict) -> str:
    h = s["health"]
    n_drop = sum(sum(d.values()) for d in h.get("dropped", {}).values())
    lat = s["latency_ms"]
    return (f"{s['t_s']:7.1f} {s['rss_mib']:8.1f} {h.get('published', -1):9d} {h.get('queue_depth', -1):7d} "
            f"{h.get('queue_full', -1):7d} {n_drop:7d} {lat['p50']:10.2f} {lat['p99']:10.2f} {lat['max']:10.2f}")


if __name__ == "__main__":
    raise SystemExit(main())
