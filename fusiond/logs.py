"""structlog set-up: human lines on a terminal, JSON lines otherwise (journald, Docker, CI).

structlog is imported at the first event, not at start-up. Importing it costs ~0.1 s
(``structlog.dev`` pulls in rich and asyncio when they are installed, and they are: rich
draws the monitor), a tenth of a whole replay of a small bag, and a replay that goes
well logs nothing. So the modules log through ``get_logger``, whose proxy imports
structlog and applies ``configure``'s settings when it is first used.

A replay that logs a warning or two (a logging gap, a time jump) would still pay that import for
a line: while structlog is not imported and the settings are this module's JSON lines, an event
is written here (``_json_line``) exactly as structlog's chain of ``_apply`` renders it (a test
holds the two byte for byte, timestamp aside). A terminal's human lines, a capture, any other
configuration go through structlog.
"""

from __future__ import annotations

import sys
import weakref
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from functools import partial
from typing import Any

__all__ = ["bind_process", "configure", "forget_loggers", "get_logger", "muted"]

# logging's level names and numbers (``logging.getLevelNamesMapping()``), spelled out: importing logging to
# check a name costs ~10 ms of a replay that logs nothing (a test holds the two equal)
LEVELS = {"CRITICAL": 50, "FATAL": 50, "ERROR": 40, "WARN": 30, "WARNING": 30, "INFO": 20, "DEBUG": 10, "NOTSET": 0}
# the level of each of structlog's level methods, so that an event below the configured level is dropped
# without importing structlog (a replay's info events: the GPS heading found)
METHOD_LEVELS = {"debug": 10, "info": 20, "msg": 20, "warning": 30, "warn": 30, "error": 40, "exception": 40,
                 "critical": 50, "fatal": 50}

# Inside ``muted()``: events are dropped. A processor reads it at each event, so it holds for loggers
# that structlog has already cached (a level change through ``configure`` would not reach those).
_MUTED: ContextVar[bool] = ContextVar("fusiond_logs_muted", default=False)

# Fields every event of this process carries (``bind_process``): the daemon's namespace, so that each of a
# fleet's log lines names its robot. A module dict, not structlog's contextvars: those do not reach the
# worker, health and Zenoh threads, which start with a context of their own.
_PROCESS: dict[str, Any] = {}

# configure()'s settings, waiting for structlog's import (None: nothing asked, structlog's defaults)
_pending: tuple[str, bool | None] | None = None
# every logger handed out (``get_logger``): a later configure() drops what structlog cached in each
_LOGGERS: "weakref.WeakSet[_LazyLogger]" = weakref.WeakSet()


def configure(level: str = "info", json: bool | None = None) -> None:
    """Render events as JSON lines (``json``; default: when stderr is not a terminal) at ``level``
    and above. Applied now if structlog is already imported, else at the first event."""
    global _pending
    if level.upper() not in LEVELS:  # said now, not at the first event
        raise ValueError(f"unknown log level {level!r}")
    _pending = (level, json)
    if "structlog" in sys.modules:
        _apply()


def _apply() -> None:
    global _pending
    if _pending is None:
        return
    level, json = _pending
    _pending = None
    import logging

    import structlog

    if json is None:
        json = not sys.stderr.isatty()
    renderer = structlog.processors.JSONRenderer() if json else structlog.dev.ConsoleRenderer(colors=False)
    forget_loggers()  # structlog caches a logger at its first event: a new level reaches those too
    structlog.configure(
        processors=[
            _drop_when_muted,
            _add_process_fields,
            structlog.processors.add_log_level,
            structlog.processors.TimeStamper(fmt="iso", utc=True),
            renderer,
        ],
        wrapper_class=structlog.make_filtering_bound_logger(logging.getLevelNamesMapping()[level.upper()]),
        logger_factory=structlog.PrintLoggerFactory(file=_Stderr()),
        cache_logger_on_first_use=True,
    )


def forget_loggers() -> None:
    """Let every logger of this module take structlog's configuration anew at its next event: structlog caches
    a logger at its first one (``cache_logger_on_first_use``), so a configuration made since (a new level, a
    test's ``structlog.testing.capture_logs``) would not reach a logger used before it."""
    for logger in list(_LOGGERS):
        logger._logger = None


def _drop_when_muted(logger: Any, method: str, event: dict) -> dict:
    if _MUTED.get():
        import structlog

        raise structlog.DropEvent
    return event


