"""An IMU's orientation innovations: NIS against the stated noise, and a roll/pitch offset in them.

A yaw the heading cross-check found following the gyro is not a disturbed one, whatever its NIS: that
check's wander figure is passed on, and a NIS high beside it is the yaw's own noise stated too small.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ...core.sensors.imu.axes import weights
from ..attitude import AXES, noise_suggestion
from ..channels import PerChannel, figures, process_overstated
from ..evidence import Evidence
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

if TYPE_CHECKING:
    from ...config import ImuSensor

__all__ = ["OrientationNis"]

ROLL_PITCH_OFFSET_RAD = 0.01  # a mean roll/pitch innovation this large is a mounting error, not noise


class OrientationNis(PerChannel):
    """An IMU's orientation innovations. A yaw the heading cross-check found following the gyro is not a
    disturbed one, whatever its NIS: that check's wander figure is passed on."""

    name = kind = "orientation"
    needs = ("heading",)

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """``yaw_vs_gyro``: the rms wander of the IMU's yaw against the integrated gyro that the heading
        cross-check measured and found below its threshold (None when it did not). A yaw NIS high beside it
        is not a disturbed yaw, whose wander the gyro would show: the innovations are the yaw's own noise,
        stated too small (an AHRS reporting a zero covariance reads as the orientation_min_sigma floor)."""
        heading = ev.findings.first("heading")
        agrees = (heading.evidence.get("imu_vs_gyro_wander_rad")
                  if heading is not None and heading.sensor == key[0] and heading.level == "ok" else None)
        imu = ev.channel_imu(key)
        t0 = ev.t0
        yaw_vs_gyro = agrees if agrees is not None and math.isfinite(agrees) else None
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
                line, note, _ = noise_suggestion(ch, imu)
                agrees = (f"; the yaw agrees with the integrated gyro to {yaw_vs_gyro:.3f} rad rms once a bias and "
                          "scale are removed, so it is not a disturbed yaw" if yaw_dominates and yaw_vs_gyro is not None
                          else "")
                out.append(Verdict(imu.name, "orientation", "problem",
                                   f"NIS high ({figures(ch, t0)}; {detail}): the stated noise is too small or the IMU "
                                   f"lies{agrees}; the measured innovations, {note}, suggest the value below",
                                   key, line))
        elif verdict == "nis_low" and (over_q := _attitude_overstated(ev, imu.name, ch)) is not None:
            c, got, floor, dt, q, attitude = over_q
            out.append(Verdict(imu.name, "orientation", "warn",
                               f"NIS low ({figures(ch, t0)}; {detail}): the {c} innovations (rms {got:.4f} rad) are "
                               f"smaller than what the process noise alone adds to the prediction between updates "
                               f"({floor:.4f} rad: filter.process_noise's attitude {attitude:g} rad/sqrt(s) over "
                               f"{dt:.2g} s), whatever the IMU's noise: the model's attitude noise is stated too large, "
                               "and no orientation_noise brings the NIS up. The value below is the most the innovations "
                               "allow it (`fusiond tune` fits it on this recording)", "filter.process_noise",
                               f"process_noise = [{ev.config.filter.process_noise[0]:g}, {q:.2g}]",
                               {"innovation_rms": got, "process_noise_alone_rms": floor}))
        elif verdict == "nis_low":
            line, note, values = noise_suggestion(ch, imu)
            # only where the line would lower no stated component (it is the noise the innovations show, or its
            # floor): a stated noise too large keeps the prediction's own uncertainty large too, and is the fix
            over = _prediction_overstated(ch, imu) if ev.gyro_fused and _settled(values, imu) else None
            if over is not None:
                c, seen, alone = over
                out.append(Verdict(imu.name, "orientation", "warn",
                                   f"NIS low ({figures(ch, t0)}; {detail}): the {c} innovations (rms {seen:.4f}) are "
                                   f"smaller than the prediction's own uncertainty before each update ({alone:.4f}: "
                                   "the predicted rms less the orientation_noise stated), so no orientation_noise "
                                   "brings the NIS to 1. The prediction is what is overstated: the gyro's noise (its "
                                   "messages' covariance, or gyro_noise) or filter.process_noise.attitude. State the "
                                   "gyro's noise measured at rest (fusiond calibrate-imu), or let fusiond tune fit it",
                                   sensor_key(imu.name, "gyro_noise"),
                                   evidence={"innovation_rms": seen, "prediction_alone_rms": alone}))
            else:
                out.append(Verdict(imu.name, "orientation", "warn",
                                   f"NIS low ({figures(ch, t0)}; {detail}): the stated orientation noise is larger "
                                   f"than the innovations show (or the process noise is); measured {note}", key, line))
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


def _attitude_overstated(ev: Evidence, sensor: str, ch: ChannelStats) -> tuple[str, float, float, float, float,
                                                                              float] | None:
    """``channels.process_overstated`` on the orientation's angles with filter.process_noise's attitude part, and
    that part; None without a config (the live monitor) or where the innovations do not show it."""
    if ev.config is None:
        return None
    attitude = float(ev.config.filter.process_noise[1])
    period = float((ev.stats or {}).get(sensor, {}).get("period") or 0.0)
    over = process_overstated(ch, attitude, ("roll", "pitch", "yaw"), period)
    return None if over is None else (*over, attitude)


def _settled(suggested: list[float], imu: ImuSensor) -> bool:
    """Would the orientation_noise line (``suggested``, its values) lower none of the components the config
    states, as the line prints them (4 decimals)?"""
    if imu.orientation_noise is None:
        return False
    return all(round(s, 4) >= round(t, 4) for s, t in zip(suggested, imu.orientation_noise))


def _prediction_overstated(ch: ChannelStats, imu: ImuSensor) -> tuple[str, float, float] | None:
    """(component, innovation rms, rms of the prediction alone) of the component whose innovations are the
    furthest below what the prediction alone claims, where they are below it: S = H P H^T + R, so with R the
    orientation_noise stated (in base axes through the mount) the prediction's share is S - R, and
    innovations smaller than that share cannot be explained by this R. None without a stated
    orientation_noise (the messages' R is not known here), or when no component is below. (An R stated too
    large keeps H P H^T large as well, the updates being weak: the caller asks this only of an R the
    innovations do not ask to lower, ``_settled``.)"""
    if imu.orientation_noise is None:
        return None
    W = weights(imu.extrinsic_rpy)
    worst = None
    for i, c in enumerate(ch.components):
        _, rms, pred = ch.component(i)
        k = AXES.index(c)
        r_var = sum(W[k][j] * imu.orientation_noise[j] ** 2 for j in range(3))
        alone_var = pred * pred - r_var
        if alone_var > 0.0 and rms * rms < alone_var:
            ratio = rms / math.sqrt(alone_var)
            if worst is None or ratio < worst[0]:
                worst = (ratio, c, rms, math.sqrt(alone_var))
    return None if worst is None else worst[1:]
