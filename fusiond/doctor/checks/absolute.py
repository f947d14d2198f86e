"""GPS and pose channels: NIS against the stated noise, and what the gate took out.

Judged over the whole run by ``nis.judge_nis`` (the same rule the summary prints), saying when the
latest window differs. These are the verdicts of last resort: a cross-source finding on the same sensor
explains them where the blame rules say so.
"""

from __future__ import annotations

import math

import numpy as np

from ..channels import (GATED_FRACTION, PerChannel, applied_verdict, figures, gps_up, innovations_below, nis_head,
                        process_overstated)
from ...core.sensors.registry import kind_of
from ..evidence import Evidence
from ..heading import gps_sigma_up
from ..median import median
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["AbsoluteNis", "absolute_verdict"]

# gated beyond this (and so beyond GATED_FRACTION): its noise is understated, as jumps are the exception, not the rule
MOST_GATED = 0.5
# the noise of a channel's kept innovations (``_spread``): 1 / Phi^-1(3/4), the median magnitude of a standard
# normal's draws, so that the median magnitude times it is sigma; from MIN_ROBUST updates on (the median's standard
# error is then within a fifth of sigma's)
ROBUST_SCALE = 1.4826
MIN_ROBUST = 20


_ANGLES = frozenset({"roll", "pitch", "yaw", "drx", "dry", "drz"})  # a pose's rotation components (and deltas)


def _unit(component: str) -> str:
    """A component's unit: rad for a pose's rotation, m for a position."""
    return "rad" if component in _ANGLES else "m"


def _spread(ch: ChannelStats, i: int) -> float:
    """Component i's noise as the innovations show it: where the channel keeps every update's innovation (a
    GPS's), ROBUST_SCALE times their median magnitude, gated ones included, which a minority of bursts (multipath
    20-40 m off for 5 s of a minute) leaves where the ordinary fixes put it and which is the rms for Gaussian
    innovations; else their rms. Either is the sensor's noise plus the filter's own uncertainty."""
    width = len(ch.components)
    column = [y[i] for y in ch.innovations if len(y) == width] if ch.keep else []
    if len(column) >= MIN_ROBUST:
        return ROBUST_SCALE * median(np.abs(column))
    return ch.component(i)[1]


def _measured_noise(ch: ChannelStats, up: ChannelStats | None = None, up_sigma: float | None = None) -> str:
    """``position_noise = [...]`` from the innovations' spread per axis (east north up, ``_spread``), when the
    channel has the three, or the horizontal two and a third: ``up_sigma``, the altitude's noise as the filter
    took it, which the horizontal's line keeps (the altitude is judged by its own channel, whose error another
    check may explain: a mount's pitch climbing the height 40 m off read as a 31 m noise that hid it), else
    the spread of ``up`` (the fix's altitude channel) where that is not known (no config: the live monitor). It
    is the sensor's noise plus the filter's own uncertainty, so an upper bound."""
    rms = [_spread(ch, i) for i in range(len(ch.components))]
    if len(rms) == 2 and up_sigma is not None:
        rms.append(up_sigma)
    elif len(rms) == 2 and up is not None and up.n and up.components == ["up"]:
        rms.append(_spread(up, 0))
    if len(rms) != 3 or not all(math.isfinite(r) and r > 0.0 for r in rms):
        return ""
    return "position_noise = [" + ", ".join(f"{r:.2g}" for r in rms) + "]"


