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


def test_the_configured_json_lines_are_written_without_structlog():
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
    assert out.stdout.split("\n")[:2] == ["before False", "after False"]
    lines = [json.loads(line) for line in out.stderr.splitlines()]
    assert len(lines) == 1, out.stderr  # the debug event is below the configured level
    assert lines[0]["event"] == "first_event" and lines[0]["answer"] == 42
    assert lines[0]["level"] == "info" and lines[0]["timestamp"].endswith("Z")


def test_structlog_is_imported_at_the_first_event_of_human_lines():
    out = _run("""
        import sys
        from fusiond.logs import configure, get_logger
        configure("info", json=False)
        log = get_logger("fusiond.test")
        print("before", "structlog" in sys.modules)
        log.info("first_event", answer=42)
        print("after", "structlog" in sys.modules)
    """)
    assert out.stdout.split("\n")[:2] == ["before False", "after True"]
    assert "first_event" in out.stderr and "answer=42" in out.stderr


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
    """configure() checks a level against its own table, so that a replay does not import logging: the
    table must be logging's."""
    import logging

    from fusiond.logs import LEVELS

    assert LEVELS == logging.getLevelNamesMapping()


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


def test_an_event_below_the_level_or_muted_does_not_import_structlog():
    """A replay's info events (the GPS heading found) and the advice replays' muted ones would each cost
    structlog's import (~0.1 s) for nothing printed."""
    out = _run("""
        import sys
        from fusiond.logs import configure, get_logger, muted
        configure("warning", json=True)
        log = get_logger("fusiond.test")
        log.info("below_level", n=1)
        log.debug("below_level_too")
        with muted():
            log.error("muted_event")
        print("structlog" in sys.modules)
        log.warning("kept", n=2)
        log.info("still_below")
        print("structlog" in sys.modules)
    """)
    assert out.stdout.split() == ["False", "False"], out.stdout
    assert [json.loads(line)["event"] for line in out.stderr.splitlines()] == ["kept"], out.stderr


def test_level_methods_are_structlogs():
    """The levels of the methods an event can be dropped through before structlog's import are the ones
    structlog's filtering logger gives them."""
    import logging

    import structlog

    from fusiond.logs import METHOD_LEVELS

    names = {"msg": "INFO", "warn": "WARNING", "exception": "ERROR", "fatal": "CRITICAL"}
    for method, level in METHOD_LEVELS.items():
        assert hasattr(structlog.make_filtering_bound_logger(logging.INFO), method)
        assert level == logging.getLevelNamesMapping()[names.get(method, method.upper())]


def test_a_json_line_written_before_structlog_is_imported_is_structlogs_line():
    """A replay's one warning is written without importing structlog: the same line structlog's chain
    renders for the same settings, byte for byte but for the timestamp."""
    code = """
        import sys
        from fusiond.logs import bind_process, configure, get_logger
        configure("info", json=True)
        bind_process(namespace="robot1")
        if IMPORT:
            import structlog
        log = get_logger("fusiond.test")
        log.warning("time_jump_forward", stamp=1650776629.818735, held=93, sensor="imu", ratio=float("nan"),
                    where=("a", 1), obj=object.__new__(type("Thing", (), {"__repr__": lambda self: "<thing>"})))
        log.info("count %d of %s", 3, "x")
        log.warn("warned")
        log.msg("said")
        log.critical("bad", namespace="own")
        print("structlog" in sys.modules)
    """
    lines = {}
    for imported in (False, True):
        out = _run(code.replace("IMPORT", str(imported)))
        assert out.stdout.split() == [str(imported)], out.stdout
        lines[imported] = [json.loads(line) for line in out.stderr.splitlines()]
        raw = out.stderr.splitlines()
        lines[imported, "raw"] = [line[: line.index('"timestamp"')] for line in raw]
    assert lines[False, "raw"] == lines[True, "raw"]
    assert [e["level"] for e in lines[False]] == ["warning", "info", "warning", "info", "critical"]
    assert all(e["timestamp"].endswith("Z") for e in lines[False])
