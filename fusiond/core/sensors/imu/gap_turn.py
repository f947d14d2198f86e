"""The IMU's turn across a logging gap: the heading carried by the IMU's own yaw (``yaw_across_gaps``).

In ``roll_pitch`` mode, on by default. In a logging gap the
filter holds the heading it had (its inputs end at their timeouts) while the vehicle may turn:
a race car turned 147 degrees in a 12 s gap and drove on along the old heading. An IMU that
integrates its own yaw ran on while the log stopped, so the change of its yaw across the gap
is the turn. At the first orientation after the IMU was silent longer than the gap threshold:
- The IMU's turn is its yaw change less its drift: outside gaps the yaw's drift against the
  filter's heading is measured in DRIFT_BLOCK_S blocks and averaged over DRIFT_TAU_S
  (``_learn_drift``; a 6-axis AHRS integrating a 0.02 rad/s bias would otherwise turn a car
  parked through a 25 s gap by 0.5 rad). That heading drifts too while the gyro's bias is not
  learned (no standstill yet): the measured drift is weighed against it (``drift_rate``). Its
  variance: that drift's uncertainty and how far it may move (DRIFT_CHANGE) over the gap, and
  the yaw's noise at both ends.
- A logging gap (the filter's inputs ended in it, ``FilterState.turn_unseen``): the filter's
  own change says nothing, the heading turns by the IMU's.
- Only the IMU silent: the wheels' yaw rate drove the heading meanwhile. Their part of the turn
  (``FilterState.wheel_turn``) is rescaled by how they read the gyro's turns before
  (``_learn_wheel_yaw``: a skid-steer reads short; not beside a GPS or pose heading, whose
  corrections the filter's turn already holds) and weighed against the IMU's by the two
  variances (the wheels': what the heading's variance grew, and the scale fit's misfit). An IMU
  turn beyond WHEELS_GATE sigma of theirs is not fused (an AHRS rebooted in the silence).
  Wheels reading zero when the IMU is back, the gyro turning, saw nothing: the IMU's turn is taken.
- The heading's variance becomes what the two leave (``ErrorStateEKF.turn_heading``).
Nothing turns for a yaw the IMU does not measure (covariance above orientation_max_sigma), one
that has never moved (a driver's constant placeholder quaternion would undo a turn the wheels
saw), one back at 0 after the gap (YAW_RESET_RAD) having read elsewhere before (an IMU restarted
in the gap), or a vehicle that stood still before and after the gap (odometry zero, gyro quiet:
a parked car's IMU change is its drift or a magnetometer's disturbance). Outside gaps the yaw is
not fused, so its drift over the run never reaches the heading (``relative`` would bring it).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Protocol

import msgspec

from ....estimator import rotation as rot
from ....logs import get_logger
from ...inputs import silent_after, smoothed_period
from .gyro_bias import quiet_bound
from .own import ImuOwn

if TYPE_CHECKING:
    from ...state import FilterState
    from ..base import SensorContext

log = get_logger("fusiond.core")


class GapTurnImu(Protocol):
    """What the gap turn reads of the IMU's model (``model.ImuModel``), so that it needs no import of it."""

    cfg: Any
    ctx: "SensorContext"
    index: int
    orientation_period: float  # s between fused orientations (0: every sample)
    gap_s: float  # filter.gap_s
    bias_sigma: float  # filter.gyro_bias_sigma
    bias_z: int  # the z gyro bias's index in the state, -1 without one
    bias_z_error: int  # ... and in its error state (the covariance's rows), -1 without one
    gap_turns: int  # headings turned across gaps so far (counted here)

GAP_YAW_DRIFT = 0.01  # rad/s: how fast an IMU's own yaw may drift through a gap before its drift is measured
DRIFT_BLOCK_S = 5.0  # s: the IMU yaw's drift against the heading is measured as the slope over blocks this long ...
DRIFT_TAU_S = 60.0  # ... averaged with this memory (exponential weights) ...
DRIFT_MIN_BLOCKS = 3  # ... and used once this many blocks agree (until then: none, GAP_YAW_DRIFT its uncertainty)
DRIFT_OUTLIER = 4.0  # a block's slope beyond this many sigma of the mean: a heading correction or a disturbance
DRIFT_REOPEN = 3  # ... unless this many in a row are: then the drift itself changed, start its average again
DRIFT_FLOOR = 1e-4  # rad/s: the block slopes' scatter is taken as at least this (quantised, steady yaws)
WHEEL_YAW_TAU_S = 120.0  # s of memory of the wheels' yaw rate against the gyro's (``_learn_wheel_yaw``)
WHEEL_YAW_MIN_SAMPLES = 20.0  # turning samples (weighted) before the wheels' yaw-rate scale is used
WHEELS_GATE = 5.0  # sigma: an IMU turn this far from the wheels' over an IMU-only silence is not fused
DRIFT_CHANGE = 1e-3  # rad/s: how far the drift may move from its measured value across a gap (bias instability)
GAP_PERIODS = 5.0  # a silence counts as a gap beyond this many of the IMU's fused-orientation periods (and gap_s)
YAW_MOVED = 1e-6  # rad: a yaw reading that changed by more than this between fused samples is live
YAW_RESET_RAD = 1e-3  # a yaw reading within this of 0 after a gap, having read elsewhere before: the IMU restarted


