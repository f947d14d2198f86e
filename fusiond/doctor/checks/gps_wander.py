"""A GPS error that wanders slowly, told from white noise by the innovations' autocorrelation.

Consumer receivers' errors are not white: multipath and atmosphere move the fix by a
metre or two over minutes (a first-order Gauss-Markov process). A filter that takes
such fixes as white noise follows the wander, so its innovations stay SMALL (NIS low)
while its position is off by the wander: "NIS low, lower position_noise" then makes it
worse. The innovations still show it: a consistent filter's innovations are white
(uncorrelated from fix to fix), a wandering error leaves most of their variance
persisting from one fix to the next.

For an error of white part w and wandering part b (variance sigma_b^2, time constant
tau) the innovations' autocorrelation at lag k fixes is about A exp(-k dt / tau) with
A = sigma_b^2 / (sigma_b^2 + w^2): the amplitude A (the share of the variance that
persists) splits the spread into error_sigma (sqrt(A) x rms) and the white
position_noise (sqrt(1 - A) x rms), and the lag where the correlation has fallen to
A / e is the correlation time. The filter follows part of the wander, so both are
lower bounds of the receiver's own (shorter, smaller): stating them moves the filter
the right way, and a second replay tells the rest.
"""

from __future__ import annotations

import math

import numpy as np

from ..channels import PerChannel, applied_verdict, gated_out, geodetic, gps_up, nis_head
from ..evidence import Evidence
from ..median import median
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key


__all__ = ["GpsWander"]

# "Strongly autocorrelated": at least 15 % of the innovations' variance persists to the next fix. A
# consistent filter's innovations are white: their lag-1 autocorrelation is ~N(0, 1/n) (0.04 over 750
# fixes); with the noise misstated the filter's own response adds a little: measured 0.00-0.04 on white
# fixes at 2 and 10 Hz, 1 to 25 m/s, stated honestly to 3.7x overstated; it must also be beyond
# 4 / sqrt(n) of zero for short runs. A Gauss-Markov error of 1.2 m (tau 60 s) under 0.6 m of white noise
# leaves 0.38 (stated honestly) to 0.54 (stated 2.2 m) at 2 Hz, where the filter follows the wander less
# the more the fixes are distrusted; at 10 Hz on a car at 25 m/s it follows more of it and leaves 0.18-0.25
# (a highway car: 0.18; a threshold of 0.3 misses it, and the advice would be "lower position_noise").
PERSISTING_SHARE = 0.15
# The range that threshold was measured over: fixes stated up to 3.7x their noise, a NIS per dof down to 1/3.7^2.
# Below it the filter hardly corrects by the fixes, so its own slow dead-reckoning error persists from fix to
# fix whatever the receiver does: a receiver stating 10 m for 0.2 m of innovations (NIS 0.0006 per dof) reads as
# a wander there, and "do not lower position_noise" keeps a highway car's aligned error at 1.56 m (0.26 m with
# the innovations' rms as its noise). There the NIS verdict speaks (the stated noise is too large), and this
# check can tell a wander once the noise is stated nearer the truth.
MIN_NIS_PER_DOF = 1.0 / 3.7**2
WANDER_MIN_FIXES = 50  # fixes for an autocorrelation: at lag 1 its standard error is ~1/sqrt(50) = 0.14
MAX_LAG_FRACTION = 0.25  # autocorrelation lags up to this share of the run (beyond, too few pairs)


