"""The pose kind's sample: what its decoders make (``codec``) and its model converts (``model``)."""

from __future__ import annotations

import msgspec


class PoseSample(msgspec.Struct, gc=False):
    """A pose of base_link's sensor origin (PoseStamped, PoseWithCovarianceStamped, Odometry.pose)."""

    sensor: str
    stamp: float
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]  # x y z w
    covariance: tuple[float, ...] = ()  # 36 (x y z roll pitch yaw, row-major), or () when the message has none


__all__ = ["PoseSample"]