def carry_yaw(imu: "GapTurnImu", s: "FilterState", yaw: float, var: float, gyro: tuple | None,
              gyro_cov: tuple | None, stamp: float, emit: bool) -> None:
    """Turn the heading across a gap by the IMU's own yaw change, less its drift, weighed against the
    filter's own change (module doc); mark this sample and learn the yaw's drift outside gaps."""
    own: ImuOwn = s.own[imu.index]
    heading = rot.yaw(s.ekf.attitude())
    quiet = gyro is not None and abs(gyro[2]) <= quiet_bound(math.sqrt(gyro_cov[8]), imu.bias_sigma)
    mark, live, period, drift = own.yaw_mark, own.yaw_live, 0.0, own.yaw_drift
    if mark is not None:
        t0, yaw0, period, still0 = mark[0], mark[1], mark[3], mark[5]
        live = live or abs(rot.wrap(yaw - yaw0)) > YAW_MOVED
        silent = stamp - t0
        # the fused orientations' period: as they came (an EMA of the intervals, gaps left out), and at
        # least orientation_rate_hz's (a bucket's burst of samples does not make it short); none yet, no gap
        typical = max(period, imu.orientation_period)
        if typical > 0.0 and silent > silent_after(imu.gap_s, typical, GAP_PERIODS):
            heading = _turn_across_gap(imu, s, yaw, var, heading, stamp, emit, silent, mark, live,
                                       still0 and quiet and s.still_since is not None, drift, own.wheel_yaw)
            drift = _restart_drift(drift, stamp, yaw - heading)  # the gap's own change is no drift
        else:
            if silent > 0.0:
                period = smoothed_period(period, silent)
            drift = _learn_drift(drift, stamp, yaw - heading)
    wheel = own.wheel_yaw
    if not quiet and gyro is not None and _wheels_turning(imu, s, stamp):
        bias = float(s.ekf.x[imu.bias_z]) if imu.bias_z >= 0 else 0.0
        wheel = _learn_wheel_yaw(wheel, stamp, gyro[2] - bias, s.wheel_angular[2])
    still = quiet and s.still_since is not None
    s.own[imu.index] = msgspec.structs.replace(
        own, yaw_mark=(stamp, yaw, heading, period, s.ekf.yaw_variance(), still, s.wheel_turn), yaw_live=live,
        yaw_drift=drift, wheel_yaw=wheel)


def _wheels_turning(imu: "GapTurnImu", s: "FilterState", stamp: float) -> bool:
    """The odometry's yaw rate is a measurement now: measured, fresh, and the wheels not at rest (a drive
    reading zero while the vehicle turns must not teach the wheels' scale as 0)."""
    odom = imu.ctx.odom_index
    last = s.last[odom] if odom >= 0 else None
    return (last is not None and s.wheel_yaw_measured and s.still_since is None
            and stamp - last <= imu.ctx.timeout(odom, s))


