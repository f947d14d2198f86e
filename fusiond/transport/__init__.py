"""Zenoh I/O: the daemon, sessions, bag playback onto Zenoh and the latency benchmark.
Its public surface is ``__all__``; the rest are this package's internals.
"""

from __future__ import annotations

from importlib import import_module

# public name -> the module of this package that defines it (imported on first use, so that
# importing the package stays cheap and no import cycle is created)
_EXPORTS = {
    "Daemon": "daemon",
    "run": "daemon",
    "build_config": "session",
    "client_config": "session",
    "open_session": "session",
    "query_health": "session",
    "SessionError": "session",
    "play": "player",
    "PlayResult": "player",
    "run_bench": "bench_latency",
    "BenchResult": "bench_latency",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
