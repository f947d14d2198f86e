"""The motion inputs held between messages, and how long each is held.

The odometry twist and the gyro rate drive the prediction from their sensor's message
until the next one. A silent sensor's input is not held forever: only for its
``timeout_s``, or TIMEOUT_PERIODS of its typical period when that is longer (a 5 Hz
drive is not "silent" after 0.3 s), or GAP_HOLD times the longest interval it showed
recently when that is longer still. Past that, the prediction runs with zero twist and no
rotation, and the core splits a prediction step at the moment an input expires.

The longest recent interval is what a stream with recurring short gaps needs: a drive at
83 Hz whose logger pauses 0.4 s every 2 s has a typical period of 12 ms, so three periods
expire its twist halfway through every pause, and the filter stops a car doing 17 m/s
for 0.2 s in each (a tenth of the distance lost). Only intervals up to the filter's
``gap_s`` count: a longer silence is a logging gap, which the gap rules handle (the
covariance inflated for it), and must not keep the last twist held. The maximum is taken
over the current and the previous RECENT_S / 2 of message time (a windowed maximum in two
halves, a comparison a message): a pattern that recurs within that keeps it, a single
hiccup is forgotten after RECENT_S / 2 to RECENT_S.

The odometry's twist, the input that moves the position, is held at least through the filter's ``gap_s``
(``HeldInputs.timeouts``): a silence shorter than that is jitter by the filter's own definition, not a
logging gap, and the first such pause of a stream comes before any recent interval can teach the hold. A
car at 17 m/s whose wheels paused 0.4 s once was stopped for the 0.2 s past its timeout: 3.4 m short, for
good where nothing absolute corrects it. Its sensor's liveness (health, the doctor) keeps ``timeout_s``.
"""

from __future__ import annotations

import math

from ..estimator import MotionInput, StateLayout, corrected_inputs, mat3
from .state import NO_RECENT, FilterState

PERIOD_SMOOTHING = 0.1  # EMA weight of a new inter-message interval
TILT_STALE_S = 5.0  # no roll/pitch information for this long: roll/pitch rates are no longer integrated
TIMEOUT_PERIODS = 3.0  # a sensor is silent after max(timeout_s, this many typical periods)
GAP_HOLD = 1.5  # ... or this many times its longest recent interval: a recurring pause varies in length
RECENT_S = 30.0  # s of message time over which an interval counts as recent (two halves: module doc)
_ZERO3 = (0.0, 0.0, 0.0)


