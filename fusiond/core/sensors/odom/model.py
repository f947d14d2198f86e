"""Wheel odometry: the twist is the motion input (held until the next message), not an update.

Once the gyro drives heading the wheels' yaw rate is not fused; it only checks
the gyro (channel ``yaw_rate``), so that skid-steer slip and hand-turning show.
It also tells the IMU when the robot stands still (for the gyro bias), through
``still_since`` in the state.

Some drives read exactly zero while the vehicle still moves: a speed controller whose
reading stops when its drive is off, while the car coasts on through a turn. A real stop
does not look like that: from a speed v to exactly zero between two messages dt apart is a
deceleration v / dt, and beyond ``STOP_DECEL_LIMIT`` (1.5 g: more than tyres can grip) no
wheel stopped that fast. Such a drop starts a coast: the vehicle rolls on, slowing as a
coasting vehicle does, taken as ``coast_decel`` (0.5 m/s^2 by default: the coast-down of a
car or a small robot, rolling resistance and drag, is 0.3-0.6 m/s^2):
the speed v0 (x 1 - coast_decel t / |v0|, same direction) until it reaches zero at
t = |v0| / coast_decel, having covered |v0|^2 / (2 coast_decel). Its variance grows as
(coast_decel t)^2: anything from no slowing to twice the assumed. The coast ends at once
when the drive reads motion again. Not a coast: a skid-steer turning on the spot (its
wheels read the turn), a stop over several messages. The gyro cannot decide it: the coast
may start on a straight, where a coasting and a stopped vehicle's gyros both read zero.
What a wrong coast costs is bounded by |v0|^2 / (2 coast_decel): a wheel-speed sensor that
cuts off at 2 m/s while the car brakes at 2 m/s^2 runs on 4 m instead of 1; a driver that
reports its commanded speed and drops it to zero at once, 0.25 m from 0.5 m/s.
``coast_decel = 0`` turns it off; a larger value shortens the coast.
"""

from __future__ import annotations

import math
from operator import itemgetter
from typing import TYPE_CHECKING

import msgspec

from .... import reasons
from ....estimator import mat3
from ....estimator import rotation as rot
from ....logs import get_logger
from ...diagnostics import DiagnosticsRecord
from ..base import SensorContext, SensorModel
from ..checks import MAX_RATE, MAX_SPEED, Rejected, finite, plausible
from ..imu.gyro_bias import quiet_bound
from . import lost_channel
from .pose_twist import PoseDifferences
from .rest import rest_window, running_noise
from .sample import OdomSample
from .table import OdomSensor

if TYPE_CHECKING:
    from ....estimator import Backend
    from ..state import FilterState

ACCEL_WINDOW_S = 0.5  # s of forward speeds whose slope is the forward acceleration
ACCEL_FIT_SIGMAS = 3.0  # the speeds fit a line (a steady acceleration) within this many noise sigmas ...
ACCEL_FIT_FLOOR = 0.02  # ... or within this many m/s (encoders quantise; drivers understate the noise)
STOP_DECEL_LIMIT = 15.0  # m/s^2 (1.5 g): a drop to exactly zero faster than this is the drive, not a stop


def impossible_stop(speed: float, interval: float, period: float) -> bool:
    """Is a drop from ``speed`` to exactly zero over ``interval`` faster than a vehicle can stop? The
    interval is taken as at least the sensor's typical ``period`` (stamps can bunch)."""
    return speed > STOP_DECEL_LIMIT * max(interval, period)


class OdomOwn(msgspec.Struct, frozen=True, gc=False):
    """The odometry's own slice of the state: what its next message is judged against."""

    window: tuple = ()  # (stamp, forward speed) of the last ACCEL_WINDOW_S (``forward_accel``), when tracked
    previous: tuple[float, float, float] | None = None  # the previous message's linear twist ...
    previous_cov: tuple = (0.0,) * 9  # ... its covariance (row-major 3x3; [0]: ``forward_accel``'s noise) ...
    previous_stamp: float = 0.0  # ... its stamp ...
    previous_moving: bool = False  # ... and whether it read motion (not stationary)
    coast: tuple | None = None  # (since, linear twist and covariance when the drive went quiet) while coasting
    rest: tuple = ()  # the standstill test's window (``rest.rest_window``)
    noise: tuple | None = None  # the twist's noise measured from the stream (``rest.running_noise``)
    watched: tuple | None = None  # angular components that may not be measurements (``lost_channel``)


