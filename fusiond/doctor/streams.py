"""The wheel and IMU streams of the doctor's series, integrated a chunk of samples at a time with numpy.

The replay hands the doctor every sample; turning each into headings and bin sums one at a time cost more
than half of what the fusion core itself spends on a message. So the collector keeps the samples of a chunk
(in the order its reorder buffer releases them) and these classes integrate the whole chunk in array
operations, carrying what the next chunk continues from: the last sample of each integrated rate, the
headings reached, the bins still open. The float expressions are those of a one-at-a-time loop, in the
same order (running sums by ``np.cumsum``/``np.bincount``, which add in array order), so the series is the
same as integrating sample by sample.
"""

from __future__ import annotations

import math
from itertools import chain
from operator import attrgetter, itemgetter

import numpy as np

from ..config import ImuSensor, OdomSensor
from ..estimator import rotation as rot
from ..core.sensors import ImuSample, OdomSample
from ..core.sensors.imu import G_UNITS_BAND, GRAVITY
from .bins import Binned, OpenBin, bin_rows

MAX_STEP_S = 1.0  # an integration step longer than this is a gap: not integrated across
_ZERO3 = (0.0, 0.0, 0.0)

__all__ = ["MAX_STEP_S", "OdomStream", "ImuStream"]


def _column(rows: list, field: str) -> np.ndarray:
    """One float field of every sample."""
    return np.fromiter(map(attrgetter(field), rows), dtype=float, count=len(rows))


def _vectors(rows: list, field: str, width: int) -> np.ndarray:
    """A tuple field of every sample as an (n, width) array (np.fromiter over the chained values: several
    times faster than np.array on a list of tuples)."""
    values = chain.from_iterable(map(attrgetter(field), rows))
    return np.fromiter(values, dtype=float, count=len(rows) * width).reshape(-1, width)


def _stated(covs: list[tuple[float, ...]]) -> tuple[np.ndarray, np.ndarray]:
    """Per 3x3 covariance: is it stated (nine values, [0] not the ROS -1 "absent"), and its [8] (NaN if
    it has not nine values)."""
    n = len(covs)
    if n and set(map(len, covs)) == {9}:
        first = np.fromiter(map(itemgetter(0), covs), dtype=float, count=n)
        return first != -1.0, np.fromiter(map(itemgetter(8), covs), dtype=float, count=n)
    return (np.array([len(c) == 9 and c[0] != -1.0 for c in covs], dtype=bool),
            np.array([c[8] if len(c) == 9 else math.nan for c in covs], dtype=float))


def _sensor_index(rows: list, index: dict[str, int]) -> np.ndarray:
    """Each sample's sensor as a position in the configured list (one sensor: no lookups)."""
    if len(index) == 1:
        return np.zeros(len(rows), dtype=np.intp)
    return np.array([index[s.sensor] for s in rows], dtype=np.intp)