class HeldInputs:
    """Which inputs hold at a time t in a state s, as one reused ``MotionInput``."""

    def __init__(self, sensors: list, odom_index: int, two_d: bool, layout: StateLayout,
                 gap_s: float = 0.0) -> None:
        self.odom_index = odom_index
        self._layout = layout  # its input blocks correct the last inputs (``unheld_motion_var``)
        self.two_d = two_d
        self.tilt_reference = True  # set by the core once the sensor models say whether any gives tilt
        self._timeout_base = [sc.timeout_s for sc in sensors]
        # the odometry's twist holds at least gap_s (module doc), before its stream's periods count (``timeouts``)
        self._odom_base = max(self._timeout_base[odom_index], gap_s) if odom_index >= 0 else 0.0
        odom = sensors[odom_index] if odom_index >= 0 else None
        unmeasured = odom.twist_unmeasured_sigma if odom is not None else [0.1, 0.1]
        # the twist nobody measures: zero, with the "not measured" variances
        self.default_linear_cov = mat3.diag(*[unmeasured[0] ** 2] * 3)
        self.default_angular_cov = mat3.diag(*[unmeasured[1] ** 2] * 3)
        self._u = MotionInput()
        self._u.twist_correlation = odom.twist_correlation_s if odom is not None else 0.0

    def timeout(self, idx: int, s: FilterState | None) -> float:
        """How long sensor idx's input is held after its last message in state s."""
        base = self._timeout_base[idx]
        if s is None:
            return base
        return silent_after(base, s.period[idx], longest=s.longest[idx][0])

    def timeouts(self, s: FilterState) -> tuple[float, float]:
        """(odometry, gyro) input timeouts in state s (0.0 where there is no such input): fixed
        during a prediction, so it reads them once for all its segments. ``timeout`` of each; the
        odometry's at least ``gap_s`` (module doc)."""
        odom = self.odom_index
        odom_timeout = gyro_timeout = 0.0
        if odom >= 0 and s.last[odom] is not None:
            odom_timeout = silent_after(self._odom_base, s.period[odom], longest=s.longest[odom][0])
        if s.gyro is not None:
            idx = s.gyro_last[0]
            gyro_timeout = silent_after(self._timeout_base[idx], s.period[idx], longest=s.longest[idx][0])
        return odom_timeout, gyro_timeout

    def timeouts_and_expiries(self, s: FilterState) -> tuple[tuple[float, float], tuple[float, float]]:
        """``timeouts`` and ``expiries`` of state s in one call (a prediction's)."""
        timeouts = self.timeouts(s)
        odom = self.odom_index
        odom_expiry = s.last[odom] + timeouts[0] if odom >= 0 and s.last[odom] is not None else -math.inf
        gyro_expiry = s.gyro_last[1] + timeouts[1] if s.gyro_last is not None else -math.inf
        return timeouts, (odom_expiry, gyro_expiry)

    def at(self, s: FilterState, t: float | None = None,
           timeouts: tuple[float, float] | None = None) -> MotionInput:
        """Motion inputs held at time t (default s.t). ``timeouts``: ``timeouts(s)`` when the caller has them."""
        u = self._u
        if t is None:
            t = s.t
        odom_timeout, gyro_timeout = self.timeouts(s) if timeouts is None else timeouts
        odom = self.odom_index
        odom_fresh = odom >= 0 and s.last[odom] is not None and t - s.last[odom] <= odom_timeout
        if odom_fresh:
            u.linear, u.linear_cov, u.linear_period = s.linear, s.linear_cov, s.period[odom]
            u.world_frame = s.linear_world
        else:
            u.linear, u.linear_cov, u.linear_period = _ZERO3, self.default_linear_cov, 0.0
            u.world_frame = False
        gyro_fresh = s.gyro is not None and t - s.gyro_last[1] <= gyro_timeout
        if gyro_fresh:
            u.angular, u.angular_cov, u.angular_period = s.gyro, s.gyro_cov, s.period[s.gyro_last[0]]
            u.from_gyro = True
        elif odom_fresh:
            u.angular, u.angular_cov, u.angular_period = s.wheel_angular, s.wheel_angular_cov, s.period[odom]
            u.from_gyro = False
        else:
            u.angular, u.angular_cov, u.angular_period = _ZERO3, self.default_angular_cov, 0.0
            u.from_gyro = False
        if self.two_d:  # vertical twist and roll/pitch rates ignored
            u.linear = (u.linear[0], u.linear[1], 0.0)
        # planar: roll/pitch rates not integrated, in two-D mode, or when nothing corrects (any
        # more) a tilt the rates would build up: no tilt reference configured, or the configured
        # one has given nothing for TILT_STALE_S (an accelerometer publishing gravity-free
        # acceleration, an IMU without orientation)
        u.planar = self.two_d or not self.tilt_reference or (
            s.tilt_seen is not None and t - s.tilt_seen > TILT_STALE_S)
        return u

    def expiries(self, s: FilterState, timeouts: tuple[float, float]) -> tuple[float, float]:
        """(odometry, gyro): when each held input's sensor times out (-inf where there is no such input)."""
        odom = self.odom_index
        odom_expiry = s.last[odom] + timeouts[0] if odom >= 0 and s.last[odom] is not None else -math.inf
        gyro_expiry = s.gyro_last[1] + timeouts[1] if s.gyro_last is not None else -math.inf
        return odom_expiry, gyro_expiry

    def unheld_motion_var(self, s: FilterState, t_end: float, timeouts: tuple[float, float],
                          expiries: tuple[float, float] | None = None) -> tuple[float, float]:
        """Variance the motion the held inputs no longer describe adds from s.t to t_end: (horizontal
        position per axis m^2, yaw rad^2).

        Past its sensor's timeout the prediction holds no input (the robot may have stopped),
        but a vehicle that was moving may as well have kept going: at its last speed v for the
        T seconds not covered by any twist it is anywhere within v T of where the filter put
        it, and with its last turn rate w its heading within w T. Taken as one standard
        deviation each: a car at 30 m/s after a 20 s gap is ~600 m uncertain, so the first GPS
        fix after it is believed instead of gated out, and its jump is not explained as a wheel
        scale. A robot that stood still before the gap gets only the gap inflation.

        The silence is one unknown however many predictions it spans (a logging gap is one step; an
        odometry that pauses while the IMU streams on is many): each step adds what it adds to
        (v T)^2, (v T1)^2 - (v T0)^2 with T0 and T1 the time past the timeout at its start and end, so
        the variance at the end of the silence is (v T)^2 whatever the steps. ``expiries``: ``expiries(s,
        timeouts)`` when the caller has them.
        """
        odom_expiry, gyro_expiry = self.expiries(s, timeouts) if expiries is None else expiries
        if odom_expiry == -math.inf or t_end <= odom_expiry:
            return 0.0, 0.0
        # the last inputs as the prediction used them (bias and scales applied)
        from_gyro = s.gyro is not None
        linear, angular = corrected_inputs(self._layout, s.ekf.x, s.linear, s.gyro if from_gyro else s.wheel_angular,
                                           from_gyro)
        v2 = linear[0] * linear[0] + linear[1] * linear[1]
        pos_var = v2 * ((t_end - odom_expiry) ** 2 - max(s.t - odom_expiry, 0.0) ** 2)
        turn_from = max(odom_expiry, gyro_expiry)
        yaw_var = 0.0
        if t_end > turn_from:
            yaw_var = angular[2] * angular[2] * ((t_end - turn_from) ** 2 - max(s.t - turn_from, 0.0) ** 2)
        return pos_var, yaw_var


