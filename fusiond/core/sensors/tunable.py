"""What a sensor kind offers `fusiond tune` to fit: its ``Param`` list, each a positive scale on some
components of one key of its [[sensors]] table.

Each kind says which of its keys are noises a recording can fit and where each starts
(``SensorKind.tunables``, written in the kind's own package, ``tunables.py``): the config's value,
or where the config leaves it unset the median of what the messages state, through the same floors
and "not measured" rules its policy applies, so that the start reproduces what the filter did. A
key that cannot start that way is listed with the reason (``Param.skipped``). ``fusiond.tune.params``
fits them, adds the filter's own keys, and writes fitted values back into a Config.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

@dataclass(frozen=True)
class Param:
    """One tunable scale: ``base`` (the key's whole value at the start) with ``indices`` of it
    (None: the key is a scalar) multiplied by exp(theta)."""

    name: str  # what --keys names and the table shows: "imu.gyro_noise", "wheel.twist_noise.linear"
    table: str  # "filter" or the sensor's name
    key: str  # the config field
    indices: tuple[int, ...] | None
    base: float | tuple[float, ...] = 1.0
    source: str = "config"  # where base came from: "config", "messages (median)" or "unstated: measured, at most"
    unit: str = ""
    skipped: str = ""  # not tunable in this recording, and why
    # other keys of the same table set together with this one when it changes
    companions: tuple[tuple[str, object], ...] = field(default=())
    floor: float = 0.0  # the sensor's floor on this noise (``*_min_sigma``): no fitted value goes below it

    def lowest(self) -> float:
        """The smallest log-scale the fit may take: down to the floor (never above 0: a start the
        user put below the floor may stay there)."""
        start = self.start()
        smallest = min(start) if isinstance(start, tuple) else start
        if self.floor <= 0.0 or not smallest > 0.0:
            return -math.inf
        return min(0.0, math.log(self.floor / smallest))

    @property
    def group(self) -> tuple[str, str]:
        return (self.table, self.key)

    def start(self) -> float | tuple[float, ...]:
        """The components this parameter scales, at the start."""
        if self.indices is None:
            return self.base  # type: ignore[return-value]
        return tuple(self.base[i] for i in self.indices)  # type: ignore[index]


def median(values: Iterable[float]) -> float | None:
    """The median of the values that are not NaN; None when none is."""
    vals = [v for v in values if v == v]
    return statistics.median(vals) if vals else None


def own_samples(samples: Sequence[object], name: str, sample_type: type) -> list:
    """The samples of one sensor (its name and its kind's sample type)."""
    return [s for s in samples if type(s) is sample_type and s.sensor == name]  # type: ignore[attr-defined]


__all__ = ["Param", "median", "own_samples"]
