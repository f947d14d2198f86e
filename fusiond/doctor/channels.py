"""NIS verdicts of the measurement channels (IMU orientation, GPS / pose), in plain words.

Each is judged over the whole run by :func:`..nis.judge_nis` (the same rule the
summary prints) and says when the latest window differs. These are the verdicts of
last resort: a cross-source check on the same sensor, when there is one, comes first
(see ``diagnose``).
"""

from __future__ import annotations

import math

from ..config import GpsSensor, ImuSensor
from ..core.sensors.gps import FROZEN_JITTER
from ..core.sensors.imu import YAW_JUMP_GATE
from .attitude import noise_suggestion
from .nis import ChannelStats
from .verdict import Verdict, sensor_key
from .thresholds import (GATED_FRACTION, JUMP_NOISE_SHARE, JUMP_NOTE_SHARE, MOST_GATED, REACQUIRE_AFTER_GAP_S,
                         ROLL_PITCH_OFFSET_RAD, UNALIGNED_LARGE)


def figures(ch: ChannelStats, t0: float | None) -> str:
    if ch.n and not ch.n_nis:  # every update was a learning one (e.g. the GPS heading search)
        return f"{ch.n} updates while the state was being learned, not judged against the stated noise"
    now = ch.now_note(t0)
    return f"{ch.nis_per_dof:.2f} per dof over {ch.n} updates" + (f"; {now}" if now else "")


def orientation_verdicts(imu: ImuSensor, ch: ChannelStats, t0: float | None,
                         yaw_vs_gyro: float | None = None) -> list[Verdict]:
    """``yaw_vs_gyro``: the rms wander of the IMU's yaw against the integrated gyro that the heading
    cross-check measured and found below its threshold (None when it did not). A yaw NIS high beside it
    is not a disturbed yaw, whose wander the gyro would show: the innovations are the yaw's own noise,
    stated too small (an AHRS reporting a zero covariance reads as the orientation_min_sigma floor)."""
    out = []
    comps = ch.components
    verdict = ch.verdict()
    key = sensor_key(imu.name, "orientation_noise")
    detail = ", ".join(f"{c} rms {ch.component(i)[1]:.4f} vs {ch.component(i)[2]:.4f} predicted"
                       for i, c in enumerate(comps))
    if verdict == "nis_high":
        comp_nis = []
        for i in range(len(comps)):
            _, rms, pred = ch.component(i)
            comp_nis.append((rms / pred) ** 2 if pred > 0 else math.nan)
        yaw_dominates = "yaw" in comps and comp_nis[comps.index("yaw")] > 3.0 * max(
            [v for c, v in zip(comps, comp_nis) if c != "yaw"] or [0.0])
        if yaw_dominates and imu.fuses_yaw and yaw_vs_gyro is None:
            out.append(Verdict(imu.name, "orientation", "problem",
                               f"NIS high ({figures(ch, t0)}; {detail}). The IMU yaw disagrees with the predicted "
                               "heading: a magnetometer-disturbed IMU yaw, or (without the gyro) wheels whose yaw "
                               "rate is wrong. Take heading from the gyro", sensor_key(imu.name, "orientation"),
                               'orientation = "roll_pitch" and angular_velocity = true'))
        else:
            line, note = noise_suggestion(ch, imu)
            agrees = (f"; the yaw agrees with the integrated gyro to {yaw_vs_gyro:.3f} rad rms once a bias and "
                      "scale are removed, so it is not a disturbed yaw" if yaw_dominates and yaw_vs_gyro is not None
                      else "")
            out.append(Verdict(imu.name, "orientation", "problem",
                               f"NIS high ({figures(ch, t0)}; {detail}): the stated noise is too small or the IMU "
                               f"lies{agrees}; the measured innovations, {note}, suggest the value below", key, line))
    elif verdict == "nis_low":
        line, note = noise_suggestion(ch, imu)
        out.append(Verdict(imu.name, "orientation", "warn",
                           f"NIS low ({figures(ch, t0)}; {detail}): the stated orientation noise is larger than the "
                           f"innovations show (or the process noise is); measured {note}", key, line))
    else:
        out.append(Verdict(imu.name, "orientation", "ok", f"consistent ({figures(ch, t0)})"))
    for i, c in enumerate(comps):
        mean, rms, _ = ch.component(i)
        if c in ("roll", "pitch") and abs(mean) > ROLL_PITCH_OFFSET_RAD and abs(mean) > 0.5 * rms:
            out.append(Verdict(imu.name, "orientation", "warn",
                               f"constant {c} offset of {mean:+.3f} rad in the innovations: a mounting rotation "
                               "not in the config", sensor_key(imu.name, "extrinsic_rpy")))
    for v in out:
        v.evidence = {**v.evidence, "nis_per_dof": ch.nis_per_dof}
    return out


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


