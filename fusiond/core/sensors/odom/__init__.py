"""The wheel-odometry sensor kind: its [[sensors]] table (``table``), its sample (``sample``), its model,
policy and coast (``model``), the twist of a driver that fills the pose only (``pose_twist``), its
standstill test (``rest``), the watch for a twist component that is no measurement (``lost_channel``), the
keys tune may fit (``tunables``), its wire formats and struct fast path (``codec``, imported only when a
decoder is asked for) and its descriptor (``kind``)."""

from __future__ import annotations

from ....lazy_exports import lazy_exports
from .kind import OdomKind
from .sample import OdomSample
from .table import OdomSensor

# the model's modules need numpy and the estimator: imported when first read, so that a config loads
# without them (``kind.ModelIn``)
_EXPORTS = {
    "STOP_DECEL_LIMIT": "model",
    "OdomInput": "model",
    "OdomModel": "model",
    "OdomOwn": "model",
    "OdomPolicy": "model",
    "body_twist": "model",
    "impossible_stop": "model",
    "PoseDifferences": "pose_twist",
}

_, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = sorted(["OdomKind", "OdomSample", "OdomSensor", *_EXPORTS])
