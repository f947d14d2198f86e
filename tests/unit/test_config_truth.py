"""config.toml is the truth: every key it shows carries the code's default. The README's configuration
steps and diagnostics schema are held to the code the same way, and the guides to their size and to
statements of why (no lab notebook).

config.toml says it lists every key with its default; a user who trusts it must get
what the code does (a file showing `angular_velocity = true` over a default of false
would leave whoever copied the rest without a gyro). The test is generic over whatever
structs and keys exist: it walks the file's tables (active and commented-out
examples), finds each table's config Struct (a sensor table by its `kind`), and
compares every `key = value` line with that Struct's field default. A commented
key whose default is "unset" (None) shows an example value; every other key must
show the default itself.
"""

from __future__ import annotations

import math
import re
import tomllib
import typing
from pathlib import Path

import msgspec

from fusiond import config as C

ROOT = Path(__file__).resolve().parents[2]
KEY_LINE = re.compile(r"^(#\s?)?\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.+)$")
HEADER = re.compile(r"^(#\s*)?\[(\[)?([A-Za-z_]+)\]?\]\s*(#.*)?$")


def sensor_classes() -> dict[str, type]:
    return {cls.__struct_config__.tag: cls for cls in typing.get_args(C.SensorConfig)}


def table_classes() -> dict[str, type]:
    hints = typing.get_type_hints(C.Config)
    return {name: t for name, t in hints.items() if isinstance(t, type) and issubclass(t, msgspec.Struct)}


def defaults(cls: type) -> dict[str, object]:
    out = {}
    for f in msgspec.structs.fields(cls):
        if f.default is not msgspec.NODEFAULT:
            out[f.name] = f.default
        elif f.default_factory is not msgspec.NODEFAULT:
            out[f.name] = f.default_factory()
    return out


def parse_value(text: str):
    """The TOML value at the start of ``text`` (a trailing # comment is cut where TOML allows)."""
    text = text.strip()
    for end in range(len(text), 0, -1):
        head = text[:end].rstrip()
        if end < len(text) and not text[end:].lstrip().startswith("#"):
            continue
        try:
            return tomllib.loads(f"v = {head}")["v"]
        except tomllib.TOMLDecodeError:
            continue
    raise ValueError(f"no TOML value in {text!r}")


def same(shown, default) -> bool:
    if isinstance(shown, list):
        shown = tuple(shown)
    if isinstance(default, list):
        default = tuple(default)
    if isinstance(shown, tuple) and isinstance(default, tuple):
        return len(shown) == len(default) and all(same(a, b) for a, b in zip(shown, default))
    if isinstance(shown, bool) or isinstance(default, bool):
        return shown is default
    if isinstance(shown, (int, float)) and isinstance(default, (int, float)):
        return shown == default or (math.isinf(shown) and math.isinf(default) and shown == default) or \
            math.isclose(shown, default, rel_tol=1e-12)
    return shown == default


def shown_keys(text: str) -> list[tuple[int, str, str, bool, object]]:
    """(line number, table, key, commented, value) for every key line, tables resolved to a Struct name."""
    tables = table_classes()
    sensors = sensor_classes()
    out = []
    table = None
    pending: list[tuple[int, str, bool, object]] = []  # sensor keys before its `kind` line

    def flush():
        nonlocal pending
        kind = next((v for _, k, _, v in pending if k == "kind"), None)
        for ln, k, commented, v in pending:
            out.append((ln, f"sensor:{kind}", k, commented, v))
        pending = []

    for ln, line in enumerate(text.splitlines(), 1):
        h = HEADER.match(line.strip())
        if h and (h.group(3) in tables or h.group(3) == "sensors"):
            flush()
            table = "sensors" if h.group(2) else h.group(3)
            continue
        m = KEY_LINE.match(line.strip())
        if not m or table is None:
            continue
        commented, key = bool(m.group(1)), m.group(2)
        try:
            value = parse_value(m.group(3))
        except ValueError:
            continue  # prose in a comment
        if table == "sensors":
            if key in {f for cls in sensors.values() for f in cls.__struct_fields__} or key == "kind":
                pending.append((ln, key, commented, value))
        elif key in tables[table].__struct_fields__:
            out.append((ln, table, key, commented, value))
    flush()
    return out


def test_every_key_config_toml_shows_carries_the_code_default():
    text = (ROOT / "config.toml").read_text()
    tables = table_classes()
    sensors = sensor_classes()
    checked, wrong = 0, []
    for ln, table, key, commented, value in shown_keys(text):
        if table.startswith("sensor:"):
            kind = table.split(":", 1)[1]
            assert kind in sensors, f"config.toml line {ln}: sensor table without a known kind ({kind!r})"
            cls = sensors[kind]
        else:
            cls = tables[table]
        if key == "kind" or key not in cls.__struct_fields__:
            continue
        d = defaults(cls)
        if key not in d:
            continue  # a required key (name, key): the file shows an example
        if d[key] is None and commented:
            continue  # unset by default: the commented line shows an example value
        checked += 1
        if not same(value, d[key]):
            wrong.append(f"line {ln}: {cls.__name__}.{key} shows {value!r}, the code's default is {d[key]!r}")
    assert not wrong, "config.toml disagrees with the code:\n" + "\n".join(wrong)
    # the walk really covered the file: every table Struct and every sensor kind had keys checked
    assert checked > 60


