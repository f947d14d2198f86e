"""A sensor whose clock is offset from the others: its samples dropped as "far from filter time".

A driver stamping in GPS time (18 s ahead of UTC since 2017) or in its own boot time
has every sample held and then dropped as ``future_stamp``/``stale_stamp``: the core
only says "a clock glitch", N times. The doctor sees every sample as it arrives, so
it measures the offset: each sample's stamp against the newest stamp of the OTHER
sensors when it arrives (what the filter's time follows). The median over the run is
that sensor's clock offset (plus its transport lag, milliseconds), and a sensor whose
samples are mostly dropped that way gets one plain verdict with it (``checks/clocks.py``). Against each
other sensor it also measures the pace (``ClockOffsets.pace``): how far its stamps advance while the other's
do, which tells a clock that does not run (a driver stamping 0 or a constant) from one that is offset.
"""

from __future__ import annotations

import math
from array import array

import numpy as np

from .median import median

MAX_KEPT = 20_000  # offsets kept per sensor (the median of that many is settled; bounded memory)


class ClockOffsets:
    """Per sensor, its samples' stamps minus the newest stamp of the other sensors at arrival.

    The replay has one for every message, so they are computed in bulk (:meth:`extend`, a chunk of
    arrivals at a time): for each sensor, a running maximum of the other sensors' stamps."""

    def __init__(self) -> None:
        self._ids: dict[str, int] = {}
        self._newest: list[float] = []  # per sensor id: its newest stamp so far
        self._offsets: dict[str, array] = {}
        # per (sensor, other sensor): [its stamp, the other's newest] at its first arrival after the other spoke,
        # and at its latest arrival, for ``pace``
        self._pairs: dict[tuple[str, str], list[float]] = {}

    def add(self, sensor: str, stamp: float) -> None:
        self.extend([sensor], [stamp])

    def extend(self, sensors: list[str], stamps: list[float]) -> None:
        """Samples' sensors and stamps, in arrival order (non-finite stamps are no evidence: skipped)."""
        ids = self._ids
        for name in dict.fromkeys(sensors):
            if name not in ids:
                ids[name] = len(ids)
                self._newest.append(-math.inf)
        idx = np.array([ids[name] for name in sensors], dtype=np.intp)
        t = np.array(stamps, dtype=float)
        finite = np.isfinite(t)
        idx, t = idx[finite], t[finite]
        # each sensor's newest stamp at every arrival of the chunk, once: the others' newest (offsets) and each
        # other's (paces) are read from them
        running = {j: np.maximum.accumulate(np.concatenate(([self._newest[j]], np.where(idx == j, t, -math.inf))))[1:]
                   for j in ids.values()}
        for name, i in ids.items():
            mine = idx == i
            rest = [running[j] for j in ids.values() if j != i]
            if not rest or not mine.any():
                continue
            others = np.maximum.reduce(rest)  # at this sensor's arrivals: the newest stamp of any other
            seen = mine & (others > -math.inf)  # another sensor has spoken: an offset
            if seen.any():
                for other, j in ids.items():
                    if j != i:
                        self._pace_pair(name, other, t, mine, running[j])
                kept = self._offsets.setdefault(name, array("d"))
                if len(kept) < MAX_KEPT:
                    kept.extend((t[seen] - others[seen])[: MAX_KEPT - len(kept)].tolist())
        for name, i in ids.items():
            mine = t[idx == i]
            if len(mine):
                self._newest[i] = max(self._newest[i], float(mine.max()))

    def lag(self, sensor: str, share: float = 0.99) -> float | None:
        """How far behind the others' newest stamp this sensor's samples arrive, at most, for ``share``
        of them (s, >= 0); None without another sensor."""
        kept = self._offsets.get(sensor)
        if not kept:
            return None
        return max(0.0, -float(np.quantile(np.frombuffer(kept, dtype=float), 1.0 - share)))

    def _pace_pair(self, name: str, other: str, t: np.ndarray, mine: np.ndarray, newest: np.ndarray) -> None:
        """``pace``'s ends for ``name`` against ``other``, over a chunk: ``newest``, the other's newest stamp at each
        arrival of it."""
        at = np.flatnonzero(mine & (newest > -math.inf))
        if not len(at):
            return
        first, last = int(at[0]), int(at[-1])
        ends = self._pairs.get((name, other))
        if ends is None:
            ends = self._pairs[(name, other)] = [float(t[first]), float(newest[first]), 0.0, 0.0]
        ends[2], ends[3] = float(t[last]), float(newest[last])

    def pace(self, sensor: str) -> dict[str, tuple[float, float]]:
        """Per other sensor: (how far this sensor's stamps advanced, how far the other's newest stamp did) between
        this sensor's first arrival after the other spoke and its latest, s. A clock that runs advances as each
        other running clock does, whatever its offset; a driver that stamps a constant (or 0) does not advance;
        an other that stopped early has advanced less (so a pace is judged against every other sensor)."""
        return {other: (ends[2] - ends[0], ends[3] - ends[1])
                for (name, other), ends in self._pairs.items() if name == sensor}

    def newest(self, sensor: str) -> float | None:
        """The sensor's newest stamp so far (None before any)."""
        i = self._ids.get(sensor)
        return None if i is None or self._newest[i] == -math.inf else self._newest[i]

    def offset(self, sensor: str) -> float | None:
        """Median offset of the sensor's stamps from the others' (s), None without another sensor."""
        kept = self._offsets.get(sensor)
        return float(median(np.frombuffer(kept, dtype=float))) if kept else None
