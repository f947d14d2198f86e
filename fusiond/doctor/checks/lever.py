"""The GPS antenna's lever arm: what the fixes move beyond the wheels as the vehicle turns.

A fix is the antenna's position, base + R(yaw) l with l the antenna in base_link
(``extrinsic_xyz``). Stated wrong (or left at 0 on a robot whose antenna sits on a mast
at the back), the fixes swing by (R(yaw2) - R(yaw1)) dl as the vehicle turns, dl the
part of l not stated. The filter follows part of that swing, so neither its innovations
nor the fixes against its estimate show all of it (30-60 % of a 1.5 m lever, with
the GPS NIS in the "ok" band). Between two consecutive fixes, though, the wheels and the
estimated heading say how far the base moved: the dead-reckoned displacement dP (the
odometry bins' speed along the estimated yaw, summed), right over a second up to the
wheel scale and a heading offset. What the fixes moved beyond dP and beyond the stated
lever's own swing is (over pairs PAIR_S apart: the longer the pair, the more the heading
turns within it, while the fixes' white noise stays what it is)

    r = (R(yaw2) - R(yaw1)) dl + k dP + theta J dP + noise,

linear in dl, a wheel-scale error k and a heading offset theta (J: a quarter turn). The
noise is the fixes' white part, twice (a wandering receiver error moves little within one
interval). Least squares over every pair gives dl with its covariance from the residuals'
scatter (pairs beyond OUTLIER_SIGMAS of it, multipath, are dropped once and the fit redone).

A lever is named when dl is both large (LEVER_TOL) and significant (its chi-square with 2
dof beyond LEVER_Z_SIGMAS^2, from a fit within MAX_SE_NAMED): ``extrinsic_xyz`` = the stated lever
+ dl, its height kept (a lever's height moves the fixes only with the tilt); "as stated" needs
the fit within MAX_SE. Only turns show a lever: a car on a highway, hardly turning, cannot
tell one: no verdict, measure it.
"""

from __future__ import annotations

import math

import numpy as np

from ..median import median
from ..series import Series
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key

__all__ = ["LeverArm"]

LEVER_TOL = 0.2  # m: a lever this close to the stated one is not worth a change
MAX_SE = 0.1  # m: "as stated" needs the fit this precise (half LEVER_TOL)
MAX_SE_NAMED = 0.3  # m: a lever is named only from a fit this precise (a fifth of a 1.5 m mast's offset)
LATENCY_ALONG = 2.0  # a misfit behind base_link this many times longer than it is wide: also says latency
# named when the lever's chi-square (2 dof) exceeds LEVER_Z_SIGMAS^2 = 25 (p ~ 4e-6, the module docstring)
LEVER_Z_SIGMAS = 5.0
OUTLIER_SIGMAS = 4.0  # a pair beyond 4 sigma of the scatter is multipath (a normal pair: 6e-5 chance)
MIN_PAIRS = 30  # fix pairs in turns before a fit: its scatter estimate then good to ~13 %
PAIR_S = 3.0  # s between the two fixes of a pair (the module docstring)
MAX_INTERVAL = 1.5  # a pair further apart than this many PAIR_S (fixes missing) is not used