def absolute_verdict(name: str, channel: str, ch: ChannelStats, t0: float | None,
                     up: ChannelStats | None = None, unstated: bool = False,
                     slow_vertical: tuple[float, float, float] | None = None,
                     up_sigma: float | None = None, stated_noise: list[float] | None = None,
                     prediction_key: str = "", process_noise: tuple[float, float] | None = None) -> Verdict:
    """GPS and pose channels: NIS against the stated noise. ``unstated``: a receiver whose fixes state no
    accuracy: the filter took its altitude's noise from the config's ``unknown_position_sigma`` (a verdict on
    it without a paste line names that key: ``position_noise`` would also replace the horizontal noise the
    filter measures), and measured its horizontal noise from the wheels (which ``position_noise`` states
    instead). ``slow_vertical``: (sigma, tau, span) of the altitude's Gauss-Markov error state where the run
    spans too few of its time constants to identify it (the kind's ``slow_errors``): an altitude NIS low is then the
    model's, not a noise to change (``_slow_altitude``). ``up_sigma``: the altitude's noise as the filter took it,
    the third value of a horizontal channel's line (``_measured_noise``). ``stated_noise``: the config's
    position_noise (east north up), with which a NIS low that no smaller noise can raise is told apart
    (``_prediction_overstated``); ``prediction_key``: the key that verdict names (the odometry's twist_noise).
    ``process_noise``: the config's filter.process_noise, whose position part alone bounds the prediction's spread
    from below (``channels.process_overstated``)."""
    frac = ch.rejected / ch.n if ch.n else 0.0
    key = sensor_key(name, "position_noise")
    detail = ", ".join(f"{c} rms {ch.component(i)[1]:.3f}" for i, c in enumerate(ch.components))
    verdict = ch.verdict()
    ev = {"nis_per_dof": ch.nis_per_dof, "gated_fraction": frac}
    if ch.n and not ch.n_nis:
        return Verdict(name, channel, "ok", figures(ch, t0), evidence=ev)
    line = _measured_noise(ch, up, up_sigma)
    stated = "the stated noise"
    if unstated and channel == "altitude":
        stated = "the noise taken for its fixes, which state none (unknown_position_sigma),"
        if not line:
            key = sensor_key(name, "unknown_position_sigma")
    elif unstated:  # the horizontal noise of fixes that state none is measured from the wheels (GpsModel)
        stated = ("the noise taken for its fixes, which state none (measured from the wheels, at the upper end of "
                  "its uncertainty; position_noise states it instead),")
    # the innovations' rms as a pasteable line when it covers every axis of the key, else said in the text
    rms = "the value below" if line else "their spread per axis (" + ", ".join(
        f"{c} {_spread(ch, i):.2g} {_unit(c)}" for i, c in enumerate(ch.components)) + ")"
    if frac > MOST_GATED:
        # Jumps (multipath, relocalisation) come in bursts among good fixes; a gate that rejects most
        # of them is cutting into the ordinary noise, which is then larger than stated.
        return Verdict(name, channel, "problem",
                       f"{100 * frac:.0f}% of updates gated ({detail}; {figures(ch, t0)}): too many for jumps, "
                       "which come in bursts among good fixes: the stated noise is too small, and the innovations "
                       f"(an upper bound: they include the filter's own uncertainty) suggest {rms}",
                       key, line, evidence=ev)
    if frac > GATED_FRACTION and applied_verdict(ch) == "nis_high":
        # The fixes the gate let through read high too: jumps come in bursts among good fixes, which would read
        # consistent; here the ordinary noise is larger than stated, and the gate cuts into it (a receiver
        # claiming an RTK fix it does not have: 16 % gated, the applied ones 2.9 per dof).
        ev["applied_nis_per_dof"] = ch.kept_nis_per_dof
        return Verdict(name, channel, "problem",
                       f"{100 * frac:.0f}% of updates gated and the applied ones read NIS high too "
                       f"({ch.kept_nis_per_dof:.2f} per dof; {detail}; {figures(ch, t0)}): not jumps among good fixes, "
                       f"{stated} is too small, and the innovations (an upper bound: they include the filter's own "
                       f"uncertainty) suggest {rms}", key, line, evidence=ev)
    if frac > GATED_FRACTION:
        return Verdict(name, channel, "warn",
                       f"{100 * frac:.0f}% of updates gated ({detail}; {figures(ch, t0)}): the sensor jumps "
                       "(multipath, relocalisation) or its noise is understated",
                       sensor_key(name, "mahalanobis_threshold"), evidence=ev)
    applied = applied_verdict(ch)
    if applied != verdict:
        ev["applied_nis_per_dof"] = ch.kept_nis_per_dof
        if applied == "nis_low" and channel == "altitude" and slow_vertical is not None:
            # the applied ones low as the slow error state makes them over a short run (below), as without
            # the rejected ones: the gate's outliers change nothing of that
            return _slow_altitude(name, ch, t0, slow_vertical, ev, nis_head(ch, t0))
        if applied == "nis_low":
            return Verdict(name, channel, "warn", f"{nis_head(ch, t0)}, below their bounds: {stated} is "
                           "larger than the applied updates show", key, evidence=ev)
        return Verdict(name, channel, "warn", f"{nis_head(ch, t0)}, consistent with the stated noise; the rejected "
                       "ones are outliers the gate kept out (mahalanobis_threshold), nothing to change in the noise",
                       evidence=ev)
    if verdict == "nis_high":
        return Verdict(name, channel, "problem",
                       f"NIS high ({figures(ch, t0)}; {detail}): {stated} is too small, a mounting offset "
                       "(extrinsic_xyz) is missing, or an odometry scale error is unmodelled (scale_estimation); "
                       f"if it is the noise, the innovations (an upper bound) suggest {rms}", key, line, evidence=ev)
    if verdict == "nis_low" and channel == "altitude" and slow_vertical is not None:
        return _slow_altitude(name, ch, t0, slow_vertical, ev)
    over_q = (process_overstated(ch, process_noise[0], ("east", "north"))
              if verdict == "nis_low" and process_noise is not None else None)
    if over_q is not None:
        c, got, floor, dt, q = over_q
        ev["innovation_rms_m"], ev["process_noise_alone_rms_m"] = got, floor
        return Verdict(name, channel, "warn",
                       f"NIS low ({figures(ch, t0)}; {detail}): the innovations ({c} rms {got:.3f} m) are smaller than "
                       f"what the process noise alone adds to the prediction between fixes ({floor:.3f} m: "
                       f"filter.process_noise {process_noise[0]:g} m/sqrt(s) over {dt:.2g} s), whatever the sensor's "
                       "noise: the model's position noise is stated too large, and no position_noise brings the NIS up. "
                       "The value below is the most the innovations allow it (`fusiond tune` fits it on this recording)",
                       "filter.process_noise", f"process_noise = [{q:.2g}, {process_noise[1]:g}]", evidence=ev)
    if verdict == "nis_low" and stated_noise is not None and channel != "altitude" and _settled(ch, stated_noise):
        over = _prediction_overstated(ch, stated_noise)
        if over is not None:
            c, got, alone = over
            ev["innovation_rms_m"], ev["prediction_alone_rms_m"] = got, alone
            return Verdict(name, channel, "warn",
                           f"NIS low ({figures(ch, t0)}; {detail}): the innovations ({c} rms {got:.3f} m) are smaller "
                           f"than what the filter's prediction alone claims between fixes ({alone:.3f} m, S less the "
                           "stated position_noise): no position_noise brings the NIS up, the prediction is what is "
                           "stated too wide (the odometry's twist_noise, filter.process_noise: `fusiond tune` fits "
                           "them on this recording); with sparse fixes a receiver's wandering error is modelled by "
                           "error_tau_s and error_sigma", prediction_key, evidence=ev)
    if verdict == "nis_low":
        return Verdict(name, channel, "warn",
                       f"NIS low ({figures(ch, t0)}; {detail}): {stated} is larger than the innovations show "
                       f"({rms}: an upper bound of the sensor's own noise)", key, line, evidence=ev)
    return Verdict(name, channel, "ok", f"consistent ({figures(ch, t0)})", evidence=ev)


