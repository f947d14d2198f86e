"""A pair of Zenoh sessions on loopback (fixture) and the waits of the in-process daemon tests."""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import pytest
import zenoh

from fusiond.config import ZenohConfig
from fusiond.transport.session import build_config, open_session


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(cond, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while not (value := cond()):
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)
    return value


def wait_answering(client: zenoh.Session, health_key: str = "t/health", timeout: float = 10.0):
    """Until a daemon answers on ``health_key``: its answer proves its subscribers are known to ``client`` (a
    peer's declarations reach it in order on the link, before the reply: transport/daemon.py)."""
    return wait_until(lambda: [r for r in client.get(health_key, timeout=1.0) if r.ok is not None], timeout,
                      "the daemon (its answer proves its subscribers are known here)")


@pytest.fixture
def sessions() -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    a = open_session(build_config(ZenohConfig(listen=[ep], multicast_scouting=False)))
    b = open_session(build_config(ZenohConfig(connect=[ep], multicast_scouting=False)))
    try:
        yield a, b
    finally:
        b.close()
        a.close()
