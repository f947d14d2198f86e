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
    # the floors the recording's standstills set on the components ``start()`` lists (0: none), and how they
    # were measured (``fusiond/tune/floors.py``)
    measured: tuple[float, ...] = ()
    measured_note: str = ""

    def lowest(self) -> float:
        """The smallest log-scale the fit may take: down to the sensor's floor and to the noise the
        recording shows at rest (never above 0: a start the user put below them may stay there)."""
        return min(0.0, max(self._constant_low(), self._measured_low()))

    def held_by_measured(self) -> bool:
        """Is the floor the fit stops at the one measured at rest rather than the sensor's constant?"""
        return self._measured_low() > self._constant_low()

    def _components(self) -> tuple[float, ...]:
        start = self.start()
        return start if isinstance(start, tuple) else (start,)

    def _constant_low(self) -> float:
        components = self._components()
        smallest = min(components) if components else 0.0
        return math.log(self.floor / smallest) if self.floor > 0.0 and smallest > 0.0 else -math.inf

    def _measured_low(self) -> float:
        ratios = [math.log(f / c) for f, c in zip(self.measured, self._components()) if f > 0.0 and c > 0.0]
        return max(ratios) if ratios else -math.inf

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