def test_every_field_of_every_struct_is_shown():
    text = (ROOT / "config.toml").read_text()
    shown: dict[str, set[str]] = {}
    for _, table, key, _, _ in shown_keys(text):
        shown.setdefault(table, set()).add(key)
    for name, cls in table_classes().items():
        missing = set(cls.__struct_fields__) - shown.get(name, set())
        assert not missing, f"config.toml [{name}] does not show {sorted(missing)}"
    for kind, cls in sensor_classes().items():
        missing = set(cls.__struct_fields__) - shown.get(f"sensor:{kind}", set()) - {"kind"}
        assert not missing, f"config.toml's {kind} sensor does not show {sorted(missing)}"


def test_the_checker_catches_a_wrong_default():
    """The comparison itself: a file showing a non-default value is caught (the issue's case)."""
    text = (ROOT / "config.toml").read_text().replace("angular_velocity = false", "angular_velocity = true", 1)
    rows = [r for r in shown_keys(text) if r[2] == "angular_velocity"]
    assert rows and not same(rows[0][4], defaults(C.ImuSensor)["angular_velocity"])


def test_the_readme_steps_load_as_configs_one_on_another():
    """README's "Configure your robot" builds a config step by step: step 1 (odometry + IMU) alone, then with
    step 2's GPS or step 3's pose added, is each a config the code accepts with the keys the README shows."""
    blocks = re.findall(r"```toml\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert len(blocks) == 3, "README's three configure steps"
    step1, gps, pose = blocks
    base = C.loads(step1, "README step 1")
    assert [s.name for s in base.sensors] == ["wheel", "imu"] and base.sensor("imu").angular_velocity is True
    with_gps = C.loads(step1 + gps, "README step 2")
    assert [s.name for s in with_gps.sensors] == ["wheel", "imu", "gps"]
    with_pose = C.loads(step1 + pose, "README step 3")
    assert with_pose.sensor("vo").differential is True


def test_the_readme_diagnostics_schema_names_every_record_field_and_verdict():
    """README's "Diagnostics record" is the schema a consumer codes against: every field a record carries and
    every `consistency` value it can take is named there."""
    from fusiond.core.diagnostics import DiagnosticsRecord

    text = (ROOT / "README.md").read_text()
    section = text[text.index("### Diagnostics record"):]
    section = section[:section.index("\n### ", 1)]
    named = set(re.findall(r'"([a-z_]+)":', section)) | set(re.findall(r"`([a-z_]+)`", section))
    assert set(DiagnosticsRecord.__struct_fields__) <= named, set(DiagnosticsRecord.__struct_fields__) - named
    assert {"ok", "nis_high", "nis_low", "warming_up"} <= named
    assert DiagnosticsRecord(0.0, "s", [], [], [], 0.0, 0, False).consistency in named


def test_the_readme_is_a_guide_of_at_most_20000_characters():
    """The README is a user guide (what fusiond is, the quick start, configure your robot, daemon, tools, a
    short results table); measurements live in docs/RESULTS.md. Counted in bytes, as `wc -c` counts."""
    size = len((ROOT / "README.md").read_bytes())
    assert size <= 20_000, f"README.md is {size} bytes: cut as much as is added"


# lab-notebook markers: a QA run's name, a session / stop / round / issue number, a "(new)" tag, a commit hash
NOTEBOOK = re.compile(r"\bQA\b|\b[Ss]ession \d|\b[Ss]top \d|\b[Rr]ound \d|\b[Ii]ssues? #?\d|\(new\)"
                      r"|\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")


def test_no_lab_notebook_lines_in_the_docs_config_examples_code_or_tests():
    """Git keeps the history; a doc, a comment or a test's docstring says why things are as they are. This
    file is left out: its pattern and the self-test below necessarily spell the markers."""
    tests = [f for f in sorted((ROOT / "tests").rglob("*.py")) if f.resolve() != Path(__file__).resolve()]
    files = [ROOT / "README.md", ROOT / "config.toml", *sorted((ROOT / "docs").glob("*.md")),
             *sorted((ROOT / "examples").glob("*.toml")), *sorted((ROOT / "fusiond").rglob("*.py")),
             *sorted((ROOT / "fusiond").rglob("*.c")), *tests]
    assert len(tests) > 50 and ROOT / "fusiond/estimator/_kernels.c" in files  # the scan reaches them
    found = [f"{f.relative_to(ROOT)}:{n}: {line.strip()}" for f in files
             for n, line in enumerate(f.read_text().splitlines(), 1) if NOTEBOOK.search(line)]
    assert not found, "\n".join(found)
    assert NOTEBOOK.search("measured in session 12") and NOTEBOOK.search("fixed by 4b3b453")
    assert NOTEBOOK.search("(issue 12 follow-up)") and NOTEBOOK.search("the second QA trial")
    assert not NOTEBOOK.search("a session that cannot open; 1e6 m; jackal_test2.bag; an issue with the clock")
