"""The odometry kind's sample: what its decoders make (``codec``) and its model converts (``model``)."""

from __future__ import annotations

import msgspec


class OdomSample(msgspec.Struct, gc=False):
    """Wheel odometry: the twist drives the prediction; the pose is kept only for plots."""

    sensor: str
    stamp: float
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    twist_covariance: tuple[float, ...]  # 36, row-major (vx vy vz wx wy wz)
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)  # x y z w


__all__ = ["OdomSample"]