_NO_OWN = OdomOwn()

log = get_logger("fusiond.core")


class OdomInput(msgspec.Struct, gc=False):
    """Body (or world) twist with per-sample covariances (row-major 9-tuples), ready for the motion model
    (a Struct, as ``ImuInput``)."""

    linear: tuple[float, float, float]
    linear_cov: tuple[float, ...]
    angular: tuple[float, float, float]
    angular_cov: tuple[float, ...]
    yaw_rate_measured: bool
    stationary: bool
    world: bool = False  # ``linear`` is in the world frame (twist_frame = "world" and the message gave no pose)
    measured: tuple[bool, ...] = (True,) * 6  # which of vx vy vz wx wy wz the message measures


_ALL_MEASURED = (True,) * 6


def body_twist(s: OdomSample) -> tuple[tuple, tuple, mat3.Mat3] | None:
    """A world-frame twist (``twist_frame = "world"``: the driver's odometry frame) in the body frame,
    turned by the message's own pose orientation, R^T v (and R^T w), with R^T; None when the message
    carries no usable orientation (identity: not filled in; zero or not unit).

    The twist is in the driver's odometry frame, whose orientation of the body the same message states:
    turned back with it, the twist is the body's, whatever the driver's heading has drifted to. Integrated
    in fusiond's world frame as it stands, it would follow the driver's (skid-corrupted) heading instead: on
    a skid-steer, 26 m RMS and a 108 deg heading error, against 1.7 m for the body twist."""
    q = s.orientation
    if len(q) != 4 or q == (0.0, 0.0, 0.0, 1.0) or not finite(q):
        return None
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    if abs(n - 1.0) > 1e-3:
        return None
    R = rot.matrix9((q[0] / n, q[1] / n, q[2] / n, q[3] / n))
    R_t = (R[0], R[3], R[6], R[1], R[4], R[7], R[2], R[5], R[8])
    return mat3.apply(R_t, s.linear), mat3.apply(R_t, s.angular), R_t


STATIONARY_LINEAR = 1e-3  # m/s: a twist within these of zero is the drive reading "stopped"
STATIONARY_ANGULAR = 1e-3  # rad/s


def stationary(linear: tuple, angular: tuple) -> bool:
    """Does the drive read itself stopped (every component within STATIONARY_* of zero)?"""
    lin, ang = STATIONARY_LINEAR, STATIONARY_ANGULAR
    return (-lin <= linear[0] <= lin and -lin <= linear[1] <= lin and -lin <= linear[2] <= lin
            and -ang <= angular[0] <= ang and -ang <= angular[1] <= ang and -ang <= angular[2] <= ang)


