"""The tuned config as TOML: every table, the keys that differ from their defaults, a comment per tuned key.

A complete config: it loads (``fusiond.config.load``) to exactly the Config it was written from, so
``replay`` and ``run`` take it as it is. Keys at their default are left out (they keep following
the documented defaults, config.toml); the tables are all written, [[sensors]] in config order.
"""

from __future__ import annotations

import json
import math
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
        out.append(f"[{table}]")
        out += _lines(getattr(cfg, table), mine)
        out.append("")
    for s in cfg.sensors:
        mine = {k: c for (t, k), c in comments.items() if t == s.name}
        out.append("[[sensors]]")
        out.append(f"name = {_value(s.name)}")
        out.append(f"kind = {_value(type(s).__struct_config__.tag)}")
        out += _lines(s, mine, ("key",), skip=("name",))
        out.append("")
    return "\n".join(out)


def write(path: Path | str, cfg: Config, comments: Mapping[tuple[str, str], str] | None = None,
          header: str = "") -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(dumps(cfg, comments, header))


__all__ = ["dumps", "write"]
