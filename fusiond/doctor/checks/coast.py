"""How a vehicle really slowed while its drive read zero: the accelerometer over the coasts.

Where the wheels read exactly zero while the gyro turns, the vehicle moved with its drive silent
(``core/sensors/odom/model.py`` rolls the position on from the last speed, slowing at ``coast_decel``, a
coast-down constant). The accelerometer measured what the vehicle did: on base x its specific force
minus gravity is dv/dt (the centripetal part of a turn is on y). Its own bias b_x (and gravity leaking
through a tilt the IMU's attitude did not remove) is the constant the mounting fit finds over the
normal driving, where the wheels give dv/dt (``mounting.mount_yaw_fit``): a coast's deceleration is
then -(mean(m_x) - b_x) over the bins in those stretches where the gyro still turns (the vehicle still
moving), signed by the way it went when its drive went quiet (the core's coast keeps that direction: a
car reversing slows with m_x > 0). Its standard error is the bins' scatter over the number of SMOOTH_BINS-long pieces (vibration
is correlated over a bin or two, manoeuvres over seconds).

A deceleration clearly off the configured one (beyond DECEL_TOLERANCE and COAST_Z_SIGMAS standard errors) is
named with the value to paste; what it cost is the difference x T^2 / 2 over a coast of T seconds.
A vehicle that held its speed (the drive's zero a dropout under power) gets the smallest value that
keeps the coast on (MIN_COAST_DECEL: 0 would stop the position where the drive went quiet).
"""

from __future__ import annotations

import math

import numpy as np

from ...core.sensors.registry import kind_of
from ...core.sensors.imu.gyro_bias import quiet_bound
from ..gyro import quiet_episodes
from ..median import median
from ..mounting import SMOOTH_BINS
from ..series import BIN_S, Series
from ..check import BaseCheck
from ..evidence import Evidence
from ..verdict import Verdict, sensor_key


__all__ = ["Coast"]

MIN_COAST_BINS = 2 * SMOOTH_BINS  # 2 s of coasting measured, at least
DECEL_TOLERANCE = 0.15  # m/s^2: a coast-down constant this close to the measured one is right enough
MIN_COAST_DECEL = 0.05  # m/s^2: the smallest advised (a 3 m/s coast then runs a minute); 0 turns the coast off
COAST_Z_SIGMAS = 3.0  # a coast-down is named beyond 3 standard errors (0.27 % two-sided for a normal error)
LEVEL_SHARE = 0.5  # an accelerometer bin counts when gravity was removed with the IMU's attitude in most of it


class Coast(BaseCheck):
    """How the vehicle slowed while its drive read zero, against the configured coast-down."""

    name = "coast"

    def run(self, ev: Evidence) -> list[Verdict]:
        """The verdict on ``coast_decel`` from the coasts (``turning``: the wheels at rest while the gyro turns;
        ``standstills``: their gyro scatter is the gyro's real noise, where there are any)."""
        if ev.run_imu is None:
            return []
        standstills, turning = quiet_episodes(ev.series, ev.config, ev.run_imu)
        series, cfg, mount = ev.series, ev.config, ev.mount
        odom = next((s for s in cfg.sensors if kind_of(s).drives_prediction), None)
        imu = next((s for s in cfg.sensors if kind_of(s).inertial), None)
        if odom is None or imu is None or not turning or mount is None or not mount.turned or mount.named:
            return []  # no coast, or an accelerometer whose axes or size are not yet right (the mounting verdict)
        if len(series.acc_t) < MIN_COAST_BINS or len(series.gyro_t) < 2:
            return []
        ta, ax, level = np.asarray(series.acc_t), np.asarray(series.acc_x), np.asarray(series.acc_level)
        # still moving: the gyro beyond the quiet bound of its noise, measured at rest where it can be (drivers
        # overstate it tenfold, which would hide a 0.3 rad/s turn), else as stated
        at_rest = [e.gyro_sigma for e in standstills if math.isfinite(e.gyro_sigma)]
        sigma = float(median(at_rest)) if at_rest else series.gyro_stated_sigma
        sigma = sigma if math.isfinite(sigma) else 0.0
        moving = np.abs(np.interp(ta, np.asarray(series.gyro_t), np.asarray(series.gyro_z))) > quiet_bound(
            sigma, cfg.filter.gyro_bias_sigma)
        along = np.zeros(len(ta))  # +1 / -1: the way the vehicle went into the stretch (0: outside one)
        # a bin clear of the stretch's ends (e.t0, e.t1: the middles of its first and last wheel bins)
        for e in turning:
            along[(ta >= e.t0 + BIN_S) & (ta <= e.t1 - BIN_S)] = _travel_sign(series, e.t0)
        use = (along != 0.0) & moving & (level >= LEVEL_SHARE) & np.isfinite(ax)
        n = int(use.sum())
        if n < MIN_COAST_BINS:
            return []
        a = (ax[use] - mount.bias_x) * along[use]  # along the way it went
        decel = -float(np.mean(a))
        se = float(np.std(a, ddof=1)) / math.sqrt(n / SMOOTH_BINS)
        coast_s = n * BIN_S
        longest = max(min(e.t1, float(ta[use][-1])) - e.t0 for e in turning)
        configured = odom.coast_decel
        evidence = {"coast_decel_measured": decel, "coast_decel_se": se, "coast_s": coast_s,
                    "accel_bias_x": mount.bias_x}
        where = (f"while the drive read zero and the gyro turned ({len(turning)} stretch(es), "
                 f"{coast_s:.1f} s measured), the accelerometer shows the vehicle ")
        if abs(decel - configured) <= max(DECEL_TOLERANCE, COAST_Z_SIGMAS * se):
            return [Verdict(odom.name, "coast", "ok", where + f"slowing at {decel:.2f} m/s^2 (+- {se:.2f}), "
                            f"as coast_decel = {configured:g} assumes", evidence=evidence)]
        key = sensor_key(odom.name, "coast_decel")
        if configured <= 0.0:
            cost = "the position waited where the drive went quiet (coast_decel = 0: no coast)"
        else:
            cost = (f"the coasting position ran {'short' if decel < configured else 'long'} by up to "
                    f"{abs(decel - configured) * longest**2 / 2.0:.1f} m over the longest ({longest:.1f} s)")
        if decel < MIN_COAST_DECEL:
            return [Verdict(odom.name, "coast", "warn",
                            where + f"holding its speed ({-decel:+.2f} m/s^2 +- {se:.2f}): "
                            "the drive's zero was a dropout "
                            f"under power, not a coast-down; {cost}. The smallest deceleration keeps the speed longest "
                            "(0 would turn the coast off)", key, f"coast_decel = {MIN_COAST_DECEL:g}", evidence)]
        return [Verdict(odom.name, "coast", "warn",
                        where + f"slowing at {decel:.2f} m/s^2 (+- {se:.2f}), "
                        f"not the {configured:g} assumed; {cost}", key,
                        f"coast_decel = {decel:.2f}", evidence)]


def _travel_sign(series: Series, t0: float) -> float:
    """+1 when the newest moving wheel bin before ``t0`` went forward, -1 backwards, 0 without one."""
    to, vo = series.odom_t, series.odom_v
    for i in range(int(np.searchsorted(np.asarray(to), t0)) - 1, -1, -1):
        if vo[i] != 0.0:
            return math.copysign(1.0, vo[i])
    return 0.0