class OdomPolicy:
    def __init__(self, cfg: OdomSensor) -> None:
        self.cfg = cfg
        lin_min, ang_min = cfg.twist_min_sigma
        lin_max, ang_max = cfg.twist_max_sigma
        lin_def, ang_def = cfg.twist_unmeasured_sigma
        self._floor = [lin_min**2] * 3 + [ang_min**2] * 3
        self._unmeasured = [lin_max**2] * 3 + [ang_max**2] * 3
        self._default = [lin_def**2] * 3 + [ang_def**2] * 3
        self._override = None if cfg.twist_noise is None else [s * s for s in cfg.twist_noise]
        # twist_measured: a component the driver does not measure takes the "not measured" path
        # whatever its covariance says (a lost yaw rate reads 0 with covariance 0)
        self._declared = tuple(cfg.twist_measured)
        self._all_measured = all(self._declared)
        self._seen: tuple | None = None  # the last twist covariance and its ``_twist_noise``
        self._resolved: tuple = ((), (), (), None)
        self._world = cfg.twist_frame == "world" and not cfg.twist_from_pose
        self.differences: PoseDifferences | None = None  # twist_from_pose (set by the model: it knows gap_s)

    def _twist_noise(self, cov) -> tuple[mat3.Mat3, mat3.Mat3, tuple[bool, ...], itemgetter]:
        """(linear, angular covariance, measured per component vx vy vz wx wy wz, its picker) of a covariance not seen
        just before: the user's noise for the components declared measured, else the driver's
        (floored; huge, non-finite or undeclared: "not measured", default noise, value unused)."""
        if self._override is not None and self._all_measured:
            var, measured = list(self._override), [True] * 6
        else:
            var, measured = [], []
            for i in range(6):
                if self._override is not None:  # the user's noise, for the components declared measured
                    measured.append(self._declared[i])
                    var.append(self._override[i] if self._declared[i] else self._default[i])
                    continue
                d = cov[7 * i]
                if d < 0.0:
                    raise Rejected(reasons.NEGATIVE_COVARIANCE, "twist")
                if not self._declared[i] or d >= self._unmeasured[i] or d != d or d == math.inf:
                    var.append(self._default[i])  # "not measured": not used, default noise
                    measured.append(False)
                else:
                    var.append(d if d > self._floor[i] else self._floor[i])
                    measured.append(True)
        # the covariances as the motion model takes them, the same tuples while the covariance
        # repeats (the prediction recognises a tuple it has seen and reuses its factorisation)
        # and the twist's components as the prediction takes them: the unmeasured ones 0.0 (index 6 of the
        # twist with a 0.0 appended)
        resolved = (mat3.diag(var[0], var[1], var[2]), mat3.diag(var[3], var[4], var[5]),
                    _ALL_MEASURED if all(measured) else tuple(measured),
                    itemgetter(*(i if m else 6 for i, m in enumerate(measured))))
        if type(cov) is tuple:  # the same covariance in every message: resolved once (kept only if immutable)
            self._seen, self._resolved = cov, resolved
        return resolved

    def convert(self, s: OdomSample) -> OdomInput:
        if self.differences is not None:  # the twist from the pose and the previous message's
            s = self.differences(s)
        if not (plausible(s.linear, MAX_SPEED) and plausible(s.angular, MAX_RATE)):  # NaN and inf fail it too
            if not (finite(s.linear) and finite(s.angular)):
                raise Rejected(reasons.NON_FINITE, "twist")
            raise Rejected(reasons.IMPLAUSIBLE_VALUE, "twist beyond 100 m/s or 100 rad/s")
        cov = s.twist_covariance
        if len(cov) != 36:
            raise Rejected(reasons.BAD_COVARIANCE, "twist covariance must have 36 entries")
        linear_cov, angular_cov, measured, pick = self._resolved if cov == self._seen else self._twist_noise(cov)
        linear, angular, world = s.linear, s.angular, False
        if self._world:
            body = body_twist(s)
            if body is None:
                world = True  # no pose to turn it with: integrated in the world frame as it is
            else:
                linear, angular, R_t = body
                linear_cov = mat3.flat(mat3.sandwich(R_t, linear_cov))
                angular_cov = mat3.flat(mat3.sandwich(R_t, angular_cov))
        v0, v1, v2, w0, w1, w2 = pick((*linear, *angular, 0.0))
        linear, angular = (v0, v1, v2), (w0, w1, w2)
        return OdomInput(linear, linear_cov, angular, angular_cov, measured[5], stationary(linear, angular), world,
                         measured)


