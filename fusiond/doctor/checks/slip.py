"""The wheels' yaw rate against the gyro: slip, a driver's scale or offset, or its stated noise.

The gyro drives heading, so what the wheels' yaw rate does wrong is only reported: a systematic scale
(skid-steer) is named as such, never as understated noise, and a NIS made high by the samples flagged as
slip alone says nothing about the stated noise.
"""

from __future__ import annotations

import math

from ...config import OdomSensor
from ...core.sensors.registry import kind_of
from ..channels import PerChannel
from ..evidence import Evidence
from ..heading import WHEEL_OFFSET_RAD_S, WHEEL_SCALE_TOLERANCE, rate_fit_text
from ..nis import ChannelStats
from ..verdict import Verdict, sensor_key

__all__ = ["YawRateSlip"]

SLIP_FRACTION = 0.2  # samples flagged as slip beyond a fifth: the wheels' yaw rate is not just noisy


class YawRateSlip(PerChannel):
    """The wheels' yaw rate against the gyro (slip); not judged when the driver does not measure it."""

    name = "slip"
    kind = "yaw_rate"
    needs = ("unmeasured_yaw_rate",)

    def judge(self, ev: Evidence, key: tuple[str, str], ch: ChannelStats) -> list[Verdict]:
        """The wheels' yaw rate checked against the gyro (the gyro drives heading).

        ``fit`` is (scale, offset) of the wheel yaw rate against the gyro's over the run: a
        systematic scale (skid-steer) is named as such, never as understated noise; and a NIS
        made high by the samples flagged as slip alone says nothing about the stated noise.
        ``floored``: (samples, their mean stated sigma) of the yaw rates whose stated noise lay below
        ``twist_min_sigma``'s floor, which the core used instead: a NIS low over mostly such samples is
        the floor's, and the value to paste is the floor's.
        """
        if ev.findings.first("unmeasured_yaw_rate") is not None:
            return []
        s = ev.sensors.get(key[0])
        odom = s if s is not None and kind_of(s).drives_prediction else OdomSensor(name=key[0], key=key[0])
        fit, floored = ev.wheel_yaw, ev.odom_floored
        frac = ch.rejected / ch.n
        mean, rms, _ = ch.component(0)
        key = sensor_key(odom.name, "slip_threshold")
        if fit is not None and (abs(fit[0] - 1.0) > WHEEL_SCALE_TOLERANCE or abs(fit[1]) > WHEEL_OFFSET_RAD_S):
            k, offset = fit
            return [Verdict(odom.name, "yaw_rate", "warn",
                            f"the wheels' yaw rate = {rate_fit_text(k, offset)} (rms residual {rms:.3f} "
                            f"rad/s, {100 * frac:.0f}% flagged as slip): skid-steer slip or a driver scale/offset. The "
                            "gyro drives heading, so this is only reported; do not state more wheel yaw-rate noise "
                            "for it",
                            key, evidence={"wheel_vs_gyro_yaw_scale": k, "wheel_vs_gyro_yaw_offset_rad_s": offset,
                                      "slip_fraction": frac})]
        verdict = ch.verdict()
        if frac > SLIP_FRACTION:
            return [Verdict(odom.name, "yaw_rate", "warn",
                            f"wheel yaw rate disagrees with the gyro in {100 * frac:.0f}% of {ch.n} samples "
                            f"(mean {mean:+.3f}, rms {rms:.3f} rad/s): skid-steer slip or a driver scale/offset. "
                            "The gyro drives heading, so this is only reported; without the gyro the heading "
                            "would follow the wheels", key, evidence={"slip_fraction": frac, "rms_rad_s": rms})]
        if verdict == "nis_high" and ch.rejected and ch.kept_verdict() != "nis_high":
            return [Verdict(odom.name, "yaw_rate", "warn",
                            f"wheel yaw rate against the gyro: NIS high ({ch.nis_per_dof:.2f} per dof over {ch.n}) "
                            f"only because of the {ch.rejected} samples ({100 * frac:.1f}%) flagged as slip, the "
                            "wheels disagreeing with the gyro in short stretches (slip, or wheels reading zero while "
                            "the vehicle still coasts or turns); the other samples agree with the stated noise. The "
                            "gyro drives heading, so this is only reported",
                            evidence={"slip_fraction": frac, "rms_rad_s": rms})]
        if abs(mean) > WHEEL_OFFSET_RAD_S:
            return [Verdict(odom.name, "yaw_rate", "warn",
                            f"wheel yaw rate offset of {mean:+.3f} rad/s against the gyro: a driver offset or "
                            "uncorrected gyro bias. The gyro drives heading, so this is only reported",
                            evidence={"mean_rad_s": mean})]
        _, _, predicted = ch.component(0)
        floor = odom.twist_min_sigma[1]
        rest = max(predicted * predicted - floor * floor, 0.0)  # S less the floor's variance: gyro, bias estimate
        mostly_floored = floored[0] > 0.5 * ch.n and math.isfinite(floored[1])
        if mostly_floored and ((verdict == "nis_low" and floor * floor > rest) or verdict == "nis_high"):
            # the filter used the floor for the wheels: NIS low where the floor is most of S (not, say, a bias
            # prior no standstill has narrowed), NIS high where the wheels are noisier than it. The residuals'
            # rms^2 less the rest of S is the wheels' own variance: the floor to paste, never below what the
            # driver states
            wheel = max(math.sqrt(max(rms * rms - rest, 0.0)), floored[1])
            move = "lower" if verdict == "nis_low" else "raise"
            stated = (f"the driver states {floored[1]:.4f} rad/s" if floored[1] > 0.0
                      else "the driver states no yaw-rate variance (0)")
            return [Verdict(odom.name, "yaw_rate", "warn",
                            f"wheel yaw rate against the gyro: NIS {verdict.removeprefix('nis_')} "
                            f"({ch.nis_per_dof:.2f} per "
                            f"dof over {ch.n}, rms {rms:.3f} rad/s): in {floored[0]} samples {stated}, below the "
                            f"twist_min_sigma floor ({floor:g}) the filter uses instead; the residuals show "
                            f"~{wheel:.4f} for the wheels: {move} the floor", sensor_key(odom.name, "twist_min_sigma"),
                            f"twist_min_sigma = [{odom.twist_min_sigma[0]:g}, {wheel:.4f}]",
                            evidence={"nis_per_dof": ch.nis_per_dof, "rms_rad_s": rms,
                                      "floored_samples": float(floored[0]),
                                      "stated_sigma_rad_s": floored[1], "wheel_sigma_rad_s": wheel})]
        if verdict != "ok":
            more = "smaller" if verdict == "nis_high" else "larger"
            evidence = {"nis_per_dof": ch.nis_per_dof, "rms_rad_s": rms}
            shown, line = _stated_wheel(odom, rms, predicted, verdict)
            if shown is not None:
                evidence["wheel_sigma_rad_s"] = shown
            value = "" if shown is None else f": they show ~{shown:.4f} rad/s for the wheels"
            return [Verdict(odom.name, "yaw_rate", "warn",
                            f"wheel yaw rate against the gyro: NIS {verdict.removeprefix('nis_')} "
                            f"({ch.nis_per_dof:.2f} per "
                            f"dof over {ch.n}, rms {rms:.3f} rad/s) without slip: the stated wheel yaw-rate noise is "
                            f"{more} than the residuals show{value}", sensor_key(odom.name, "twist_noise"), line,
                            evidence=evidence)]
        return [Verdict(odom.name, "yaw_rate", "ok", f"wheels agree with the gyro (rms {rms:.3f} rad/s over {ch.n})")]


