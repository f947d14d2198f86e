"""Wheel speed against GPS speed: the wheels' scale error, measured over chords of the track.

Over a chord between two fixes the GPS displacement is the truth up to the fixes'
errors; the wheels' displacement over the same time is their speed dead-reckoned
along the integrated gyro heading (exact over a minute up to the bias, and a
heading offset does not change a chord's length), so curved stretches count too.
Per chord i (from fix a_i to fix b_i, direction u_i), with g_i the GPS chord length
and d_i the wheels':

    g_i = k d_i + e_i,        k = true speed / wheel speed,   e_i = u_i . (E(b_i) - E(a_i)),

E the fixes' horizontal error, per axis with covariance

    K(s, t) = sigma_w^2 [s = t] + sigma_m^2 exp(-|s - t| / tau):

white noise, and a slow wander (multipath, ionosphere: a first-order Gauss-Markov
error). A chord's error variance is V_i = 2 sigma_w^2 + 2 sigma_m^2 (1 - exp(-dt_i / tau)):
over dt << tau the wander is a random walk (2 sigma_m^2 dt / tau), so it alone would
favour no chord length. Weighted least squares, weights 1 / V_i:

    k = sum(d g / V) / sum(d^2 / V).

Chords are consecutive (each starts at the fix the last one ended at) and short
(10 m, or 20 sigma_w), so that they follow the path: then the wander telescopes.
Consecutive chords share a fix, and OU increments over disjoint intervals are
negatively correlated (Cov = -sigma_m^2 (1 - e^(-dt_1/tau)) (1 - e^(-dt_2/tau)) e^(-gap/tau)),
so along a stretch the sum of chords carries only the wander's change from its start
to its end, not one increment per chord. (Measured on sim_gps, sigma_m = 2 m,
tau = 100 s, 300 s at 2 m/s, six seeds: 10 m chords give a 0.8 % rms scale error,
30 m chords that cut the curves 1.4 %.) The standard error therefore takes the correlations in:

* the model's: Var(k) = sum_ij c_i c_j C_ij with c_i = (d_i / V_i) / sum(d^2 / V) and
  C_ij = (u_i . u_j) [K(b_i, b_j) - K(b_i, a_j) - K(a_i, b_j) + K(a_i, a_j)];
* the residuals' (Newey-West): the variance of sum c_i r_i from the residuals'
  products up to NW lags apart (Bartlett weights), which measures whatever the
  chords' errors really are, including a wander larger than the model's.

The verdict uses the larger. sigma_m and tau are the GPS's ``error_sigma``/``error_tau_s``
when the config states them. Otherwise the receiver's stated sigma is taken as its
wander's size too (a consumer receiver states metres and wanders metres, an RTK fix
states and wanders centimetres) with tau = ASSUMED_TAU_S, the fast end of what receivers
show (100 to 300 s: over a chord, the larger increment); a receiver that wanders more
than it states is caught by the residuals' standard error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...config import Config, GpsSensor
from ...core.sensors.registry import kind_of
from ...core.diagnostics import t_quantile
from ..check import BaseCheck
from .clocks import dropped_by_clock
from ..chords import ASSUMED_TAU_S, CHORD_M, MIN_CHORDS, SCALE_Z_SIGMAS, cumulative, newey_west, wheel_chords
from ..evidence import Evidence
from ..heading import gps_sigma, timed
from ..series import Series
from ..verdict import Verdict, sensor_key


__all__ = ["Speed", "wheel_scale_fit"]

SCALE_TOLERANCE = 0.02  # a wheel scale within 2 % is not worth a state


@dataclass
class ScaleFit:
    scale: float  # true / wheel speed
    se: float
    se_model: float
    se_empirical: float  # Newey-West, from the residuals
    chords: int
    distance_m: float  # GPS distance over the chords

    @property
    def band(self) -> float:
        """The half-width within which the scale is not named: the tolerance, or SCALE_Z_SIGMAS of the model's
        standard error (known noise: a normal quantile), or the same quantile of Student's t for the
        residuals' standard error (estimated from the chords themselves)."""
        return max(SCALE_TOLERANCE, SCALE_Z_SIGMAS * self.se_model, t_quantile(SCALE_Z_SIGMAS, self.chords - 1) * self.se_empirical)

    def evidence(self) -> dict[str, float]:
        return {"wheel_scale_vs_gps": self.scale, "wheel_scale_se": self.se, "wheel_scale_se_model": self.se_model,
                "wheel_scale_se_residuals": self.se_empirical, "stretches": float(self.chords),
                "gps_distance_m": self.distance_m}