def next_expiry(expiries: tuple[float, float], t: float, end: float) -> float:
    """The first of ``expiries`` (``HeldInputs.expiries``) after t and before ``end``, else ``end``: where a
    prediction from t to ``end`` ends its segment."""
    odom_expiry, gyro_expiry = expiries
    if t < odom_expiry < end:
        end = odom_expiry
    if t < gyro_expiry < end:
        end = gyro_expiry
    return end


def silent_after(timeout_s: float, period: float, periods: float = TIMEOUT_PERIODS, longest: float = 0.0) -> float:
    """How long after its last message a sensor is silent: its ``timeout_s``, or ``periods`` of its
    typical period (0: none yet), or GAP_HOLD times its longest recent interval (``recent_longest``'s first),
    whichever is longest. The core's held inputs (message time) and the service's liveness (wall time)
    both use it with TIMEOUT_PERIODS; the IMU's gap rule with its own count and no recent interval
    (core/sensors/imu/gap_turn.py)."""
    if period <= 0.0:
        return timeout_s
    # max(timeout_s, periods * period, GAP_HOLD * longest) as comparisons: the same float (max keeps the first
    # of equals too), without a builtin call (asked at every message)
    held = periods * period
    if held > timeout_s:
        timeout_s = held
    held = GAP_HOLD * longest
    return held if held > timeout_s else timeout_s


def recent_longest(recent: tuple[float, float, float], interval: float, stamp: float,
                   gap_s: float) -> tuple[float, float, float]:
    """``recent`` (``NO_RECENT`` at first: the longest interval under ``gap_s`` over the current and the previous
    half of RECENT_S, the current half's, and when it ends) after one more ``interval``, ended at ``stamp``."""
    longest, current, end = recent
    counts = interval <= gap_s
    if stamp >= end:  # a new half: the one ending carries its maximum into the next
        now = interval if counts else 0.0
        return max(current, now), now, stamp + 0.5 * RECENT_S
    if counts and interval > current:
        return max(longest, interval), interval, end
    return recent


def smoothed_period(period: float, interval: float) -> float:
    """A typical message period (0: none yet) after one more interval between messages: an EMA of the
    intervals, each capped at 1 s so that a gap does not make the sensor's timeout long."""
    d = 1.0 if 1.0 < interval else interval  # min(interval, 1.0), the same float, without a builtin call
    return d if period <= 0.0 else period + PERIOD_SMOOTHING * (d - period)


def note_period(s: FilterState, idx: int, stamp: float, gap_s: float) -> None:
    """Sensor idx's newest stamp, its typical message period (``smoothed_period``) and its longest recent
    interval under ``gap_s`` (``recent_longest``)."""
    last = s.last[idx]
    if last is None:
        s.last[idx] = stamp
    elif stamp > last:
        d = stamp - last
        s.period[idx] = smoothed_period(s.period[idx], d)
        recent = s.longest[idx]
        if stamp >= recent[2] or recent[1] < d <= gap_s:  # else unchanged (nearly every message)
            s.longest[idx] = recent_longest(recent, d, stamp, gap_s)
        s.last[idx] = stamp


__all__ = ["HeldInputs", "next_expiry", "note_period", "recent_longest", "silent_after", "smoothed_period",
           "GAP_HOLD", "NO_RECENT", "RECENT_S", "TIMEOUT_PERIODS",
           "TILT_STALE_S"]
