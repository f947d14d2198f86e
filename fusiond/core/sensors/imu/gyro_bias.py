"""The gyro's bias, learned at confirmed standstills, per axis and robustly.

Some drives report exactly zero speed while the vehicle still coasts or turns, so
the odometry alone does not confirm a standstill: the gyro must be quiet too (each
axis within QUIET_SIGMAS of its noise plus the prior bias range, judged on the raw
reading so that a wrong bias estimate cannot veto it). Samples are averaged over a
window of ``standstill_s`` and each window makes one scalar update per axis, gated on
its own, so that a wrong x/y bias (learned through roll/pitch) cannot block the z bias that
drives heading. When an axis's windows keep being rejected while agreeing with each
other, the estimate (locked in by an earlier false standstill) is what is wrong: its
variance is re-opened to the prior and the evidence let in, so one bad update cannot
lock out every later one.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import msgspec

from ....estimator import observations as obs
from ....logs import get_logger
from ...diagnostics import DiagnosticsRecord, chi2_ppf

if TYPE_CHECKING:
    from ...state import FilterState
    from ..base import SensorModel
    from .inputs import ImuInput

log = get_logger("fusiond.core")

ZERO_RATE_GATE = 5.0  # sqrt(NIS) gate of a standstill bias update: a hand-turned robot is not at rest
GYRO_COMPONENTS = ("gyro_x", "gyro_y", "gyro_z")
QUIET_SIGMAS = 3.0  # at rest the gyro reads noise + bias: beyond 3 sigma of each (prior bias) it is turning
MIN_WINDOW_SAMPLES = 5  # gyro samples averaged into one standstill update, at least
BIAS_MEAN_FLOOR = 1e-4  # rad/s: the mean of a window is no better than this (quantisation, vibration)
REOPEN_AFTER = 4  # consecutive rejected windows of one axis that agree: the bias estimate is what is wrong
AGREE_SIGMAS = 4.0  # ... "agree": their spread within this many sigma of one window's mean
STATED_REFUTED = 0.01  # size of the test that refutes the stated gyro noise by a window's scatter
LEARNING_PRIOR_RATIO = 10.0  # prior variance this many times the window's: the update learns, it does not test


class BiasLearning(msgspec.Struct, frozen=True, gc=False):
    """The standstill window being averaged (start stamp, samples, sums of rate, of stated variance and
    of squared rate per axis) and, per axis, the means of the recent windows that were rejected."""

    window: tuple[float, int, float, float, float, float, float, float, float, float, float] | None = None
    rejects: tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]] = ((), (), ())


def quiet_bound(gyro_sigma: float, bias_sigma: float) -> float:
    """The largest raw gyro rate that is still "not turning": noise plus the prior bias range, each
    QUIET_SIGMAS wide. Judged on the raw reading, so that a wrong bias estimate cannot veto it. The
    standstill confirmation, the slip check and the doctor's standstill episodes all use it."""
    return QUIET_SIGMAS * (gyro_sigma + bias_sigma)


def _turning(w: tuple, bias_sigma: float, min_sigma: float) -> bool:
    """Does a closed window's mean rate exceed the quiet bound of the gyro's *measured* noise? The
    per-sample check uses the stated noise, which drivers overstate (razor_imu_9dof: 0.02 rad^2/s^2):
    a slow steady turn then passes for rest. Within a window the readings scatter by the true
    noise only, so the sample standard deviation (floored at ``gyro_min_sigma``) bounds it."""
    n = w[1]
    for axis in range(3):
        mean = w[2 + axis] / n
        scatter = math.sqrt(max(w[8 + axis] / n - mean * mean, 0.0) * n / (n - 1))
        if abs(mean) > quiet_bound(max(scatter, min_sigma), bias_sigma):
            return True
    return False


def _measured_variance(w: tuple, axis: int, min_sigma: float) -> float:
    """One gyro reading's variance on ``axis``: the stated one unless the window's own scatter refutes it,
    then the scatter (floored at ``gyro_min_sigma``). A window at rest is where the gyro's noise shows: a
    driver stating 0.14 rad/s for a 0.003 rad/s gyro would make every standstill's update ~50 times too
    weak to teach the bias (one stating too little, too strong). Refuted: (n - 1) s^2 / sigma^2 outside
    the two-sided STATED_REFUTED chi-square interval on n - 1 degrees of freedom (a sample variance of 30
    readings is itself uncertain by a quarter, within which the stated noise stands)."""
    n = w[1]
    mean = w[2 + axis] / n
    measured = max(w[8 + axis] - n * mean * mean, 0.0) / (n - 1)
    stated = w[5 + axis] / n
    if stated > 0.0:
        ratio = (n - 1) * measured / stated
        if chi2_ppf(0.5 * STATED_REFUTED, n - 1) <= ratio <= chi2_ppf(1.0 - 0.5 * STATED_REFUTED, n - 1):
            return stated
    return measured if measured > min_sigma * min_sigma else min_sigma * min_sigma


