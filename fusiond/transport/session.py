"""One Zenoh session from the `[zenoh]` config table.

Everything Zenoh can refuse (a mode, an endpoint, a namespace, the native JSON5
file) is refused here as a one-line `ConfigError` naming the key, before any
subscriber exists, so `fusiond run` fails fast with exit code 2 instead of
half-starting.

Rules (config.toml documents them):
- `config_file` (native Zenoh JSON5: TLS, ACL, ...) is loaded first; a relative
  path is resolved against the directory of the TOML file.
- The TOML keys are applied on top of it. Without a file every key is applied;
  with a file only keys that differ from their defaults are, so the file's own
  `mode` or endpoints are not silently replaced by defaults nobody wrote.
- Empty `connect` / `listen` lists leave Zenoh's defaults (a peer listens on a
  random TCP port, which is how peers found by scouting reach each other).
- `namespace` is Zenoh's own key prefix: local keys stay unprefixed.
- `connect_retry_*` are Zenoh's `connect/retry` (how soon a lost router is dialled again).
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from ..config import ConfigError, ZenohConfig
from ..errors import SessionError  # importable from here, as before

_DEFAULTS = ZenohConfig()
_WILDCARD_HOSTS = {"0.0.0.0": "127.0.0.1", "[::]": "[::1]", "::": "[::1]"}


def zenoh_error_text(err: BaseException) -> str:
    """Zenoh's errors carry Rust source locations and debug wrappers; keep the sentence a user needs."""
    text = str(err)
    m = re.search(r'msg: "(.*?)"', text)
    if m:
        text = m.group(1)
    text = re.sub(r"\s+at /\S+?\.rs:\d+\.?", "", text)
    text = re.sub(r"^(Json5Err|JSON error|Str)\W*", "", text)
    return " ".join(text.split()).rstrip(".") or type(err).__name__


def _insert(conf: zenoh.Config, key: str, value: Any, where: str) -> None:
    try:
        conf.insert_json5(key, json.dumps(value))
    except zenoh.ZError as err:
        raise ConfigError(f"{where}: {zenoh_error_text(err)}") from None


def build_config(
    zc: ZenohConfig,
    *,
    base_dir: Path | None = None,
    mode: str | None = None,
    connect: Sequence[str] | None = None,
    listen: Sequence[str] | None = None,
) -> zenoh.Config:
    """The zenoh.Config of a `[zenoh]` table; `mode`/`connect`/`listen` override it (CLI flags, client tools)."""
    if zc.config_file:
        path = Path(zc.config_file)
        if not path.is_absolute() and base_dir is not None:
            path = base_dir / path
        if not path.is_file():
            raise ConfigError(f"zenoh.config_file: no such file {str(path)!r}")
        try:
            conf = zenoh.Config.from_file(str(path))
        except zenoh.ZError as err:
            raise ConfigError(f"zenoh.config_file: {path}: {zenoh_error_text(err)}") from None
    else:
        conf = zenoh.Config()
    layered = bool(zc.config_file)

    def wanted(field: str) -> bool:
        return not layered or getattr(zc, field) != getattr(_DEFAULTS, field)

    if mode is not None:
        _insert(conf, "mode", mode, "zenoh.mode")
    elif wanted("mode"):
        _insert(conf, "mode", zc.mode, "zenoh.mode")
    if wanted("multicast_scouting"):
        _insert(conf, "scouting/multicast/enabled", zc.multicast_scouting, "zenoh.multicast_scouting")
    endpoints = list(connect) if connect is not None else zc.connect
    if endpoints:
        _insert(conf, "connect/endpoints", endpoints, "--connect" if connect is not None else "zenoh.connect")
    if listen is not None:  # explicit, even empty: a tool must not take the daemon's port
        _insert(conf, "listen/endpoints", list(listen), "--listen")
    elif zc.listen:
        _insert(conf, "listen/endpoints", zc.listen, "zenoh.listen")
    if zc.namespace:
        _insert(conf, "namespace", zc.namespace, "zenoh.namespace")
    if any(wanted(f) for f in ("connect_retry_init_s", "connect_retry_max_s", "connect_retry_factor")):
        _insert(conf, "connect/retry", {"period_init_ms": round(zc.connect_retry_init_s * 1000),
                                        "period_max_ms": round(zc.connect_retry_max_s * 1000),
                                        "period_increase_factor": zc.connect_retry_factor}, "zenoh.connect_retry_*")
    return conf


