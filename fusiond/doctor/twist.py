"""Odometry twist: a yaw rate that is not measured, slip against the gyro, the twist frame.

A driver that lost its yaw rate publishes 0 with covariance 0: to the filter a
perfect measurement of "not turning". Against the gyro it looks like slip in every
turn. The difference is in the numbers: slip reads a wrong rate, a lost component
reads exactly zero (with zero variance) while the gyro turns. That is "not
measured", declared with ``twist_measured``.
"""

from __future__ import annotations

import math
from itertools import chain

import numpy as np

from ..config import ImuSensor, OdomSensor
from .nis import ChannelStats
from .series import Series
from .settled import Settled
from .heading import rate_fit_text
from .verdict import Verdict, sensor_key
from .thresholds import (ALL_ZEROS_FRACTION, ALONG_SIN, MIN_TURNED_RAD, MOVING_M_S, SLIP_FRACTION, TURNED_RAD,
                         TURNING_RAD_S, UNMEASURED_FRACTION, WHEEL_OFFSET_RAD_S, WHEEL_SCALE_TOLERANCE)

CHUNK = 4096  # twists noted before they are summed (bounded memory)


class TwistStats:
    """Whole-run sums of |vx|, |vy| and |wz| of the accepted odometry (is the twist in the body frame?),
    and, over the moving messages whose own pose is turned beyond TURNED_RAD from the odom frame's x, how
    many point their twist along x (a body-frame twist: a world one would point where that pose heads).

    Fed one twist per accepted odometry message, so it only notes it; the sums are taken a chunk at a
    time by ``np.cumsum`` (adds in order: the same floats as adding one message at a time)."""

    def __init__(self) -> None:
        self._linear: list[tuple[float, float, float]] = []  # the samples' own tuples: nothing allocated
        self._angular: list[tuple[float, float, float]] = []
        self._orientation: list[tuple[float, float, float, float]] = []
        self._n = 0
        self._sums = [0.0, 0.0, 0.0]
        self._turned = 0
        self._along_x = 0

    def add(self, linear: tuple[float, float, float], angular: tuple[float, float, float],
            orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)) -> None:
        self._linear.append(linear)
        self._angular.append(angular)
        self._orientation.append(orientation)
        if len(self._linear) >= CHUNK:
            self._settle()

    n = Settled("_n")
    abs_vx = Settled("_sums", 0)
    abs_vy = Settled("_sums", 1)
    abs_wz = Settled("_sums", 2)
    turned = Settled("_turned")  # moving messages whose pose yaw is beyond TURNED_RAD ...
    along_x = Settled("_along_x")  # ... whose twist points along the odom frame's x (body-frame, or the robot heads x)

    def _settle(self) -> None:
        n = len(self._linear)
        if not n:
            return
        linear = np.fromiter(chain.from_iterable(self._linear), dtype=float, count=3 * n).reshape(n, 3)
        angular = np.fromiter(chain.from_iterable(self._angular), dtype=float, count=3 * n).reshape(n, 3)
        q = np.fromiter(chain.from_iterable(self._orientation), dtype=float, count=4 * n).reshape(n, 4)
        self._linear, self._angular, self._orientation = [], [], []
        x, y, z, w = q.T
        pose_yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        direction = np.arctan2(linear[:, 1], linear[:, 0])
        turned = (np.hypot(linear[:, 0], linear[:, 1]) > MOVING_M_S) & (np.abs(np.sin(pose_yaw)) > math.sin(TURNED_RAD))
        self._turned += int(turned.sum())
        self._along_x += int((turned & (np.abs(np.sin(direction)) < ALONG_SIN)).sum())
        rows = np.abs(np.column_stack((linear[:, 0], linear[:, 1], angular[:, 2])))
        self._n += n
        self._sums = np.cumsum(np.concatenate(([self._sums], rows)), axis=0)[-1].tolist()