def autocorrelation(y: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised autocorrelation of the columns of y (pooled), lags 0..max_lag."""
    y = y - y.mean(axis=0)
    var = float(np.mean(y * y))
    if var <= 0.0:
        return np.zeros(max_lag + 1)
    return np.array([1.0] + [float(np.mean(y[k:] * y[:-k])) / var for k in range(1, max_lag + 1)])


def _up_sigma(innovations: list) -> float | None:
    """The vertical wandering part, split like the horizontal (its own persisting share)."""
    u = np.array([y[2] for y in innovations if len(y) >= 3])
    if len(u) < WANDER_MIN_FIXES:
        return None
    acf = autocorrelation(u[:, None], 1)
    share = min(max(float(acf[1]), 0.0), 1.0)
    return float(math.sqrt(share) * np.std(u)) if share > 0.0 else None


class GpsWander(PerChannel):
    """A wandering receiver error, which reads as NIS low (the filter follows it): a candidate finding for
    a GPS position channel whose applied updates are not too many gated and read low or consistent. It
    replaces the channel's NIS finding only where the blame rules say so."""

    name = "gps_wander"
    kind = "absolute"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """A finding when the channel's innovations are strongly autocorrelated (module doc).

        Nothing when the wander is already modelled (``error_tau_s`` set): the filter then follows the
        modelled wander even more closely, so the innovations' correlation time says nothing more about
        the receiver's (it would only shrink replay after replay); a NIS low is then the white part's
        position_noise overstated, which the NIS verdict says."""
        gps = ev.sensors.get(key[0])
        if key[1] != "position" or not geodetic(gps) or gated_out(ch):
            return []
        if applied_verdict(ch) not in ("nis_low", "ok") or not ch.kept_nis_per_dof >= MIN_NIS_PER_DOF:
            return []
        head, up_ch = f"{nis_head(ch, ev.t0)}: ", gps_up(ev, key)
        if gps.error_tau_s > 0.0:
            return []
        rows = [(t, y) for t, y, rej in zip(ch.stamps, ch.innovations, ch.rejected_flags)
                if not rej and len(y) >= 2]
        if len(rows) < WANDER_MIN_FIXES:
            return []
        t = np.array([r[0] for r in rows])
        order = np.argsort(t)
        t = t[order]
        y = np.array([r[1][:2] for r in rows])[order]
        dt = float(median(np.diff(t)))
        if not dt > 0.0:
            return []
        n = len(t)
        acf = autocorrelation(y, max(2, int(MAX_LAG_FRACTION * n)))
        share = float(acf[1])  # the amplitude A: lag 1 is a fraction of tau, so hardly below its lag-0 limit
        if share <= max(PERSISTING_SHARE, 4.0 / math.sqrt(n)):
            return []
        below = np.nonzero(acf[1:] < share / math.e)[0]
        if not len(below):
            return []  # never decorrelates within the run: a drift or an offset, not a wander
        k = int(below[0]) + 1  # first lag below A/e; interpolate between k-1 and k
        lo, hi = acf[k - 1], acf[k]
        lag = (k - 1) + (lo - share / math.e) / (lo - hi) if lo > hi else float(k)
        if lag < 2.0:
            # gone within two fix intervals (its amplitude is read at the first): an error state that forgets it
            # that fast is white noise to the filter at this rate, and its correlation time rounds to nothing
            return []
        tau = float(lag * dt)
        yc = y - y.mean(axis=0)
        rms = np.sqrt(np.mean(yc * yc, axis=0))
        sigma_h = [float(math.sqrt(share) * r) for r in rms]
        white = [float(math.sqrt(1.0 - share) * r) for r in rms]
        # The vertical: with error_tau_s set, error_sigma's up replaces the altitude's own error state
        # (vertical_error_sigma over vertical_error_tau_s), whose innovations are what is left after it
        # absorbed the altitude's wander: their persisting part is far below it (0.6 m against a 5 m state;
        # pasted, z would wander 5 m instead of 0.18 m). So never below vertical_error_sigma.
        # the altitude is its own measurement block (channel "altitude"); a 3-component channel carries it too
        if up_ch is not None and up_ch.components == ["up"]:
            up = _up_sigma([(0.0, 0.0, y[0]) for y, rej in zip(up_ch.innovations, up_ch.rejected_flags) if not rej])
        else:
            up = _up_sigma([r[1] for r in rows])
        sigma = [*sigma_h, max(up if up is not None else 0.0, gps.vertical_error_sigma)]
        evidence = {"innovation_lag1_correlation": share, "error_tau_s": tau, "error_sigma_east_m": sigma[0],
                    "error_sigma_north_m": sigma[1], "white_sigma_m": max(white), "fixes": float(n),
                    "fix_interval_s": dt}
        msg = head + (f"the innovations are autocorrelated from fix to fix ({100 * share:.0f}% of their "
                      f"variance persists to the next fix, correlation time ~{_secs(tau)} s over {n} fixes): the "
                      "receiver's error wanders (multipath, atmosphere), it is not white noise. The filter follows the "
                      "wander, so the NIS understates the error and the covariance is overconfident: do not lower "
                      "position_noise; model the wander (error_tau_s, error_sigma), leaving position_noise "
                      f"~{max(white):.2f} m for the white part. Estimated from the innovations, which the filter "
                      "already smooths: lower bounds")
        return [Verdict(gps.name, "position", "warn", msg, sensor_key(gps.name, "error_tau_s"),
                        f"error_tau_s = {_secs(tau)}\nerror_sigma = [{sigma[0]:.2f}, {sigma[1]:.2f}, {sigma[2]:.2f}]",
                        evidence)]


def _secs(tau: float) -> str:
    """A correlation time as pasted: whole seconds from 10 s on, two significant digits below (never 0, which
    turns the error state off)."""
    return f"{tau:.0f}" if tau >= 10.0 else f"{tau:.2g}"
