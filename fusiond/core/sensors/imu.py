"""IMU: orientation observed as roll/pitch(/yaw) per mode; gyro as motion input; roll/pitch from gravity.

The gyro rate is held as the motion input until the next sample (or its timeout); at
a confirmed standstill it also teaches the filter its bias (``gyro_bias.py``). The
orientation is an update of roll/pitch(/yaw) by mode: ``absolute`` yaw is ENU heading
(with an estimated offset beside GPS/pose), ``relative`` yaw is measured against the
yaw the filter had at the IMU's first message, ``roll_pitch`` fuses tilt only. Without
orientation, the accelerometer's gravity gives roll/pitch (``tilt_from_gravity``).

Heading across logging gaps (``yaw_across_gaps``, ``roll_pitch`` mode, on by default). In a logging gap the
filter holds the heading it had (its inputs end at their timeouts) while the vehicle may turn:
a race car turned 147 degrees in a 12 s gap and drove on along the old heading. An IMU that
integrates its own yaw ran on while the log stopped, so the change of its yaw across the gap
is the turn. At the first orientation after the IMU was silent longer than the gap threshold:
- The IMU's turn is its yaw change less its drift: outside gaps the yaw's drift against the
  filter's heading is measured in DRIFT_BLOCK_S blocks and averaged over DRIFT_TAU_S
  (``_learn_drift``; a 6-axis AHRS integrating a 0.02 rad/s bias would otherwise turn a car
  parked through a 25 s gap by 0.5 rad). Its variance: that drift's uncertainty and how far it
  may move (DRIFT_CHANGE) over the gap, and the yaw's noise at both ends.
- A logging gap (the filter's inputs ended in it, ``FilterState.turn_unseen``): the filter's
  own change says nothing, the heading turns by the IMU's.
- Only the IMU silent: the wheels' yaw rate drove the heading meanwhile. Their part of the turn
  (``FilterState.wheel_turn``) is rescaled by how they read the gyro's turns before
  (``_learn_wheel_yaw``: a skid-steer reads short; not beside a GPS or pose heading, whose
  corrections the filter's turn already holds) and weighed against the IMU's by the two
  variances (the wheels': what the heading's variance grew, and the scale fit's misfit). An IMU
  turn beyond WHEELS_GATE sigma of theirs is not fused (an AHRS rebooted in the silence, QA8).
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
from dataclasses import dataclass
from typing import TYPE_CHECKING

import msgspec

from ... import reasons
from ...config import ImuSensor
from ...estimator import mat3
from ...estimator import observations as obs
from ...estimator import rotation as rot
from ...logs import get_logger
from ...samples import ImuSample
from ..diagnostics import DiagnosticsRecord
from ..inputs import smoothed_period
from .base import SensorContext, SensorModel
from .checks import MAX_RATE, Rejected, finite, plausible, resolve_variances, unit_quaternion
from .gyro_bias import BiasLearning, learn_bias_at_rest, quiet_bound

if TYPE_CHECKING:
    from ..state import FilterState

log = get_logger("fusiond.core")

GRAVITY = 9.80665  # m/s^2, standard gravity
_ZERO3 = (0.0, 0.0, 0.0)
G_UNITS_BAND = (0.8, 1.2)  # |specific force| in this band: the accelerometer reports in g
GRAVITY_DYNAMIC_GATE = 0.5  # m/s^2: |specific force| further than this from g is not "low dynamics"
GRAVITY_AVERAGE_S = 0.1  # s of specific force averaged into one gravity roll/pitch update
ADAPTIVE_MIN, ADAPTIVE_MAX = 0.1, 100.0
ORIENTATION_BURST = 3.0  # samples' worth of credit ``orientation_rate_hz`` can save up (``_orientation_due``)
YAW_JUMP_GATE = 5.0  # sigma of the sample-to-sample change of an absolute yaw's residual (``_yaw_jump``)
GAP_YAW_DRIFT = 0.01  # rad/s: how fast an IMU's own yaw may drift through a gap before its drift is measured
DRIFT_BLOCK_S = 5.0  # s: the IMU yaw's drift against the heading is measured as the slope over blocks this long ...
DRIFT_TAU_S = 60.0  # ... averaged with this memory (exponential weights) ...
DRIFT_MIN_BLOCKS = 3  # ... and used once this many blocks agree (before: none, GAP_YAW_DRIFT its uncertainty)
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


class ImuOwn(msgspec.Struct, frozen=True, gc=False):
    """The IMU's slice of the filter state (immutable: history snapshots share it)."""

    yaw_offset: float | None = None  # relative orientation: the yaw read at the first message minus the filter's
    yaw_residual: float | None = None  # absolute yaw: reading - heading - offset after the previous sample ...
    yaw_stamp: float | None = None  # ... and its stamp (the yaw-jump gate)
    adaptive: tuple[float, float, int] = (1.0, 0.0, 0)  # R scale of the orientation, window NIS/dof sum, count
    bias: BiasLearning = BiasLearning()  # the standstill windows of the gyro-bias learning
    gravity: tuple | None = None  # (start stamp, samples, sums of x, y, z) of the specific force being averaged
    orientation_credit: tuple[float, float] | None = None  # (credit, stamp): ``orientation_rate_hz``'s bucket
    # yaw_across_gaps: (stamp, the IMU's yaw, the filter's yaw, the fused orientations' period, the heading's
    # variance, standing still: odometry zero and gyro quiet, the state's wheel_turn)
    # at the last fused orientation, and whether the IMU's yaw has ever moved; its drift (``_learn_drift``)
    yaw_mark: tuple[float, float, float, float, float, bool, float] | None = None
    yaw_live: bool = False
    yaw_drift: tuple[float, float, float, int, float, float, int] | None = None
    wheel_yaw: tuple[float, float, float, float, float] | None = None  # ``_learn_wheel_yaw``'s sums


