"""When the wheels drive heading (no gyro fused): their yaw rate against the gyro's, and the IMU's yaw.

A skid-steer's wheels turn at a scale of the gyro's (slip), a driver may add an offset, and a drive that
reads zero while the vehicle turns misses the turn: each bends the predicted heading, and every heading
update then fights it. The gyro, fused, drives heading instead.
"""

from __future__ import annotations

import math

import numpy as np

from ...core.sensors.registry import kind_of
from ..check import BaseCheck
from ..evidence import Evidence
from ..heading import (WHEEL_OFFSET_RAD_S, WHEEL_SCALE_TOLERANCE, WheelOffset, rate_fit_text, timed, wheel_yaw_fit,
                       wheel_yaw_offset, yaw_scale, zero_while_turning)
from ..series import Series
from ..verdict import Verdict, sensor_key

__all__ = ["WheelHeading"]

MISSED_INTERVAL_S = 0.5  # s: an odometry interval counts for at most this much turn time (gaps count nothing)
MISSED_TURN_RAD = 0.2  # rad (11 deg) of turn the wheels missed in all: worth fusing the gyro for


def _missed_turn(series: Series) -> tuple[float, float]:
    """(rad, s): what the gyro turned while the wheels read exactly zero (``zero_while_turning``), each
    odometry interval capped at MISSED_INTERVAL_S so a logging gap counts for nothing. No scale information,
    but with the wheels driving heading, turns the heading never made (a race car's hairpins with the
    drive reading zero)."""
    to, wz = np.array(series.odom_t), np.array(series.odom_wz)
    tg, gz = np.array(series.gyro_t), np.array(series.gyro_z)
    if len(to) < 2 or len(tg) < 2:
        return 0.0, 0.0
    g, zero = zero_while_turning(to, wz, tg, gz)
    zero &= (to >= tg[0]) & (to <= tg[-1])
    dt = np.minimum(np.diff(to, append=to[-1]), MISSED_INTERVAL_S)
    return float(np.sum(np.abs(g[zero]) * dt[zero])), float(np.sum(dt[zero]))


class WheelHeading(BaseCheck):
    """The wheels' yaw rate against the gyro's; not asked when the wheels' yaw rate is known unmeasured
    (either check it needs already says so)."""

    name = "wheel_heading"
    group = "cross"
    needs = ("unmeasured_yaw_rate", "yaw_rate_not_measured")

    def run(self, ev: Evidence) -> list[Verdict]:
        """When the wheels drive heading (no gyro fused): their yaw against the gyro and the IMU yaw."""
        if any(ev.findings.first(n) is not None for n in self.needs):
            return []
        series, cfg = ev.series, ev.config
        odom = next((s for s in cfg.sensors if kind_of(s).drives_prediction), None)
        if odom is None or any(kind_of(s).fuses_gyro(s) for s in cfg.sensors) or not odom.twist_measured[5]:
            return []
        if len(series.odom_t) < 10 or len(series.gyro_t) < 10:
            return []
        imu = ev.imu
        fit = wheel_yaw_fit(series)
        if fit is None:  # the run hardly turns: only an offset shows
            off = wheel_yaw_offset(series, cfg, imu) if imu is not None else None
            return [] if off is None else [_offset_verdict(odom.name, imu.name, off)]
        k, offset = fit
        tg, hg = timed(series.gyro_heading_at, series.gyro_heading)
        evidence = {"wheel_vs_gyro_yaw_scale": k, "wheel_vs_gyro_yaw_offset_rad_s": offset}
        ti, yi = timed(series.imu_yaw_at, series.imu_yaw)
        k_imu = (yaw_scale(ti, yi, tg, hg, [*series.gyro_breaks, *series.imu_breaks]) if len(ti) >= 10 and len(tg)
                 else math.nan)
        if math.isfinite(k_imu):
            evidence["imu_vs_gyro_yaw_scale"] = k_imu
        missed, seconds = _missed_turn(series)
        if missed > MISSED_TURN_RAD and imu is not None:
            evidence.update({"turn_missed_rad": missed, "zero_while_turning_s": seconds})
            return [Verdict(odom.name, "heading", "problem",
                            f"the wheels read exactly zero for {seconds:.1f} s in all while the gyro turned "
                            f"({missed:.2f} rad of turn: the drive at rest while the vehicle turns, or its yaw rate "
                            "lost). The gyro "
                            "is not fused, so the predicted heading missed every one of those turns (outside them the "
                            f"wheels' yaw rate = {rate_fit_text(k, offset)}); fuse the gyro so it drives heading",
                            sensor_key(imu.name, "angular_velocity"), "angular_velocity = true", evidence)]
        if abs(k - 1.0) <= WHEEL_SCALE_TOLERANCE and abs(offset) <= WHEEL_OFFSET_RAD_S:
            return [Verdict(odom.name, "heading", "ok",
                            f"wheel yaw rate agrees with the gyro (scale {k:.2f}, offset {offset:+.3f} rad/s)",
                            evidence=evidence)]
        agree = (f"; the IMU's own yaw agrees with the gyro (scale {k_imu:.2f})"
                 if math.isfinite(k_imu) and abs(k_imu - 1.0) <= WHEEL_SCALE_TOLERANCE else "")
        msg = (f"the wheels' yaw rate = {rate_fit_text(k, offset)}{agree}: skid-steer slip "
               "or a driver scale. The gyro "
               "is not fused, so this wheel yaw rate drives the predicted heading and every heading update fights it")
        if imu is None:
            return [Verdict(odom.name, "heading", "warn", msg, evidence=evidence)]
        return [Verdict(odom.name, "heading", "problem", msg + "; fuse the gyro so it drives heading",
                        sensor_key(imu.name, "angular_velocity"), "angular_velocity = true", evidence)]


def _offset_verdict(odom: str, imu: str, off: WheelOffset) -> Verdict:
    """The wheels' yaw-rate offset on a run that hardly turns, with the gyro not fused: a problem when it is the
    wheels' beyond what the gyro's own bias may be (``WheelOffset.significant``), since that offset then turns
    the predicted heading all run long; otherwise said with the bound it stays within."""
    bias = (f"the gyro's bias at rest ({off.bias_at_rest:+.4f} rad/s) taken off" if math.isfinite(off.bias_at_rest)
            else f"the gyro's own bias unknown without a standstill (gyro_bias_sigma {off.bias_sigma:g} rad/s)")
    evidence = {"wheel_vs_gyro_yaw_offset_rad_s": off.offset, "wheel_vs_gyro_yaw_offset_se": off.se,
                "gyro_bias_sigma_rad_s": off.bias_sigma, "offset_bound_rad_s": off.bound, "driving_s": off.seconds}
    figure = (f"over {off.seconds:.0f} s of driving that hardly turns, the wheels' yaw rate reads {off.offset:+.4f} "
              f"rad/s against the gyro ({bias}; +- {off.bound:.4f} would be chance)")
    if not off.significant:
        return Verdict(odom, "heading", "ok", f"{figure}: within what the gyro's own bias may be, so no offset of "
                       "the wheels' own can be told from it", evidence=evidence)
    return Verdict(odom, "heading", "problem",
                   f"{figure}: the wheels' own offset. The gyro is not fused, so it turns the predicted heading by "
                   f"{abs(off.offset) * off.seconds:.2f} rad over the run and every heading update fights it; fuse "
                   "the gyro so it drives heading (its bias is then learned)",
                   sensor_key(imu, "angular_velocity"), "angular_velocity = true", evidence)
