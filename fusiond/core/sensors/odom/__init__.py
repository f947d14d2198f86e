"""The wheel-odometry sensor kind: its [[sensors]] table (``table``), its model, policy and coast
(``model``), its standstill test (``rest``), the watch for a twist component that is no measurement
(``lost_channel``), the keys tune may fit (``tunables``) and its descriptor (``kind``)."""

from __future__ import annotations

from .kind import OdomKind
from .model import STOP_DECEL_LIMIT, OdomInput, OdomModel, OdomOwn, OdomPolicy, body_twist, impossible_stop
from .table import OdomSensor

__all__ = ["STOP_DECEL_LIMIT", "OdomInput", "OdomKind", "OdomModel", "OdomOwn", "OdomPolicy", "OdomSensor",
           "body_twist", "impossible_stop"]
