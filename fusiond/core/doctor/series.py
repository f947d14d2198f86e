"""Light time series of what each source says, for the doctor's cross-source checks.

NIS alone cannot tell which of two contradicting sources is wrong: a filter that
trusts a disturbed magnetometer yaw makes the GPS look bad. So the replay also
hands the doctor, per source, the quantities two sources can be compared on:
headings (IMU absolute yaw, integrated gyro, integrated wheel yaw rate, GPS track),
speeds (wheels, GPS), the gyro at rest, and the filter's own estimate. Binned to
a few hertz: enough for windows of seconds to a minute, small for an hour's run.

The collector is pure (no I/O, no clock): it is fed samples in any order (a short
reorder buffer sorts them by stamp before integrating) and returns a
:class:`Series`.
"""

from __future__ import annotations

import heapq
import math

import msgspec

from ...config import Config, GpsSensor, ImuSensor, OdomSensor
from ...estimator import rotation as rot
from ...estimator.geodesy import EnuFrame
from ...samples import GpsSample, ImuSample, OdomSample
from ..sensors.imu import G_UNITS_BAND, GRAVITY

BIN_S = 0.2  # series resolution: 5 Hz
REORDER_S = 1.0  # samples are integrated in stamp order once they are this much older than the newest
MAX_STEP_S = 1.0  # an integration step longer than this is a gap: not integrated across


_ZERO3 = (0.0, 0.0, 0.0)


class Series(msgspec.Struct):
    """Binned series (one row per BIN_S of each stream) and gaps; NaN where a value is absent."""

    odom_t: list[float] = []
    odom_v: list[float] = []  # mean forward speed, m/s
    odom_wz: list[float] = []  # mean wheel yaw rate, rad/s
    odom_heading: list[float] = []  # integrated wheel yaw rate, rad (unwrapped, starts at 0)
    odom_zero_wz: list[int] = []  # samples reporting a yaw rate of exactly 0 with variance 0
    odom_n: list[int] = []
    # samples whose yaw rate the core takes as "not measured" (declared so in twist_measured, or a variance
    # at or above twist_max_sigma^2, NaN or inf: the 1e6 of a driver that has none), so not used
    odom_wz_unmeasured: list[int] = []
    odom_rest: list[bool] = []  # every sample of the bin exactly at rest
    odom_gaps: list[tuple[float, float]] = []  # (stamp, length s) of silences longer than gap_s
    # Where an integrated heading was NOT integrated (a step longer than MAX_STEP_S): the stamp of the
    # first sample after the silence. A comparison of integrated headings must not span one (the turn
    # made in the silence is missing from one side only and would look like wander).
    odom_breaks: list[float] = []
    imu_t: list[float] = []
    imu_yaw: list[float] = []  # the IMU's own yaw in base_link (unwrapped), NaN when not measured
    imu_breaks: list[float] = []  # silences of the IMU yaw longer than MAX_STEP_S (its unwrap may skip a turn)
    gyro_t: list[float] = []
    gyro_z: list[float] = []  # mean base-frame gyro z, rad/s
    gyro_var: list[float] = []  # its variance within the bin
    gyro_n: list[int] = []
    gyro_heading: list[float] = []  # integrated raw gyro z (no bias removed), rad
    gyro_breaks: list[float] = []  # silences of the gyro longer than MAX_STEP_S: not integrated across
    gyro_stated_sigma: float = float("nan")  # the noise the filter assumes for the gyro z, rad/s (mean)
    acc_t: list[float] = []
    acc_x: list[float] = []  # accelerometer specific force minus gravity, base_link x through the configured
    acc_y: list[float] = []  # extrinsic_rpy (so a mounting missing from it shows), m/s^2
    acc_level: list[float] = []  # fraction of the bin's samples whose gravity was removed with the IMU's attitude
    gps_t: list[float] = []
    gps_e: list[float] = []
    gps_n: list[float] = []
    gps_sigma: list[float] = []  # stated horizontal sigma, m
    est_t: list[float] = []
    est_yaw: list[float] = []
    est_roll: list[float] = []
    est_pitch: list[float] = []
    est_bias_z: list[float] = []
    est_pos_var: list[float] = []  # largest position variance, m^2
    est_att_var: list[float] = []  # largest attitude variance, rad^2