def open_session(conf: zenoh.Config) -> zenoh.Session:
    try:
        return zenoh.open(conf)
    except zenoh.ZError as err:
        raise SessionError(f"cannot open the Zenoh session: {zenoh_error_text(err)}") from None


def loopback(endpoint: str) -> str:
    """A listen endpoint as a local client dials it: wildcard hosts become loopback."""
    proto, sep, rest = endpoint.partition("/")
    if not sep:
        return endpoint
    for wild, local in _WILDCARD_HOSTS.items():
        if rest.startswith(wild + ":"):
            return f"{proto}/{local}{rest[len(wild):]}"
    return endpoint


def client_endpoints(zc: ZenohConfig, connect: Sequence[str] | None) -> list[str]:
    """Where a tool (`play`, `health`) reaches the daemon described by a config.

    Explicit `--connect` wins; otherwise the config's `connect`, else the daemon's own
    `listen` endpoints dialled locally. Empty: rely on scouting.
    """
    if connect:
        return list(connect)
    if zc.connect:
        return list(zc.connect)
    return [loopback(e) for e in zc.listen]


def client_config(zc: ZenohConfig, *, base_dir: Path | None = None, connect: Sequence[str] | None = None,
                  listen: Sequence[str] | None = None) -> zenoh.Config:
    """The session of a tool talking to a daemon: same namespace and scouting, never the daemon's listen
    endpoints (the port is the daemon's), a peer (a router mode in the file is the daemon's role).

    Without ``listen`` a peer tool listens where Zenoh's default puts a peer, a random TCP port: two peers
    that both dial a third peer (``play`` and a live ``calibrate-imu``, each connected to the daemon) reach
    each other only by connecting to each other, at the locators the daemon's gossip tells them, since a
    peer routes nothing between two others (Zenoh's peer-to-peer routing). Listening nowhere, neither
    could be dialled, and the IMU ``play`` published never reached ``calibrate-imu``."""
    tool = msgspec.structs.replace(zc, listen=[], connect=[] if connect else client_endpoints(zc, None),
                                   mode="peer" if zc.mode == "router" else zc.mode)
    return build_config(tool, base_dir=base_dir, connect=list(connect) if connect else None,
                        listen=list(listen) if listen else None)


# A query that no queryable serves ends at once; a session opened a moment ago may not yet know the route to
# the daemon (a peer learns the router's routes after it connects: a health check right after opening went
# unanswered about half the time). So an unserved query is asked again, this often, until its timeout.
UNSERVED_RETRY_S = 0.05


def _served(session: zenoh.Session, key: str, timeout: float, payload: bytes | None = None) -> list:
    """The replies to a query on `key` within `timeout`, asked again while it ends unserved (no reply, before its
    timeout: UNSERVED_RETRY_S). A query that reached a queryable is never repeated (a set_pose applies once)."""
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        replies = list(session.get(key, payload=payload, timeout=max(left, 0.001)))
        if replies or deadline - time.monotonic() <= UNSERVED_RETRY_S:
            return replies
        time.sleep(UNSERVED_RETRY_S)


def query_health(session: zenoh.Session, key: str, timeout: float) -> list[bytes]:
    """The health answers of every daemon whose queryable matches `key` (possibly none) within `timeout`."""
    return [reply.ok.payload.to_bytes() for reply in _served(session, key, timeout) if reply.ok is not None]


def request_set_pose(session: zenoh.Session, key: str, payload: bytes, timeout: float
                     ) -> tuple[list[bytes], list[str]]:
    """Send a set_pose request (JSON or PoseWithCovarianceStamped CDR) to every daemon on `key`.

    Returns (the health answers of the daemons that applied it, the error texts of those that
    refused it); both empty when no daemon answered within `timeout` (or an ACL dropped the query).
    """
    ok: list[bytes] = []
    errors: list[str] = []
    for reply in _served(session, key, timeout, payload):
        if reply.ok is not None:
            ok.append(reply.ok.payload.to_bytes())
        elif reply.err is not None:
            errors.append(reply.err.payload.to_bytes().decode(errors="replace"))
    return ok, errors