def _slow_altitude(name: str, ch: ChannelStats, t0: float | None, slow: tuple[float, float, float],
                   ev: dict, head: str = "") -> Verdict:
    """The altitude's NIS low beside a slow vertical error state: the filter takes the receiver's altitude to
    wander by sigma over tau (minutes), and every fix's predicted spread carries that whole wander; a run shorter
    than a few tau shows only a slice of it, so the innovations sit far inside that spread. That is the model
    over a short run, not a noise stated too large: a smaller position_noise changes next to nothing (the wander
    is most of the spread), and a smaller wander is for a recording that spans it to tell (tune fits it there).
    ``head``: what opens the message (default: the NIS low and its figures)."""
    sigma, tau, span = slow
    over = _wander_overstated(ch, sigma, tau)
    if over is not None:
        got, alone, dt, most = over
        ev["innovation_rms_m"], ev["wander_alone_rms_m"] = got, alone
        return Verdict(name, "altitude", "warn",
                       f"{head or f'NIS low ({figures(ch, t0)})'}: the altitude's innovations (rms {got:.3f} m) are "
                       f"smaller than what its modelled wander alone moves it between two fixes ({alone:.3f} m: "
                       f"vertical_error_sigma {sigma:g} m over vertical_error_tau_s {tau:g} s, the fixes {dt:.2g} s "
                       "apart), whatever their noise: this receiver's altitude does not wander so far (an RTK "
                       "receiver's holds to centimetres), and the model lets the estimate's height drift from it. The "
                       "value below is the most the innovations allow", sensor_key(name, "vertical_error_sigma"),
                       f"vertical_error_sigma = {most:.2g}", evidence=ev)
    return Verdict(name, "altitude", "ok",
                   f"{head or f'NIS low ({figures(ch, t0)})'}, as the altitude's error model expects over {span:.0f} s: it takes "
                   f"the receiver's altitude to wander by {sigma:g} m over {tau:g} s (vertical_error_sigma, "
                   "vertical_error_tau_s), a slice of which this run spans; nothing to change from it (a recording "
                   "spanning several of those time constants tells whether the wander is smaller)", evidence=ev)


