"""A fleet on loopback: a `fusiond router` process, daemons in client mode with a namespace each, a feeder
per robot, and a `fusiond monitor` whose JSON lines are read as they come. Every process is bounded in
time by its caller's deadlines and killed on exit."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from fusiond.config import ZenohConfig
from fusiond.transport.session import build_config, open_session

from .daemon import ROOT, fusiond_cmd, wait_until
from .reliability import IMU_KEY, WHEEL_KEY, imu_payload, odom_payload


def start_router(port: int, log: Path) -> subprocess.Popen:
    """`fusiond router` on 127.0.0.1:port, once it says it listens."""
    err = open(log, "ab")
    proc = subprocess.Popen(fusiond_cmd("router", "--listen", f"tcp/127.0.0.1:{port}"), cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=err, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    err.close()
    line: list[str] = []
    reader = threading.Thread(target=lambda: line.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(20)
    if not line or "listening" not in line[0]:
        proc.kill()
        proc.wait(5)
        raise AssertionError(f"the router did not start on port {port}: {log.read_text()}")
    return proc


def robot_config(path: Path, router_port: int, namespace: str, metrics_port: int | None = None) -> Path:
    """A daemon of examples/jackal.toml's sensors, a client of the router, in ``namespace``."""
    metrics = f'[metrics]\nlisten = "127.0.0.1:{metrics_port}"\n\n' if metrics_port else ""
    path.write_text(f'[zenoh]\nmode = "client"\nconnect = ["tcp/127.0.0.1:{router_port}"]\n'
                    f'multicast_scouting = false\nnamespace = "{namespace}"\n\n{metrics}'
                    + (ROOT / "examples" / "jackal.toml").read_text())
    return path


def start_daemon(config: Path, log: Path) -> subprocess.Popen:
    with open(log, "ab") as err:
        return subprocess.Popen(fusiond_cmd("run", "--config", str(config)), cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=err, env={**os.environ, "PYTHONUNBUFFERED": "1"})


def client(port: int, namespace: str = "") -> zenoh.Session:
    return open_session(build_config(ZenohConfig(mode="client", connect=[f"tcp/127.0.0.1:{port}"],
                                                 multicast_scouting=False, namespace=namespace)))


class Feeder:
    """Odometry at 50 Hz and IMU at 100 Hz into one robot's namespace through the router, on a thread
    (puts into a lost router are dropped by Zenoh: the feeder goes on)."""

    def __init__(self, port: int, namespace: str) -> None:
        self.session = client(port, namespace)
        self.odom = self.session.declare_publisher(WHEEL_KEY)
        self.imu = self.session.declare_publisher(IMU_KEY)
        self.stop = threading.Event()
        self.paused = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        k = 0
        t0 = time.monotonic()
        while not self.stop.wait(max(t0 + 0.01 * k - time.monotonic(), 0.0)):
            if not self.paused.is_set():
                stamp = 1000.0 + 0.01 * k
                self.imu.put(imu_payload(stamp))
                if k % 2 == 0:
                    self.odom.put(odom_payload(stamp))
            k += 1

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)
        self.session.close()


class MonitorLines:
    """`fusiond monitor ... --json` as a process; its records, each with the monotonic time it was read
    (``json_lines=False``: the plain text lines it prints into a pipe, in ``lines``)."""

    def __init__(self, *args: str, json_lines: bool = True) -> None:
        self.proc = subprocess.Popen(fusiond_cmd("monitor", *(["--json"] if json_lines else []), *args), cwd=ROOT,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.json_lines = json_lines
        self.records: list[tuple[float, dict]] = []
        self.lines: list[tuple[float, str]] = []
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            with self.lock:
                if self.json_lines and line.startswith("{"):
                    self.records.append((time.monotonic(), json.loads(line)))
                elif not self.json_lines:
                    self.lines.append((time.monotonic(), line.rstrip("\n")))

    def wait_line(self, text: str, timeout: float, after: float = 0.0) -> tuple[float, str]:
        """The first plain line holding ``text`` read after ``after`` (monotonic), and when."""
        def found():
            with self.lock:
                return next(((t, ln) for t, ln in self.lines if t >= after and text in ln), None)
        return wait_until(found, timeout, f"{text!r} in the monitor's lines", step=0.05)

    def of(self, daemon: str, after: float = 0.0) -> list[dict]:
        with self.lock:
            return [r for t, r in self.records if t >= after and r["daemon"] == daemon]

    def wait(self, daemon: str, status: str, timeout: float, after: float = 0.0) -> tuple[float, dict]:
        """The first record of ``daemon`` with ``status`` read after ``after`` (monotonic), and when."""
        def found():
            if self.proc.poll() is not None and not self.thread.is_alive():
                raise AssertionError(f"the monitor exited {self.proc.returncode}: {self.proc.stderr.read()}")
            with self.lock:
                return next(((t, r) for t, r in self.records
                             if t >= after and r["daemon"] == daemon and r["status"] == status), None)
        return wait_until(found, timeout, f"{daemon} {status} in the monitor's records", step=0.05)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.thread.join(5)


@contextmanager
def processes() -> Iterator[list]:
    """Processes and closables started inside the block: killed / closed on the way out, in reverse."""
    started: list = []
    try:
        yield started
    finally:
        for p in reversed(started):
            if isinstance(p, subprocess.Popen):
                if p.poll() is None:
                    p.kill()
                p.wait(10)
            else:
                p.close()
