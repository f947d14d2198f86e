"""GPS and pose channels: NIS against the stated noise, and what the gate took out.

Judged over the whole run by ``nis.judge_nis`` (the same rule the summary prints), saying when the
latest window differs. These are the verdicts of last resort: a cross-source finding on the same sensor
explains them where the blame rules say so.
"""

from __future__ import annotations

import math

from ..channels import GATED_FRACTION, PerChannel, applied_verdict, figures, gps_up, nis_head
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["AbsoluteNis", "absolute_verdict"]

# gated beyond this (and so beyond GATED_FRACTION): its noise is understated, as jumps are the exception, not the rule
MOST_GATED = 0.5


def _measured_noise(ch: ChannelStats, up: ChannelStats | None = None) -> str:
    """``position_noise = [...]`` from the innovations' rms per axis (east north up), when the channel
    has the three, or the horizontal two and ``up`` (the fix's altitude channel) the third: the sensor's
    noise plus the filter's own uncertainty, so an upper bound."""
    rms = [ch.component(i)[1] for i in range(len(ch.components))]
    if len(rms) == 2 and up is not None and up.n and up.components == ["up"]:
        rms.append(up.component(0)[1])
    if len(rms) != 3 or not all(math.isfinite(r) and r > 0.0 for r in rms):
        return ""
    return "position_noise = [" + ", ".join(f"{r:.2g}" for r in rms) + "]"


def absolute_verdict(name: str, channel: str, ch: ChannelStats, t0: float | None,
                     up: ChannelStats | None = None, unstated: bool = False) -> Verdict:
    """GPS and pose channels: NIS against the stated noise. ``unstated``: a receiver whose fixes state no
    accuracy: the filter took its altitude's noise from the config's ``unknown_position_sigma`` (a verdict on
    it without a paste line names that key: ``position_noise`` would also replace the horizontal noise the
    filter measures), and measured its horizontal noise from the wheels (which ``position_noise`` states
    instead)."""
    frac = ch.rejected / ch.n if ch.n else 0.0
    key = sensor_key(name, "position_noise")
    detail = ", ".join(f"{c} rms {ch.component(i)[1]:.3f}" for i, c in enumerate(ch.components))
    verdict = ch.verdict()
    ev = {"nis_per_dof": ch.nis_per_dof, "gated_fraction": frac}
    if ch.n and not ch.n_nis:
        return Verdict(name, channel, "ok", figures(ch, t0), evidence=ev)
    line = _measured_noise(ch, up)
    stated = "the stated noise"
    if unstated and channel == "altitude":
        stated = "the noise taken for its fixes, which state none (unknown_position_sigma),"
        if not line:
            key = sensor_key(name, "unknown_position_sigma")
    elif unstated:  # the horizontal noise of fixes that state none is measured from the wheels (GpsModel)
        stated = ("the noise taken for its fixes, which state none (measured from the wheels, at the upper end of "
                  "its uncertainty; position_noise states it instead),")
    # the innovations' rms as a pasteable line when it covers every axis of the key, else said in the text
    rms = "the value below" if line else "their rms per axis (" + ", ".join(
        f"{c} {ch.component(i)[1]:.2g} m" for i, c in enumerate(ch.components)) + ")"
    if frac > MOST_GATED:
        # Jumps (multipath, relocalisation) come in bursts among good fixes; a gate that rejects most
        # of them is cutting into the ordinary noise, which is then larger than stated.
        return Verdict(name, channel, "problem",
                       f"{100 * frac:.0f}% of updates gated ({detail}; {figures(ch, t0)}): too many for jumps, "
                       "which come in bursts among good fixes: the stated noise is too small, and the innovations "
                       f"(an upper bound: they include the filter's own uncertainty) suggest {rms}",
                       key, line, evidence=ev)
    if frac > GATED_FRACTION:
        return Verdict(name, channel, "warn",
                       f"{100 * frac:.0f}% of updates gated ({detail}; {figures(ch, t0)}): the sensor jumps "
                       "(multipath, relocalisation) or its noise is understated",
                       sensor_key(name, "mahalanobis_threshold"), evidence=ev)
    applied = applied_verdict(ch)
    if applied != verdict:
        ev["applied_nis_per_dof"] = ch.kept_nis_per_dof
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
    if verdict == "nis_low":
        return Verdict(name, channel, "warn",
                       f"NIS low ({figures(ch, t0)}; {detail}): {stated} is larger than the innovations show "
                       f"({rms}: an upper bound of the sensor's own noise)", key, line, evidence=ev)
    return Verdict(name, channel, "ok", f"consistent ({figures(ch, t0)})", evidence=ev)


class AbsoluteNis(PerChannel):
    """GPS and pose channels: NIS against the stated noise."""

    name = kind = "absolute"

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        return [absolute_verdict(key[0], key[1], ch, ev.t0, gps_up(ev, key), _unstated(ev, key[0]))]


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