def _stated_wheel(odom: OdomSensor, rms: float, predicted: float, verdict: str) -> tuple[float | None, str]:
    """(the wheels' own yaw-rate sigma the residuals show, a twist_noise line stating it) for a yaw-rate NIS high or
    low over samples whose noise the floor did not replace. The residuals' rms^2 is the wheels' variance plus the
    rest of S (the gyro's rate noise, the bias estimate's spread): S less the wheels' variance as the filter took
    it. Known where the config states twist_noise (the filter took max(its yaw sigma, the floor)); the line keeps
    its five other sigmas. (None, "") where the wheels' share cannot be told from S (the messages state it, each
    its own), or the value is one the floor would replace (a NIS low below twist_min_sigma: no twist_noise moves
    it). Where the gyro drives heading the filter takes the wheels' yaw rate only while the gyro is silent: the
    replay of a run without such silences cannot judge the line (the proof says so), the gaps of another can."""
    floor = odom.twist_min_sigma[1]
    stated = odom.twist_noise
    if stated is None:
        return None, ""
    took = max(float(stated[5]), floor)
    rest = max(predicted * predicted - took * took, 0.0)
    wheel = math.sqrt(max(rms * rms - rest, 0.0))
    if not math.isfinite(wheel) or wheel <= floor:  # the floor stands: no twist_noise below it changes the filter
        return None, ""
    if (verdict == "nis_high") != (wheel > took):  # the value would move the noise against the verdict
        return None, ""
    return wheel, "twist_noise = [" + ", ".join(f"{float(v):g}" for v in stated[:5]) + f", {wheel:.4f}]"
