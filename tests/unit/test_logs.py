"""Logging set-up: structlog imported at the first event, with the settings configure() asked for.

Each case runs in a fresh interpreter: structlog's configuration and ``sys.modules`` are
process-wide, and the point is what happens before and after structlog's import.
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True,
                          timeout=60, check=True)


def test_structlog_is_imported_at_the_first_event_with_the_configured_json_lines():
    out = _run("""
        import sys
        from fusiond.logs import configure, get_logger
        from fusiond.core.fusion import FusionCore  # the core's modules hold loggers too
        configure("info", json=True)
        log = get_logger("fusiond.test")
        print("before", "structlog" in sys.modules)
        log.info("first_event", answer=42)
        log.debug("filtered_out")
        print("after", "structlog" in sys.modules)
    """)
    assert out.stdout.split("\n")[:2] == ["before False", "after True"]
    lines = [json.loads(line) for line in out.stderr.splitlines()]
    assert len(lines) == 1, out.stderr  # the debug event is below the configured level
    assert lines[0]["event"] == "first_event" and lines[0]["answer"] == 42
    assert lines[0]["level"] == "info" and lines[0]["timestamp"].endswith("Z")


def test_configure_after_structlog_is_imported_applies_at_once():
    out = _run("""
        import structlog
        from fusiond.logs import configure, get_logger
        configure("error", json=True)
        log = get_logger("fusiond.test")
        log.warning("below_level")
        log.error("kept", n=1)
    """)
    lines = [json.loads(line) for line in out.stderr.splitlines()]
    assert [e["event"] for e in lines] == ["kept"]


def test_a_capture_made_before_the_first_event_is_not_replaced_by_the_pending_settings():
    out = _run("""
        import structlog.testing
        from fusiond.logs import get_logger
        import fusiond.logs as logs
        logs._pending = ("info", True)  # as if configure() ran before structlog was imported
        log = get_logger("fusiond.test")
        with structlog.testing.capture_logs() as captured:
            log.warning("captured_event", k=1)
        print([e["event"] for e in captured])
    """)
    assert out.stdout.strip() == "['captured_event']"
    assert out.stderr == ""


def test_every_module_logs_through_fusiond_logs():
    """A module that imported structlog itself would log with structlog's defaults (rendered to
    stdout) whenever configure() ran before structlog's import, which is every command."""
    from pathlib import Path

    import fusiond

    root = Path(fusiond.__file__).parent
    direct = [str(p.relative_to(root)) for p in root.rglob("*.py")
              if p.name != "logs.py" and any(line.strip().startswith(("import structlog", "from structlog"))
                                             for line in p.read_text().splitlines())]
    assert direct == []



def test_an_unknown_level_is_refused_by_configure_not_at_the_first_event():
    import pytest

    from fusiond.logs import configure

    with pytest.raises(ValueError, match="verbose"):
        configure("verbose")


def test_the_level_names_are_loggings():
    """configure() checks a level against its own list, so that a replay does not import logging: the
    list must be logging's."""
    import logging

    from fusiond.logs import LEVELS

    assert set(LEVELS) == set(logging.getLevelNamesMapping())


def test_a_replay_that_logs_nothing_imports_neither_structlog_nor_logging():
    out = _run("""
        import sys
        from fusiond.logs import configure
        from fusiond.replay.run import replay
        configure("warning")
        print("structlog" in sys.modules, "logging" in sys.modules)
    """)
    assert out.stdout.split() == ["False", "False"], out.stdout


def test_muted_drops_the_events_of_its_block_even_from_a_logger_already_used():
    out = _run("""
        from fusiond.logs import configure, get_logger, muted
        configure("info", json=True)
        log = get_logger("fusiond.test")
        log.warning("before_block")  # structlog caches this logger now
        with muted():
            log.warning("inside_block")
            get_logger("fusiond.other").error("inside_block_new_logger")
        log.warning("after_block")
    """)
    events = [json.loads(line)["event"] for line in out.stderr.splitlines()]
    assert events == ["before_block", "after_block"], out.stderr
