"""The tuned config as TOML: the user's own file with the tuned keys edited in, or written whole.

A complete config either way: it loads (``fusiond.config.load``) to exactly the Config it was written
from, so ``replay`` and ``run`` take it as it is. Edited in (``edited``): the user's file, its comments
and layout kept (``fusiond init`` explains each choice in them), each changed key's line replaced in its
table, or added at the end of it, with a comment saying it was tuned; kept only when it loads to that
Config. Written whole (``dumps``): the keys that differ from their defaults (the others keep following
the documented defaults, config.toml), a table only when it has one, [[sensors]] in config order.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Mapping
from pathlib import Path

import msgspec

from ..config import Config

# every table of a Config but its [[sensors]] array, read from the struct: a table added to Config is written too
_TABLES = tuple(name for name in Config.__struct_fields__ if name != "sensors")


def _value(v: object) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            raise ValueError("NaN has no place in a config")
        return "inf" if v == math.inf else "-inf" if v == -math.inf else repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # JSON's escapes are TOML basic-string escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _defaults(obj: msgspec.Struct) -> dict[str, object]:
    out = {}
    for f in msgspec.structs.fields(obj):
        if f.default is not msgspec.NODEFAULT:
            out[f.name] = f.default
        elif f.default_factory is not msgspec.NODEFAULT:
            out[f.name] = f.default_factory()
    return out


def _lines(obj: msgspec.Struct, comments: Mapping[str, str], first: tuple[str, ...] = (),
           skip: tuple[str, ...] = ()) -> list[str]:
    defaults = _defaults(obj)
    lines = []
    fields = [f.name for f in msgspec.structs.fields(obj)]
    for name in [*first, *[f for f in fields if f not in first and f not in skip]]:
        v = getattr(obj, name)
        if name not in comments and name in defaults and v == defaults[name]:
            continue
        if v is None:  # unset (TOML has no null): its default; a tuned key is never None
            continue
        line = f"{name} = {_value(v)}"
        if name in comments:
            line += f"  # {comments[name]}"
        lines.append(line)
    return lines


def dumps(cfg: Config, comments: Mapping[tuple[str, str], str] | None = None, header: str = "") -> str:
    """``cfg`` as TOML. ``comments``: (table, key) -> a comment for that key's line; the table is one of
    ``_TABLES`` ("zenoh", "output", "ros", "filter", "state"), or a sensor's name."""
    comments = comments or {}
    out = [f"# {line}" if line else "#" for line in header.splitlines()]
    if out:
        out.append("")
    for table in _TABLES:
        mine = {k: c for (t, k), c in comments.items() if t == table}
        lines = _lines(getattr(cfg, table), mine)
        if lines:  # a table of defaults only says nothing
            out += [f"[{table}]", *lines, ""]
    for s in cfg.sensors:
        mine = {k: c for (t, k), c in comments.items() if t == s.name}
        out.append("[[sensors]]")
        out.append(f"name = {_value(s.name)}")
        out.append(f"kind = {_value(type(s).__struct_config__.tag)}")
        out += _lines(s, mine, ("key",), skip=("name",))
        out.append("")
    return "\n".join(out)


_HEADER = re.compile(r"^\s*\[\s*([A-Za-z0-9_]+)\s*\]\s*(#.*)?$")  # [filter]
_SENSORS = re.compile(r"^\s*\[\[\s*sensors\s*\]\]\s*(#.*)?$")  # [[sensors]]
_ANY_HEADER = re.compile(r"^\s*\[")  # any other header ends a block too (a line of an array spread over lines
# may look like one: what is written is checked by loading it)
_NAME = re.compile(r"^\s*name\s*=\s*(\"[^\"]*\"|'[^']*')")


def _blocks(lines: list[str]) -> dict[str, tuple[int, int]]:
    """Table (a top-level name, or a sensor's name) -> (first line after its header, end of its block)."""
    out: dict[str, tuple[int, int]] = {}
    current: str | None = None  # the block's table; a [[sensors]] block's once its name line is read
    start, in_sensor = 0, False

    def close(end: int) -> None:
        if current is not None:
            out.setdefault(current, (start, end))

    for i, line in enumerate(lines):
        if _ANY_HEADER.match(line):
            close(i)
            header = _HEADER.match(line)
            current, start, in_sensor = (header.group(1) if header else None), i + 1, bool(_SENSORS.match(line))
        elif in_sensor and current is None and (m := _NAME.match(line)):
            current = m.group(1)[1:-1]
    close(len(lines))
    return out


def _changed(before: msgspec.Struct, after: msgspec.Struct) -> list[str]:
    return [f.name for f in msgspec.structs.fields(after) if getattr(after, f.name) != getattr(before, f.name)]


def edited(text: str, original: Config, cfg: Config, comments: Mapping[tuple[str, str], str] | None = None,
           header: str = "") -> str | None:
    """``text`` (the file ``original`` was loaded from) with the keys ``cfg`` changes edited in (module doc);
    None where that cannot be done line by line (a key written over several lines, a table written inline, a
    sensor added): ``dumps`` then."""
    from ..config import ConfigError, loads

    comments = comments or {}
    if [s.name for s in original.sensors] != [s.name for s in cfg.sensors]:
        return None
    edits: list[tuple[str, str, str]] = []  # (table, key, line)
    pairs = [(t, getattr(original, t), getattr(cfg, t)) for t in _TABLES]
    pairs += [(a.name, a, b) for a, b in zip(original.sensors, cfg.sensors)]
    for table, a, b in pairs:
        for key in _changed(a, b):
            value = getattr(b, key)
            if value is None:
                return None
            line = f"{key} = {_value(value)}"
            note = comments.get((table, key))
            edits.append((table, key, line + f"  # {note}" if note else line + "  # tuned"))
    lines = text.splitlines()
    for table, key, new in edits:
        blocks = _blocks(lines)
        pattern = re.compile(rf"^\s*{re.escape(key)}\s*=")
        if table in blocks:
            start, end = blocks[table]
            at = next((i for i in range(start, end) if pattern.match(lines[i])), None)
            if at is not None:
                lines[at] = new
            else:
                last = max((i for i in range(start, end) if lines[i].strip() and not lines[i].lstrip().startswith("#")),
                           default=start - 1)
                lines.insert(last + 1, new)
        elif table in _TABLES:
            lines += ["", f"[{table}]", new]
        else:
            return None
    out = "\n".join([*(f"# {h}" if h else "#" for h in header.splitlines()), *lines]) + "\n"
    try:
        same = loads(out) == cfg
    except ConfigError:
        same = False
    return out if same else None  # any doubt: the whole config is written instead


def write(path: Path | str, cfg: Config, comments: Mapping[tuple[str, str], str] | None = None,
          header: str = "", original: tuple[str, Config] | None = None) -> None:
    """The tuned config at ``path``; ``original``: the user's file (text, Config) to edit the keys into."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    text = edited(original[0], original[1], cfg, comments, header) if original is not None else None
    p.write_text(text if text is not None else dumps(cfg, comments, header))


__all__ = ["dumps", "edited", "write"]
