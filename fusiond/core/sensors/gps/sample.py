"""The GPS kind's sample: what its decoders make (``codec``) and its model converts (``model``)."""

from __future__ import annotations

import msgspec


class GpsSample(msgspec.Struct, gc=False):
    """sensor_msgs/NavSatFix: WGS84 position; the core converts it to ENU at the datum."""

    sensor: str
    stamp: float
    latitude: float  # degrees
    longitude: float  # degrees
    altitude: float  # m above the ellipsoid
    status: int = 0  # NavSatStatus.status: -1 no fix, 0 fix, 1 SBAS, 2 GBAS (RTK)
    position_covariance: tuple[float, ...] = (0.0,) * 9  # ENU, row-major, m^2
    covariance_type: int = 0  # 0 unknown, 1 approximated, 2 diagonal known, 3 known


__all__ = ["GpsSample"]
