"""WGS84 geodetic coordinates to a local East-North-Up frame (REP-103: x east, y north, z up).

Exact (no flat-earth shortcut): geodetic -> ECEF -> rotation into the tangent
frame at the datum, so a robot kilometres from its datum still gets metres right.
"""

from __future__ import annotations

import math

WGS84_A = 6378137.0  # semi-major axis, m
WGS84_F = 1.0 / 298.257223563  # flattening
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)  # first eccentricity squared


def geodetic_to_ecef(lat_deg: float, lon_deg: float, alt: float) -> tuple[float, float, float]:
    lat, lon = math.radians(lat_deg), math.radians(lon_deg)
    sl, cl = math.sin(lat), math.cos(lat)
    n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * sl * sl)  # prime vertical radius of curvature
    return ((n + alt) * cl * math.cos(lon), (n + alt) * cl * math.sin(lon), (n * (1.0 - WGS84_E2) + alt) * sl)


class EnuFrame:
    """The tangent frame at a datum; ``enu(lat, lon, alt)`` is a point's position in it."""

    def __init__(self, lat_deg: float, lon_deg: float, alt: float) -> None:
        self.datum = (lat_deg, lon_deg, alt)
        self.origin = geodetic_to_ecef(lat_deg, lon_deg, alt)
        lat, lon = math.radians(lat_deg), math.radians(lon_deg)
        sl, cl, so, co = math.sin(lat), math.cos(lat), math.sin(lon), math.cos(lon)
        # rows: east, north, up unit vectors in ECEF
        self._rows = ((-so, co, 0.0), (-sl * co, -sl * so, cl), (cl * co, cl * so, sl))

    def enu(self, lat_deg: float, lon_deg: float, alt: float) -> tuple[float, float, float]:
        x, y, z = geodetic_to_ecef(lat_deg, lon_deg, alt)
        dx, dy, dz = x - self.origin[0], y - self.origin[1], z - self.origin[2]
        e, n, u = self._rows
        return (e[0] * dx + e[1] * dy + e[2] * dz, n[0] * dx + n[1] * dy + n[2] * dz, u[0] * dx + u[1] * dy + u[2] * dz)


def ecef_to_geodetic(x: float, y: float, z: float) -> tuple[float, float, float]:
    """Inverse of ``geodetic_to_ecef`` (fixed-point iteration on latitude; sub-millimetre after 5 steps)."""
    lon = math.atan2(y, x)
    p = math.hypot(x, y)
    lat = math.atan2(z, p * (1.0 - WGS84_E2))
    alt = 0.0
    for _ in range(8):
        sl = math.sin(lat)
        n = WGS84_A / math.sqrt(1.0 - WGS84_E2 * sl * sl)
        alt = p / math.cos(lat) - n if abs(lat) < 1.5 else z / sl - n * (1.0 - WGS84_E2)
        lat = math.atan2(z, p * (1.0 - WGS84_E2 * n / (n + alt)))
    return math.degrees(lat), math.degrees(lon), alt


def enu_to_geodetic(frame: EnuFrame, e: float, n: float, u: float) -> tuple[float, float, float]:
    """A point of the ENU frame back to WGS84 (to publish a fused position as NavSatFix, and for simulators)."""
    r = frame._rows
    dx = r[0][0] * e + r[1][0] * n + r[2][0] * u
    dy = r[0][1] * e + r[1][1] * n + r[2][1] * u
    dz = r[0][2] * e + r[1][2] * n + r[2][2] * u
    o = frame.origin
    return ecef_to_geodetic(o[0] + dx, o[1] + dy, o[2] + dz)
