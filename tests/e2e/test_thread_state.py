"""Zenoh's receive threads keep their Python thread state between the daemon's direct callbacks
(`fusiond.transport.thread_state`), on a real loopback Zenoh session.

A `threading.local` stores its values in the thread state: without the pin, each callback on a
thread Python did not create starts from a fresh state and never sees what the previous one stored.
"""

from __future__ import annotations

import threading

import zenoh

from fusiond.transport.daemon import direct
from fusiond.transport.thread_state import keep_thread_state

from tests.support.loopback import sessions, wait_until  # noqa: F401  (fixture)

N = 50


def test_a_thread_local_survives_between_direct_callbacks_on_zenohs_threads(sessions):  # noqa: F811
    a, b = sessions
    local = threading.local()
    seen: list[tuple[int, int, bool]] = []  # (thread id, calls this thread state saw before, a Python thread)

    def on_sample(_: zenoh.Sample) -> None:
        calls = getattr(local, "calls", 0)
        local.calls = calls + 1
        seen.append((threading.get_ident(), calls, isinstance(threading.current_thread(), threading._DummyThread)))

    sub = a.declare_subscriber("t/pin", direct(on_sample))
    try:
        pub = b.declare_publisher("t/pin", congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: (pub.put(b"probe"), bool(seen))[1], 10, "the subscriber's route")
        for _ in range(N):
            pub.put(b"x")
        wait_until(lambda: len(seen) >= N, 10, f"{N} callbacks")
    finally:
        sub.undeclare()
    per_thread: dict[int, list[int]] = {}
    for ident, calls, _ in seen:
        per_thread.setdefault(ident, []).append(calls)
    # each thread's count runs 0, 1, 2, ...: the state (and the local in it) lived across the calls
    for counts in per_thread.values():
        assert counts == list(range(len(counts))), counts
    assert max(len(c) for c in per_thread.values()) > 1
    # and the callbacks did run on threads Python did not start (Zenoh's), where the pin matters
    assert all(foreign for *_, foreign in seen)


def test_keeping_the_state_of_a_python_thread_is_harmless():
    """On a thread Python created (already holding a state) the call only nests the GIL state."""
    done: list[bool] = []

    def run() -> None:
        keep_thread_state()
        keep_thread_state()  # the second call on the same thread does nothing
        done.append(True)

    t = threading.Thread(target=run)
    t.start()
    t.join(10)
    assert done == [True] and not t.is_alive()
