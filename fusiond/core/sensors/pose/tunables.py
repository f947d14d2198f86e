"""The pose sensor's tunable keys (``SensorKind.tunables``): its position and orientation noise, one
scale each."""

from __future__ import annotations

import math
from collections.abc import Sequence

from ..tunable import Param, median, own_samples
from .sample import PoseSample
from .table import PoseSensor


def pose_tunables(s: PoseSensor, samples: Sequence[object]) -> list[Param]:
    """position_noise and orientation_noise, one scale each (all three axes): from the config, else
    from the messages' median variances (``unknown_sigma`` for a message without covariance)."""
    out = []
    mine = own_samples(samples, s.name, PoseSample)
    for key, rows, floor, cap, unknown, unit in (
            ("position_noise", (0, 1, 2), s.position_min_sigma, s.max_sigma[0], s.unknown_sigma[0], "m"),
            ("orientation_noise", (3, 4, 5), s.orientation_min_sigma, s.max_sigma[1], s.unknown_sigma[1], "rad")):
        name = f"{s.name}.{key}"
        given = getattr(s, key)
        if given is not None:
            base = tuple(given)
            out.append(Param(name, s.name, key, (0, 1, 2), base, unit=unit, floor=floor,
                             skipped="" if all(v > 0.0 for v in base) else "0 in the config"))
            continue
        if not mine:
            out.append(Param(name, s.name, key, (0, 1, 2), unit=unit, skipped="no messages"))
            continue
        variances = [median(m.covariance[7 * r] if len(m.covariance) == 36 else unknown**2 for m in mine)
                     for r in rows]
        if any(v is None or not (0.0 <= v < cap**2) for v in variances):
            out.append(Param(name, s.name, key, (0, 1, 2), unit=unit, skipped=(
                "the messages state an axis not measured (an override would fuse it)")))
            continue
        base = tuple(max(math.sqrt(v), floor) for v in variances)  # type: ignore[arg-type]
        out.append(Param(name, s.name, key, (0, 1, 2), base, "messages (median)", unit, floor=floor))
    return out


__all__ = ["pose_tunables"]
