"""Zenoh I/O: the daemon, sessions, bag playback onto Zenoh and the daemon's state file.
Its public surface is ``__all__``; the rest are this package's internals.
"""

from __future__ import annotations

from ..lazy_exports import lazy_exports

# public name -> the module of this package that defines it (imported on first use)
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
    "StateFile": "state_file",
    "StateRefused": "state_file",
    "StateSaver": "state_file",
    "load_state": "state_file",
    "save_state": "state_file",
}

__all__, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