@dataclass(slots=True)
class ImuInput:
    """Base-frame attitude observation (roll, pitch, yaw rows usable) and gyro rate; 9-tuple covariances.

    The attitude is kept as the base-frame quaternion and turned into roll/pitch/yaw (``rpy``) only
    when the model fuses it: an IMU faster than ``orientation_rate_hz`` has most of its orientations
    thinned, and their angles would be computed for nothing."""

    attitude: tuple[float, float, float, float] | None
    rpy_cov: tuple[float, ...] | None
    rows: tuple[int, ...]
    gyro: tuple[float, float, float] | None
    gyro_cov: tuple[float, ...] | None
    accel: tuple[float, float, float] | None = None  # base-frame specific force, when gravity gives the tilt
    yaw_measured: bool = False  # the message's yaw is measured (its variance below orientation_max_sigma^2)

    @property
    def rpy(self) -> tuple[float, float, float] | None:
        """Fixed-axis roll, pitch, yaw of ``attitude`` (None without one)."""
        return None if self.attitude is None else rot.to_rpy(self.attitude)


class ImuPolicy:
    """sensor_msgs/Imu: orientation rows per ``orientation`` mode, gyro rate, accelerometer, all turned
    from the IMU's axes into base_link by ``extrinsic_rpy`` (covariances too), so the estimator only
    ever sees base_link quantities."""

    def __init__(self, cfg: ImuSensor) -> None:
        self.cfg = cfg
        r, p, y = cfg.extrinsic_rpy
        self.q_ext = rot.from_rpy(r, p, y)
        self.q_ext_inv = rot.conj(self.q_ext)
        self.R_ext = rot.matrix9(self.q_ext)
        self._identity = (r, p, y) == (0.0, 0.0, 0.0)
        self.mode = cfg.orientation
        self._rows = {"absolute": (0, 1, 2), "relative": (0, 1, 2), "roll_pitch": (0, 1), "off": ()}[self.mode]
        self._ori_floor = cfg.orientation_min_sigma**2
        self._ori_unmeasured = cfg.orientation_max_sigma**2
        self._ori_override = None if cfg.orientation_noise is None else [s * s for s in cfg.orientation_noise]
        self._gyro_floor = cfg.gyro_min_sigma**2
        self._gyro_override = None if cfg.gyro_noise is None else cfg.gyro_noise**2
        self._gravity_tilt = cfg.tilt_from_gravity
        # The last covariance tuple of each kind and what it resolved to: a driver sends the same
        # covariance in every message, so its checks, floors and rotation into base_link are done
        # once per distinct value (a tuple compares equal only if finite: NaN != NaN).
        self._ori_seen: tuple | None = None
        self._ori_resolved: tuple[tuple[int, ...], tuple[float, ...], bool] = ((), (), False)
        self._gyro_seen: tuple | None = None
        self._gyro_resolved: tuple[float, ...] = ()
        self._gyro_unknown_said = False  # the gyro_covariance_unknown warning was logged

    @property
    def gives_tilt(self) -> bool:
        """Can this IMU's messages constrain roll/pitch (orientation rows or gravity)?"""
        return 0 in self._rows or 1 in self._rows or self._gravity_tilt

    def planar(self) -> None:
        """Two-D mode: roll and pitch are held at 0, so only a yaw row can be fused."""
        self._rows = tuple(r for r in self._rows if r == 2)
        self._gravity_tilt = False
        self._ori_seen = None  # its rows were resolved for the old mode

    def _rotate_cov(self, diag: list[float]) -> mat3.Mat3:
        C = mat3.diag(diag[0], diag[1], diag[2])
        if self._identity:
            return C
        return mat3.flat(mat3.sandwich(self.R_ext, C))

    def _orientation_noise(self, oc) -> tuple[tuple[int, ...], tuple[float, ...], bool]:
        """(rows to fuse, base-frame covariance, the yaw is measured) of a finite orientation covariance not
        seen just before."""
        if self._ori_override is not None:
            var, measured = list(self._ori_override), [True, True, True]
        else:
            diag = [oc[0], oc[4], oc[8]]
            if any(d < 0.0 for d in diag):
                raise Rejected(reasons.NEGATIVE_COVARIANCE, "orientation")
            var, measured = resolve_variances(diag, self._ori_floor, self._ori_unmeasured, 1.0)
        resolved = (tuple(i for i in self._rows if measured[i]), self._rotate_cov(var), measured[2])
        if type(oc) is tuple:  # kept only if immutable
            self._ori_seen, self._ori_resolved = oc, resolved
        return resolved

    def _gyro_noise(self, gc) -> tuple[float, ...]:
        """Base-frame gyro covariance of a finite angular-velocity covariance not seen just before."""
        if self._gyro_override is not None:
            var = [self._gyro_override] * 3
        else:
            diag = [gc[0], gc[4], gc[8]]
            if any(d < 0.0 for d in diag):
                raise Rejected(reasons.NEGATIVE_COVARIANCE, "angular_velocity")
            var = [max(d, self._gyro_floor) for d in diag]
        cov = self._rotate_cov(var)
        if type(gc) is tuple:
            self._gyro_seen, self._gyro_resolved = gc, cov
        return cov

    def convert(self, s: ImuSample) -> ImuInput:
        q_base = rpy_cov = None
        rows: tuple[int, ...] = ()
        yaw_measured = False
        if self._rows and len(s.orientation_covariance) == 9 and s.orientation_covariance[0] != -1.0:
            oc = s.orientation_covariance
            known = oc == self._ori_seen
            if not (finite(s.orientation) and (known or finite(oc))):
                raise Rejected(reasons.NON_FINITE, "orientation")
            q_imu = unit_quaternion(s.orientation)
            q_base = rot.mul(q_imu, self.q_ext_inv) if not self._identity else q_imu
            rows, rpy_cov, yaw_measured = self._ori_resolved if known else self._orientation_noise(oc)
        elif len(s.orientation_covariance) != 9:
            raise Rejected(reasons.BAD_COVARIANCE, "orientation covariance must have 9 entries")

        if q_base is None and s.angular_velocity == _ZERO3 and s.linear_acceleration == _ZERO3:
            # rates and specific force all exactly zero (at rest an accelerometer reads gravity): a
            # driver's placeholder for a lost sample, not a measurement of zero rate
            raise Rejected(reasons.NOTHING_TO_FUSE, "rates and acceleration all exactly zero: a lost sample")
        gyro = gyro_cov = None
        if self.cfg.angular_velocity and len(s.angular_velocity_covariance) == 9:
            gc = s.angular_velocity_covariance
            # [0] == -1: "no angular velocity" (sensor_msgs/Imu), unless the user states the gyro's noise: some
            # drivers mark the covariance unknown that way while publishing the rates; the override says fuse them
            if gc[0] != -1.0 or self._gyro_override is not None:
                known = gc == self._gyro_seen
                if not (finite(s.angular_velocity) and (known or finite(gc))):
                    raise Rejected(reasons.NON_FINITE, "angular_velocity")
                if not plausible(s.angular_velocity, MAX_RATE):
                    raise Rejected(reasons.IMPLAUSIBLE_VALUE, "angular velocity beyond 100 rad/s")
                gyro_cov = self._gyro_resolved if known else self._gyro_noise(gc)
                w = s.angular_velocity
                gyro = w if self._identity else mat3.apply(self.R_ext, w)
            elif not self._gyro_unknown_said:
                self._gyro_unknown_said = True  # said once: it is the driver's constant, not one message's
                log.warning("gyro_covariance_unknown", sensor=self.cfg.name,
                            hint="angular_velocity_covariance[0] is -1 (no angular velocity): the rates are not "
                                 "fused; if the driver publishes them, state their noise with gyro_noise")
        elif self.cfg.angular_velocity:
            raise Rejected(reasons.BAD_COVARIANCE, "angular velocity covariance must have 9 entries")
        accel = None
        if self._gravity_tilt and not (0 in rows or 1 in rows):
            a = s.linear_acceleration
            ac = s.linear_acceleration_covariance
            # [0] == -1: no accelerometer (sensor_msgs/Imu); an all-zero vector: not filled in
            if len(ac) == 9 and ac[0] != -1.0 and finite(a) and a != (0.0, 0.0, 0.0):
                accel = a if self._identity else mat3.apply(self.R_ext, a)
        if q_base is None and gyro is None and accel is None:
            raise Rejected(reasons.NOTHING_TO_FUSE, "no orientation, angular velocity or acceleration in the message")
        return ImuInput(q_base, rpy_cov, rows, gyro, gyro_cov, accel, yaw_measured)


