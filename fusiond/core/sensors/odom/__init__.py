"""The wheel-odometry sensor kind: its [[sensors]] table (``table``), its sample (``sample``), its model,
policy and coast (``model``), the twist of a driver that fills the pose only (``pose_twist``), its
standstill test (``rest``), the watch for a twist component that is no measurement (``lost_channel``), the
keys tune may fit (``tunables``), its wire formats and struct fast path (``codec``, imported only when a
decoder is asked for) and its descriptor (``kind``)."""

from __future__ import annotations

from .kind import OdomKind
from .model import STOP_DECEL_LIMIT, OdomInput, OdomModel, OdomOwn, OdomPolicy, body_twist, impossible_stop
from .pose_twist import PoseDifferences
from .sample import OdomSample
from .table import OdomSensor

__all__ = ["STOP_DECEL_LIMIT", "OdomInput", "OdomKind", "OdomModel", "OdomOwn", "OdomPolicy", "OdomSample", "OdomSensor",
           "PoseDifferences", "body_twist", "impossible_stop"]
