"""The GPS sensor kind: its [[sensors]] table (``table``), its sample (``sample``), its model with the
heading search, the gate and its re-acquisition (``model``), the keys tune may fit (``tunables``), its wire
formats (``codec``, imported only when a decoder is asked for) and its descriptor (``kind``)."""

from __future__ import annotations

from .kind import GpsKind
from .model import (
    ENU_NAMES, FROZEN_JITTER, FROZEN_JITTER_TRAVEL, FROZEN_MIN_TRAVEL, HEADING_MAX_FIXES, HEADING_MIN_TRAVEL,
    HEADING_PROVISIONAL_SIGMA, HEADING_READY_SIGMA, BURST_REPEAT, HEADING_UNKNOWN_SIGMA, HEADING_WANDER_READY_SIGMA, JUMP_AFTER_PERIODS, JUMP_AFTER_S,
    REACQUIRE_AGREE, REACQUIRE_FIXES, REACQUIRE_JUMP_S, REACQUIRE_S, REACQUIRE_SIGMAS, GpsInput, GpsModel, GpsOwn,
    GpsPolicy, GpsTrack,
)
from .sample import GpsSample
from .table import GpsSensor

__all__ = [
    "BURST_REPEAT", "ENU_NAMES", "FROZEN_JITTER", "FROZEN_JITTER_TRAVEL", "FROZEN_MIN_TRAVEL", "HEADING_MAX_FIXES",
    "HEADING_MIN_TRAVEL", "HEADING_PROVISIONAL_SIGMA", "HEADING_READY_SIGMA", "HEADING_UNKNOWN_SIGMA", "HEADING_WANDER_READY_SIGMA",
    "JUMP_AFTER_PERIODS", "JUMP_AFTER_S", "REACQUIRE_AGREE", "REACQUIRE_FIXES", "REACQUIRE_JUMP_S", "REACQUIRE_S", "REACQUIRE_SIGMAS",
    "GpsInput", "GpsKind", "GpsModel", "GpsSample", "GpsOwn", "GpsPolicy", "GpsSensor", "GpsTrack",
]