def applied_verdict(ch: ChannelStats) -> str:
    """The channel's whole-run NIS verdict, judged on the applied updates when it is high only through the
    ones the gate rejected. Those were not fused, so they say nothing of the stated noise: a receiver that
    reported three fixes at 0, 0 (a NIS of 1e14 each) among thousands of good ones would otherwise read as
    noise stated too small, and advising a larger one would only blunt the gate. The applied ones are
    truncated by the gate, which lowers their mean only where the gate cuts into the distribution, where
    the gated fraction (GATED_FRACTION, judged first) speaks instead."""
    verdict = ch.verdict()
    if verdict == "nis_high" and ch.rejected and ch.kept_verdict() != "nis_high":
        return ch.kept_verdict()
    return verdict


def nis_head(ch: ChannelStats, t0: float | None) -> str:
    """'NIS high (figures)', and when the applied updates are judged apart, what the gate took out."""
    head = f"NIS {ch.verdict().removeprefix('nis_')} ({figures(ch, t0)})"
    if applied_verdict(ch) == ch.verdict():
        return head
    frac = ch.rejected / ch.n if ch.n else 0.0
    return (f"{head} only because of the {ch.rejected} update(s) the gate rejected ({100 * frac:.1f}%, not fused): "
            f"the {ch.n_nis_kept} applied ones read {ch.kept_nis_per_dof:.2f} per dof")


def gated_out(ch: ChannelStats) -> bool:
    """Whether the gate rejected more of the channel's judged updates than jumps explain (GATED_FRACTION):
    its verdict (``absolute_verdict``) is then about the gate, not the innovations of what was fused."""
    return bool(ch.n and ch.n_nis) and ch.rejected / ch.n > GATED_FRACTION


def absolute_verdict(name: str, channel: str, ch: ChannelStats, t0: float | None,
                     up: ChannelStats | None = None) -> Verdict:
    """GPS and pose channels: NIS against the stated noise."""
    frac = ch.rejected / ch.n if ch.n else 0.0
    key = sensor_key(name, "position_noise")
    detail = ", ".join(f"{c} rms {ch.component(i)[1]:.3f}" for i, c in enumerate(ch.components))
    verdict = ch.verdict()
    ev = {"nis_per_dof": ch.nis_per_dof, "gated_fraction": frac}
    if ch.n and not ch.n_nis:
        return Verdict(name, channel, "ok", figures(ch, t0), evidence=ev)
    line = _measured_noise(ch, up)
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
            return Verdict(name, channel, "warn", f"{nis_head(ch, t0)}, below their bounds: the stated noise is "
                           "larger than the applied updates show", key, evidence=ev)
        return Verdict(name, channel, "warn", f"{nis_head(ch, t0)}, consistent with the stated noise; the rejected "
                       "ones are outliers the gate kept out (mahalanobis_threshold), nothing to change in the noise",
                       evidence=ev)
    if verdict == "nis_high":
        return Verdict(name, channel, "problem",
                       f"NIS high ({figures(ch, t0)}; {detail}): the stated noise is too small, a mounting offset "
                       "(extrinsic_xyz) is missing, or an odometry scale error is unmodelled (scale_estimation); "
                       f"if it is the noise, the innovations (an upper bound) suggest {rms}", key, line, evidence=ev)
    if verdict == "nis_low":
        return Verdict(name, channel, "warn",
                       f"NIS low ({figures(ch, t0)}; {detail}): the stated noise is larger than the innovations show "
                       f"({rms}: an upper bound of the sensor's own noise)", key, line, evidence=ev)
    return Verdict(name, channel, "ok", f"consistent ({figures(ch, t0)})", evidence=ev)