def unmeasured_yaw_rate(series: Series, odom: OdomSensor) -> Verdict | None:
    if len(series.gyro_t) < 10 or len(series.odom_t) < 10 or not odom.twist_measured[5]:
        return None
    tg, z = np.array(series.gyro_t), np.array(series.gyro_z)
    to = np.array(series.odom_t)
    bias = float(np.interp(to, series.est_t, series.est_bias_z).mean()) if series.est_bias_z else 0.0
    gyro_at = np.interp(to, tg, z) - bias
    turning = np.abs(gyro_at) > TURNING_RAD_S
    n = np.array(series.odom_n)[turning].sum()
    zeros = np.array(series.odom_zero_wz)[turning].sum()
    where = f"where the gyro turns faster than {TURNING_RAD_S} rad/s"
    if n < 20 or zeros / n < UNMEASURED_FRACTION:
        # A vehicle that only turns gently (a highway's curves, under TURNING_RAD_S) never shows that. But no
        # real yaw rate reads exactly 0 with variance 0 in every moving sample of a run whose heading the gyro
        # turns by radians: that is a driver filling in a component it does not measure.
        moving = ~np.array(series.odom_rest, dtype=bool)
        n = np.array(series.odom_n)[moving].sum()
        zeros = np.array(series.odom_zero_wz)[moving].sum()
        turned = float(np.ptp(series.gyro_heading)) if len(series.gyro_heading) else 0.0
        if n < 20 or zeros < ALL_ZEROS_FRACTION * n or turned < MIN_TURNED_RAD:
            return None
        where = f"while moving, over a run the gyro turned through {turned:.1f} rad"
    frac = zeros / n
    measured = ["true"] * 6
    measured[5] = "false"
    return Verdict(odom.name, "yaw_rate", "problem",
                   f"the wheel yaw rate reads exactly 0 with variance 0 in {100 * frac:.0f}% of the {int(n)} samples "
                   f"{where}: the driver does not measure it (not slip). A fused gyro makes the filter take it as "
                   "not measured (log twist_component_lost); declare it so that it is never used nor checked",
                   sensor_key(odom.name, "twist_measured"), f"twist_measured = [{', '.join(measured)}]",
                   {"zero_fraction_in_turns": float(frac), "turning_samples": float(n)})


def yaw_rate_not_measured(series: Series, odom: OdomSensor, imu: ImuSensor | None,
                          gyro_fused: bool) -> Verdict | None:
    """Nothing measures the turn rate: the odometry marks its yaw rate "not measured" (a driver sending
    covariance 1e6, or twist_measured) and no gyro is fused. The heading then only changes through the
    absolute updates (IMU yaw, GPS), lagging every turn; against the gyro it looks like a wheel yaw rate
    of 0 x the gyro, but it is neither slip nor a scale: fuse the gyro."""
    if gyro_fused or not series.odom_n:
        return None
    n = int(np.sum(series.odom_n))
    unmeasured = int(np.sum(series.odom_wz_unmeasured))
    if n == 0 or unmeasured < UNMEASURED_FRACTION * n:
        return None
    msg = (f"the odometry does not measure yaw rate ({unmeasured} of {n} samples state it not measured: "
           "variance >= twist_max_sigma^2, or twist_measured) and the gyro is not fused: nothing measures the "
           "turn rate, so the heading only follows the absolute updates, lagging every turn (not skid-steer slip)")
    ev = {"yaw_rate_unmeasured_fraction": unmeasured / n}
    if imu is None:
        return Verdict(odom.name, "heading", "problem", msg + "; add an IMU and fuse its gyro", evidence=ev)
    return Verdict(odom.name, "heading", "problem", msg + "; fuse the gyro: angular_velocity = true",
                   sensor_key(imu.name, "angular_velocity"), "angular_velocity = true", ev)