def _rot(yaw: np.ndarray, l: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(yaw), np.sin(yaw)
    return c * l[0] - s * l[1], s * l[0] + c * l[1]


def lever_fit(series: Series, stated: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, int] | None:
    """(dl east/north in base_link x/y, its 2x2 covariance, pairs used), or None without enough pairs."""
    tf, fe, fn = np.asarray(series.gps_t), np.asarray(series.gps_e), np.asarray(series.gps_n)
    to, vo = np.asarray(series.odom_t), np.asarray(series.odom_v)
    te = np.asarray(series.est_t)
    if len(tf) < MIN_PAIRS + 1 or len(to) < 2 or len(te) < 2:
        return None
    ye = np.unwrap(np.asarray(series.est_yaw))
    # the dead-reckoned base track: the odometry bins' speed along the estimated yaw, integrated between the
    # bins' middles (trapezoids: a bin per BIN_S when the wheels report that often, fewer when they do not)
    yaw_o = np.interp(to, te, ye)
    v = np.where(np.isfinite(vo), vo, 0.0)
    ve, vn, h = v * np.cos(yaw_o), v * np.sin(yaw_o), np.diff(to)
    pe = np.concatenate(([0.0], np.cumsum(0.5 * (ve[1:] + ve[:-1]) * h)))
    pn = np.concatenate(([0.0], np.cumsum(0.5 * (vn[1:] + vn[:-1]) * h)))
    inside = (tf >= to[0]) & (tf <= to[-1]) & (tf >= te[0]) & (tf <= te[-1])
    tf, fe, fn = tf[inside], fe[inside], fn[inside]
    if len(tf) < MIN_PAIRS + 1:
        return None
    # pairs PAIR_S apart, not overlapping (their noise independent): the signal grows with the heading
    # change across a pair, the fixes' white noise does not (the wheels' error and a wander's change do,
    # slowly), so longer pairs tell more, fewer of them
    k = max(1, int(round(PAIR_S / float(median(np.diff(tf))))))
    tf, fe, fn = tf[::k], fe[::k], fn[::k]
    if len(tf) < MIN_PAIRS + 1:
        return None
    de_p, dn_p = np.diff(np.interp(tf, to, pe)), np.diff(np.interp(tf, to, pn))
    yaw_f = np.interp(tf, te, ye)
    dt = np.diff(tf)
    # a pair is usable when its fixes are PAIR_S apart (none missing) and the wheels reported across it
    use = (dt > 0.0) & (dt <= MAX_INTERVAL * max(PAIR_S, float(median(dt))))
    for start, length in series.odom_gaps:  # the wheels' travel in a logging gap is not in dP
        use &= ~((tf[1:] > start) & (tf[:-1] < start + length))
    if use.sum() < MIN_PAIRS:
        return None
    se0, sn0 = _rot(yaw_f, stated)
    re = np.diff(fe) - de_p - np.diff(se0)
    rn = np.diff(fn) - dn_p - np.diff(sn0)
    c, s = np.cos(yaw_f), np.sin(yaw_f)
    dc, ds = np.diff(c), np.diff(s)
    # rows: east then north of each pair; columns: dl_x, dl_y, k, theta
    A_e = np.stack([dc, -ds, de_p, -dn_p], axis=1)
    A_n = np.stack([ds, dc, dn_p, de_p], axis=1)
    keep = use.copy()
    for _ in range(2):
        A = np.concatenate([A_e[keep], A_n[keep]])
        r = np.concatenate([re[keep], rn[keep]])
        x, *_ = np.linalg.lstsq(A, r, rcond=None)
        res = r - A @ x
        dof = len(r) - 4
        if dof <= 0:
            return None
        var = float(res @ res) / dof
        m = int(keep.sum())
        pair = np.hypot(res[:m], res[m:])
        bad = np.zeros_like(keep)
        bad[np.nonzero(keep)[0]] = pair > OUTLIER_SIGMAS * math.sqrt(2.0 * var)
        if not bad.any():
            break
        keep &= ~bad
    try:
        cov = var * np.linalg.inv(A.T @ A)
    except np.linalg.LinAlgError:
        return None
    return x[:2], cov[:2, :2], int(keep.sum())


def _unmeasured(gps, series: Series, why: str) -> list[Verdict]:
    """Said, at level ok, where the antenna is left where ``extrinsic_xyz`` puts it by default (at the base) and
    this run cannot show a lever (module doc: only turns do): a user whose antenna sits on a mast should not read
    the silence as "no lever"."""
    if any(float(v) != 0.0 for v in gps.extrinsic_xyz):
        return []  # stated: nothing here contradicts it, and nothing to add
    turned = series.gyro_heading or series.odom_heading  # what the vehicle turned (not the heading search's jumps)
    span = math.degrees(float(np.ptp(np.asarray(turned)))) if turned else 0.0
    return [Verdict(gps.name, "lever_arm", "ok",
                    f"the antenna's lever arm cannot be measured on this run ({why}; the vehicle turned through "
                    f"{span:.0f} deg): extrinsic_xyz puts the antenna at the base. If it sits elsewhere (a mast, the roof's "
                    "back), state it, or record a drive with turns and ask again", evidence={"heading_span_deg": span})]


class LeverArm(BaseCheck):
    """The GPS antenna's lever arm, from how the fixes swing as the vehicle turns."""

    name = "lever"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        """A verdict on the first GPS's ``extrinsic_xyz`` (module doc); none when the run cannot tell."""
        series, gps = ev.series, ev.gps
        if gps is None:
            return []
        stated = (float(gps.extrinsic_xyz[0]), float(gps.extrinsic_xyz[1]))
        fit = lever_fit(series, stated)
        if fit is None:
            return _unmeasured(gps, series, f"fewer than {MIN_PAIRS} pairs of fixes {PAIR_S:g} s apart with the "
                                            "wheels reporting between them")
        dl, cov, pairs = fit
        se = math.sqrt(max(float(np.max(np.diag(cov))), 0.0))
        try:
            chi2 = float(dl @ np.linalg.solve(cov, dl))
        except np.linalg.LinAlgError:
            return _unmeasured(gps, series, f"{pairs} pairs of fixes, too little turning among them to fit one")
        named = math.hypot(*dl) >= LEVER_TOL and chi2 >= LEVER_Z_SIGMAS**2 and se <= MAX_SE_NAMED
        if not (named or se <= MAX_SE):
            return _unmeasured(gps, series, f"{pairs} pairs of fixes, the fit's standard error {se:.2f} m (at most "
                                            f"{MAX_SE:g} m tells one)")
        lever = (stated[0] + float(dl[0]), stated[1] + float(dl[1]), float(gps.extrinsic_xyz[2]))
        evidence = {"lever_x_m": lever[0], "lever_y_m": lever[1], "lever_dx_m": float(dl[0]),
                    "lever_dy_m": float(dl[1]),
                    "lever_se_m": se, "fix_pairs": float(pairs)}
        where = (f"over {pairs} pairs of fixes, what they moved beyond the wheels' dead-reckoned travel as the vehicle "
                 "turned puts the antenna at ")
        if not named:
            # not "as stated" when it is not: the distance is said, and why it is not named (a 0.25 m lever at
            # 4.2 standard errors is not shown to be what extrinsic_xyz says, only not proven to differ)
            off = math.hypot(*dl)
            why = (f"within {LEVER_TOL:g} m: not worth a change" if off < LEVER_TOL else
                   f"not named: {math.sqrt(chi2):.1f} standard errors, {LEVER_Z_SIGMAS:g} needed")
            return [Verdict(gps.name, "lever_arm", "ok",
                            where + f"x {lever[0]:+.2f} y {lever[1]:+.2f} m (+- {se:.2f}) in base_link, "
                            f"{off:.2f} m from "
                            f"extrinsic_xyz's ({stated[0]:+.2f}, {stated[1]:+.2f}): {why}", evidence=evidence)]
        latency = ""
        if dl[0] < 0.0 and abs(dl[0]) > LATENCY_ALONG * abs(dl[1]):
            # fixes stamped late trail the vehicle by speed x latency: at one speed that looks like a lever behind it
            latency = (". Behind and along the vehicle, it can also be fixes stamped late (a latency tau trails them "
                       "by speed x tau): if the antenna is not there, see the GPS's clock verdict and stamp_offset_s")
        return [Verdict(gps.name, "lever_arm", "warn",
                        where + f"x {lever[0]:+.2f} y {lever[1]:+.2f} m (+- {se:.2f}) in base_link, "
                        f"{math.hypot(*dl):.2f} m from where extrinsic_xyz puts it ({stated[0]:+.2f}, "
                        f"{stated[1]:+.2f}): its fixes swing by that as the vehicle turns, which the filter takes for "
                        "the base moving (and partly follows, so the NIS need not show it). State the antenna's "
                        "position (the height is kept: only the tilt shows it)"
                        + latency,
                        sensor_key(gps.name, "extrinsic_xyz"),
                        f"extrinsic_xyz = [{lever[0]:.2f}, {lever[1]:.2f}, {lever[2]:.2f}]", evidence)]