class _Bin:
    __slots__ = ("t0", "n", "sums", "sq", "extra")

    def __init__(self, t0: float, width: int) -> None:
        self.t0 = t0
        self.n = 0
        self.sums = [0.0] * width
        self.sq = 0.0
        self.extra = 0


class SeriesCollector:
    """Feeds a :class:`Series` from raw samples (pre-policy: what the sensors said) and estimates."""

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.series = Series()
        self._heap: list = []
        self._seq = 0
        self._newest = -math.inf
        self._imu_cfg = {s.name: s for s in cfg.sensors if isinstance(s, ImuSensor)}
        self._odom_cfg = {s.name: s for s in cfg.sensors if isinstance(s, OdomSensor)}
        gps = [s for s in cfg.sensors if isinstance(s, GpsSensor)]
        self._gps_names = {s.name for s in gps}
        # the filter's ENU frame: the configured datum, else the first valid fix (as the core does)
        # IMU -> base: None for an IMU mounted as base_link (the common case: nothing to rotate)
        self._ext = {n: None if s.extrinsic_rpy == (0.0, 0.0, 0.0) else rot.conj(rot.from_rpy(*s.extrinsic_rpy))
                     for n, s in self._imu_cfg.items()}
        self._R = {n: tuple(tuple(float(v) for v in row) for row in rot.matrix(rot.from_rpy(*s.extrinsic_rpy)))
                   for n, s in self._imu_cfg.items()}  # IMU -> base, as configured
        # the accelerometer series is the first IMU's (the one the mounting check judges): two IMUs' axes
        # averaged into one bin would show neither mounting
        self._acc_imu = next(iter(self._imu_cfg), None)
        self._gap_s = cfg.filter.gap_s
        # integration state
        self._odom_last: tuple[float, float] | None = None  # (stamp, wz)
        self._wheel_heading = 0.0
        self._gyro_last: tuple[float, float] | None = None
        self._gyro_heading = 0.0
        self._yaw_prev: float | None = None
        self._yaw_unwrapped = 0.0
        self._yaw_stamp = -math.inf
        self._enu: EnuFrame | None = EnuFrame(*gps[0].datum) if gps and gps[0].datum is not None else None
        self._bins: dict[str, _Bin | None] = {"odom": None, "imu": None, "gyro": None, "acc": None}
        self._rest = True
        self._est_next = -math.inf
        self._stated = [0.0, 0]

    # -- feeding --------------------------------------------------------------
    def add_sample(self, sample) -> None:
        """Any sample, in arrival order."""
        if not (isinstance(sample, (OdomSample, ImuSample, GpsSample)) and math.isfinite(sample.stamp)):
            return
        self._seq += 1
        heapq.heappush(self._heap, (sample.stamp, self._seq, sample))
        if sample.stamp > self._newest:
            self._newest = sample.stamp
        while self._heap and self._heap[0][0] < self._newest - REORDER_S:
            self._process(heapq.heappop(self._heap)[2])

    def add_estimate(self, t: float, q: tuple[float, float, float, float], pos_var: float, att_var: float,
                     bias_z: float) -> None:
        """The filter's estimate at t (the caller may call it at every publish: it is decimated here)."""
        if t < self._est_next:
            return
        self._est_next = t + BIN_S
        r, p, y = rot.to_rpy(q)
        s = self.series
        s.est_t.append(t)
        s.est_roll.append(r)
        s.est_pitch.append(p)
        s.est_yaw.append(y)
        s.est_bias_z.append(bias_z)
        s.est_pos_var.append(pos_var)
        s.est_att_var.append(att_var)

    def wants_estimate(self, t: float) -> bool:
        return t >= self._est_next

    def finish(self) -> Series:
        while self._heap:
            self._process(heapq.heappop(self._heap)[2])
        for kind in ("odom", "imu", "gyro", "acc"):
            self._flush(kind)
        if self._stated[1]:
            self.series.gyro_stated_sigma = self._stated[0] / self._stated[1]
        return self.series

    # -- internals --------------------------------------------------------------
    def _process(self, s) -> None:
        if isinstance(s, OdomSample) and s.sensor in self._odom_cfg:
            self._odom(s)
        elif isinstance(s, ImuSample) and s.sensor in self._imu_cfg:
            self._imu(s)
        elif isinstance(s, GpsSample) and s.sensor in self._gps_names:
            self._gps(s)

    def _bin(self, kind: str, t: float, width: int) -> _Bin:
        b = self._bins[kind]
        if b is not None and t >= b.t0 + BIN_S:
            self._flush(kind)
            b = None
        if b is None:
            b = self._bins[kind] = _Bin(t, width)
        return b

    def _flush(self, kind: str) -> None:
        b = self._bins[kind]
        if b is None or b.n == 0:
            self._bins[kind] = None
            return
        s, n = self.series, b.n
        if kind == "odom":
            s.odom_t.append(b.t0 + BIN_S / 2)
            s.odom_v.append(b.sums[0] / n)
            s.odom_wz.append(b.sums[1] / n)
            s.odom_heading.append(self._wheel_heading)
            s.odom_zero_wz.append(b.extra)
            s.odom_wz_unmeasured.append(b.sums[2])
            s.odom_n.append(n)
            s.odom_rest.append(self._rest)
            self._rest = True
        elif kind == "imu":
            s.imu_t.append(b.t0 + BIN_S / 2)
            s.imu_yaw.append(b.sums[0] / n)
        elif kind == "acc":
            s.acc_t.append(b.t0 + BIN_S / 2)
            s.acc_x.append(b.sums[0] / n)
            s.acc_y.append(b.sums[1] / n)
            s.acc_level.append(b.extra / n)
        else:
            m = b.sums[0] / n
            s.gyro_t.append(b.t0 + BIN_S / 2)
            s.gyro_z.append(m)
            s.gyro_var.append(max(b.sq / n - m * m, 0.0) * n / max(n - 1, 1))
            s.gyro_n.append(n)
            s.gyro_heading.append(self._gyro_heading)
        self._bins[kind] = None

    def _odom(self, s: OdomSample) -> None:
        vx, wz = s.linear[0], s.angular[2]
        if not (math.isfinite(vx) and math.isfinite(wz)):
            return
        cov = s.twist_covariance
        last = self._odom_last
        if last is not None:
            dt = s.stamp - last[0]
            if dt > self._gap_s:
                self.series.odom_gaps.append((last[0], dt))
            if 0.0 < dt <= MAX_STEP_S:
                self._wheel_heading += last[1] * dt
            elif dt > MAX_STEP_S:
                self.series.odom_breaks.append(s.stamp)
        self._odom_last = (s.stamp, wz)
        b = self._bin("odom", s.stamp, 3)
        b.n += 1
        b.sums[0] += vx
        b.sums[1] += wz
        b.sums[2] += self._wz_unmeasured(s.sensor, cov)
        if wz == 0.0 and len(cov) == 36 and cov[35] <= 0.0:
            b.extra += 1
        if self._rest and (s.linear != _ZERO3 or s.angular != _ZERO3):
            self._rest = False

    def _wz_unmeasured(self, name: str, cov) -> int:
        """1 when the core's odometry model takes this sample's yaw rate as not measured (see
        core/sensors/odom.py: declared so, or without a twist_noise override a variance >= twist_max_sigma^2)."""
        cfg = self._odom_cfg[name]
        if not cfg.twist_measured[5]:
            return 1
        if cfg.twist_noise is not None or len(cov) != 36:
            return 0
        d = cov[35]
        return int(d != d or d >= cfg.twist_max_sigma[1] ** 2)

    def _imu(self, s: ImuSample) -> None:
        name = s.sensor
        cfg = self._imu_cfg[name]
        oc = s.orientation_covariance
        q = None  # the IMU's own attitude, when it reports one
        if len(oc) == 9 and oc[0] != -1.0 and all(map(math.isfinite, s.orientation)):
            n = math.sqrt(sum(v * v for v in s.orientation))
            if n > 0.5:
                q = tuple(v / n for v in s.orientation)
                ext = self._ext[name]
                qb = q if ext is None else rot.mul(q, ext)
                yaw_measured = cfg.orientation_noise is not None or oc[8] < cfg.orientation_max_sigma ** 2
                if yaw_measured:
                    # as the filter takes it: corrected = raw + yaw_offset + magnetic_declination (navsat_transform's
                    # keys; read with getattr so that a config without them reads as 0)
                    correction = getattr(cfg, "yaw_offset", 0.0) + getattr(cfg, "magnetic_declination", 0.0)
                    y = rot.wrap(rot.yaw(qb) + correction)
                    if self._yaw_prev is None:
                        self._yaw_unwrapped = y
                    else:
                        self._yaw_unwrapped += rot.wrap(y - self._yaw_prev)
                        if s.stamp - self._yaw_stamp > MAX_STEP_S:
                            self.series.imu_breaks.append(s.stamp)
                    self._yaw_prev = y
                    self._yaw_stamp = s.stamp
                    b = self._bin("imu", s.stamp, 1)
                    b.n += 1
                    b.sums[0] += self._yaw_unwrapped
        gc = s.angular_velocity_covariance
        if len(gc) == 9 and gc[0] != -1.0 and all(map(math.isfinite, s.angular_velocity)):
            r0, r1, r2 = self._R[name][2]
            w = s.angular_velocity
            wz = r0 * w[0] + r1 * w[1] + r2 * w[2]
            last = self._gyro_last
            if last is not None and 0.0 < s.stamp - last[0] <= MAX_STEP_S:
                self._gyro_heading += last[1] * (s.stamp - last[0])
            elif last is not None and s.stamp - last[0] > MAX_STEP_S:
                self.series.gyro_breaks.append(s.stamp)
            self._gyro_last = (s.stamp, wz)
            stated = cfg.gyro_noise if cfg.gyro_noise is not None else math.sqrt(max(gc[8], cfg.gyro_min_sigma ** 2))
            self._stated[0] += stated
            self._stated[1] += 1
            b = self._bin("gyro", s.stamp, 1)
            b.n += 1
            b.sums[0] += wz
            b.sq += wz * wz
        self._accel(s, q)

    def _accel(self, s: ImuSample, q: tuple[float, ...] | None) -> None:
        """The horizontal specific force minus gravity, in base_link as the configured extrinsic_rpy puts it.

        Gravity is removed in the IMU's own axes with the IMU's own attitude (R(q)^T (0, 0, g) is g times
        the third row of R(q)), which does not depend on the mounting; without an attitude it stays in
        (the doctor fits a constant for it). Then the configured IMU -> base rotation: an IMU turned
        about z by an angle extrinsic_rpy does not state shows the motion's acceleration turned by it.
        """
        if s.sensor != self._acc_imu:
            return
        a = s.linear_acceleration
        ac = s.linear_acceleration_covariance
        # as the core reads it: [0] == -1 is no accelerometer, an all-zero vector was not filled in
        if len(ac) != 9 or ac[0] == -1.0 or a == _ZERO3 or not all(map(math.isfinite, a)):
            return
        fx, fy, fz = a
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        if G_UNITS_BAND[0] <= norm <= G_UNITS_BAND[1]:  # a driver reporting in g
            fx, fy, fz = fx * GRAVITY, fy * GRAVITY, fz * GRAVITY
        level = q is not None
        if level:
            x, y, z, w = q
            fx -= GRAVITY * 2.0 * (x * z - w * y)
            fy -= GRAVITY * 2.0 * (y * z + w * x)
            fz -= GRAVITY * (1.0 - 2.0 * (x * x + y * y))
        R = self._R[s.sensor]
        b = self._bin("acc", s.stamp, 2)
        b.n += 1
        b.sums[0] += R[0][0] * fx + R[0][1] * fy + R[0][2] * fz
        b.sums[1] += R[1][0] * fx + R[1][1] * fy + R[1][2] * fz
        b.extra += level

    def _gps(self, s: GpsSample) -> None:
        if s.status < 0 or not all(map(math.isfinite, (s.latitude, s.longitude, s.altitude))):
            return
        if self._enu is None:
            self._enu = EnuFrame(s.latitude, s.longitude, s.altitude)
        e, n, _ = self._enu.enu(s.latitude, s.longitude, s.altitude)
        c = s.position_covariance
        sigma = math.sqrt(max(0.5 * (c[0] + c[4]), 0.0)) if len(c) == 9 and s.covariance_type > 0 else math.nan
        ser = self.series
        ser.gps_t.append(s.stamp)
        ser.gps_e.append(e)
        ser.gps_n.append(n)
        ser.gps_sigma.append(sigma)