class ImuModel(SensorModel):
    config_type = ImuSensor
    sample_type = ImuSample
    policy_type = ImuPolicy

    def __init__(self, cfg: ImuSensor, index: int, ctx: SensorContext) -> None:
        super().__init__(cfg, index, ctx)
        self.absolute = cfg.orientation == "absolute"
        self.relative = cfg.orientation == "relative"
        # absolute yaw read as heading + an estimated offset (the core adds the yaw_offset block)
        self.offset = self.absolute and ctx.layout.has("yaw_offset")
        self._offset_index = ctx.layout.nominal["yaw_offset"].start if self.offset else -1
        self.learns_bias = cfg.angular_velocity and ctx.layout.has("gyro_bias")
        self._fixed_yaw = cfg.yaw_offset + cfg.magnetic_declination  # navsat_transform's convention
        self._period = 1.0 / cfg.orientation_rate_hz if cfg.orientation_rate_hz > 0.0 else 0.0
        self.thinned = 0  # orientations not fused for ``orientation_rate_hz`` (the gyro of the sample is)
        self.carries_yaw = cfg.yaw_across_gaps and cfg.orientation == "roll_pitch" and not ctx.two_d
        self._gap_s = ctx.filter.gap_s
        self._bias_sigma = ctx.filter.gyro_bias_sigma
        self._bias_z = ctx.layout.index("gyro_bias", 2)
        self.gap_turns = 0  # headings turned across gaps (``_carry_yaw``)

    @property
    def gives_tilt(self) -> bool:
        return self.policy.gives_tilt

    def planar(self) -> None:
        self.policy.planar()

    def on_start(self, s: "FilterState") -> None:
        s.own[self.index] = ImuOwn()

    def apply(self, s: "FilterState", inp: ImuInput, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        records: list[DiagnosticsRecord] = []
        if inp.gyro is not None:
            s.gyro, s.gyro_cov, s.gyro_last = inp.gyro, inp.gyro_cov, (self.index, stamp)
            if self.learns_bias:
                records.extend(learn_bias_at_rest(self, s, inp, stamp, emit, late))
        if inp.attitude is not None and inp.rows and self._orientation_due(s, stamp, emit):
            rpy, rows = inp.rpy, inp.rows
            if self.absolute and self._fixed_yaw:
                rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] + self._fixed_yaw))
            if not s.attitude_ready:
                initialise_attitude(s, rpy, self.absolute)
            if self.carries_yaw and inp.yaw_measured:
                self._carry_yaw(s, rpy[2], inp.rpy_cov[8], inp.gyro, inp.gyro_cov, stamp, emit)
            if self.relative:
                own: ImuOwn = s.own[self.index]
                off = own.yaw_offset
                if off is None:
                    off = rot.wrap(rpy[2] - rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2])
                    s.own[self.index] = msgspec.structs.replace(own, yaw_offset=off)
                rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] - off))
            if self.offset and 2 in rows:
                jump, allowed = self._yaw_jump(s, rpy[2], inp.rpy_cov[8], stamp)
                if jump * jump > YAW_JUMP_GATE**2 * allowed:
                    rows = tuple(i for i in rows if i != 2)  # this sample's yaw is not fused (counted as rejected)
                    if emit:
                        records.append(self.record(stamp, ["yaw"], [jump], [allowed], jump * jump / allowed, 1, True,
                                                   "yaw_jump", late))
            if rows:
                records += self._fuse_orientation(s, rpy, inp.rpy_cov, rows, stamp, emit, late)
        if inp.accel is not None:
            records.extend(self._tilt_from_gravity(s, inp.accel, stamp, emit, late))
        return records

    def _carry_yaw(self, s: "FilterState", yaw: float, var: float, gyro: tuple | None, gyro_cov: tuple | None,
                   stamp: float, emit: bool) -> None:
        """Turn the heading across a gap by the IMU's own yaw change, less its drift, weighed against the
        filter's own change (module doc); mark this sample and learn the yaw's drift outside gaps."""
        own: ImuOwn = s.own[self.index]
        heading = rot.yaw(tuple(s.ekf.x[3:7].tolist()))
        quiet = gyro is not None and abs(gyro[2]) <= quiet_bound(math.sqrt(gyro_cov[8]), self._bias_sigma)
        mark, live, period, drift = own.yaw_mark, own.yaw_live, 0.0, own.yaw_drift
        if mark is not None:
            t0, yaw0, period, still0 = mark[0], mark[1], mark[3], mark[5]
            live = live or abs(rot.wrap(yaw - yaw0)) > YAW_MOVED
            silent = stamp - t0
            # the fused orientations' period: as they came (an EMA of the intervals, gaps left out), and at
            # least orientation_rate_hz's (a bucket's burst of samples does not make it short); none yet, no gap
            typical = max(period, self._period)
            if typical > 0.0 and silent > max(self._gap_s, GAP_PERIODS * typical):
                heading = self._turn_across_gap(s, yaw, var, heading, stamp, emit, silent, mark, live,
                                                still0 and quiet and s.still_since is not None, drift,
                                                own.wheel_yaw)
                drift = _restart_drift(drift, stamp, yaw - heading)  # the gap's own change is no drift
            else:
                if silent > 0.0:
                    period = smoothed_period(period, silent)
                drift = _learn_drift(drift, stamp, yaw - heading)
        wheel = own.wheel_yaw
        if not quiet and gyro is not None and self._wheels_turning(s, stamp):
            bias = float(s.ekf.x[self._bias_z]) if self._bias_z >= 0 else 0.0
            wheel = _learn_wheel_yaw(wheel, stamp, gyro[2] - bias, s.wheel_angular[2])
        still = quiet and s.still_since is not None
        s.own[self.index] = msgspec.structs.replace(
            own, yaw_mark=(stamp, yaw, heading, period, float(s.ekf.P[5, 5]), still, s.wheel_turn), yaw_live=live,
            yaw_drift=drift, wheel_yaw=wheel)

    def _wheels_turning(self, s: "FilterState", stamp: float) -> bool:
        """The odometry's yaw rate is a measurement now: measured, fresh, and the wheels not at rest (a drive
        reading zero while the vehicle turns must not teach the wheels' scale as 0)."""
        odom = self.ctx.odom_index
        last = s.last[odom] if odom >= 0 else None
        return (last is not None and s.wheel_yaw_measured and s.still_since is None
                and stamp - last <= self.ctx.timeout(odom, s))

    def _turn_across_gap(self, s: "FilterState", yaw: float, var: float, heading: float, stamp: float, emit: bool,
                         silent: float, mark: tuple, live: bool, parked: bool, drift: tuple | None,
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
                log.warning("heading_not_turned_across_gap", sensor=self.cfg.name, stamp=stamp, gap_s=silent,
                            reason=why)
            return heading
        rate, rate_var = drift_rate(drift)
        imu_turn = rot.wrap(yaw - yaw0)
        filter_turn = rot.wrap(heading - heading0)
        corrected = imu_turn - rate * silent
        # what is not known of the IMU's turn: its drift over the gap (the estimate's error and how much
        # the drift may change) and the yaw's noise at both ends; of the filter's: what its variance grew
        turn_var = (rate_var + DRIFT_CHANGE**2) * silent**2 + 2.0 * var
        if (s.turn_unseen is not None and s.turn_unseen > t0) or s.still_since is not None:
            # a logging gap: the filter's inputs ended with it, so its own change says nothing of the turn; or
            # the wheels read zero while the gyro or the yaw says the vehicle turned (not parked, above): a
            # drive at rest can lie (coasting, turned by hand), its zero is no measurement of the turn
            gain, wheels_turn, yaw_var = 1.0, filter_turn, var0 + turn_var
        else:
            # the wheels' yaw rate drove the heading through the IMU's silence: their turn, rescaled by how
            # they read the gyro's turns before (a skid-steer's reads short), against the IMU's. Beside a
            # heading reference (GPS, pose) the filter's turn holds its corrections too: not rescaled then.
            wheels_turn, wheels_var = filter_turn, max(float(s.ekf.P[5, 5]) - var0, 0.0)
            if not s.heading_ready:
                scale, relative_var = wheel_yaw_scale(wheel)
                by_wheels = s.wheel_turn - wheel0  # the part the wheels turned (a held gyro rate turned the rest)
                wheels_turn += by_wheels * (1.0 / scale - 1.0)
                wheels_var += (by_wheels / scale) ** 2 * relative_var
            innovation = rot.wrap(corrected - wheels_turn)
            if innovation * innovation > WHEELS_GATE**2 * (wheels_var + turn_var):
                # far beyond both turns' uncertainty: the IMU's yaw is no longer the one before the silence
                # (QA8: an AHRS rebooted in it and integrating since, so not back at 0), keep the wheels'
                if emit:
                    log.warning("heading_not_turned_across_gap", sensor=self.cfg.name, stamp=stamp, gap_s=silent,
                                reason="the IMU's turn disagrees with the wheels' beyond both their uncertainties",
                                imu_turn_rad=corrected, wheels_turn_rad=wheels_turn)
                return heading
            gain = wheels_var / (wheels_var + turn_var) if wheels_var + turn_var > 0.0 else 0.0
            yaw_var = var0 + wheels_var * (1.0 - gain)
        turn = rot.wrap(wheels_turn + gain * rot.wrap(corrected - wheels_turn) - filter_turn)
        s.ekf.turn_heading(turn, yaw_var)
        if emit:
            self.gap_turns += 1
            log.info("heading_turned_across_gap", sensor=self.cfg.name, stamp=stamp, gap_s=silent, turn_rad=turn,
                     imu_turn_rad=imu_turn, drift_rad=rate * silent, filter_turn_rad=filter_turn,
                     wheels_turn_rad=wheels_turn, gain=gain)
        return rot.wrap(heading + turn)

    def _orientation_due(self, s: "FilterState", stamp: float, emit: bool) -> bool:
        """Is this sample's orientation fused, at most ``orientation_rate_hz`` (f) on average?

        An AHRS's orientation at hundreds of Hz is the output of one filter: its errors are alike from
        sample to sample, so fusing each as an independent measurement makes the filter sure of roll,
        pitch (and yaw) far beyond what the sensor knows, and costs an update each (at 1 kHz most of
        the core's time). A token bucket: credit accrues at f, up to ORIENTATION_BURST samples' worth,
        and a sample finding one credit is fused and spends it. So a faster IMU is fused at f on
        average; an IMU at f loses no sample however its stamps jitter (short of reordering them,
        its credit stays within one sample of where it settled, never empty nor overflowing); after
        a pause up to ORIENTATION_BURST samples are fused at once. The bucket lives in the IMU's state
        slice, so a late sample re-applied from the history thins exactly as the first time.
        """
        if self._period == 0.0 or not s.attitude_ready:
            return True
        own: ImuOwn = s.own[self.index]
        bucket = own.orientation_credit
        credit = ORIENTATION_BURST if bucket is None else min(
            ORIENTATION_BURST, bucket[0] + max(stamp - bucket[1], 0.0) * self.cfg.orientation_rate_hz)
        due = credit >= 1.0
        s.own[self.index] = msgspec.structs.replace(own, orientation_credit=(credit - 1.0 if due else credit, stamp))
        if not due and emit:
            self.thinned += 1
            if self.thinned == 1:
                log.info("orientation_thinned", sensor=self.cfg.name, rate_hz=self.cfg.orientation_rate_hz,
                         hint="the IMU is faster than orientation_rate_hz: its orientation is fused at that "
                              "rate, its gyro at every sample (orientation_rate_hz = 0 fuses every sample)")
        return due

    def _fuse_orientation(self, s: "FilterState", rpy, cov, rows: tuple[int, ...], stamp: float, emit: bool,
                          late: bool) -> list[DiagnosticsRecord]:
        cfg = self.cfg
        observe = obs.orientation_with_offset if self.offset else obs.orientation
        y, H, R = observe(self.ctx.layout, s.ekf.x, rpy, cov, rows)
        own: ImuOwn = s.own[self.index]
        scale = own.adaptive[0] if cfg.adaptive else 1.0
        tilt_only = 2 not in rows
        res = s.ekf.update(y, H, R * scale if scale != 1.0 else R, cfg.mahalanobis_threshold,
                           self.ctx.tilt_mask if tilt_only else None, hold_heading=tilt_only)
        if not res.rejected and (0 in rows or 1 in rows):
            s.tilt_seen = stamp
        if self.offset and not tilt_only:
            own = msgspec.structs.replace(own, yaw_residual=self._yaw_residual(s, rpy[2]))  # after the update
        if cfg.adaptive:
            own = msgspec.structs.replace(own, adaptive=adapt(own.adaptive, res.nis, len(rows), cfg.adaptive_window))
        s.own[self.index] = own
        if not emit:
            return []
        return [self.record(stamp, [obs.RPY_NAMES[i] for i in rows], y.tolist(), res.innovation_var, res.nis,
                            len(rows), res.rejected, "orientation", late)]

    def _yaw_residual(self, s: "FilterState", yaw: float) -> float:
        o = float(s.ekf.x[self._offset_index])
        return rot.wrap(yaw - rot.yaw(tuple(s.ekf.x[3:7].tolist())) - o)

    def _yaw_jump(self, s: "FilterState", yaw: float, var: float, stamp: float) -> tuple[float, float]:
        """How far the yaw reading jumped against the gyro-carried heading since the previous sample,
        and the variance the model allows that jump.

        Between two samples the filter's heading follows the gyro, so the yaw residual (reading -
        heading - offset) changes only by the reading's noise (twice) and the offset's random walk
        over the interval. A larger jump is the reading's own (a disturbance switching on, a
        magnetometer near a motor): beyond YAW_JUMP_GATE sigma that sample's yaw is not fused. The
        residual is remembered either way, so a disturbance that persists is fused from the next
        sample on, and its slow part goes into the offset.
        """
        r = self._yaw_residual(s, yaw)
        own: ImuOwn = s.own[self.index]
        prev = own.yaw_residual
        last = stamp if own.yaw_stamp is None else own.yaw_stamp
        s.own[self.index] = msgspec.structs.replace(own, yaw_residual=r, yaw_stamp=stamp)
        allowed = 2.0 * var + self.cfg.yaw_offset_walk**2 * max(stamp - last, 0.0)
        return (0.0 if prev is None else rot.wrap(r - prev)), allowed

    def _tilt_from_gravity(self, s: "FilterState", accel: tuple[float, float, float], stamp: float, emit: bool,
                           late: bool) -> list[DiagnosticsRecord]:
        """Roll and pitch from the accelerometer, when the IMU gives no orientation.

        At low dynamics the accelerometer reads the specific force R^T (0, 0, g) plus the
        centripetal term w x v and the forward acceleration: both are removed (the gyro rate and
        odometry twist held now, the slope of the odometry's speed), and a sample whose
        remaining magnitude is not g (hard braking, bumps) is skipped. Without this an ``orientation = "off"`` IMU left the tilt to
        integrate the gyro's x/y bias: tens of degrees and metres of z on a flat floor.
        """
        u = self.ctx.inputs_at(s)
        forward = 0.0 if u.world_frame else self.ctx.forward_accel(s)
        if forward != forward:
            return []  # the acceleration is changing: not known well enough to separate from gravity
        wx, wy, wz = u.angular
        vx, vy, vz = u.linear
        if u.world_frame:  # the twist is in the world: into the body
            vx, vy, vz = mat3.apply_transposed(rot.matrix9(tuple(s.ekf.x[3:7].tolist())), (vx, vy, vz))
        n = math.sqrt(accel[0] ** 2 + accel[1] ** 2 + accel[2] ** 2)
        if G_UNITS_BAND[0] < n < G_UNITS_BAND[1]:  # a driver that reports in g, not m/s^2
            accel = (accel[0] * GRAVITY, accel[1] * GRAVITY, accel[2] * GRAVITY)
        ax = accel[0] - (wy * vz - wz * vy) - forward
        ay = accel[1] - (wz * vx - wx * vz)
        az = accel[2] - (wx * vy - wy * vx)
        # Averaged over GRAVITY_AVERAGE_S before the tilt is taken: vibration (an engine's 30 Hz, several m/s^2)
        # is zero-mean in the specific force, but not in atan2 of it, nor in which samples pass the magnitude
        # gate: sample by sample it read as a steady tilt of tenths of a degree (QA4's car: 30 m of z). The
        # mean's gate and angles are unbiased; its update carries the information of its n samples.
        own: ImuOwn = s.own[self.index]
        w = own.gravity
        if w is None:
            w = (stamp, 1, ax, ay, az)
        else:
            w = (w[0], w[1] + 1, w[2] + ax, w[3] + ay, w[4] + az)
        if stamp - w[0] < GRAVITY_AVERAGE_S:
            s.own[self.index] = msgspec.structs.replace(own, gravity=w)
            return []
        s.own[self.index] = msgspec.structs.replace(own, gravity=None)
        n = w[1]
        ax, ay, az = w[2] / n, w[3] / n, w[4] / n
        if abs(math.sqrt(ax * ax + ay * ay + az * az) - GRAVITY) > GRAVITY_DYNAMIC_GATE:
            return []
        roll = math.atan2(ay, az)
        pitch = math.atan2(-ax, math.hypot(ay, az))
        if not s.attitude_ready:
            initialise_attitude(s, (roll, pitch, 0.0), False)
        var = self.cfg.gravity_tilt_noise**2 / n
        y, H, R = obs.orientation(self.ctx.layout, s.ekf.x, (roll, pitch, 0.0),
                                  (var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var), (0, 1))
        res = s.ekf.update(y, H, R, self.cfg.mahalanobis_threshold, self.ctx.tilt_mask, hold_heading=True)
        if not res.rejected:
            s.tilt_seen = stamp
        if not emit:
            return []
        return [self.record(stamp, ["roll", "pitch"], y.tolist(), res.innovation_var, res.nis, 2, res.rejected,
                            "gravity", late)]


def initialise_attitude(s: "FilterState", rpy: tuple[float, float, float], with_yaw: bool) -> None:
    """Take roll/pitch (and yaw when absolute) from the first orientation sample."""
    yaw = rpy[2] if with_yaw else rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2]
    s.ekf.set_attitude(rot.from_rpy(rpy[0], rpy[1], yaw))
    s.attitude_ready = True