def bind_process(**fields: Any) -> None:
    """Add ``fields`` to every event logged from now on, by any thread (an event's own value wins)."""
    _PROCESS.update(fields)


def _add_process_fields(logger: Any, method: str, event: dict) -> dict:
    for key, value in _PROCESS.items():
        event.setdefault(key, value)
    return event


@contextmanager
def muted() -> Iterator[None]:
    """Drop every event logged inside the block. For a caller that replays one recording many times
    (``fusiond tune``): the recording's warnings are said once, by the replay that is shown, not once
    per replay of the fit."""
    token = _MUTED.set(True)
    try:
        yield
    finally:
        _MUTED.reset(token)


class _Stderr:
    """``sys.stderr`` as it is at each write, not as it was at ``configure``: a caller that swaps it
    (a test's capture, a daemon redirecting its output) must not leave the logs writing to a closed file."""

    def write(self, text: str) -> int:
        return sys.stderr.write(text)

    def flush(self) -> None:
        sys.stderr.flush()


class _LazyLogger:
    """Stands for ``structlog.get_logger(name)`` until an event is logged through it."""

    def __init__(self, name: str) -> None:
        self._name = name
        self._logger: Any = None

    def __getattr__(self, method: str) -> Any:
        logger = self._logger
        if logger is None:
            if "structlog" not in sys.modules:  # not cached: a later configure() or import of structlog is heeded
                if _dropped(method):
                    return _drop
                name = _LEVEL_NAMES.get(method)
                if name is not None and _pending is not None and _json_pending():
                    return partial(_json_line, name)
            import structlog

            # A configuration made since (a test's ``structlog.testing.capture_logs``) wins
            # over the pending one, which would otherwise replace it.
            if not structlog.is_configured():
                _apply()
            logger = self._logger = structlog.get_logger(self._name)
        return getattr(logger, method)


def _dropped(method: str) -> bool:
    """Whether an event through ``method`` would be dropped by the settings pending for structlog: inside
    ``muted()``, or below the configured level. Only for settings this module holds (``_pending``): with
    none, structlog's defaults log every level."""
    if _pending is None:
        return False
    if _MUTED.get():
        return True
    level = METHOD_LEVELS.get(method)
    return level is not None and level < LEVELS[_pending[0].upper()]


def _drop(*args: Any, **kwargs: Any) -> None:
    """A filtered-out event, as structlog's filtering logger returns it."""
    return None


# the level an event is written with, per method (structlog's ``add_log_level``); ``exception`` (a traceback
# to format) and ``log`` (a level number) are left to structlog
_LEVEL_NAMES = {"debug": "debug", "info": "info", "msg": "info", "warning": "warning", "warn": "warning",
                "error": "error", "critical": "critical", "fatal": "critical"}


def _json_pending() -> bool:
    """Whether the pending settings render JSON lines (``configure``'s default: when stderr is no terminal)."""
    assert _pending is not None
    json = _pending[1]
    return (not sys.stderr.isatty()) if json is None else json


def _json_line(level: str, event: str | None = None, *args: Any, **kw: Any) -> None:
    """One event as ``_apply``'s chain writes it with JSON lines: the event's keys, ``event``, the
    process's fields, ``level``, an ISO UTC ``timestamp``, rendered by ``json.dumps`` (an unknown type
    by its ``__structlog__`` or ``repr``), one line on stderr."""
    import datetime
    import json

    if args:  # structlog's positional interpolation
        event = event % (args[0] if len(args) == 1 and isinstance(args[0], dict) and args[0] else args)
    fields = dict(kw)
    if event is not None:
        fields["event"] = event
    _add_process_fields(None, level, fields)
    fields["level"] = level
    fields["timestamp"] = datetime.datetime.now(tz=datetime.timezone.utc).isoformat().replace("+00:00", "Z")
    line = json.dumps(fields, default=_json_default) + "\n"
    with _WRITE_LOCK:  # one line at a time from the daemon's threads, as structlog's printer locks its file
        sys.stderr.write(line)
        sys.stderr.flush()


_WRITE_LOCK = threading.Lock()


def _json_default(obj: Any) -> Any:
    try:
        return obj.__structlog__()
    except AttributeError:
        return repr(obj)


def get_logger(name: str) -> Any:
    """A logger named ``name`` (structlog's bound-logger API: ``log.info("event", key=value)``)."""
    logger = _LazyLogger(name)
    _LOGGERS.add(logger)
    return logger
