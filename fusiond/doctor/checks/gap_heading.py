"""Heading across logging gaps: the IMU's own yaw saw a turn the filter could not.

In a logging gap nothing reaches the filter: its inputs end at their sensors' timeouts
and it holds the heading it had. The vehicle may have turned meanwhile, and without an
absolute heading (a GPS track, a pose sensor, an absolute IMU yaw) nothing ever tells
the filter: every metre after the gap is driven along the wrong heading (a race car
that turned 160 degrees in a 25 s gap). An IMU that integrates its own yaw kept it
through the gap (the device ran; only the log stopped), so its yaw change across the
gap shows the turn. With ``orientation = "roll_pitch"``, ``yaw_across_gaps`` (on by default)
turns the heading by that change at the first orientation after a gap, so a turn missed is
named with it to turn on where it is off (with ``"off"``: roll/pitch fused, and it). The IMU's yaw drifts by
itself (a 6-axis AHRS integrating its gyro's bias): the drift measured against the
bias-corrected gyro over the run, times the gap, is taken off its change first, so a car
parked through a gap shows no turn (a drift of 0.02 rad/s is 0.5 rad over a 25 s gap: taken as a
turn, it sends a parked car's track tens of metres off); a constant yaw (a placeholder) shows nothing.

A gap counts when the IMU's yaw change across it differs from the estimate's by more
than the IMU's own yaw could drift in that time: GAP_TURN_RAD (several times the yaw noise
of one 0.2 s bin, ~0.01-0.05 rad) plus GAP_DRIFT_RATE x the gap (an uncorrected consumer
gyro bias, <= 0.01 rad/s, integrated by the IMU through the gap).

Not ``relative``: fused so, the IMU's yaw holds the heading for the whole run, and its own
drift with it: a 6-axis IMU integrating its uncorrected gyro bias (0.004 rad/s) turns the
heading by 1.9 rad over 8 minutes, and drags the filter's bias estimate towards its own
(a race car's error between gaps grew from 0.5 to 6 m RMS so). Across gaps only, the yaw's drift costs
|r| x the gap, once: the drift r (against the bias-corrected gyro) is quoted with the advice.
"""

from __future__ import annotations

import math

import numpy as np

from ...config import Config, ImuSensor
from ...core.sensors.registry import kind_of
from ...estimator import rotation as rot
from ..bins import BIN_S
from ..heading import imu_yaw_drift, timed
from ..series import Series
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key


__all__ = ["GapHeading"]

MIN_GAP_S = 1.0  # shorter silences: the held inputs cover most of them
GAP_TURN_RAD = 0.2  # rad of unexplained turn across a gap: several times the yaw noise (the module docstring)
GAP_DRIFT_RATE = 0.01  # rad/s: an uncorrected consumer gyro bias, integrated by the IMU through the gap
# the estimates compared lie this close to the gap's ends (a time jump holds poses ~1 s), or it is not judged
GAP_EDGE_S = 2.0


def _around(t: np.ndarray, start: float, end: float) -> tuple[int, int] | None:
    """Indices of the bins just before start and just after end, None if none is near."""
    i0 = int(np.searchsorted(t, start, side="right")) - 1
    i1 = int(np.searchsorted(t, end, side="left"))
    if i0 < 0 or i1 >= len(t) or start - t[i0] > GAP_EDGE_S or t[i1] - end > GAP_EDGE_S:
        return None
    return i0, i1


def _at(t: np.ndarray, y: np.ndarray, when: float) -> float | None:
    """The IMU's yaw at ``when``: interpolated between the two bins around it (``t``: the instants their
    mean yaws hold at) when they are consecutive (at most 2 BIN_S apart, no silence between), else the
    value nearest ``when``; None if no bin is within BIN_S. The nearest bin alone can be BIN_S / 2 off
    ``when``: at a race car's 1 rad/s, 0.1 rad of the GAP_TURN_RAD allowance."""
    if not len(t):
        return None
    i = int(np.searchsorted(t, when))
    k = min((j for j in (i - 1, i) if 0 <= j < len(t)), key=lambda j: abs(t[j] - when))
    if abs(t[k] - when) > BIN_S:
        return None
    if 0 < i < len(t) and t[i] - t[i - 1] <= 2.0 * BIN_S:
        return float(y[i - 1] + (y[i] - y[i - 1]) * (when - t[i - 1]) / (t[i] - t[i - 1]))
    return float(y[k])


def _relative_drift(series: Series, cfg: Config, imu: ImuSensor) -> tuple[float, float] | None:
    """(wander, drift rate) of the IMU's yaw against the bias-corrected gyro (``heading.imu_yaw_drift``; without a
    standstill r - b, the drift a relative yaw adds to the gyro's). None without a gyro to compare with."""
    drift = imu_yaw_drift(series, cfg, imu)
    return None if drift is None else drift[:2]