def _turn_across_gap(imu: "GapTurnImu", s: "FilterState", yaw: float, var: float, heading: float, stamp: float,
                     emit: bool, silent: float, mark: tuple, live: bool, parked: bool, drift: tuple | None,
                     wheel: tuple | None) -> float:
    """The heading after the gap (module doc), from the filter's ``heading`` now: turned by the gain-weighted
    difference of the IMU's drift-corrected turn and the filter's, or left as it is (and why, logged)."""
    t0, yaw0, heading0, _, var0, _, wheel0 = mark
    if not live:
        return heading  # a yaw that never moved (a placeholder): nothing to say, nothing turned
    why = None
    if abs(yaw) < YAW_RESET_RAD < 10.0 * YAW_RESET_RAD < abs(yaw0):
        why = "the IMU's yaw reads 0 after the gap: restarted, not turned"
    elif parked:
        why = "stood still before and after the gap (odometry zero, gyro quiet): the IMU's change is its drift or a disturbance"
    if why is not None:
        if emit:
            log.warning("heading_not_turned_across_gap", sensor=imu.cfg.name, stamp=stamp, gap_s=silent,
                        reason=why)
        return heading
    rate, rate_var = drift_rate(drift, heading_drift_var(imu, s))
    imu_turn = rot.wrap(yaw - yaw0)
    filter_turn = rot.wrap(heading - heading0)
    corrected = imu_turn - rate * silent
    # what is not known of the IMU's turn: its drift over the gap (the estimate's error and how much
    # the drift may change) and the yaw's noise at both ends; of the filter's: what its variance grew
    turn_var = (rate_var + DRIFT_CHANGE**2) * silent**2 + 2.0 * var
    if (s.turn_unseen is not None and s.turn_unseen > t0) or s.still_since is not None or not s.wheel_yaw_measured:
        # a logging gap: the filter's inputs ended with it, so its own change says nothing of the turn; or
        # the wheels read zero while the gyro or the yaw says the vehicle turned (not parked, above): a
        # drive at rest can lie (coasting, turned by hand), its zero is no measurement of the turn; or the
        # wheels do not measure yaw rate at all (twist_measured): nothing turned the heading through the silence
        gain, wheels_turn, yaw_var = 1.0, filter_turn, var0 + turn_var
    else:
        # the wheels' yaw rate drove the heading through the IMU's silence: their turn, rescaled by how
        # they read the gyro's turns before (a skid-steer's reads short), against the IMU's. Beside a
        # heading reference (GPS, pose) the filter's turn holds its corrections too: not rescaled then.
        wheels_turn, wheels_var = filter_turn, max(s.ekf.yaw_variance() - var0, 0.0)
        if not s.heading_ready:
            scale, relative_var = wheel_yaw_scale(wheel)
            by_wheels = s.wheel_turn - wheel0  # the part the wheels turned (a held gyro rate turned the rest)
            wheels_turn += by_wheels * (1.0 / scale - 1.0)
            wheels_var += (by_wheels / scale) ** 2 * relative_var
        innovation = rot.wrap(corrected - wheels_turn)
        if innovation * innovation > WHEELS_GATE**2 * (wheels_var + turn_var):
            # far beyond both turns' uncertainty: the IMU's yaw is no longer the one before the silence
            # (an AHRS rebooted in it and integrating since, so not back at 0), keep the wheels'
            if emit:
                log.warning("heading_not_turned_across_gap", sensor=imu.cfg.name, stamp=stamp, gap_s=silent,
                            reason="the IMU's turn disagrees with the wheels' beyond both their uncertainties",
                            imu_turn_rad=corrected, wheels_turn_rad=wheels_turn)
            return heading
        gain = wheels_var / (wheels_var + turn_var) if wheels_var + turn_var > 0.0 else 0.0
        yaw_var = var0 + wheels_var * (1.0 - gain)
    turn = rot.wrap(wheels_turn + gain * rot.wrap(corrected - wheels_turn) - filter_turn)
    s.ekf.turn_heading(turn, yaw_var)
    if emit:
        imu.gap_turns += 1
        log.info("heading_turned_across_gap", sensor=imu.cfg.name, stamp=stamp, gap_s=silent, turn_rad=turn,
                 imu_turn_rad=imu_turn, drift_rad=rate * silent, filter_turn_rad=filter_turn,
                 wheels_turn_rad=wheels_turn, gain=gain)
    return rot.wrap(heading + turn)


def _learn_drift(drift: tuple | None, t: float, diff: float) -> tuple:
    """One more fused sample of (IMU yaw - heading) at t outside a gap: the drift's blocks and average.

    The IMU's yaw drifts against the filter's heading (a 6-axis AHRS integrating its own gyro bias, a
    magnetometer's slow disturbance); a gap's turn must not include what that drift adds over the gap.
    Each DRIFT_BLOCK_S block of the unwrapped difference gives a slope; the slopes are averaged with
    DRIFT_TAU_S of memory (their exponentially weighted mean and variance). A slope far from the
    average (the heading corrected by a GPS, a magnetometer's disturbance) is left out, unless
    DRIFT_REOPEN in a row are: then the drift changed and its average starts again.
    State: (block start, difference there, last difference, blocks, mean, variance, outliers in a row).
    """
    if drift is None:
        return (t, diff, diff, 0, 0.0, 0.0, 0)
    t_block, r_block, r_last, n, mean, m2, outliers = drift
    r = r_last + rot.wrap(diff - r_last)  # unwrapped
    span = t - t_block
    if span < DRIFT_BLOCK_S:
        return (t_block, r_block, r, n, mean, m2, outliers)
    slope = (r - r_block) / span
    if n >= DRIFT_MIN_BLOCKS and abs(slope - mean) > DRIFT_OUTLIER * math.sqrt(max(m2, DRIFT_FLOOR**2)):
        if outliers + 1 < DRIFT_REOPEN:
            return (t, r, r, n, mean, m2, outliers + 1)
        n = 0  # the drift itself changed: start the average again from this block
    if n == 0:
        return (t, r, r, 1, slope, 0.0, 0)
    w = -math.expm1(-span / DRIFT_TAU_S)  # this block's weight
    delta = slope - mean
    return (t, r, r, n + 1, mean + w * delta, (1.0 - w) * (m2 + w * delta * delta), 0)