class OdomModel(SensorModel):
    config_type = OdomSensor
    sample_type = OdomSample
    policy_type = OdomPolicy

    def __init__(self, cfg: OdomSensor, index: int, ctx: SensorContext) -> None:
        super().__init__(cfg, index, ctx)
        layout = ctx.layout
        # the gyro's z rate as the filter corrects it (bias, scale): what the wheels' yaw rate checks
        self._bias_z_error = layout.index("gyro_bias", 2, error=True)
        self._gyro_scale = layout.index("gyro_scale")
        self._coast_decel = cfg.coast_decel
        self._bias = tuple(layout.index("gyro_bias", i) for i in range(3))  # -1: no bias state
        self._bias_z = self._bias[2]
        self._unmeasured_var = cfg.twist_unmeasured_sigma[1] ** 2
        self._last_fit: tuple = ((), math.nan, 0.0)  # (window, linear variance, its forward_accel)
        self._lost_kept: tuple | None = None  # the last ``_lost_noise``: (its three arguments, its answer)
        self._bounds_kept: tuple = (None, None)  # the last gyro covariance ``_watch`` read, and its quiet bounds
        if cfg.twist_from_pose:  # an interval longer than the filter's gap_s is a logging gap, no twist
            self.policy.differences = PoseDifferences(ctx.filter.gap_s)

    def lost_components(self, s: "FilterState") -> tuple[str, ...]:
        own = s.own[self.index] or _NO_OWN
        return tuple(name for name, lost in zip(lost_channel.ANGULAR, lost_channel.lost(own.watched)) if lost)

    def apply(self, s: "FilterState", inp: OdomInput, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        own = s.own[self.index] or _NO_OWN
        watched = own.watched
        if watched is None or watched[2]:  # a component still under watch
            watched = self._watch(s, watched, inp, stamp, emit)
        if watched[3]:  # a component found lost
            inp = self._without_lost(inp, lost_channel.lost(watched))
        coast = self._coast(s, own, inp, stamp)
        if coast is None:
            s.linear, s.linear_cov, s.linear_world = inp.linear, inp.linear_cov, inp.world
        else:
            since, v0, v0_cov = coast
            speed = math.hypot(*v0)
            slowed = self._coast_decel * (stamp - since)  # m/s lost since the drive went quiet
            k = 1.0 - slowed / speed
            s.linear, s.linear_cov = (k * v0[0], k * v0[1], k * v0[2]), mat3.add_diag(v0_cov, slowed * slowed)
            if emit and since == stamp:
                log.info("coast_started", sensor=self.cfg.name, stamp=stamp, speed=speed,
                         coast_s=speed / self._coast_decel)
        # the forward speeds for ``forward_accel``: in a coast, the coasting speed, not the drive's zero
        window = self._speeds(own.window, s.linear[0], stamp) if self.ctx.track_acceleration else ()
        rest, noise, at_rest = self._rest(s, own, inp, stamp)
        s.own[self.index] = OdomOwn(window, inp.linear, inp.linear_cov, stamp, not inp.stationary, coast, rest, noise,
                                    watched)
        s.wheel_angular, s.wheel_angular_cov = inp.angular, inp.angular_cov
        s.wheel_yaw_measured = inp.yaw_rate_measured
        if (at_rest or inp.stationary) and coast is None:
            # a drive reading zero says so itself; a noisy one is at rest since its window's first message
            if s.still_since is None:
                s.still_since = rest[0][0] if at_rest else stamp
        else:
            s.still_since = None
        if not emit or not inp.yaw_rate_measured:
            return []
        gyro = self._gyro_yaw_rate(s, stamp)
        if gyro is None:
            return []
        # The wheels' yaw rate is not fused once the gyro drives heading; it only
        # checks the gyro, so that skid and hand-turning show up as slip.
        gyro_z, var = gyro
        var += inp.angular_cov[8]
        r = inp.angular[2] - gyro_z
        # Flagged: a wheel rate that misses the gyro's by more than slip_threshold, or wheels reading
        # exactly zero while the gyro turns beyond the standstill quiet bound (the vehicle coasting or
        # turned with its drive at rest: not a wheel measurement of the turn at all).
        quiet = quiet_bound(math.sqrt(s.gyro_cov[8]), self.ctx.filter.gyro_bias_sigma)
        slip = abs(r) > self.cfg.slip_threshold or (inp.stationary and abs(gyro_z) > quiet)
        return [self.record(stamp, ["yaw_rate"], [r], [var], r * r / var, 1, slip, "yaw_rate", late)]

    def _watch(self, s: "FilterState", watched: tuple | None, inp: OdomInput, stamp: float, emit: bool) -> tuple:
        """``lost_channel.watch`` with the gyro as the filter corrects it now (None when stale or not fused),
        logging a component the moment it is found lost."""
        gyro = bounds = None
        if s.gyro is not None and stamp - s.gyro_last[1] <= self.ctx.timeout(s.gyro_last[0], s):
            g, cov = s.gyro, s.gyro_cov
            b0 = self._bias[0]
            if b0 >= 0:  # the bias block's three rates: one slice, the same floats as float(x[i]) each
                c0, c1, c2 = s.ekf.x[b0 : b0 + 3].tolist()
                gyro = (g[0] - c0, g[1] - c1, g[2] - c2)
            else:  # no bias state: the rates as read
                gyro = g
            kept = self._bounds_kept  # the IMU's covariance is one tuple while it repeats: its bounds once
            if kept[0] is cov:
                bounds = kept[1]
            else:
                bias_sigma = self.ctx.filter.gyro_bias_sigma
                bounds = tuple(quiet_bound(math.sqrt(cov[4 * i]), bias_sigma) for i in range(3))
                self._bounds_kept = (cov, bounds)  # holds the covariance: its identity stays its own
        before = lost_channel.lost(watched)
        watched = lost_channel.watch(watched, inp.angular, inp.measured, gyro, bounds)
        if emit:
            for i, (was, now) in enumerate(zip(before, lost_channel.lost(watched))):
                if now and not was:
                    log.warning("twist_component_lost", sensor=self.cfg.name, stamp=stamp,
                                component=lost_channel.ANGULAR[i], value=inp.angular[i],
                                advice="declare it in twist_measured")
        return watched

    def _without_lost(self, inp: OdomInput, lost: tuple[bool, bool, bool]) -> OdomInput:
        """The input with the lost angular components taken as not measured: zero, the unmeasured noise."""
        a0, a1, a2 = inp.angular
        angular = (0.0 if lost[0] else a0, 0.0 if lost[1] else a1, 0.0 if lost[2] else a2)
        cov, measured = self._lost_noise(inp.angular_cov, inp.measured, lost)
        return OdomInput(inp.linear, inp.linear_cov, angular, cov, measured[5],
                         stationary(inp.linear, angular), inp.world, measured)

    def _lost_noise(self, angular_cov: tuple, measured: tuple, lost: tuple[bool, bool, bool]) -> tuple[tuple, tuple]:
        """(angular covariance, measured flags) with the lost components not measured. Once a component is
        lost every message asks this of the same tuples (the policy resolves a repeating covariance once), so
        the last answer is kept for them (tuples: the same objects hold the same values)."""
        kept = self._lost_kept
        if kept is not None and kept[0] is angular_cov and kept[1] is measured and kept[2] == lost:
            return kept[3], kept[4]
        cov = list(angular_cov)
        for i, gone in enumerate(lost):
            if gone:
                cov[4 * i] = self._unmeasured_var
        out = (tuple(cov), measured[:3] + tuple(m and not gone for m, gone in zip(measured[3:], lost)))
        if type(angular_cov) is tuple and type(measured) is tuple:
            self._lost_kept = (angular_cov, measured, lost, *out)
        return out

    def _rest(self, s: "FilterState", own: OdomOwn, inp: OdomInput, stamp: float) -> tuple[tuple, tuple, bool]:
        """The standstill test after this message (``rest.py``): its window, the running noise, and whether
        the wheels are at rest, judged on the noise the stream shows, not the stated one."""
        values = (*inp.linear, *inp.angular)
        backend = s.ekf.backend
        noise = running_noise(own.noise, values, stamp, s.period[self.index], backend)
        fc = self.ctx.filter
        window, at_rest = rest_window(own.rest, values, inp.measured, noise[1], stamp, fc.standstill_s,
                                      fc.standstill_alpha, backend)
        return window, noise, at_rest

    @staticmethod
    def _speeds(window: tuple, speed: float, stamp: float) -> tuple:
        """The last ACCEL_WINDOW_S of forward speeds with this one, for ``forward_accel``: only the
        expired ones dropped from the front."""
        k = 0
        while k < len(window) and stamp - window[k][0] >= ACCEL_WINDOW_S:
            k += 1
        return window[k:] + ((stamp, speed),)

    def _coast(self, s: "FilterState", own: OdomOwn, inp: OdomInput, stamp: float) -> tuple | None:
        """The coast (since, the twist and its covariance before the drop) this message is part of, or None
        (module doc): it lasts while the slowing speed is above zero.

        Only a twist of exactly zero in every measured component, the forward speed among them, can be one: a
        drive that measures no yaw rate (a race car's) coasts as one that does (it stopped dead where the F1/10's
        drive read zero at 1.5 m/s); a message that measures no speed says nothing of one."""
        decel = self._coast_decel
        if decel <= 0.0 or not (inp.stationary and inp.measured[0]):
            return None
        coast = own.coast
        if coast is not None:
            return coast if stamp - coast[0] < math.hypot(*coast[1]) / decel else None
        if not own.previous_moving or stamp <= own.previous_stamp:
            return None
        if not impossible_stop(math.hypot(*own.previous), stamp - own.previous_stamp, s.period[self.index]):
            return None  # a stop a vehicle can make
        return (stamp, own.previous, own.previous_cov)

    def _gyro_yaw_rate(self, s: "FilterState", stamp: float) -> tuple[float, float] | None:
        """The newest gyro z rate as the filter corrects it (bias, scale) with its variance (the
        gyro's and the bias estimate's), or None when no gyro is fused or it has gone silent."""
        if s.gyro is None or stamp - s.gyro_last[1] > self.ctx.timeout(s.gyro_last[0], s):
            return None
        x = s.ekf.x
        gyro_z = s.gyro[2]
        var = s.gyro_cov[8]
        if self._bias_z >= 0:  # (item: the same float as float(x[i]), at a third of the cost)
            gyro_z -= x.item(self._bias_z)
            e = self._bias_z_error
            var += s.ekf.P.item(e, e)
        if self._gyro_scale >= 0:
            gyro_z *= x.item(self._gyro_scale)
        return gyro_z, var

    def forward_accel(self, s: "FilterState") -> float:
        """The forward acceleration, for an IMU that takes roll/pitch from gravity: braking or
        accelerating at a reads as a pitch of a/g (0.7 deg at 0.125 m/s^2), which on a car at
        30 m/s climbs metres of z. It is the least-squares slope of the odometry's forward speed
        over the last ACCEL_WINDOW_S (a two-point difference of 0.02 m/s noise at 50 Hz would be
        1.4 m/s^2 of noise; the slope over 25 points of 0.5 s is ~0.03 m/s^2), computed when the
        IMU asks (an IMU with orientation never does).

        A line fits the speeds only while the acceleration is steady: where it changes (a robot
        starting off, the brakes coming on) the slope lags by half the window. There the fit's
        residual exceeds the speed noise, and the acceleration is "unknown" (NaN): the IMU skips
        those samples rather than read the lag as tilt. So is a coast's: its slowing at ``coast_decel``
        is assumed, anything from none to twice that (module doc), and half a m/s^2 is 3 deg of pitch."""
        own = s.own[self.index]
        if own is None or not own.window:
            return 0.0
        if own.coast is not None:
            return math.nan
        window, linear_var = own.window, own.previous_cov[0]
        last_fit = self._last_fit  # the IMU asks at its own rate, the window moves at the odometry's
        if last_fit[0] is window and last_fit[1] == linear_var:
            return last_fit[2]
        accel = _fitted_accel(window, linear_var, s.ekf.backend)
        self._last_fit = (window, linear_var, accel)  # holds the window: its identity stays its own
        return accel


def _fitted_accel(window: tuple, linear_var: float, backend: Backend) -> float:
    """``OdomModel.forward_accel`` of one window of (stamp, forward speed) pairs: the slope of their
    least-squares line (the estimator's ``line_fit``, the same bits in either backend).

    Not memoised across replays: hashing a window of 25-40 (stamp, speed) pairs to find an earlier fit
    costs more instructions than the compiled fit itself."""
    n = len(window)
    if n < 3 or window[-1][0] - window[0][0] < 0.5 * ACCEL_WINDOW_S:
        # too few speeds for a slope: known only when they are all alike (at rest, cruising)
        last = window[-1][1]
        return 0.0 if all(p[1] == last for p in window) else math.nan
    slope, misfit = backend.line_fit(window)
    noise = ACCEL_FIT_SIGMAS * math.sqrt(linear_var)
    if ACCEL_FIT_FLOOR > noise:  # max(noise, ACCEL_FIT_FLOOR) as a comparison (the same float, no builtin call)
        noise = ACCEL_FIT_FLOOR
    return slope if misfit <= noise else math.nan


__all__ = ["OdomInput", "OdomModel", "OdomOwn", "OdomPolicy", "STOP_DECEL_LIMIT", "body_twist", "impossible_stop"]