class GapHeading(BaseCheck):
    """The IMU's yaw against the estimate's across logging gaps."""

    name = "gap_heading"

    def run(self, ev: Evidence) -> list[Verdict]:
        """A verdict when the IMU's unfused yaw turned across logging gaps more than the estimate did. ``t0``: the
        run's first stamp (the gap is then placed in seconds from it)."""
        series, cfg, imu, t0 = ev.series, ev.config, ev.run_imu, ev.t0
        if imu is None or imu.fuses_yaw:
            return []
        if any(kind_of(s).measures_position for s in cfg.sensors):
            return []  # an absolute position/pose finds the heading again
        gaps = [(start, length) for start, length in series.odom_gaps if length >= MIN_GAP_S]
        if not gaps:
            return []
        ti, yi = timed(series.imu_yaw_at, series.imu_yaw)
        if len(yi) < 2 or float(np.ptp(yi)) < 1e-6:
            return []  # a constant yaw (a driver's placeholder): it shows no turn, in a gap or out of one
        te, ye = np.array(series.est_t), np.array(series.est_yaw)
        # the IMU yaw's own drift against the bias-corrected gyro, measured over the run: a 6-axis AHRS integrating
        # its gyro's bias turns by r x the gap with the vehicle parked (0.5 rad over 25 s at 0.02 rad/s); what
        # it turned beyond that is the turn
        drift = _relative_drift(series, cfg, imu)
        rate = drift[1] if drift is not None and math.isfinite(drift[1]) else 0.0
        missed = []
        for start, length in gaps:
            # the estimate's heading change over the gap and the IMU's over the same interval (outside the gap
            # the filter's heading follows the gyro, and so does the IMU's yaw: only the gap differs)
            # (a bin after the gap: the first pose after it is the odometry's, published before the IMU sample
            # of the same instant turns the heading across the gap)
            around = _around(te, start, start + length + BIN_S)
            if around is None:
                continue
            e0, e1 = around
            before, after = _at(ti, yi, float(te[e0])), _at(ti, yi, float(te[e1]))
            if before is None or after is None:
                continue
            imu_turn = rot.wrap(after - before - rate * (float(te[e1]) - float(te[e0])))
            est_turn = rot.wrap(float(ye[e1]) - float(ye[e0]))
            miss = rot.wrap(imu_turn - est_turn)
            if abs(miss) > GAP_TURN_RAD + GAP_DRIFT_RATE * length:
                missed.append((start, length, imu_turn, est_turn))
        if not missed:
            return []
        worst = max(missed, key=lambda m: abs(rot.wrap(m[2] - m[3])))
        start, length, imu_turn, est_turn = worst
        evidence = {"gaps_with_missed_turn": float(len(missed)),
                    "largest_missed_turn_rad": rot.wrap(imu_turn - est_turn),
                    "estimate_turn_rad": est_turn, "gap_s": length}
        msg = (f"across {len(missed)} logging gap(s) the IMU's own yaw turned by more than the estimate (the largest: "
               f"{length:.1f} s from {start - (t0 or 0.0):.1f} s{' into the run' if t0 is not None else ''}, the IMU "
               f"turned {math.degrees(imu_turn):+.0f} deg beyond its own drift, the estimate "
               f"{math.degrees(est_turn):+.0f} deg): nothing "
               "else tells the filter the heading after a gap (no GPS or pose, the IMU's yaw not fused)")
        held = ", so it drives on along the heading it had"
        if imu.roll_pitch_only and imu.yaw_across_gaps and abs(est_turn) >= GAP_TURN_RAD:
            # on, and it turned the heading, by less: the drift it took off the IMU's change is measured against
            # the filter's heading before the gap, which drifts with a gyro bias not learned yet
            return [Verdict(imu.name, "heading_across_gaps", "warn",
                            msg + f". yaw_across_gaps turned it by {math.degrees(est_turn):+.0f} deg: it "
                            "takes off the IMU's change the drift the yaw showed against the filter's heading before "
                            "the gap (drift_rad in the heading_turned_across_gap log line), a share of it while that "
                            "heading may drift itself, its gyro's bias not learned yet (start at rest: see "
                            "imu/heading). Log without gaps, or add an absolute heading (GPS, pose)",
                            evidence=evidence)]
        if imu.roll_pitch_only and imu.yaw_across_gaps:
            # on, and it did not turn the heading: the messages' yaw is marked not measured, or never moved
            return [Verdict(imu.name, "heading_across_gaps", "warn",
                            msg + held + ". yaw_across_gaps did not turn it: the IMU's yaw is marked not measured "
                            "(covariance above orientation_max_sigma), never moved, read 0 after the gap (a restart), "
                            "or the vehicle stood still before and after the gap (see the heading_not_turned_across_gap "
                            "log lines). Log without gaps, or add an absolute heading (GPS, pose)", evidence=evidence)]
        cost = ""
        if drift is not None:
            wander, rate = drift
            evidence.update({"imu_yaw_wander_rad": wander, "imu_yaw_drift_rad_s": rate})
            cost = (f"; it drifts {rate:+.5f} rad/s against the bias-corrected gyro, "
                    f"~{abs(rate) * length:.3f} rad over "
                    f"the largest gap, turned in with the turn (fused as relative, over the whole run)")
        if imu.roll_pitch_only:
            return [Verdict(imu.name, "heading_across_gaps", "warn",
                            msg + held + ". The IMU kept its yaw through the gaps: let its yaw change across a gap "
                            f"turn the heading{cost}", sensor_key(imu.name, "yaw_across_gaps"),
                            "yaw_across_gaps = true", evidence)]
        fuse = ("take its orientation as roll_pitch (two_d_mode holds roll and pitch at 0: only its yaw's turns "
                "across gaps are used)" if cfg.filter.two_d_mode else "fuse its roll/pitch")
        return [Verdict(imu.name, "heading_across_gaps", "warn",
                        msg + held + f". The IMU kept its yaw through the gaps: {fuse}, and with yaw_across_gaps its "
                        f"yaw change across a gap turns the heading{cost}", sensor_key(imu.name, "orientation"),
                        'orientation = "roll_pitch"\nyaw_across_gaps = true', evidence)]