def slip_verdict(odom: OdomSensor, ch: ChannelStats, fit: tuple[float, float] | None = None,
                 floored: tuple[int, float] = (0, math.nan)) -> Verdict:
    """The wheels' yaw rate checked against the gyro (the gyro drives heading).

    ``fit`` is (scale, offset) of the wheel yaw rate against the gyro's over the run: a
    systematic scale (skid-steer) is named as such, never as understated noise; and a NIS
    made high by the samples flagged as slip alone says nothing about the stated noise.
    ``floored``: (samples, their mean stated sigma) of the yaw rates whose stated noise lay below
    ``twist_min_sigma``'s floor, which the core used instead: a NIS low over mostly such samples is
    the floor's, and the value to paste is the floor's.
    """
    frac = ch.rejected / ch.n
    mean, rms, _ = ch.component(0)
    key = sensor_key(odom.name, "slip_threshold")
    if fit is not None and (abs(fit[0] - 1.0) > WHEEL_SCALE_TOLERANCE or abs(fit[1]) > WHEEL_OFFSET_RAD_S):
        k, offset = fit
        return Verdict(odom.name, "yaw_rate", "warn",
                       f"the wheels' yaw rate = {rate_fit_text(k, offset)} (rms residual {rms:.3f} "
                       f"rad/s, {100 * frac:.0f}% flagged as slip): skid-steer slip or a driver scale/offset. The "
                       "gyro drives heading, so this is only reported; do not state more wheel yaw-rate noise for it",
                       key, evidence={"wheel_vs_gyro_yaw_scale": k, "wheel_vs_gyro_yaw_offset_rad_s": offset,
                                 "slip_fraction": frac})
    verdict = ch.verdict()
    if frac > SLIP_FRACTION:
        return Verdict(odom.name, "yaw_rate", "warn",
                       f"wheel yaw rate disagrees with the gyro in {100 * frac:.0f}% of {ch.n} samples "
                       f"(mean {mean:+.3f}, rms {rms:.3f} rad/s): skid-steer slip or a driver scale/offset. "
                       "The gyro drives heading, so this is only reported; without the gyro the heading "
                       "would follow the wheels", key, evidence={"slip_fraction": frac, "rms_rad_s": rms})
    if verdict == "nis_high" and ch.rejected and ch.kept_verdict() != "nis_high":
        return Verdict(odom.name, "yaw_rate", "warn",
                       f"wheel yaw rate against the gyro: NIS high ({ch.nis_per_dof:.2f} per dof over {ch.n}) only "
                       f"because of the {ch.rejected} samples ({100 * frac:.1f}%) flagged as slip, the wheels "
                       "disagreeing with the gyro in short stretches (slip, or wheels reading zero while the vehicle "
                       "still coasts or turns); the other samples agree with the stated noise. The gyro drives "
                       "heading, so this is only reported", evidence={"slip_fraction": frac, "rms_rad_s": rms})
    if abs(mean) > 0.02:
        return Verdict(odom.name, "yaw_rate", "warn",
                       f"wheel yaw rate offset of {mean:+.3f} rad/s against the gyro: a driver offset or "
                       "uncorrected gyro bias", key, evidence={"mean_rad_s": mean})
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
        return Verdict(odom.name, "yaw_rate", "warn",
                       f"wheel yaw rate against the gyro: NIS {verdict.removeprefix('nis_')} ({ch.nis_per_dof:.2f} per "
                       f"dof over {ch.n}, rms {rms:.3f} rad/s): in {floored[0]} samples {stated}, below the "
                       f"twist_min_sigma floor ({floor:g}) the filter uses instead; the residuals show ~{wheel:.4f} "
                       f"for the wheels: {move} the floor", sensor_key(odom.name, "twist_min_sigma"),
                       f"twist_min_sigma = [{odom.twist_min_sigma[0]:g}, {wheel:.4f}]",
                       evidence={"nis_per_dof": ch.nis_per_dof, "rms_rad_s": rms, "floored_samples": float(floored[0]),
                                 "stated_sigma_rad_s": floored[1], "wheel_sigma_rad_s": wheel})
    if verdict != "ok":
        more = "smaller" if verdict == "nis_high" else "larger"
        return Verdict(odom.name, "yaw_rate", "warn",
                       f"wheel yaw rate against the gyro: NIS {verdict.removeprefix('nis_')} ({ch.nis_per_dof:.2f} per "
                       f"dof over {ch.n}, rms {rms:.3f} rad/s) without slip: the stated wheel yaw-rate noise is {more} "
                       "than the residuals show", sensor_key(odom.name, "twist_noise"),
                       evidence={"nis_per_dof": ch.nis_per_dof, "rms_rad_s": rms})
    return Verdict(odom.name, "yaw_rate", "ok", f"wheels agree with the gyro (rms {rms:.3f} rad/s over {ch.n})")


def twist_frame_verdict(odom: OdomSensor, t: TwistStats, min_updates: int = 50) -> Verdict | None:
    if t.n < min_updates or t.abs_vx + t.abs_vy < 1e-6:
        return None
    lateral = t.abs_vy / max(t.abs_vx + t.abs_vy, 1e-12)
    key = sensor_key(odom.name, "twist_frame")
    if odom.twist_frame == "world" and t.turned >= min_updates and t.along_x >= 0.9 * t.turned:
        # a world-frame twist points where the vehicle heads, which the message's own pose says: one that
        # keeps pointing along x while that pose turns away is a body-frame twist. Gentle curves (a highway:
        # 37 m off, otherwise blamed on the wheel scale and an IMU mounting) never make the turn-rate rule
        # below fire
        return Verdict(odom.name, "twist", "problem",
                       f"twist configured in the world frame, but in {100 * t.along_x / t.turned:.0f}% of the "
                       f"{t.turned} moving messages whose own pose is turned beyond {TURNED_RAD:g} rad from the odom "
                       "frame's x it points along x, not where that pose heads: it is a body-frame twist, and the "
                       "trajectory runs off sideways", key, 'twist_frame = "body"',
                       evidence={"twist_along_x_share": t.along_x / t.turned})
    if odom.twist_frame == "world" and lateral < 0.05 and t.abs_wz / t.n > 0.05:
        return Verdict(odom.name, "twist", "problem",
                       "twist configured in the world frame, but its lateral velocity stays near zero while "
                       "the robot turns: it is a body-frame twist, and the trajectory heading will run away",
                       key, 'twist_frame = "body"')
    if odom.twist_frame == "body" and lateral > 0.35:
        return Verdict(odom.name, "twist", "warn",
                       f"lateral velocity is {100 * lateral:.0f}% of the motion: a wheeled robot's body twist "
                       "has little; if the driver reports the twist in the odom frame, say so", key,
                       'twist_frame = "world"')
    return None
