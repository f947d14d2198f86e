"""structlog set-up: human lines on a terminal, JSON lines otherwise (journald, Docker, CI).

structlog is imported at the first event, not at start-up. Importing it costs ~0.1 s
(``structlog.dev`` pulls in rich and asyncio when they are installed, and they are: rich
draws the monitor), a tenth of a whole replay of a small bag, and a replay that goes
well logs nothing. So the modules log through ``get_logger``, whose proxy imports
structlog and applies ``configure``'s settings when it is first used.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from typing import Any

__all__ = ["bind_process", "configure", "get_logger", "muted"]

# logging's level names (``logging.getLevelNamesMapping()``), spelled out: importing logging to check
# a name costs ~10 ms of a replay that logs nothing (a test holds the two equal)
LEVELS = ("CRITICAL", "FATAL", "ERROR", "WARN", "WARNING", "INFO", "DEBUG", "NOTSET")

# Inside ``muted()``: events are dropped. A processor reads it at each event, so it holds for loggers
# that structlog has already cached (a level change through ``configure`` would not reach those).
_MUTED: ContextVar[bool] = ContextVar("fusiond_logs_muted", default=False)

# Fields every event of this process carries (``bind_process``): the daemon's namespace, so that each of a
# fleet's log lines names its robot. A module dict, not structlog's contextvars: those do not reach the
# worker, health and Zenoh threads, which start with a context of their own.
_PROCESS: dict[str, Any] = {}

# configure()'s settings, waiting for structlog's import (None: nothing asked, structlog's defaults)
_pending: tuple[str, bool | None] | None = None


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
            import structlog

            # A configuration made since (a test's ``structlog.testing.capture_logs``) wins
            # over the pending one, which would otherwise replace it.
            if not structlog.is_configured():
                _apply()
            logger = self._logger = structlog.get_logger(self._name)
        return getattr(logger, method)


def get_logger(name: str) -> Any:
    """A logger named ``name`` (structlog's bound-logger API: ``log.info("event", key=value)``)."""
    return _LazyLogger(name)