def learn_bias_at_rest(imu: "SensorModel", s: "FilterState", inp: "ImuInput", stamp: float, emit: bool,
                       late: bool) -> list[DiagnosticsRecord]:
    """One gyro sample at a possible standstill (module doc): extend the window, or close it with
    one gated scalar update per axis. The window lives in the IMU's slice of the state."""
    ctx = imu.ctx
    fc = ctx.filter
    odom = ctx.odom_index
    own = s.own[imu.index]
    learning_state: BiasLearning = own.bias
    resting = (
        s.still_since is not None
        and stamp - s.still_since >= fc.standstill_s
        and s.last[odom] is not None
        and stamp - s.last[odom] <= ctx.timeout(odom, s)
    )
    g, gc = inp.gyro, inp.gyro_cov
    if not resting or any(abs(g[i]) > quiet_bound(math.sqrt(gc[4 * i]), fc.gyro_bias_sigma) for i in range(3)):
        if learning_state.window is not None:  # moving, or turning with the wheels at rest: not a standstill
            s.own[imu.index] = msgspec.structs.replace(own, bias=msgspec.structs.replace(learning_state, window=None))
        return []
    w = learning_state.window
    if w is None:
        w = (stamp, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    w = (w[0], w[1] + 1, w[2] + g[0], w[3] + g[1], w[4] + g[2], w[5] + gc[0], w[6] + gc[4], w[7] + gc[8],
         w[8] + g[0] * g[0], w[9] + g[1] * g[1], w[10] + g[2] * g[2])
    if w[1] < MIN_WINDOW_SAMPLES or stamp - w[0] < fc.standstill_s:
        s.own[imu.index] = msgspec.structs.replace(own, bias=msgspec.structs.replace(learning_state, window=w))
        return []
    n = w[1]
    if _turning(w, fc.gyro_bias_sigma, imu.cfg.gyro_min_sigma):
        # Quiet by the stated noise, but a steady turn by the gyro's own scatter (a driver stating
        # 0.14 rad/s of noise for a 0.004 rad/s gyro, the vehicle coasting round a bend).
        if emit:  # not again at each re-application after a late sample
            log.info("standstill_turning", sensor=imu.name, stamp=stamp, rate=[w[2 + i] / n for i in range(3)])
        s.own[imu.index] = msgspec.structs.replace(own, bias=msgspec.structs.replace(learning_state, window=None))
        return []
    rejects = list(learning_state.rejects)
    layout = ctx.layout
    e0 = layout.error["gyro_bias"].start
    axes = (0, 1, 2) if ctx.tilt_reference and not ctx.two_d else (2,)
    ys, svars, nis, rejected, learning = [], [], 0.0, False, False
    for axis in axes:
        mean = w[2 + axis] / n
        var = max(_measured_variance(w, axis, imu.cfg.gyro_min_sigma) / n, BIAS_MEAN_FLOOR**2)
        # An update whose prior is far wider than the window's noise mostly learns the bias: its
        # NIS tests the prior (gyro_bias_sigma), not the gyro's noise, so it is marked as learning
        # and left out of the consistency tests.
        learning |= float(s.ekf.P[e0 + axis, e0 + axis]) > LEARNING_PRIOR_RATIO * var
        y, H, R = obs.bias_axis(layout, s.ekf.x, axis, mean, var)
        res = s.ekf.update(y, H, R, ZERO_RATE_GATE, ctx.rest_mask)
        if res.rejected:
            recent = (rejects[axis] + (mean,))[-REOPEN_AFTER:]
            if len(recent) == REOPEN_AFTER and max(recent) - min(recent) <= AGREE_SIGMAS * math.sqrt(var):
                if emit:  # not again at each re-application after a late sample
                    log.warning("gyro_bias_reopened", sensor=imu.name, axis=GYRO_COMPONENTS[axis], stamp=stamp,
                                estimate=float(s.ekf.x[layout.nominal["gyro_bias"].start + axis]), at_rest=mean)
                s.ekf.reset_variance(e0 + axis, fc.gyro_bias_sigma**2)
                y, H, R = obs.bias_axis(layout, s.ekf.x, axis, mean, var)
                res = s.ekf.update(y, H, R, ZERO_RATE_GATE, ctx.rest_mask)
                learning = True
                recent = ()
            rejects[axis] = recent
        else:
            rejects[axis] = ()
        ys.append(float(y[0]))
        svars.append(res.innovation_var[0])
        nis += res.nis
        rejected |= res.rejected
    s.own[imu.index] = msgspec.structs.replace(own, bias=BiasLearning(None, tuple(rejects)))
    if not emit:
        return []
    return [imu.record(stamp, [GYRO_COMPONENTS[a] for a in axes], ys, svars, nis, len(axes), rejected, "gyro_bias",
                       late, learning=learning)]


__all__ = ["BiasLearning", "quiet_bound", "learn_bias_at_rest"]
