"""Per-sensor policy: turn a raw sample into filter inputs, or reject it with a reason.

Message covariances lie (all zeros, 1e6 for "not measured", a gyro covariance ten
times the real noise), so every variance goes through a floor, a "not measured"
cap and the user's override from the config. The IMU's mounting rotation
(``extrinsic_rpy``) is applied here to orientation, rates and their covariances
alike, so the estimator only ever sees base_link quantities.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .. import reasons
from ..config import GpsSensor, ImuSensor, OdomSensor, PoseSensor
from ..estimator import mat3
from ..estimator import rotation as rot
from ..samples import GpsSample, ImuSample, OdomSample, PoseSample

_QUAT_NORM_TOLERANCE = 0.1  # drivers round; anything further off is not a rotation
MAX_SPEED = 100.0  # m/s: beyond any wheeled robot, so a value this large is corrupt
MAX_RATE = 100.0  # rad/s: beyond any gyro's range (they saturate near 35 rad/s)


def _plausible(values: tuple[float, float, float], limit: float) -> bool:
    a, b, c = values
    return -limit <= a <= limit and -limit <= b <= limit and -limit <= c <= limit


class Rejected(Exception):
    """A sample the core refuses; ``reason`` is a stable counter name."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason


@dataclass(slots=True)
class OdomInput:
    """Body (or world) twist with per-sample covariances (row-major 9-tuples), ready for the motion model."""

    linear: tuple[float, float, float]
    linear_cov: tuple[float, ...]
    angular: tuple[float, float, float]
    angular_cov: tuple[float, ...]
    yaw_rate_measured: bool
    stationary: bool


@dataclass(slots=True)
class ImuInput:
    """Base-frame attitude observation (roll, pitch, yaw rows usable) and gyro rate; 9-tuple covariances."""

    rpy: tuple[float, float, float] | None
    rpy_cov: tuple[float, ...] | None
    rows: tuple[int, ...]
    gyro: tuple[float, float, float] | None
    gyro_cov: tuple[float, ...] | None
    accel: tuple[float, float, float] | None = None  # base-frame specific force, when gravity gives the tilt