def yaw_jump_verdict(name: str, ch: ChannelStats, orientation: ChannelStats | None) -> Verdict:
    """The ``yaw_jump`` channel (core/sensors/imu/model.py ``_yaw_jump``): every record is an absolute yaw reading
    that jumped against the gyro-carried heading beyond YAW_JUMP_GATE sigma and was not fused, so its NIS
    says nothing about the stated noise (all are beyond the gate by construction). What it says is how often
    the magnetometer's disturbance switched on."""
    total = ch.n + (orientation.n if orientation is not None else 0)
    share = ch.n / total if total else 0.0
    head = (f"{ch.n} yaw readings ({100 * share:.1f}% of the IMU's) jumped against the gyro-carried heading "
            f"beyond {YAW_JUMP_GATE:g} sigma of their stated noise and were not fused")
    evidence = {"yaw_jumps": float(ch.n), "yaw_jump_share": share}
    if share <= JUMP_NOTE_SHARE:
        return Verdict(name, "yaw_jump", "ok", head + ": a disturbance switching on now and then (a motor, steel "
                       "nearby); one that persists is fused from the next reading and goes into the yaw offset",
                       evidence=evidence)
    if share <= JUMP_NOISE_SHARE:
        return Verdict(name, "yaw_jump", "warn", head + ": the magnetometer's yaw is disturbed often (motors, steel); "
                       "the heading holds on the gyro meanwhile. If the track bends near those places, take only "
                       'roll/pitch from the IMU (orientation = "roll_pitch")', evidence=evidence)
    return Verdict(name, "yaw_jump", "warn", head + ": too many for disturbances: the stated yaw noise is far below "
                   "the yaw's real sample-to-sample noise (state it), or the yaw is unusable (orientation = "
                   '"roll_pitch")', sensor_key(name, "orientation_noise"), evidence=evidence)


def frozen_verdict(name: str, ch: ChannelStats, fixes: int) -> Verdict:
    """The ``position_frozen`` channel (core/sensors/gps/model.py ``_frozen``): every record is a fix that repeated
    an earlier one (bit for bit, or to FROZEN_JITTER) while the wheels moved on, and was not fused, so its
    NIS says nothing. What it says is that the receiver lost its fix and kept publishing it as if it had
    one: a fault of the receiver (or its driver), no key of the config's."""
    share = ch.n / fixes if fixes else 0.0
    return Verdict(name, "position_frozen", "warn",
                   f"{ch.n} fixes ({100 * share:.1f}% of the GPS's) repeated an earlier fix while the wheels moved "
                   f"on (to within {100 * FROZEN_JITTER:g} cm): the receiver lost its fix and kept publishing it, "
                   "with a fix status. Not fused; the pose was dead-reckoned meanwhile. Nothing to change in the "
                   "config: check the receiver's sky view and antenna, or have its driver publish status NO_FIX",
                   evidence={"frozen_fixes": float(ch.n), "frozen_share": share})


