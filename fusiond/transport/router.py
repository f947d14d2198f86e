"""`fusiond router`: a Zenoh router for a fleet, without writing one.

A fleet's daemons (client mode, one namespace each) and its operators' monitors meet at a
router. zenohd is the reference router; this is the same router from zenoh-python, so a
machine with fusiond installed needs nothing else: a session in router mode listening on
the given endpoints, its own liveliness and queries routed as zenohd routes them, until
SIGINT/SIGTERM. ``deploy/fusiond-router.service`` runs it under systemd.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..config import ZenohConfig
from ..logs import get_logger
from .session import build_config, open_session

__all__ = ["router_config", "run_router"]

log = get_logger("fusiond.router")


def router_config(listen: Sequence[str], connect: Sequence[str] = (), *, multicast_scouting: bool = False,
                  config_file: str = "", base_dir: Path | None = None) -> Any:
    """The zenoh.Config of a router listening on ``listen`` (and dialling other routers on ``connect``)."""
    zc = ZenohConfig(mode="router", listen=list(listen), connect=list(connect),
                     multicast_scouting=multicast_scouting, config_file=config_file)
    return build_config(zc, base_dir=base_dir, mode="router")


def run_router(conf: Any, *, stop: threading.Event | None = None, ready: Any = None) -> int:
    """Serve as a router until SIGINT/SIGTERM (or ``stop``); ``ready(session)`` once it listens.

    Raises SessionError when the session cannot open (an endpoint in use, a bad address).
    """
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    session = open_session(conf)
    try:
        log.info("router_started", zid=str(session.zid()), listen=conf.get_json("listen/endpoints"))
        if ready is not None:
            ready(session)
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    log.info("router_stopped")
    return 0