def _unit_quaternion(q: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """q normalised; a zero or clearly non-unit quaternion (beyond driver rounding) is refused."""
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n < 1e-6:
        raise Rejected(reasons.ZERO_QUATERNION)
    if abs(n - 1.0) > _QUAT_NORM_TOLERANCE:
        raise Rejected(reasons.NON_UNIT_QUATERNION, f"norm {n:.3f}")
    return (x / n, y / n, z / n, w / n)


def _finite(values) -> bool:
    return all(map(math.isfinite, values))


def _resolve_variances(diag, floor: float, unmeasured: float, default: float) -> tuple[list[float], list[bool]]:
    """Floor tiny/zero variances; mark huge or non-finite ones as "not measured"."""
    out, measured = [], []
    for v in diag:
        if v >= unmeasured or v != v or v == math.inf:
            out.append(default)
            measured.append(False)
        else:
            out.append(v if v > floor else floor)
            measured.append(True)
    return out, measured


class OdomPolicy:
    STATIONARY_LINEAR = 1e-3  # m/s
    STATIONARY_ANGULAR = 1e-3  # rad/s

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

    def convert(self, s: OdomSample) -> OdomInput:
        if not (_finite(s.linear) and _finite(s.angular)):
            raise Rejected(reasons.NON_FINITE, "twist")
        if not (_plausible(s.linear, MAX_SPEED) and _plausible(s.angular, MAX_RATE)):
            raise Rejected(reasons.IMPLAUSIBLE_VALUE, "twist beyond 100 m/s or 100 rad/s")
        cov = s.twist_covariance
        if len(cov) != 36:
            raise Rejected(reasons.BAD_COVARIANCE, "twist covariance must have 36 entries")
        twist = (*s.linear, *s.angular)
        if self._override is not None and self._all_measured:
            var = self._override
            values = twist
            measured = (True,) * 6
        else:
            var, values, measured = [], [], []
            for i in range(6):
                if self._override is not None:  # the user's noise, for the components declared measured
                    measured.append(self._declared[i])
                    var.append(self._override[i] if self._declared[i] else self._default[i])
                    values.append(twist[i] if self._declared[i] else 0.0)
                    continue
                d = cov[7 * i]
                if d < 0.0:
                    raise Rejected(reasons.NEGATIVE_COVARIANCE, "twist")
                if not self._declared[i] or d >= self._unmeasured[i] or d != d or d == math.inf:
                    var.append(self._default[i])  # "not measured": not used, default noise
                    values.append(0.0)
                    measured.append(False)
                else:
                    var.append(d if d > self._floor[i] else self._floor[i])
                    values.append(twist[i])
                    measured.append(True)
        lin, ang = self.STATIONARY_LINEAR, self.STATIONARY_ANGULAR
        v0, v1, v2, w0, w1, w2 = values
        stationary = (
            -lin <= v0 <= lin and -lin <= v1 <= lin and -lin <= v2 <= lin
            and -ang <= w0 <= ang and -ang <= w1 <= ang and -ang <= w2 <= ang
        )
        return OdomInput(
            (v0, v1, v2),
            mat3.diag(var[0], var[1], var[2]),
            (w0, w1, w2),
            mat3.diag(var[3], var[4], var[5]),
            measured[5],
            stationary,
        )


class ImuPolicy:
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

    @property
    def gives_tilt(self) -> bool:
        """Can this IMU's messages constrain roll/pitch (orientation rows or gravity)?"""
        return 0 in self._rows or 1 in self._rows or self._gravity_tilt

    def planar(self) -> None:
        """Two-D mode: roll and pitch are held at 0, so only a yaw row can be fused."""
        self._rows = tuple(r for r in self._rows if r == 2)
        self._gravity_tilt = False

    def _rotate_cov(self, diag: list[float]) -> mat3.Mat3:
        C = mat3.diag(diag[0], diag[1], diag[2])
        if self._identity:
            return C
        return mat3.flat(mat3.sandwich(self.R_ext, C))

    def convert(self, s: ImuSample) -> ImuInput:
        rpy = rpy_cov = None
        rows: tuple[int, ...] = ()
        if self._rows and len(s.orientation_covariance) == 9 and s.orientation_covariance[0] != -1.0:
            if not (_finite(s.orientation) and _finite(s.orientation_covariance)):
                raise Rejected(reasons.NON_FINITE, "orientation")
            q_imu = _unit_quaternion(s.orientation)
            q_base = rot.mul(q_imu, self.q_ext_inv) if not self._identity else q_imu
            rpy = rot.to_rpy(q_base)
            if self._ori_override is not None:
                var, measured = list(self._ori_override), [True, True, True]
            else:
                oc = s.orientation_covariance
                diag = [oc[0], oc[4], oc[8]]
                if any(d < 0.0 for d in diag):
                    raise Rejected(reasons.NEGATIVE_COVARIANCE, "orientation")
                var, measured = _resolve_variances(diag, self._ori_floor, self._ori_unmeasured, 1.0)
            rows = tuple(i for i in self._rows if measured[i])
            rpy_cov = self._rotate_cov(var)
        elif len(s.orientation_covariance) != 9:
            raise Rejected(reasons.BAD_COVARIANCE, "orientation covariance must have 9 entries")

        gyro = gyro_cov = None
        if self.cfg.angular_velocity and len(s.angular_velocity_covariance) == 9:
            gc = s.angular_velocity_covariance
            if gc[0] != -1.0:
                if not (_finite(s.angular_velocity) and _finite(gc)):
                    raise Rejected(reasons.NON_FINITE, "angular_velocity")
                if not _plausible(s.angular_velocity, MAX_RATE):
                    raise Rejected(reasons.IMPLAUSIBLE_VALUE, "angular velocity beyond 100 rad/s")
                if self._gyro_override is not None:
                    var = [self._gyro_override] * 3
                else:
                    diag = [gc[0], gc[4], gc[8]]
                    if any(d < 0.0 for d in diag):
                        raise Rejected(reasons.NEGATIVE_COVARIANCE, "angular_velocity")
                    var = [max(d, self._gyro_floor) for d in diag]
                w = s.angular_velocity
                gyro = w if self._identity else mat3.apply(self.R_ext, w)
                gyro_cov = self._rotate_cov(var)
        elif self.cfg.angular_velocity:
            raise Rejected(reasons.BAD_COVARIANCE, "angular velocity covariance must have 9 entries")
        accel = None
        if self._gravity_tilt and not (0 in rows or 1 in rows):
            a = s.linear_acceleration
            ac = s.linear_acceleration_covariance
            # [0] == -1: no accelerometer (sensor_msgs/Imu); an all-zero vector: not filled in
            if len(ac) == 9 and ac[0] != -1.0 and _finite(a) and a != (0.0, 0.0, 0.0):
                accel = a if self._identity else mat3.apply(self.R_ext, a)
        if rpy is None and gyro is None and accel is None:
            raise Rejected(reasons.NOTHING_TO_FUSE, "no orientation, angular velocity or acceleration in the message")
        return ImuInput(rpy, rpy_cov, rows, gyro, gyro_cov, accel)


@dataclass(slots=True)
class GpsInput:
    """A valid fix: WGS84 position and its ENU covariance (row-major 9-tuple, m^2)."""

    lla: tuple[float, float, float]
    cov: tuple[float, ...]


class GpsPolicy:
    """NavSatFix: skip fixes without a fix (status < 0), take the noise from the message
    covariance (floored), the config's ``position_noise``, or a conservative default
    when the receiver says its covariance is unknown."""

    def __init__(self, cfg: GpsSensor) -> None:
        self.cfg = cfg
        self._floor = cfg.position_min_sigma**2
        self._override = None if cfg.position_noise is None else mat3.diag(*[v * v for v in cfg.position_noise])
        self._unknown = mat3.diag(*[v * v for v in cfg.unknown_position_sigma])

    def convert(self, s: GpsSample) -> GpsInput:
        if s.status < 0:
            raise Rejected(reasons.NO_FIX, f"status {s.status}")
        lla = (s.latitude, s.longitude, s.altitude)
        if not _finite(lla):
            raise Rejected(reasons.NON_FINITE, "latitude/longitude/altitude")
        if not (-90.0 <= s.latitude <= 90.0 and -180.0 <= s.longitude <= 180.0 and -1e5 < s.altitude < 1e6):
            raise Rejected(reasons.IMPLAUSIBLE_VALUE, "latitude/longitude/altitude out of range")
        if self._override is not None:
            return GpsInput(lla, self._override)
        if s.covariance_type == 0:
            return GpsInput(lla, self._unknown)
        c = s.position_covariance
        if len(c) != 9 or not _finite(c):
            raise Rejected(reasons.BAD_COVARIANCE, "position covariance must be 9 finite numbers")
        if c[0] < 0.0 or c[4] < 0.0 or c[8] < 0.0:
            raise Rejected(reasons.NEGATIVE_COVARIANCE, "position")
        if s.covariance_type == 2:  # COVARIANCE_TYPE_DIAGONAL_KNOWN: off-diagonals are not meaningful
            c = mat3.diag(c[0], c[4], c[8])
        f = self._floor
        cov = (max(c[0], f), c[1], c[2], c[3], max(c[4], f), c[5], c[6], c[7], max(c[8], f))
        return GpsInput(lla, cov)


@dataclass(slots=True)
class PoseInput:
    """Sensor pose (position, unit quaternion, its rpy) with a 6x6 covariance (x y z roll pitch yaw,
    row-major 36-tuple, diagonal) and the usable rows."""

    position: tuple[float, float, float]
    q: tuple[float, float, float, float]
    rpy: tuple[float, float, float]
    cov: tuple[float, ...]
    rows: tuple[int, ...]


class PosePolicy:
    """Covariances of pose sensors are as unreliable as any: the diagonal is used, floored,
    replaced by the config's noise when given, and a component above ``max_sigma`` is not
    measured (a 2D visual odometry sends 1e6 for z, roll and pitch)."""

    def __init__(self, cfg: PoseSensor) -> None:
        self.cfg = cfg
        pmin, omin = cfg.position_min_sigma**2, cfg.orientation_min_sigma**2
        self._floor = [pmin] * 3 + [omin] * 3
        self._max = [cfg.max_sigma[0] ** 2] * 3 + [cfg.max_sigma[1] ** 2] * 3
        self._unknown = [cfg.unknown_sigma[0] ** 2] * 3 + [cfg.unknown_sigma[1] ** 2] * 3
        self._pos_override = None if cfg.position_noise is None else [v * v for v in cfg.position_noise]
        self._ori_override = None if cfg.orientation_noise is None else [v * v for v in cfg.orientation_noise]
        self._held: tuple[int, ...] = ()

    def planar(self) -> None:
        """Two-D mode: z, roll and pitch are held at 0 and never fused."""
        self._held = (2, 3, 4)

    def convert(self, s: PoseSample) -> PoseInput:
        if not (_finite(s.position) and _finite(s.orientation)):
            raise Rejected(reasons.NON_FINITE, "pose")
        if not _plausible(s.position, 1e6):
            raise Rejected(reasons.IMPLAUSIBLE_VALUE, "position beyond 1000 km")
        q = _unit_quaternion(s.orientation)
        c = s.covariance
        if len(c) == 36:
            diag = [c[7 * i] for i in range(6)]
            if any(d < 0.0 for d in diag):
                raise Rejected(reasons.NEGATIVE_COVARIANCE, "pose")
        elif len(c) == 0:
            diag = list(self._unknown)
        else:
            raise Rejected(reasons.BAD_COVARIANCE, "pose covariance must have 36 entries")
        if self._pos_override is not None:
            diag[0:3] = self._pos_override
        if self._ori_override is not None:
            diag[3:6] = self._ori_override
        rows = []
        var = [0.0] * 6
        for i, d in enumerate(diag):
            if d != d or d >= self._max[i] or i in self._held:
                continue
            var[i] = d if d > self._floor[i] else self._floor[i]
            rows.append(i)
        if not rows:
            raise Rejected(reasons.NOTHING_TO_FUSE, "every pose component is marked not measured")
        cov = [0.0] * 36
        for i in range(6):
            cov[7 * i] = var[i] if var[i] > 0.0 else 1.0
        return PoseInput(s.position, q, rot.to_rpy(q), tuple(cov), tuple(rows))