def adapt(a: tuple[float, float, int], nis: float, dof: int, window: int) -> tuple[float, float, int]:
    """Window of NIS/dof; at its end R's scale moves by the window mean (bounded)."""
    if not math.isfinite(nis):
        return a
    scale, total, n = a[0], a[1] + nis / dof, a[2] + 1
    if n >= window:
        return (min(max(scale * (total / n), ADAPTIVE_MIN), ADAPTIVE_MAX), 0.0, 0)
    return (scale, total, n)


__all__ = ["ImuInput", "ImuModel", "ImuOwn", "ImuPolicy"]


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


def drift_rate(drift: tuple | None) -> tuple[float, float]:
    """(rate rad/s, its variance) of the IMU yaw's drift against the heading: the blocks' average and
    its standard error (their scatter over the effective number of blocks averaged); before
    DRIFT_MIN_BLOCKS blocks, none measured: 0 with GAP_YAW_DRIFT as its standard deviation."""
    if drift is None or drift[3] < DRIFT_MIN_BLOCKS:
        return 0.0, GAP_YAW_DRIFT**2
    n, mean, m2 = drift[3], drift[4], drift[5]
    effective = min(float(n), 2.0 * DRIFT_TAU_S / DRIFT_BLOCK_S)  # (1 + a) / (1 - a) of the weights, about
    return mean, max(m2, DRIFT_FLOOR**2) / effective


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
    explains (a skid-steer slips more on the spot than on an arc: one k fits neither exactly, QA8) plus k's
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