def _wander_overstated(ch: ChannelStats, sigma: float, tau: float) -> tuple[float, float, float, float] | None:
    """(innovation rms, the rms the modelled wander alone adds between two fixes, their interval, the largest
    vertical_error_sigma the innovations allow) where the altitude's innovations are smaller than the wander's
    own increment: the Gauss-Markov state b (sigma, tau) moves by sigma^2 (1 - exp(-2 dt / tau)) in variance over
    the interval dt between fixes, which the prediction of every fix carries whatever the fix's noise
    (``channels.innovations_below``, as a process noise is judged). None otherwise."""
    if not (sigma > 0.0 and tau > 0.0):
        return None
    found = innovations_below(ch, lambda dt: sigma * sigma * -math.expm1(-2.0 * dt / tau), ("up",))
    if found is None:
        return None
    _, rms, dt = found
    share = -math.expm1(-2.0 * dt / tau)  # of sigma^2, the increment's variance
    return rms, sigma * math.sqrt(share), dt, rms / math.sqrt(share)


class AbsoluteNis(PerChannel):
    """GPS and pose channels: NIS against the stated noise."""

    name = kind = "absolute"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        up_sigma = _stated_vertical(ev, key[0]) if key[1] != "altitude" else None
        sc = ev.sensors.get(key[0]) if ev.config is not None else None
        stated = getattr(sc, "position_noise", None)
        # what drives the prediction between fixes: the odometry's twist noise, named where the fixes say it is wide
        wheels = sensor_key(ev.odom.name, "twist_noise") if ev.config is not None and ev.odom is not None else ""
        process = tuple(ev.config.filter.process_noise) if ev.config is not None else None
        return [absolute_verdict(key[0], key[1], ch, ev.t0, gps_up(ev, key), _unstated(ev, key[0]),
                                 _slow_vertical(ev, key[0], ch), up_sigma,
                                 None if stated is None else [float(v) for v in stated], wheels, process)]


