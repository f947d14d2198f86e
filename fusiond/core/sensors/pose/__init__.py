"""The pose sensor kind (absolute, or differential: deltas between its poses): its [[sensors]] table
(``table``), its sample (``sample``), its model (``model``), the keys tune may fit (``tunables``), its
wire formats (``codec``, imported only when a decoder is asked for) and its descriptor (``kind``)."""

from __future__ import annotations

from .kind import PoseKind
from .model import PoseAnchor, PoseInput, PoseModel, PosePolicy
from .sample import PoseSample
from .table import POSE_MSGTYPES, PoseSensor

__all__ = ["POSE_MSGTYPES", "PoseAnchor", "PoseInput", "PoseKind", "PoseModel", "PosePolicy", "PoseSample", "PoseSensor"]
