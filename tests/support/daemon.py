"""`fusiond run` as a subprocess on loopback Zenoh: config, process, client session, waits."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from fusiond.config import ZenohConfig
from fusiond.transport.session import build_config, open_session, query_health

ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def write_config(path: Path, port: int, sensors_from: Path = ROOT / "examples" / "jackal.toml") -> Path:
    path.write_text(
        f'[zenoh]\nmode = "peer"\nlisten = ["tcp/127.0.0.1:{port}"]\nmulticast_scouting = false\n\n'
        + sensors_from.read_text()
    )
    return path


def fusiond_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "fusiond", *args]


@contextmanager
def daemon_process(config: Path, log: Path) -> Iterator[subprocess.Popen]:
    with open(log, "wb") as err:
        proc = subprocess.Popen(fusiond_cmd("run", "--config", str(config)), cwd=ROOT, stdout=subprocess.DEVNULL,
                                stderr=err, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)


@contextmanager
def client_session(port: int) -> Iterator[zenoh.Session]:
    session = open_session(build_config(ZenohConfig(mode="peer", connect=[f"tcp/127.0.0.1:{port}"],
                                                    multicast_scouting=False)))
    try:
        yield session
    finally:
        session.close()


def wait_until(cond: Callable[[], object], timeout: float, what: str, step: float = 0.02):
    deadline = time.monotonic() + timeout
    while True:
        value = cond()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(step)


def health(session: zenoh.Session, timeout: float = 1.0) -> dict | None:
    answers = query_health(session, "fusiond/health", timeout)
    return json.loads(answers[0]) if answers else None


def wait_daemon_ready(session: zenoh.Session, proc: subprocess.Popen, log: Path, timeout: float = 30.0) -> dict:
    def ready():
        if proc.poll() is not None:
            raise AssertionError(f"daemon exited with {proc.returncode}: {log.read_text()}")
        return health(session, 0.5)

    return wait_until(ready, timeout, "the daemon's health queryable")


def sensor_publishers(session: zenoh.Session, cfg) -> dict[str, zenoh.Publisher]:
    """Publishers on the sensor keys. Call after the daemon answered a health query: it declares
    that queryable after its subscribers, so the answer proves they are known here."""
    return {s.name: session.declare_publisher(s.key, congestion_control=zenoh.CongestionControl.BLOCK)
            for s in cfg.sensors}


def log_events(log: Path) -> list[dict]:
    return [json.loads(line) for line in log.read_text().splitlines() if line.startswith("{")]
