"""The pose sensor kind (absolute, or differential: deltas between its poses): its [[sensors]] table
(``table``), its sample (``sample``), its model (``model``), the keys tune may fit (``tunables``), its
wire formats (``codec``, imported only when a decoder is asked for) and its descriptor (``kind``)."""

from __future__ import annotations

from ....lazy_exports import lazy_exports
from .kind import PoseKind
from .sample import PoseSample
from .table import POSE_MSGTYPES, PoseSensor

# the model's modules need numpy and the estimator: imported when first read, so that a config loads
# without them (``kind.ModelIn``)
_EXPORTS = {
    "PoseAnchor": "model",
    "PoseInput": "model",
    "PoseModel": "model",
    "PosePolicy": "model",
}

_, __getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
__all__ = sorted(["POSE_MSGTYPES", "PoseKind", "PoseSample", "PoseSensor", *_EXPORTS])
