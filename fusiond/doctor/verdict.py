"""The verdict: what the doctor says about one sensor channel, and how keys are spelled.

Key paths use one spelling everywhere (replay summary, report, monitor): the TOML
path a user edits, ``sensors.<sensor name>.<key>`` for a sensor table (found by its
``name``) and ``filter.<key>`` for the filter table.
"""

from __future__ import annotations

import msgspec

LEVELS = ("ok", "warn", "problem")


class Proof(msgspec.Struct):
    """What a verdict's paste line did when the recording was replayed with it (``fusiond.tune.advice``).
    ``advised``: it improved the innovations' likelihood by more than the change's own complexity, so it
    is printed as a fix; otherwise it is printed as tried, with what it did."""

    advised: bool
    effect: str  # e.g. "likelihood +812, NIS/dof 0.04 -> 0.93"; or why it was not tried
    tried: bool = True
    # False: the line changed none of the replay's updates (it moved only what no update measures, such as a
    # heading with no heading reference, or nothing but the doctor's own check), so the likelihood cannot say
    # whether it helps: the verdict's evidence is the case for it
    judged: bool = True
    # True: it made the likelihood worse by more than the keys it sets (the advice rule's margin the other way):
    # the replay contradicts the check, and a problem it came with is shown as a warning
    refuted: bool = False


class Verdict(msgspec.Struct):
    """One channel's verdict. ``suggestion`` is ready-to-paste TOML when there is one (a line per key),
    in the frame of ``key`` (e.g. orientation noise in the IMU's own axes). ``proof``: set when the
    suggestion was replayed on the recording it came from (None: not replayed, e.g. the live monitor)."""

    sensor: str
    channel: str
    level: str  # ok | warn | problem
    message: str
    key: str = ""  # the config key to change, when there is one
    suggestion: str = ""  # e.g. 'orientation_noise = [0.005, 0.005, 0.05]'
    evidence: dict[str, float] = {}  # measured figures behind the verdict (offsets, drifts, scales)
    proof: Proof | None = None


def sensor_key(sensor: str, key: str) -> str:
    """The TOML path of a sensor's key: ``sensors.wheel.slip_threshold``."""
    return f"sensors.{sensor}.{key}"


def filter_key(key: str) -> str:
    return f"filter.{key}"


def where_to_set(key: str) -> str:
    """``sensors.imu.yaw_offset`` -> 'in the [[sensors]] table with name = "imu"'."""
    parts = key.split(".")
    if parts[0] == "sensors" and len(parts) >= 3:
        return f'in the [[sensors]] table with name = "{".".join(parts[1:-1])}"'
    return f"in the [{parts[0]}] table"


def worst(levels: list[str]) -> str:
    return max(levels, key=LEVELS.index) if levels else "ok"


def format_verdicts(verdicts: list[Verdict]) -> str:
    marks = {"ok": "ok     ", "warn": "WARN   ", "problem": "PROBLEM"}
    lines = []
    for v in verdicts:
        key = f"  [{v.key}]" if v.key else ""
        lines.append(f"doctor {marks[v.level]} {v.sensor}/{v.channel}: {v.message}{key}")
        if not v.suggestion:
            continue
        p = v.proof
        # a line per key, each as it pastes
        where = f"{where_to_set(v.key)}: {v.suggestion}".replace("\n", "\n          ")
        if p is None:
            lines.append(f"       -> {where}")
        elif p.advised or not p.judged:
            lines.append(f"       -> {where}\n          ({'replayed' if p.tried else 'not replayed'}: {p.effect})")
        else:
            lines.append(f"       {'tried' if p.tried else 'not replayed'} {where}\n          ({p.effect}; not advised)")
    return "\n".join(lines)