def _restart_drift(drift: tuple | None, t: float, diff: float) -> tuple:
    """After a gap: the drift's average stays, its next block starts here (the gap's turn is no drift)."""
    if drift is None:
        return (t, diff, diff, 0, 0.0, 0.0, 0)
    return (t, diff, diff, *drift[3:])


def heading_drift_var(imu: "GapTurnImu", s: "FilterState") -> float:
    """The variance (rad^2/s^2) of how fast the filter's heading drifts: its z gyro bias's error, from the
    state's covariance (0 without a bias state)."""
    if imu.bias_z_error < 0:
        return 0.0
    return float(s.ekf.P[imu.bias_z_error, imu.bias_z_error])


def drift_rate(drift: tuple | None, heading_var: float = 0.0) -> tuple[float, float]:
    """(rate rad/s, its variance) of the IMU yaw's drift, measured against the filter's heading.

    The blocks' average has their scatter over the effective number of blocks averaged as its variance,
    and the heading's own drift (``heading_var``: its gyro bias's error) besides: one error common to every
    block, which averaging does not shrink. A gyro bias not learned yet (no standstill) drifts the heading
    as much as the IMU's yaw may drift. So the measured drift is weighed against GAP_YAW_DRIFT, the prior on
    any IMU's drift (zero mean), as a Gaussian posterior: a drift measured against a heading as unsure as
    the drift itself is taken at half its value. Before DRIFT_MIN_BLOCKS blocks, none measured: 0 with
    GAP_YAW_DRIFT as its standard deviation."""
    prior = GAP_YAW_DRIFT**2
    if drift is None or drift[3] < DRIFT_MIN_BLOCKS:
        return 0.0, prior
    n, mean, m2 = drift[3], drift[4], drift[5]
    effective = min(float(n), 2.0 * DRIFT_TAU_S / DRIFT_BLOCK_S)  # (1 + a) / (1 - a) of the weights, about
    measured = max(m2, DRIFT_FLOOR**2) / effective + heading_var
    gain = prior / (prior + measured)
    return gain * mean, gain * measured


def _learn_wheel_yaw(sums: tuple | None, t: float, gyro_z: float, wheel_z: float) -> tuple:
    """One more pair of (bias-corrected gyro, wheel) yaw rates while both measure a turn: exponentially
    weighted sums (WHEEL_YAW_TAU_S) of g^2, g w, w^2 and the weight, for ``wheel_yaw_scale``.

    A skid-steer's wheels read the yaw rate short (slip), a car's by its steering geometry; when only the
    IMU goes silent the wheels drive the heading, and the turn they give is off by that scale."""
    if sums is None:
        return (t, 1.0, gyro_z * gyro_z, gyro_z * wheel_z, wheel_z * wheel_z)
    a = math.exp(-(t - sums[0]) / WHEEL_YAW_TAU_S)
    return (t, a * sums[1] + 1.0, a * sums[2] + gyro_z * gyro_z, a * sums[3] + gyro_z * wheel_z,
            a * sums[4] + wheel_z * wheel_z)


def wheel_yaw_scale(sums: tuple | None) -> tuple[float, float]:
    """(k, the relative variance of a turn the wheels read, rescaled by 1/k): the wheels' yaw rate as k x the
    gyro's, least squares through the origin. The relative variance is the fit's misfit against what it
    explains (a skid-steer slips more on the spot than on an arc: one k fits neither exactly) plus k's
    own; the misfit does not average down over a turn, the noise in it would. (1, 0) before
    WHEEL_YAW_MIN_SAMPLES turning samples (weighted), or for a fit that is not a scale (k below 0.2 or
    above 5: wheels that do not see the turn)."""
    if sums is None:
        return 1.0, 0.0
    _, n, gg, gw, ww = sums
    if n < WHEEL_YAW_MIN_SAMPLES or gg <= 0.0:
        return 1.0, 0.0
    k = gw / gg
    if not 0.2 <= k <= 5.0:
        return 1.0, 0.0
    misfit = max(ww - 2.0 * k * gw + k * k * gg, 0.0)
    k_var = misfit / max(n - 1.0, 1.0) / gg
    return k, misfit / (k * k * gg) + k_var / (k * k)


__all__ = ["carry_yaw", "drift_rate", "heading_drift_var", "wheel_yaw_scale"]