def wander(gps: GpsSensor | None, sigma_w: float) -> tuple[float, float]:
    """(sigma_m, tau) of the GPS's slow error: as configured, else assumed (see the module docstring)."""
    if gps is not None and gps.error_tau_s > 0.0 and gps.error_sigma is not None:
        return float(max(gps.error_sigma[0], gps.error_sigma[1])), float(gps.error_tau_s)
    return sigma_w, ASSUMED_TAU_S


def wheel_scale_fit(series: Series, cfg: Config) -> ScaleFit | None:
    """The weighted chord fit of the wheel scale, or None without enough chords."""
    gps = next((s for s in cfg.sensors if kind_of(s).geodetic), None)
    if len(series.gps_t) < 5 or len(series.odom_t) < 10:
        return None
    sigma_w = gps_sigma(series, gps)
    sigma_m, tau = wander(gps, sigma_w)
    to = np.array(series.odom_t)
    # the heading at the instants the bins' mean speeds hold at (their middles), not the one each bin
    # closed with (its end: BIN_S / 2 later, a turn's worth of heading on an agile vehicle)
    tg, hg = timed(series.gyro_heading_at, series.gyro_heading)
    if len(tg) < 10:
        tg, hg = timed(series.odom_heading_at, series.odom_heading)
    heading = np.interp(to, tg, hg)
    v = np.array(series.odom_v)
    # dead-reckon the wheels with the (short-term exact) integrated gyro: chords compare, curves or not
    x = cumulative(to, v * np.cos(heading))
    y = cumulative(to, v * np.sin(heading))
    g, d, dt, ta, tb, u = [], [], [], [], [], []
    # a chord across a logging gap or a coast is no evidence of a scale (``wheel_chords``)
    for i, j in wheel_chords(series, cfg, to, cumulative(to, np.abs(v)), max(CHORD_M, 20.0 * sigma_w)):
        t0, t1 = series.gps_t[i], series.gps_t[j]
        de, dn = series.gps_e[j] - series.gps_e[i], series.gps_n[j] - series.gps_n[i]
        wheel = math.hypot(np.interp(t1, to, x) - np.interp(t0, to, x), np.interp(t1, to, y) - np.interp(t0, to, y))
        if wheel > 0.0:
            g.append(math.hypot(de, dn))
            d.append(wheel)
            dt.append(t1 - t0)
            ta.append(t0)
            tb.append(t1)
            u.append(math.atan2(dn, de))
    n = len(g)
    if n < MIN_CHORDS:
        return None
    g_, d_ = np.array(g), np.array(d)
    V = 2.0 * sigma_w**2 + 2.0 * sigma_m**2 * (1.0 - np.exp(-np.array(dt) / tau))
    V = np.maximum(V, 1e-6)  # a perfect receiver: still a finite weight
    info = float(np.sum(d_ * d_ / V))
    k = float(np.sum(d_ * g_ / V)) / info
    c = d_ / V / info
    se_model = math.sqrt(max(_model_variance(c, np.array(ta), np.array(tb), np.array(u), sigma_w, sigma_m, tau),
                             0.0))
    se_emp = math.sqrt(newey_west(c * (g_ - k * d_)) * n / (n - 1))
    return ScaleFit(k, max(se_model, se_emp), se_model, se_emp, n, float(g_.sum()))


def _model_variance(c: np.ndarray, ta: np.ndarray, tb: np.ndarray, u: np.ndarray, sigma_w: float, sigma_m: float,
                    tau: float) -> float:
    """sum_ij c_i c_j C_ij (module docstring), over the chord pairs the wander still correlates (6 tau)."""

    def K(s: np.ndarray, t: np.ndarray) -> np.ndarray:
        return sigma_w**2 * (s == t) + sigma_m**2 * np.exp(-np.abs(s - t) / tau)

    n = len(c)
    total = 0.0
    for lag in range(n):
        i = np.arange(n - lag)
        j = i + lag
        if lag and np.min(ta[j] - tb[i]) > 6.0 * tau:
            break
        cij = np.cos(u[i] - u[j]) * (K(tb[i], tb[j]) - K(tb[i], ta[j]) - K(ta[i], tb[j]) + K(ta[i], ta[j]))
        total += (1.0 if lag == 0 else 2.0) * float(np.sum(c[i] * c[j] * cij))
    return total