def _settled(ch: ChannelStats, noise: list[float]) -> bool:
    """Would the position_noise line (the innovations' rms, as it prints them: 2 digits) lower none of the
    horizontal components the config states? Only then is a NIS low asked of the prediction
    (``_prediction_overstated``): a noise stated too large keeps the filter's own uncertainty large as well,
    its updates being weak, and its line comes first."""
    for i, c in enumerate(ch.components):
        if c in ("east", "north"):
            stated = noise[("east", "north").index(c)]
            if float(f"{ch.component(i)[1]:.2g}") < float(f"{stated:.2g}"):
                return False
    return True


def _prediction_overstated(ch: ChannelStats, noise: list[float]) -> tuple[str, float, float] | None:
    """(component, innovation rms, rms of the prediction alone) of the horizontal component whose innovations are
    the furthest below what the prediction alone claims, where every horizontal one is below it: S = H P H^T + R,
    so with R the position_noise stated the prediction's share is S - R, and innovations smaller than that share
    cannot be explained by R (the innovations between 1 Hz fixes are the fixes' scatter, while the prediction
    claims a second's dead-reckoning: lowering position_noise round after round left the NIS where it was).
    None when a component is not below, or has no stated noise."""
    worst = None
    for i, c in enumerate(ch.components):
        axis = ("east", "north").index(c) if c in ("east", "north") else None
        if axis is None:
            continue
        _, rms, pred = ch.component(i)
        alone_var = pred * pred - noise[axis] ** 2
        if not (alone_var > 0.0 and rms * rms < alone_var):
            return None
        ratio = rms / math.sqrt(alone_var)
        if worst is None or ratio < worst[0]:
            worst = (ratio, c, rms, math.sqrt(alone_var))
    return None if worst is None else worst[1:]


def _stated_vertical(ev: Evidence, name: str) -> float | None:
    """The altitude's noise (m) as the filter took it for sensor ``name``'s fixes: the config's position_noise,
    else the fixes' own (their median), else unknown_position_sigma for fixes that state none; None without a
    config or series (the live monitor), or for a sensor without those keys (a pose)."""
    if ev.config is None or ev.series is None:
        return None
    sc = ev.sensors.get(name)
    if sc is None or getattr(sc, "unknown_position_sigma", None) is None:
        return None
    return gps_sigma_up(ev.series, sc)


def _slow_vertical(ev: Evidence, name: str, ch: ChannelStats) -> tuple[float, float, float] | None:
    """(vertical_error_sigma, its tau, the run's span) when the sensor's kind calls its vertical error slow
    against that span (``slow_errors``), else None (no config: the live monitor)."""
    if ev.config is None or not ch.stamps:
        return None
    sc = ev.sensors.get(name)
    if sc is None:
        return None
    span = float(max(ch.stamps) - min(ch.stamps))
    tau = kind_of(sc).slow_errors(sc, span).get("vertical")
    sigma = float(getattr(sc, "vertical_error_sigma", 0.0))
    if tau is None or not ch.components or sigma <= 0.0:
        return None
    # the model's only where its wander alone puts the NIS below its bound: then no noise of the fixes, however
    # small, brings it up (else a noise stated too large is part of it, and the NIS verdict names that)
    rms, bounds = ch.component(0)[1], ch.bounds()
    if bounds is None or not (math.isfinite(rms) and rms * rms < bounds[0] / ch.mean_dof * sigma * sigma):
        return None
    return sigma, float(tau), span


def _unstated(ev: Evidence, name: str) -> bool:
    """Did sensor ``name``'s fixes state no accuracy, the config stating none for them either (a receiver's
    covariance type UNKNOWN)? False where the doctor has no config or series (the live monitor)."""
    if ev.config is None or ev.series is None:
        return False
    sc = next((s for s in ev.config.sensors if s.name == name), None)
    if getattr(sc, "unknown_position_sigma", None) is None:  # not a receiver with that default (a pose)
        return False
    if sc.position_noise is not None:  # the config states the fixes' noise
        return False
    up = ev.series.gps_sigma_up
    return bool(up) and not any(math.isfinite(v) for v in up)
