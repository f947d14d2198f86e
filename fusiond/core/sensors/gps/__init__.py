"""The GPS sensor kind: its [[sensors]] table (``table``), its sample (``sample``), its model with the
heading search, the gate and its re-acquisition (``model``), the keys tune may fit (``tunables``), its wire
formats (``codec``, imported only when a decoder is asked for) and its descriptor (``kind``)."""

from __future__ import annotations

from ....lazy_exports import lazy_exports
from .kind import GpsKind
from .sample import GpsSample
from .table import GpsSensor

# the model's modules need numpy and the estimator: imported when first read, so that a config loads
# without them (``kind.ModelIn``)
_EXPORTS = {
    "BURST_REPEAT": "model",
    "ENU_NAMES": "model",
    "FROZEN_JITTER": "model",
    "FROZEN_JITTER_TRAVEL": "model",
    "FROZEN_MIN_TRAVEL": "model",
    "HEADING_MAX_FIXES": "model",
    "HEADING_MIN_TRAVEL": "model",
    "HEADING_PROVISIONAL_SIGMA": "model",
    "HEADING_READY_SIGMA": "model",
    "HEADING_UNKNOWN_SIGMA": "model",
    "HEADING_WANDER_READY_SIGMA": "model",
    "JUMP_AFTER_PERIODS": "model",
    "JUMP_AFTER_S": "model",
    "REACQUIRE_AGREE": "model",
    "REACQUIRE_FIXES": "model",
    "REACQUIRE_JUMP_S": "model",
    "REACQUIRE_S": "model",
    "REACQUIRE_SIGMAS": "model",
    "GpsInput": "model",
    "GpsModel": "model",
    "GpsOwn": "model",
    "GpsPolicy": "model",
    "GpsTrack": "model",
}

_, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = sorted(["GpsKind", "GpsSample", "GpsSensor", *_EXPORTS])