class _Rate:
    """A rate integrated over a stream's own stamps (wheel yaw rate, gyro z): each step adds the previous
    sample's rate times the step, except across a silence longer than MAX_STEP_S (a break: the turn made
    in it is unknown).

    Each heading also gets the instant at which it is the vehicle's heading. Holding the previous sample's
    rate over a step integrates the rate as it was half a step earlier, so the heading reached at a sample
    is the heading of half a step before its stamp. A step that adds nothing (a break, a repeated or older
    stamp) leaves the heading, and its instant, as they were: the heading that closes the bin before a gap
    is the one reached before the gap, not one stamped after it."""

    def __init__(self) -> None:
        self.last_t: float | None = None
        self.last_rate = 0.0
        self.heading = 0.0
        self.at: float | None = None  # the instant of ``heading``

    def step(self, t: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(heading after each row, its instant, step before each row (NaN for the very first), previous
        stamp)."""
        n = len(t)
        if n == 0:
            return np.empty(0), np.empty(0), np.empty(0), np.empty(0)
        prev_t = np.concatenate(([self.last_t if self.last_t is not None else math.nan], t[:-1]))
        prev_rate = np.concatenate(([self.last_rate], rate[:-1]))
        dt = t - prev_t
        stepped = (dt > 0.0) & (dt <= MAX_STEP_S)
        inc = np.where(stepped, prev_rate * dt, 0.0)
        heading = np.cumsum(np.concatenate(([self.heading], inc)))[1:]
        # the instant: half a step before the stamp where the row stepped, else the previous row's (forward
        # filled; the very first heading, 0 before any step, is the heading at its own stamp)
        at = np.where(stepped, t - 0.5 * dt, math.nan)
        filled = np.maximum.accumulate(np.where(stepped, np.arange(n), -1))
        before = self.at if self.at is not None else float(t[0])
        at = np.where(filled >= 0, at[np.maximum(filled, 0)], before)
        self.last_t, self.last_rate, self.heading = float(t[-1]), float(rate[-1]), float(heading[-1])
        self.at = float(at[-1])
        return heading, at, dt, prev_t


def _closing_headings(binned: Binned, heading: np.ndarray, at: np.ndarray, carried: tuple[float, float | None],
                      final: bool) -> tuple[list[float], list[float]]:
    """The heading each complete bin reports and the instant it holds at: the one reached when the bin
    closed (after the increment of the sample that opened the next bin), or, for the bin flushed at the
    end, the last one reached. ``carried``: the heading and instant before these rows.

    The instant is not the bin's middle (where the series stamps the bin's means): it is about the bin's
    end. A comparison with a mean over the bin (the IMU's yaw) must interpolate to the same instant, or a
    vehicle turning at w shows a false difference of w x BIN_S / 2."""
    closing = binned.opener[1:]
    out, instants = heading[closing].tolist(), at[closing].tolist()
    if final and len(binned.n):
        out.append(float(heading[-1]) if len(heading) else carried[0])
        instants.append(float(at[-1]) if len(at) else (carried[1] if carried[1] is not None else math.nan))
    return out, instants


class OdomStream:
    """Wheel odometry: mean speed and yaw rate per bin, the integrated wheel heading, gaps and breaks."""

    def __init__(self, sensors: list[OdomSensor], gap_s: float) -> None:
        self.index = {s.name: i for i, s in enumerate(sensors)}
        # the core's "yaw rate not measured" rule per sensor (see core/sensors/odom/model.py)
        self.declared_unmeasured = np.array([not s.twist_measured[5] for s in sensors], dtype=bool)
        self.overridden = np.array([s.twist_noise is not None for s in sensors], dtype=bool)
        self.max_var = np.array([s.twist_max_sigma[1] ** 2 for s in sensors])
        self.min_var = np.array([s.twist_min_sigma[1] ** 2 for s in sensors])
        self.gap_s = gap_s
        self.rate = _Rate()
        self.open: OpenBin | None = None

    def take(self, rows: list[OdomSample], series, final: bool) -> None:
        t = _column(rows, "stamp")
        vx = np.fromiter((s.linear[0] for s in rows), dtype=float, count=len(rows))
        wz = np.fromiter((s.angular[2] for s in rows), dtype=float, count=len(rows))
        valid = np.isfinite(vx) & np.isfinite(wz)
        if not valid.all():
            rows = [s for s, ok in zip(rows, valid.tolist()) if ok]
            t, vx, wz = t[valid], vx[valid], wz[valid]
        covs = [s.twist_covariance for s in rows]
        has36 = np.array([len(c) == 36 for c in covs], dtype=bool)
        c35 = np.array([c[35] if len(c) == 36 else math.nan for c in covs], dtype=float)
        idx = _sensor_index(rows, self.index)
        moving = np.array([s.linear != _ZERO3 or s.angular != _ZERO3 for s in rows], dtype=float)
        unmeasured = np.where(self.declared_unmeasured[idx], 1.0, np.where(
            self.overridden[idx] | ~has36, 0.0, ((c35 != c35) | (c35 >= self.max_var[idx])).astype(float)))
        zero_wz = ((wz == 0.0) & has36 & (c35 <= 0.0)).astype(float)
        # a measured yaw rate whose stated variance the core raised to the floor: stated below it, or stated
        # 0 (a driver leaving its covariance empty), except a rate of exactly 0 with variance 0 (zero_wz: a lost
        # measurement, not a noise)
        floored = (~self.overridden[idx] & has36 & (unmeasured == 0.0) & (c35 >= 0.0) & (c35 < self.min_var[idx])
                   & (zero_wz == 0.0))
        if floored.any():
            series.odom_wz_floored += int(floored.sum())
            series.odom_wz_floored_sigma_sum += float(np.sqrt(c35[floored]).sum())

        carried = (self.rate.heading, self.rate.at)
        heading, at, dt, prev_t = self.rate.step(t, wz)
        gap = dt > self.gap_s
        series.odom_gaps.extend(zip(prev_t[gap].tolist(), dt[gap].tolist()))
        series.odom_breaks.extend(t[dt > MAX_STEP_S].tolist())

        binned = bin_rows(t, np.column_stack((vx, wz, unmeasured, zero_wz, moving)), self.open)
        k = binned.done(final)
        n, sums = binned.n[:k], binned.sums[:k]
        series.odom_t.extend(binned.mids(k))
        series.odom_v.extend((sums[:, 0] / n).tolist())
        series.odom_wz.extend((sums[:, 1] / n).tolist())
        closing, instants = _closing_headings(binned, heading, at, carried, final)
        series.odom_heading.extend(closing)
        series.odom_heading_at.extend(instants)
        series.odom_zero_wz.extend(sums[:, 3].astype(int).tolist())
        series.odom_wz_unmeasured.extend(sums[:, 2].tolist())
        series.odom_n.extend(n.tolist())
        series.odom_rest.extend((sums[:, 4] == 0.0).tolist())
        self.open = None if final else binned.last_open()


class ImuStream:
    """The IMUs: their own yaw (unwrapped), the base-frame gyro z (integrated, and its spread per bin), and
    the first IMU's horizontal specific force (for the mounting check)."""

    def __init__(self, sensors: list[ImuSensor]) -> None:
        self.index = {s.name: i for i, s in enumerate(sensors)}
        # IMU -> base: identity rows for an IMU mounted as base_link (the common case: nothing to rotate)
        self.rotated = np.array([s.extrinsic_rpy != (0.0, 0.0, 0.0) for s in sensors], dtype=bool)
        self.ext = np.array([rot.conj(rot.from_rpy(*s.extrinsic_rpy)) for s in sensors]).reshape(-1, 4)
        self.R = np.array([rot.matrix(rot.from_rpy(*s.extrinsic_rpy)) for s in sensors]).reshape(-1, 3, 3)
        self.yaw_overridden = np.array([s.orientation_noise is not None for s in sensors], dtype=bool)
        self.yaw_max_var = np.array([s.orientation_max_sigma ** 2 for s in sensors])
        # as the filter takes the yaw: raw + yaw_offset + magnetic_declination (navsat_transform's keys; read
        # with getattr so that a config without them reads as 0)
        self.correction = np.array([getattr(s, "yaw_offset", 0.0) + getattr(s, "magnetic_declination", 0.0)
                                    for s in sensors])
        self.gyro_noise = np.array([s.gyro_noise if s.gyro_noise is not None else math.nan for s in sensors])
        self.gyro_floor = np.array([s.gyro_min_sigma ** 2 for s in sensors])
        # the cap the core applies to a stated gyro noise (a driver's 1e6 "unknown"); read with getattr so that a
        # config without the key reads as no cap
        self.gyro_cap = np.array([max(getattr(s, "gyro_max_sigma", math.inf), s.gyro_min_sigma) ** 2 for s in sensors])
        # the accelerometer series is the first IMU's (the one the mounting check judges): two IMUs' axes
        # averaged into one bin would show neither mounting
        self.acc_index = 0
        self.yaw_prev: float | None = None
        self.yaw_unwrapped = 0.0
        self.yaw_stamp = -math.inf
        self.yaw_ref: float | None = None  # the first yaw's stamp: the bins sum stamps from it
        self.gyro = _Rate()
        self.stated_sum = 0.0
        self.stated_n = 0
        self.open: dict[str, OpenBin | None] = {"imu": None, "gyro": None, "acc": None}

    def take(self, rows: list[ImuSample], series, final: bool) -> None:
        if not self.index:
            return  # no IMU configured: no series to integrate (and no mounting to rotate through)
        t = _column(rows, "stamp")
        idx = _sensor_index(rows, self.index)
        q = _vectors(rows, "orientation", 4)
        oc_ok, oc8 = _stated(list(map(attrgetter("orientation_covariance"), rows)))
        w = _vectors(rows, "angular_velocity", 3)
        gc_ok, gc8 = _stated(list(map(attrgetter("angular_velocity_covariance"), rows)))
        a = _vectors(rows, "linear_acceleration", 3)
        ac_ok, _ = _stated(list(map(attrgetter("linear_acceleration_covariance"), rows)))

        qn, level = self._attitude(q, oc_ok)
        self._yaw(t[level], idx[level], qn[level], oc8[level], series, final)
        # a covariance marked absent (-1) with the user's gyro_noise stated: the core fuses those rates too
        ok = (gc_ok | (self.gyro_noise[idx] == self.gyro_noise[idx])) & np.isfinite(w).all(axis=1)
        self._gyro(t[ok], idx[ok], w[ok], gc8[ok], series, final)
        ok = (idx == self.acc_index) & ac_ok & ~(a == 0.0).all(axis=1) & np.isfinite(a).all(axis=1)
        self._accel(t[ok], a[ok], qn[ok], level[ok], series, final)

    @staticmethod
    def _attitude(q: np.ndarray, oc_ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The IMU's own attitude, normalised, and where it reports one (a stated covariance, finite, and a
        norm above 0.5)."""
        x, y, z, w = q.T
        with np.errstate(invalid="ignore", over="ignore"):
            norm = np.sqrt(x * x + y * y + z * z + w * w)
            level = oc_ok & np.isfinite(q).all(axis=1) & (norm > 0.5)
            qn = q / np.where(level, norm, 1.0)[:, None]
        return qn, level

    def _yaw(self, t, idx, qn, oc8, series, final: bool) -> None:
        measured = self.yaw_overridden[idx] | (oc8 < self.yaw_max_var[idx])
        t, idx, q = t[measured], idx[measured], qn[measured]
        rotated = self.rotated[idx]
        if rotated.any():
            q = q.copy()
            q[rotated] = _mul(q[rotated], self.ext[idx[rotated]])
        x, y, z, w = q.T
        # math.atan2, not np.arctan2: numpy's SIMD atan2 may differ from libm's in the last bit, and the
        # series should not depend on the machine's vector unit
        raw = np.fromiter(map(math.atan2, (2.0 * (w * z + x * y)).tolist(), (1.0 - 2.0 * (y * y + z * z)).tolist()),
                          dtype=float, count=len(t))
        yaw = _wrap(raw + self.correction[idx])
        if len(t):
            prev = np.concatenate(([self.yaw_prev if self.yaw_prev is not None else math.nan], yaw[:-1]))
            inc = _wrap(yaw - prev)
            prev_t = np.concatenate(([self.yaw_stamp], t[:-1]))
            if self.yaw_prev is None:  # the first yaw ever starts the unwrapped one; no step before it
                inc[0] = yaw[0]
                series.imu_breaks.extend(t[1:][(t - prev_t)[1:] > MAX_STEP_S].tolist())
                unwrapped = np.cumsum(inc)
            else:
                series.imu_breaks.extend(t[(t - prev_t) > MAX_STEP_S].tolist())
                unwrapped = np.cumsum(np.concatenate(([self.yaw_unwrapped], inc)))[1:]
            self.yaw_prev, self.yaw_unwrapped, self.yaw_stamp = float(yaw[-1]), float(unwrapped[-1]), float(t[-1])
        else:
            unwrapped = np.empty(0)
        # the bin's mean yaw is the yaw at the mean stamp of its samples (to within the turn's curvature):
        # summed from a fixed reference, so that the sums keep the stamps' precision
        if self.yaw_ref is None and len(t):
            self.yaw_ref = float(t[0])
        ref = self.yaw_ref if self.yaw_ref is not None else 0.0
        binned = bin_rows(t, np.column_stack((unwrapped, t - ref)), self.open["imu"])
        k = binned.done(final)
        series.imu_t.extend(binned.mids(k))
        series.imu_yaw.extend((binned.sums[:k, 0] / binned.n[:k]).tolist())
        series.imu_yaw_at.extend((ref + binned.sums[:k, 1] / binned.n[:k]).tolist())
        self.open["imu"] = None if final else binned.last_open()

    def _gyro(self, t, idx, w, gc8, series, final: bool) -> None:
        r = self.R[idx, 2]  # base z row of IMU -> base
        wz = r[:, 0] * w[:, 0] + r[:, 1] * w[:, 1] + r[:, 2] * w[:, 2]
        carried = (self.gyro.heading, self.gyro.at)
        heading, at, dt, _ = self.gyro.step(t, wz)
        series.gyro_breaks.extend(t[dt > MAX_STEP_S].tolist())
        noise = self.gyro_noise[idx]
        with np.errstate(invalid="ignore"):
            stated = np.where(noise == noise, noise,
                              np.sqrt(np.minimum(np.maximum(gc8, self.gyro_floor[idx]), self.gyro_cap[idx])))
        if len(stated):
            self.stated_sum = float(np.cumsum(np.concatenate(([self.stated_sum], stated)))[-1])
            self.stated_n += len(stated)
        binned = bin_rows(t, np.column_stack((wz, wz * wz)), self.open["gyro"])
        k = binned.done(final)
        n, total, sq = binned.n[:k], binned.sums[:k, 0], binned.sums[:k, 1]
        m = total / n
        series.gyro_t.extend(binned.mids(k))
        series.gyro_z.extend(m.tolist())
        # the sample variance within the bin, as max(sq / n - m * m, 0.0) * n / max(n - 1, 1)
        series.gyro_var.extend((np.maximum(sq / n - m * m, 0.0) * n / np.maximum(n - 1, 1)).tolist())
        series.gyro_n.extend(n.tolist())
        closing, instants = _closing_headings(binned, heading, at, carried, final)
        series.gyro_heading.extend(closing)
        series.gyro_heading_at.extend(instants)
        self.open["gyro"] = None if final else binned.last_open()
        if final and self.stated_n:
            series.gyro_stated_sigma = self.stated_sum / self.stated_n

    def _accel(self, t, a, qn, level, series, final: bool) -> None:
        """The horizontal specific force minus gravity, in base_link as the configured extrinsic_rpy puts it.

        Gravity is removed in the IMU's own axes with the IMU's own attitude (R(q)^T (0, 0, g) is g times
        the third row of R(q)), which does not depend on the mounting; without an attitude it stays in
        (the doctor fits a constant for it). Then the configured IMU -> base rotation: an IMU turned
        about z by an angle extrinsic_rpy does not state shows the motion's acceleration turned by it.
        """
        fx, fy, fz = a.T
        norm = np.sqrt(fx * fx + fy * fy + fz * fz)
        in_g = (G_UNITS_BAND[0] <= norm) & (norm <= G_UNITS_BAND[1])  # a driver reporting in g
        series.acc_samples += len(norm)
        series.acc_in_g += int(np.count_nonzero(in_g))
        fx, fy, fz = (np.where(in_g, f * GRAVITY, f) for f in (fx, fy, fz))
        x, y, z, w = qn.T
        fx = np.where(level, fx - GRAVITY * 2.0 * (x * z - w * y), fx)
        fy = np.where(level, fy - GRAVITY * 2.0 * (y * z + w * x), fy)
        fz = np.where(level, fz - GRAVITY * (1.0 - 2.0 * (x * x + y * y)), fz)
        R = self.R[self.acc_index].tolist()
        bx = R[0][0] * fx + R[0][1] * fy + R[0][2] * fz
        by = R[1][0] * fx + R[1][1] * fy + R[1][2] * fz
        binned = bin_rows(t, np.column_stack((bx, by, level.astype(float))), self.open["acc"])
        k = binned.done(final)
        n, sums = binned.n[:k], binned.sums[:k]
        series.acc_t.extend(binned.mids(k))
        series.acc_x.extend((sums[:, 0] / n).tolist())
        series.acc_y.extend((sums[:, 1] / n).tolist())
        series.acc_level.extend((sums[:, 2] / n).tolist())
        self.open["acc"] = None if final else binned.last_open()


def _wrap(angle: np.ndarray) -> np.ndarray:
    """rot.wrap on arrays (the same float expression: numpy's % on floats is Python's)."""
    return (angle + math.pi) % rot.TWO_PI - math.pi


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """rot.mul row by row (the same expression order)."""
    ax, ay, az, aw = a.T
    bx, by, bz, bw = b.T
    return np.column_stack((aw * bx + ax * bw + ay * bz - az * by,
                            aw * by - ax * bz + ay * bw + az * bx,
                            aw * bz + ax * by - ay * bx + az * bw,
                            aw * bw - ax * bx - ay * by - az * bz))