class Speed(BaseCheck):
    """The wheel speed's scale against the GPS chords."""

    name = "speed"
    group = "cross"

    def run(self, ev: Evidence) -> list[Verdict]:
        series, cfg, scales = ev.series, ev.config, ev.scales
        odom, gps = ev.odom, ev.gps
        if odom is None or gps is None:
            return []
        far = dropped_by_clock((ev.stats or {}).get(gps.name, {}))
        if far:
            # fixes on another clock than the wheels' (the GPS's time verdict): their chords pair the wheels'
            # travel with the GPS's over another stretch of the drive, which agrees only where speed is steady
            return [Verdict(odom.name, "speed", "ok",
                            f"the wheel speed cannot be checked against the GPS: {far} of its fixes were dropped as "
                            "far from the filter's time (a clock off: see the time verdict); ask again once it is "
                            "mended")]
        fit = wheel_scale_fit(series, cfg)
        if fit is None:
            return []
        scale, se, n = fit.scale, fit.se, fit.chords
        evidence = fit.evidence()
        estimated = (scales or {}).get("wheel_scale")
        # scale_estimation unset means on with a GPS: the core then has a wheel_scale state
        estimating = odom.scale_estimation or (odom.scale_estimation is None and estimated is not None)
        band = fit.band
        if abs(scale - 1.0) > band:
            if estimating:
                if estimated is not None and abs(estimated - scale) <= band:
                    return [Verdict(odom.name, "speed", "ok",
                                    f"the wheels read {100 * (1 / scale - 1):+.1f}% against the GPS over {n} chords; "
                                    f"the estimated wheel scale {estimated:.3f} matches ({scale:.3f} +- {se:.3f} "
                                    "measured)",
                                    evidence=evidence)]
                return [Verdict(odom.name, "speed", "warn",
                                f"the wheels read {100 * (1 / scale - 1):+.1f}% against the GPS (scale {scale:.3f} +- "
                                f"{se:.3f} measured over {n} chords) but the estimated wheel scale is "
                                f"{estimated if estimated is not None else float('nan'):.3f}: it has not converged; "
                                "filter.wheel_scale_sigma may be too small",
                                "filter.wheel_scale_sigma", evidence=evidence)]
            return [Verdict(odom.name, "speed", "problem",
                            f"the wheels read {100 * (1 / scale - 1):+.1f}% against the GPS distance (true/wheel speed "
                            f"{scale:.3f} +- {se:.3f}, over {n} chords, {fit.distance_m:.0f} m): a tyre radius or slip "
                            "error; estimate the wheel scale", sensor_key(odom.name, "scale_estimation"),
                            "scale_estimation = true", evidence)]
        if estimating and estimated is not None and abs(estimated - scale) > band:
            # The wheels agree with the GPS chords, yet the filter's wheel_scale state moved away: it learned
            # something the data does not contain (fixes gated out while the estimate drifted, a heading or
            # altitude error explained as a scale, a filter re-acquired after a gap), and it bends every
            # dead-reckoned metre by that much.
            return [Verdict(odom.name, "speed", "warn",
                            f"wheel speed agrees with the GPS (scale {scale:.3f} +- {se:.3f} over {n} chords, "
                            f"{fit.distance_m:.0f} m) but the filter's estimated wheel scale is {estimated:.3f}: the "
                            "state learned an error the wheels do not have; see the GPS verdicts (gated or lost fixes, "
                            "a wrong heading), or turn the state off", sensor_key(odom.name, "scale_estimation"),
                            "scale_estimation = false", {**evidence, "wheel_scale_estimated": estimated})]
        return [Verdict(odom.name, "speed", "ok",
                        f"wheel speed agrees with the GPS (scale {scale:.3f} +- {se:.3f} over {n} chords, "
                        f"{fit.distance_m:.0f} m)", evidence=evidence)]
