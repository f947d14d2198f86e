"""IMU: orientation observed as roll/pitch(/yaw) per mode; gyro as motion input; roll/pitch from gravity.

The gyro rate is held as the motion input until the next sample (or its timeout); at
a confirmed standstill it also teaches the filter its bias (``gyro_bias.py``). The
orientation is an update of roll/pitch(/yaw) by mode: ``absolute`` yaw is ENU heading
(with an estimated offset beside GPS/pose), ``relative`` yaw is measured against the
yaw the filter had at the IMU's first message, ``roll_pitch`` fuses tilt only. Without
orientation, the accelerometer's gravity gives roll/pitch (``tilt_from_gravity``). In ``roll_pitch``
mode the IMU's own yaw still carries the heading across logging gaps (``gap_turn.py``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import msgspec

from .... import reasons
from ....estimator import mat3
from ....estimator import observations as obs
from ....estimator import rotation as rot
from ....logs import get_logger
from ...diagnostics import DiagnosticsRecord
from ..base import SensorContext, SensorModel
from ..checks import MAX_RATE, Rejected, finite, near_unit, plausible, resolve_variances, unit_quaternion
from .gap_turn import carry_yaw
from .gyro_bias import learn_bias_at_rest
from .inputs import ImuInput
from .own import ImuOwn
from .sample import ImuSample
from .table import ImuSensor

if TYPE_CHECKING:
    from ...state import FilterState

log = get_logger("fusiond.core")

GRAVITY = 9.80665  # m/s^2, standard gravity
_ZERO3 = (0.0, 0.0, 0.0)
G_UNITS_BAND = (0.8, 1.2)  # |specific force| in this band: the accelerometer reports in g
GRAVITY_DYNAMIC_GATE = 0.5  # m/s^2: |specific force| further than this from g is not "low dynamics"
GRAVITY_AVERAGE_S = 0.1  # s of specific force averaged into one gravity roll/pitch update
ADAPTIVE_MIN, ADAPTIVE_MAX = 0.1, 100.0
# Samples' worth of credit ``orientation_rate_hz`` can save up (``_orientation_due``). Derived: an IMU at f
# arrives with the bucket full, so a sample late by l < 1 period clips l of credit and the next one, early by
# l, finds 2 - l >= 1: two is the least that loses no sample to jitter under a period; more only fuses more of
# one AHRS's correlated samples at once after a pause (tests/sensors/test_orientation_rate.py pins both sides).
ORIENTATION_BURST = 2.0
YAW_JUMP_GATE = 5.0  # sigma of the sample-to-sample change of an absolute yaw's residual (``_yaw_jump``)


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
        self._gyro_cap = max(cfg.gyro_max_sigma, cfg.gyro_min_sigma) ** 2
        self._gyro_override = None if cfg.gyro_noise is None else cfg.gyro_noise**2
        self._gravity_tilt = cfg.tilt_from_gravity
        # roll_pitch with yaw_across_gaps reads the yaw for the gap turn even where no row is fused (two-D mode)
        self._reads_yaw = cfg.yaw_across_gaps and cfg.roll_pitch_only
        # The last covariance tuple of each kind and what it resolved to: a driver sends the same
        # covariance in every message, so its checks, floors and rotation into base_link are done
        # once per distinct value (a tuple compares equal only if finite: NaN != NaN).
        self._ori_seen: tuple | None = None
        self._ori_resolved: tuple[tuple[int, ...], tuple[float, ...], bool] = ((), (), False)
        self._gyro_seen: tuple | None = None
        self._gyro_resolved: tuple[float, ...] = ()
        self._gyro_unknown_said = False  # the gyro_covariance_unknown warning was logged
        self.orientation_dropped: dict[str, int] = {}  # per reason: orientations refused beside a gyro fused
        self.acceleration_dropped = 0  # accelerations not finite, left out of the gravity tilt (the rest fused)

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
            var = [min(max(d, self._gyro_floor), self._gyro_cap) for d in diag]
        cov = self._rotate_cov(var)
        if type(gc) is tuple:
            self._gyro_seen, self._gyro_resolved = gc, cov
        return cov

    def _orientation(self, s: ImuSample) -> tuple[tuple[float, ...], tuple[int, ...], tuple[float, ...], bool]:
        """(the orientation in base_link, rows to fuse, their covariance, the yaw is measured); Rejected when
        the orientation or its covariance is not a measurement."""
        oc = s.orientation_covariance
        known = oc == self._ori_seen
        if not (known or finite(oc)):
            raise Rejected(reasons.NON_FINITE, "orientation")
        q_imu = near_unit(s.orientation)  # a unit quaternion is finite: the usual message's one check
        if q_imu is None:
            if not finite(s.orientation):
                raise Rejected(reasons.NON_FINITE, "orientation")
            q_imu = unit_quaternion(s.orientation)  # raises: zero or not of unit norm
        q_base = rot.mul(q_imu, self.q_ext_inv) if not self._identity else q_imu
        rows, rpy_cov, yaw_measured = self._ori_resolved if known else self._orientation_noise(oc)
        return q_base, rows, rpy_cov, yaw_measured

    def convert(self, s: ImuSample) -> ImuInput:
        q_base = rpy_cov = None
        rows: tuple[int, ...] = ()
        yaw_measured = False
        refused: Rejected | None = None  # a bad orientation: it costs the sample only when nothing else is fused
        if (self._rows or self._reads_yaw) and len(s.orientation_covariance) == 9 and s.orientation_covariance[0] != -1.0:
            try:
                q_base, rows, rpy_cov, yaw_measured = self._orientation(s)
            except Rejected as err:
                # read for the gap turn alone (two-D mode), or beside a gyro: a bad orientation costs its own
                # rows, not the sample's gyro (an AHRS's NaN quaternion for 10 s turned the heading 87 deg off)
                q_base, rows, rpy_cov, yaw_measured = None, (), None, False
                refused = err if self._rows else None
        elif len(s.orientation_covariance) != 9:
            raise Rejected(reasons.BAD_COVARIANCE, "orientation covariance must have 9 entries")

        if q_base is None and s.angular_velocity == _ZERO3 and s.linear_acceleration == _ZERO3:
            # rates and specific force all exactly zero (at rest an accelerometer reads gravity): a
            # driver's placeholder for a lost sample, not a measurement of zero rate (its bad orientation, if
            # it had one, says more)
            raise refused or Rejected(reasons.NOTHING_TO_FUSE, "rates and acceleration all exactly zero: a lost sample")
        gyro = gyro_cov = None
        if self.cfg.angular_velocity and len(s.angular_velocity_covariance) == 9:
            gc = s.angular_velocity_covariance
            # [0] == -1: "no angular velocity" (sensor_msgs/Imu), unless the user states the gyro's noise: some
            # drivers mark the covariance unknown that way while publishing the rates; the override says fuse them
            if gc[0] != -1.0 or self._gyro_override is not None:
                known = gc == self._gyro_seen
                if not (known or finite(gc)):
                    raise Rejected(reasons.NON_FINITE, "angular_velocity")
                if not plausible(s.angular_velocity, MAX_RATE):  # NaN and inf fail it too
                    if not finite(s.angular_velocity):
                        raise Rejected(reasons.NON_FINITE, "angular_velocity")
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
            elif len(ac) == 9 and ac[0] != -1.0 and not finite(a):  # NaN from the chip: said, not lost unseen
                n = self.acceleration_dropped = self.acceleration_dropped + 1
                if n == 1 or n % 1000 == 0:
                    log.warning("acceleration_dropped", sensor=self.cfg.name, reason=reasons.NON_FINITE, count=n,
                                kept="the rest of the message")
        if refused is not None:
            if gyro is None:
                raise refused
            n = self.orientation_dropped[refused.reason] = self.orientation_dropped.get(refused.reason, 0) + 1
            if n == 1 or n % 1000 == 0:
                log.warning("orientation_dropped", sensor=self.cfg.name, reason=refused.reason, count=n,
                            kept="the gyro rate of the same message")
        if q_base is None and gyro is None and accel is None:
            raise Rejected(reasons.NOTHING_TO_FUSE, "no orientation, angular velocity or acceleration in the message")
        return ImuInput(q_base, rpy_cov, rows, gyro, gyro_cov, accel, yaw_measured)


class ImuModel(SensorModel):
    config_type = ImuSensor
    sample_type = ImuSample
    policy_type = ImuPolicy

    def __init__(self, cfg: ImuSensor, index: int, ctx: SensorContext) -> None:
        super().__init__(cfg, index, ctx)
        self.absolute = cfg.absolute_yaw
        self.relative = cfg.relative_yaw
        # absolute yaw read as heading + an estimated offset (the core adds the yaw_offset block)
        self.offset = self.absolute and ctx.layout.has("yaw_offset")
        self._offset_index = ctx.layout.nominal["yaw_offset"].start if self.offset else -1
        self.learns_bias = cfg.angular_velocity and ctx.layout.has("gyro_bias")
        self._fixed_yaw = cfg.yaw_offset + cfg.magnetic_declination  # navsat_transform's convention
        self.orientation_period = 1.0 / cfg.orientation_rate_hz if cfg.orientation_rate_hz > 0.0 else 0.0
        self.thinned = 0  # orientations not fused for ``orientation_rate_hz`` (the gyro of the sample is)
        # in two-D mode too: roll and pitch are held at 0 there, the IMU's yaw still kept its turns in a gap
        self.carries_yaw = cfg.yaw_across_gaps and cfg.roll_pitch_only
        self.gap_s = ctx.filter.gap_s
        self.bias_sigma = ctx.filter.gyro_bias_sigma
        self.bias_z = ctx.layout.index("gyro_bias", 2)
        self.bias_z_error = ctx.layout.index("gyro_bias", 2, error=True)
        self.gap_turns = 0  # headings turned across gaps (``gap_turn.carry_yaw``)

    @property
    def gives_tilt(self) -> bool:
        return self.policy.gives_tilt

    def planar(self) -> None:
        self.policy.planar()

    def on_start(self, s: "FilterState") -> None:
        s.own[self.index] = ImuOwn()

    def estimated_keys(self, s: "FilterState") -> dict[str, float]:
        """``yaw_offset`` when the absolute yaw's offset is in the state: there the yaw reads heading + o,
        and the key adds to the reading (ENU yaw = reading + yaw_offset + magnetic_declination), so the key
        that states o is the configured yaw_offset - o."""
        if not self.offset:
            return {}
        return {"yaw_offset": self.cfg.yaw_offset - float(s.ekf.x[self._offset_index])}

    def apply(self, s: "FilterState", inp: ImuInput, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        records: list[DiagnosticsRecord] = []
        if inp.gyro is not None:
            s.gyro, s.gyro_cov, s.gyro_last = inp.gyro, inp.gyro_cov, (self.index, stamp)
            if self.learns_bias:
                records.extend(learn_bias_at_rest(self, s, inp, stamp, emit, late))
        if inp.attitude is not None and (inp.rows or self.carries_yaw) and self._orientation_due(s, stamp, emit):
            rpy, rows = inp.rpy, inp.rows
            if self.absolute and self._fixed_yaw:
                rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] + self._fixed_yaw))
            if rows and not s.attitude_ready:
                initialise_attitude(s, rpy, self.absolute)
            if self.carries_yaw and inp.yaw_measured:
                carry_yaw(self, s, rpy[2], inp.rpy_cov[8], inp.gyro, inp.gyro_cov, stamp, emit)
            if self.relative:
                own: ImuOwn = s.own[self.index]
                off = own.yaw_offset
                if off is None:
                    off = rot.wrap(rpy[2] - rot.to_rpy(s.ekf.attitude())[2])
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
        if self.orientation_period == 0.0 or not s.attitude_ready:
            return True
        own: ImuOwn = s.own[self.index]
        bucket = own.orientation_credit
        if bucket is None:
            credit = ORIENTATION_BURST
        else:
            # min(BURST, credit + max(elapsed, 0) f) as comparisons: the same float (NaN included), no builtin calls
            elapsed = stamp - bucket[1]
            if elapsed < 0.0:
                elapsed = 0.0
            credit = bucket[0] + elapsed * self.cfg.orientation_rate_hz
            if not credit < ORIENTATION_BURST:
                credit = ORIENTATION_BURST
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
        y, H, R = observe(self.ctx.layout, s.ekf.x, rpy, cov, rows, s.ekf.backend)
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
        return rot.wrap(yaw - rot.yaw(s.ekf.attitude()) - o)

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
            vx, vy, vz = mat3.apply_transposed(rot.matrix9(s.ekf.attitude()), (vx, vy, vz))
        n = math.sqrt(accel[0] ** 2 + accel[1] ** 2 + accel[2] ** 2)
        if G_UNITS_BAND[0] < n < G_UNITS_BAND[1]:  # a driver that reports in g, not m/s^2
            accel = (accel[0] * GRAVITY, accel[1] * GRAVITY, accel[2] * GRAVITY)
        ax = accel[0] - (wy * vz - wz * vy) - forward
        ay = accel[1] - (wz * vx - wx * vz)
        az = accel[2] - (wx * vy - wy * vx)
        # Averaged over GRAVITY_AVERAGE_S before the tilt is taken: vibration (an engine's 30 Hz, several m/s^2)
        # is zero-mean in the specific force, but not in atan2 of it, nor in which samples pass the magnitude
        # gate: sample by sample it reads as a steady tilt of tenths of a degree (on a car, 30 m of z). The
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
                                  (var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, var), (0, 1), s.ekf.backend)
        res = s.ekf.update(y, H, R, self.cfg.mahalanobis_threshold, self.ctx.tilt_mask, hold_heading=True)
        if not res.rejected:
            s.tilt_seen = stamp
        if not emit:
            return []
        return [self.record(stamp, ["roll", "pitch"], y.tolist(), res.innovation_var, res.nis, 2, res.rejected,
                            "gravity", late)]


def initialise_attitude(s: "FilterState", rpy: tuple[float, float, float], with_yaw: bool) -> None:
    """Take roll/pitch (and yaw when absolute) from the first orientation sample."""
    yaw = rpy[2] if with_yaw else rot.to_rpy(s.ekf.attitude())[2]
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