def unaligned_verdict(gps: GpsSensor, ch: ChannelStats, up: ChannelStats | None = None) -> Verdict:
    """The ``position_unaligned`` channel of a GPS whose heading search never ended: every fix was fused
    as a position-only update, ungated, and none was judged against the stated noise. The search fits
    the fixes to the wheels' track and waits until the fit's heading uncertainty is small; a stated noise
    (``position_noise``, or ``error_sigma``'s wander) far above the fixes' real scatter keeps it large
    forever (a mower's GPS stated 10x too noisy: heading error 19.5 deg instead of 4.7, every verdict ok).
    The innovations' rms against what S predicted shows it: far below, the statement is what is wrong."""
    seen = [ch.learning_component(i) for i in range(len(ch.components))]
    rms, pred = [r for r, _ in seen], [p for _, p in seen]
    if len(rms) == 2 and up is not None and up.n and up.components == ["up"]:
        rms.append(up.component(0)[1])  # the fix's altitude, judged as its own block
    horizontal = [(r, p) for c, r, p in zip(ch.components, rms, pred) if c in ("east", "north")]
    measured = math.sqrt(sum(r * r for r, _ in horizontal) / len(horizontal)) if horizontal else math.nan
    predicted = math.sqrt(sum(p * p for _, p in horizontal) / len(horizontal)) if horizontal else math.nan
    head = (f"the heading was never found from the GPS: all {ch.n} fixes were fused as position only, ungated and "
            f"unjudged (innovations' horizontal rms {measured:.2f} m, {predicted:.2f} m predicted)")
    ev = {"unaligned_fixes": float(ch.n), "innovation_rms_m": measured, "predicted_rms_m": predicted}
    if math.isfinite(measured) and measured > 0.0 and predicted > UNALIGNED_LARGE * measured:
        return Verdict(gps.name, "position_unaligned", "warn",
                       f"{head}: the fixes scatter far less than stated, so the fit of their track never became "
                       "certain enough. The innovations' rms (an upper bound of the receiver's noise) "
                       "suggest the value below", sensor_key(gps.name, "position_noise"),
                       "position_noise = [" + ", ".join(f"{r:.2g}" for r in rms) + "]" if len(rms) == 3 else "",
                       evidence=ev)
    return Verdict(gps.name, "position_unaligned", "warn",
                   f"{head}: the fixes did not line up with the wheels' track. Check the odometry (twist_frame, "
                   "the wheels' scale) and that the vehicle drove at least heading_init_m in a line",
                   sensor_key(gps.name, "heading_init_m"), evidence=ev)


def reacquired_verdict(name: str, ch: ChannelStats, gaps: list[tuple[float, float]] | None = None) -> Verdict:
    """The ``position_reacquired`` channel (core/sensors/gps/model.py ``_locked_out``): each record is a fix that
    ended a run of gated-out fixes which agreed with each other and moved with the wheels, the filter's
    position having drifted beyond its gate; the position was taken from it and the heading searched
    again. Its NIS tests the drift, not the receiver (learning): what it says is that the filter lost the
    GPS. One cause is named: a logging gap (``gaps``: the odometry's silences, (stamp, length s)) that ended
    within REACQUIRE_AFTER_GAP_S before every reacquisition, or, with none before any, the motion model; with
    some of each, or without the gaps to look at, the verdict says it cannot tell."""
    head = (f"the filter lost this GPS {ch.n} time(s): its fixes were gated out for seconds while agreeing with "
            "each other and moving with the wheels, so the position was taken from the fix again and the heading "
            "searched anew. The estimate had drifted beyond its own uncertainty")
    evidence = {"reacquired": float(ch.n)}
    stamps = ch.stamps if len(ch.stamps) == ch.n else [ch.first_stamp] if ch.n == 1 and ch.first_stamp else None
    if gaps is None or not stamps:
        return Verdict(name, "position_reacquired", "warn",
                       head + "; whether a logging gap or the motion model cannot be told here (no odometry series "
                       "and stamps to look for gaps in)", evidence=evidence)
    after_gap = []
    for t in stamps:
        ends = [(start + length, length) for start, length in gaps
                if 0.0 <= t - (start + length) <= REACQUIRE_AFTER_GAP_S]
        after_gap.append(max((length for _, length in ends), default=0.0))
    blamed = sum(length > 0.0 for length in after_gap)
    evidence["after_logging_gap"] = float(blamed)
    if blamed == len(after_gap):
        longest = max(after_gap)
        return Verdict(name, "position_reacquired", "warn",
                       head + f": each time just after a logging gap (the longest {longest:.1f} s), which the "
                       "dead reckoning crossed without input further than the position's uncertainty allowed "
                       "(bounded by filter.covariance_cap); the fixes after it put the position back",
                       evidence={**evidence, "longest_gap_s": longest})
    if blamed == 0:
        return Verdict(name, "position_reacquired", "warn",
                       head + ": with no logging gap before it, so the motion model drifted: see the wheel "
                       "(twist_frame, the wheels' scale) and imu (gyro bias, mounting) verdicts",
                       evidence=evidence)
    return Verdict(name, "position_reacquired", "warn",
                   head + f": {blamed} time(s) just after a logging gap and {len(after_gap) - blamed} without one; "
                   "which one cause explains them cannot be told: see the wheel and imu verdicts for the latter",
                   evidence=evidence)
