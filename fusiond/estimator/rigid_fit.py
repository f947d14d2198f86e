"""Least-squares rigid fit (rotation + translation) of a dead-reckoned track to GPS fixes.

A wrong initial heading rotates the whole dead-reckoned track about its start, so the
track and the fixes differ by one planar rigid motion g_i = R(theta) d_i + t + n_i.
With weights w_i = 1 / sigma_i^2 (isotropic fix noise) the weighted Procrustes solution is
closed-form: centre both point sets on their weighted centroids (d', g'); then

    theta = atan2(sum w (d'_x g'_y - d'_y g'_x), sum w (d'_x g'_x + d'_y g'_y)),
    t = g_bar - R(theta) d_bar.

Its uncertainty, linearised at the solution: the centroid and the angle are independent,
var(centroid) = 1 / sum w per axis and var(theta) = 1 / sum w |d'|^2 -- the track's
weighted "moment of inertia": a longer, more spread track pins the angle better. Where
the residuals say the fixes scatter more than stated (or the dead-reckoned track is not
rigid: slip, a scale error), both are scaled by the residual variance factor
s^2 = sum w |r|^2 / (2N - 3) when it exceeds 1.

Unlike a chord angle between two points it uses every fix since the first, and keeps
improving as the track grows, so it can be applied provisionally and refined.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RigidFit:
    theta: float  # rotation to apply to the track, rad
    tx: float  # translation after the rotation, m
    ty: float
    var_theta: float  # rad^2
    var_centroid: float  # m^2 per axis, of the fitted track's (weighted) centroid
    centroid: tuple[float, float]  # weighted centroid of the dead-reckoned points
    residual_factor: float  # s^2 (>= 1 once applied to the variances)

    def apply(self, x: float, y: float) -> tuple[float, float]:
        """R(theta) (x, y) + t: a dead-reckoned point moved onto the fixes."""
        c, s = math.cos(self.theta), math.sin(self.theta)
        return c * x - s * y + self.tx, s * x + c * y + self.ty

    def point_covariance(self, x: float, y: float) -> tuple[tuple[float, float, float], ...]:
        """Covariance of (fitted x, fitted y, theta) at the dead-reckoned point (x, y), 3x3 rows.

        p = g_bar + R (d - d_bar): dp = d g_bar + J dtheta with J = (-r_y, r_x), r = R (d - d_bar).
        """
        c, s = math.cos(self.theta), math.sin(self.theta)
        ux, uy = x - self.centroid[0], y - self.centroid[1]
        rx, ry = c * ux - s * uy, s * ux + c * uy
        jx, jy, vt, vc = -ry, rx, self.var_theta, self.var_centroid
        return ((vc + jx * jx * vt, jx * jy * vt, jx * vt),
                (jx * jy * vt, vc + jy * jy * vt, jy * vt),
                (jx * vt, jy * vt, vt))


def fit_rigid(points: list[tuple[float, float, float, float, float]]) -> RigidFit | None:
    """Fit (gx, gy, dx, dy, w) pairs: fix g, dead-reckoned point d, weight w = 1/sigma^2.

    None while the track has no extent (fewer than 2 points, or all dead-reckoned points equal).
    """
    if len(points) < 2:
        return None
    sw = sgx = sgy = sdx = sdy = 0.0
    for gx, gy, dx, dy, w in points:
        sw += w
        sgx += w * gx
        sgy += w * gy
        sdx += w * dx
        sdy += w * dy
    gbx, gby, dbx, dby = sgx / sw, sgy / sw, sdx / sw, sdy / sw
    cross = dot = inertia = 0.0
    for gx, gy, dx, dy, w in points:
        ux, uy, vx, vy = dx - dbx, dy - dby, gx - gbx, gy - gby
        cross += w * (ux * vy - uy * vx)
        dot += w * (ux * vx + uy * vy)
        inertia += w * (ux * ux + uy * uy)
    if inertia <= 0.0:
        return None
    theta = math.atan2(cross, dot)
    c, s = math.cos(theta), math.sin(theta)
    tx, ty = gbx - (c * dbx - s * dby), gby - (s * dbx + c * dby)
    chi2 = 0.0
    for gx, gy, dx, dy, w in points:
        ex, ey = gx - (c * dx - s * dy + tx), gy - (s * dx + c * dy + ty)
        chi2 += w * (ex * ex + ey * ey)
    dof = 2 * len(points) - 3
    factor = max(1.0, chi2 / dof) if dof > 0 else 1.0
    return RigidFit(theta, tx, ty, factor / inertia, factor / sw, (dbx, dby), factor)
