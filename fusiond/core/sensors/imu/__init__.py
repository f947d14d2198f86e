"""The IMU sensor kind: its descriptor (``kind``), its model (``model``), the filter input a message
becomes (``inputs``), its [[sensors]] table (``table``), its slice of the filter state (``own``), the gyro bias learned at standstills
(``gyro_bias``), the heading carried across logging gaps by the IMU's own yaw (``gap_turn``) and where a
noise stated in the IMU's axes lands in base_link's (``axes``), the keys tune may fit (``tunables``), its sample (``sample``) and its wire
formats and struct fast path (``codec``, imported only when a decoder is asked for)."""

from __future__ import annotations

from ....lazy_exports import lazy_exports
from .kind import ImuKind
from .sample import ImuSample
from .table import ImuSensor

# the model's modules need numpy and the estimator: imported when first read, so that a config loads
# without them (``kind.ModelIn``)
_EXPORTS = {
    "BiasLearning": "gyro_bias",
    "quiet_bound": "gyro_bias",
    "ImuInput": "inputs",
    "G_UNITS_BAND": "model",
    "GRAVITY": "model",
    "ORIENTATION_BURST": "model",
    "YAW_JUMP_GATE": "model",
    "ImuModel": "model",
    "ImuPolicy": "model",
    "ImuOwn": "own",
}

_, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = sorted(["ImuKind", "ImuSample", "ImuSensor", *_EXPORTS])
