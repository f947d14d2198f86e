"""The state of a Zenoh session's link to the rest of the system: connected or disconnected.

A daemon in client mode reaches everything through its router; when the router goes (a
restart, a cable), the daemon keeps fusing but nothing it publishes reaches anyone, and
nothing in its own input says so (its sensors may sit on the same host). This watches the
session's routers and peers (``session.info``) on a thread of its own and says when the link
is lost and regained: a log line each way (``zenoh_link_lost``, ``zenoh_link_restored`` with
the outage's length) and the figures the health answer and the metrics carry (state, losses,
reconnections). Connected means at least one router or peer session is open.

Only a link the config asks for is announced and counted (``watched``: client mode, or `connect`
endpoints): a peer daemon that merely listens sees tools dial it and leave (`fusiond health`
every 30 s from a Docker HEALTHCHECK), which is no loss of anything. With no router or peer session open
its state is ``listening``, not ``disconnected``: a tool that dials it is not among the session's routers and
peers until the next poll sees it, and never in client mode (``session.info`` lists those two only), so
"disconnected" would be said to the very tool whose query it answers.

Polled rather than driven by Zenoh's transport events: the poll costs two short calls per
period and holds on every zenoh-python 1.x; its period bounds how late a change is seen.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any, Literal

import msgspec

from ..logs import get_logger

__all__ = ["LinkHealth", "LinkWatch", "POLL_S", "link_counts"]

log = get_logger("fusiond.link")

POLL_S = 0.2  # how often the session's routers and peers are looked at

LinkState = Literal["connected", "disconnected", "listening"]


class LinkHealth(msgspec.Struct, kw_only=True):
    """The link as the health answer carries it."""

    state: LinkState
    routers: int  # router sessions open now
    peers: int  # peer sessions open now
    losses: int = 0  # connected -> disconnected since start
    reconnections: int = 0  # disconnected -> connected after a loss
    since_s: float = 0.0  # seconds in the current state


def link_counts(session: Any) -> tuple[int, int]:
    """(routers, peers) the session has a transport to now."""
    info = session.info
    return len(list(info.routers_zid())), len(list(info.peers_zid()))


class LinkWatch:
    """Follows a session's link on a thread; ``health()`` is its state now (thread-safe)."""

    def __init__(self, session: Any, *, watched: bool = True, poll_s: float = POLL_S,
                 clock: Callable[[], float] = time.monotonic,
                 counts: Callable[[Any], tuple[int, int]] = link_counts) -> None:
        self._session = session
        self._watched = watched
        self._poll_s = poll_s
        self._clock = clock
        self._counts = counts
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._routers, self._peers = 0, 0
        self._connected = False
        self._ever = False  # connected once: a start without anyone to talk to is no loss
        self._since = clock()
        self.losses = 0
        self.reconnections = 0

    def start(self) -> None:
        self.poll()
        self._thread = threading.Thread(target=self._run, name="fusiond-link", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)

    def _run(self) -> None:
        while not self._stop.wait(self._poll_s):
            try:
                self.poll()
            except Exception:  # a closing session: the daemon is stopping
                if self._stop.is_set():
                    return
                log.exception("zenoh_link_poll_failed")

    def poll(self) -> None:
        """Look at the session's transports once; log and count a change."""
        routers, peers = self._counts(self._session)
        connected = routers + peers > 0
        now = self._clock()
        with self._lock:
            self._routers, self._peers = routers, peers
            if connected == self._connected:
                return
            lasted = now - self._since
            self._connected, self._since = connected, now
            if not self._watched:
                return
            if connected:
                reconnect = self._ever
                self._ever = True
                if reconnect:
                    self.reconnections += 1
            else:
                self.losses += 1
            reconnections, losses = self.reconnections, self.losses
        if connected and reconnect:
            log.warning("zenoh_link_restored", routers=routers, peers=peers, outage_s=round(lasted, 3),
                        reconnections=reconnections)
        elif connected:
            log.info("zenoh_link_up", routers=routers, peers=peers)
        else:
            log.warning("zenoh_link_lost", losses=losses, connected_for_s=round(lasted, 3))

    def health(self) -> LinkHealth:
        with self._lock:
            state = "connected" if self._connected else "disconnected" if self._watched else "listening"
            return LinkHealth(state=state, routers=self._routers,
                              peers=self._peers, losses=self.losses, reconnections=self.reconnections,
                              since_s=max(self._clock() - self._since, 0.0))
