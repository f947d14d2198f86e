"""The heading sources compared: what the heading, wheel-heading, slip, late-bias and gap checks share.

Headings are compared at the instants each holds at (``timed``); the IMU's own yaw against the
integrated gyro over windows of a minute (``detrended_rms``: a gyro bias is a linear drift, a scale
error proportional to the turn, so what is left is the yaw wandering); the wheels' yaw rate fitted
against the gyro's (``wheel_yaw_fit``). The thresholds here judge those shared figures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..config import Config, GpsSensor, ImuSensor
from .gyro import quiet_episodes, rest_bias
from .median import median
from .bins import BIN_S
from .series import Series

__all__ = ["WANDER_RAD", "WHEEL_OFFSET_RAD_S", "WHEEL_SCALE_TOLERANCE", "MIN_TURN_RAD", "timed", "imu_vs_gyro", "gps_sigma_up",
           "imu_yaw_drift", "vs_gyro", "segments", "detrended_rms", "gps_sigma", "rate_fit_text", "zero_while_turning",
           "wheel_yaw_fit", "wheel_yaw_offset", "WheelOffset", "wrap", "yaw_scale"]

WINDOW_S = 60.0  # detrending window: a gyro bias is constant over a minute
# 7 deg a minute, far beyond a magnetometer's (no secular drift) and a learned gyro bias's (~1e-4 rad/s)
MIN_SPAN_S = 10.0  # s: a detrending window whose samples span less than this is too short to fit a bias and is skipped
WANDER_RAD = 0.05  # rms yaw wander (after bias and scale are removed) that is a disturbance, not noise
MIN_TURN_RAD = 0.5  # total turn needed to measure a yaw scale
WHEEL_SCALE_TOLERANCE = 0.1  # wheel yaw within 10 % of the gyro's is fine for a prediction
WHEEL_OFFSET_RAD_S = 0.02  # a wheel yaw-rate offset that turns the heading by a radian a minute
ZERO_TURNING_RAD_S = 0.05  # the gyro turning this fast while the wheels read exactly zero: not at rest
OFFSET_BLOCK_S = 1.0  # s: the wheel-gyro difference averaged per block before its scatter is taken (batch means)
OFFSET_MIN_BLOCKS = 10  # fewer blocks than this measure no offset (a standard error from a handful says little)
OFFSET_ALPHA = 1e-3  # two-sided false-alarm rate of the offset test on a run that hardly turns


def wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2.0 * np.pi) - np.pi


def timed(at: list[float], values: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """A heading series at the instants it holds at (finite values only, in time order, for np.interp).

    Two sources' headings are compared at the same instants, whatever their bins do: the IMU's yaw is a
    mean over its bin and holds at its samples' mean stamp, an integrated heading is the one reached when
    its bin closed and holds about the bin's end (Series.*_heading_at). Paired by bin instead, an agile
    vehicle turning at w shows a false difference of w x BIN_S / 2 (a race car at 1 rad/s: 0.1 rad)."""
    t, v = np.asarray(at, dtype=float), np.asarray(values, dtype=float)
    ok = np.isfinite(t) & np.isfinite(v)
    t, v = t[ok], v[ok]
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def imu_vs_gyro(series: Series) -> tuple[float, float] | None:
    """(wander, drift) of the IMU's own yaw against the integrated raw gyro (``detrended_rms`` of their
    difference, the gyro heading as the scale shape, never across either's silences), compared at the
    instants each holds at; None when they overlap in fewer than 10 bins. The drift is the yaw's own less
    the gyro's bias: yaw - gyro heading drifts at r - b."""
    ti, yi = timed(series.imu_yaw_at, series.imu_yaw)
    return vs_gyro(series, ti, yi, series.imu_breaks)


def imu_yaw_drift(series: Series, cfg: Config, imu: ImuSensor) -> tuple[float, float, bool] | None:
    """(wander, drift rate r, measured at rest) of the IMU's own yaw against the bias-corrected gyro: ``imu_vs_gyro``'s
    slope is r - b, and b is the gyro's z bias as it reads at rest, the median over the run's standstills (the
    first alone can be a false standstill, and the bias moves over a run; one figure for every check that
    names the drift). Without a fused gyro or a standstill b is unknown: 0, and r - b is all that can be told
    (the third item False). None without the IMU's yaw and a gyro heading to compare."""
    compared = imu_vs_gyro(series)
    if compared is None or not all(math.isfinite(v) for v in compared):
        return None
    wander, slope = compared
    rest, _ = quiet_episodes(series, cfg, imu) if imu.angular_velocity else ([], [])
    b = rest_bias(rest)
    if not math.isfinite(b):
        return wander, slope, False
    return wander, slope + b, True


def vs_gyro(series: Series, t: np.ndarray, y: np.ndarray, breaks: list[float]) -> tuple[float, float] | None:
    """``detrended_rms`` of a heading (y at instants t) less the integrated raw gyro at those instants, never
    across the gyro's silences or ``breaks``; None when they overlap in fewer than 10 bins."""
    tg, hg = timed(series.gyro_heading_at, series.gyro_heading)
    if len(t) < 10 or len(tg) < 10:
        return None
    m = (t >= tg[0]) & (t <= tg[-1])
    if m.sum() < 10:
        return None
    gyro_at = np.interp(t[m], tg, hg)
    return detrended_rms(t[m], y[m] - gyro_at, gyro_at, [*series.gyro_breaks, *breaks])


def yaw_scale(t: np.ndarray, h: np.ndarray, t_ref: np.ndarray, h_ref: np.ndarray, breaks=()) -> float:
    """k in h = a + k h_ref + b t (least squares), or NaN when the reference hardly turns. Each stretch
    between breaks (a heading not integrated across a gap) gets its own a: the turn made in a gap is
    missing from h_ref only, not a scale."""
    m = (t >= t_ref[0]) & (t <= t_ref[-1])
    if m.sum() < 10:
        return math.nan
    ref = np.interp(t[m], t_ref, h_ref)
    if np.ptp(ref) < MIN_TURN_RAD:
        return math.nan
    tm = t[m]
    offsets = []
    for idx in segments(tm, breaks):
        col = np.zeros(len(tm))
        col[idx] = 1.0
        offsets.append(col)
    A = np.vstack([*offsets, ref, tm - tm[0]]).T
    coef, *_ = np.linalg.lstsq(A, h[m], rcond=None)
    return float(coef[len(offsets)])


def segments(t: np.ndarray, breaks) -> list[np.ndarray]:
    """Index ranges of t (sorted) between the breaks: data on both sides of a break is never fitted together."""
    cuts = np.searchsorted(t, np.asarray(sorted(set(breaks)), dtype=float), side="left")
    edges = [0, *[int(c) for c in cuts if 0 < c < len(t)], len(t)]
    return [np.arange(a, b) for a, b in zip(edges[:-1], edges[1:]) if b > a]


def detrended_rms(t: np.ndarray, d: np.ndarray, shape: np.ndarray | None, breaks=()) -> tuple[float, float]:
    """rms of d after fitting a + b t (+ c shape) over windows of WINDOW_S; and the median slope b.

    A window never spans a break (a silence across which one of the compared headings was not
    integrated): the turn made in the silence is missing from one side only, and a window spanning
    it would read that step as wander. The windows restart after each break."""
    if len(t) < 10:
        return math.nan, math.nan
    resid, slopes = [], []
    for idx in segments(t, breaks):
        ts, ds = t[idx], d[idx]
        sh = shape[idx] if shape is not None else None
        start = ts[0]
        while start < ts[-1]:
            m = (ts >= start) & (ts < start + WINDOW_S)
            if m.sum() >= 10 and ts[m][-1] - ts[m][0] >= MIN_SPAN_S:
                cols = [np.ones(m.sum()), ts[m] - ts[m][0]]
                if sh is not None:
                    s = sh[m] - sh[m][0]
                    if np.ptp(s) > 0.05:  # the turn is large enough to tell a scale from an offset
                        cols.append(s)
                A = np.vstack(cols).T
                coef, *_ = np.linalg.lstsq(A, ds[m], rcond=None)
                resid.append(ds[m] - A @ coef)
                slopes.append(coef[1])
            start += WINDOW_S / 2.0 if ts[-1] - start > WINDOW_S else WINDOW_S
    if not resid:
        return math.nan, math.nan
    r = np.concatenate(resid)
    return float(np.sqrt(np.mean(r * r))), float(median(slopes))


def gps_sigma(series: Series, gps: GpsSensor | None) -> float:
    if gps is not None and gps.position_noise is not None:
        return float(max(gps.position_noise[0], gps.position_noise[1]))
    s = [v for v in series.gps_sigma if math.isfinite(v)]
    if s:
        return float(median(s))
    return float(gps.unknown_position_sigma[0]) if gps is not None else 2.5


def gps_sigma_up(series: Series, gps: GpsSensor) -> float:
    """The fixes' altitude noise (m) as the filter takes it (``gps_sigma``'s vertical twin): the config's
    position_noise, else the fixes' own (their median), else unknown_position_sigma for fixes that state none."""
    if gps.position_noise is not None:
        return float(gps.position_noise[2])
    stated = [v for v in series.gps_sigma_up if math.isfinite(v)]
    return float(median(stated)) if stated else float(gps.unknown_position_sigma[2])


def rate_fit_text(k: float, offset: float) -> str:
    """'0.70 x gyro - 0.002 rad/s': the scale and the offset of a rate fit, printed apart."""
    return f"{k:.2f} x gyro {'-' if offset < 0 else '+'} {abs(offset):.3f} rad/s"


def zero_while_turning(to: np.ndarray, wz: np.ndarray, tg: np.ndarray,
                        gz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the gyro's rate at the odometry bins, the bins whose wheels read exactly zero while it turned faster
    than ZERO_TURNING_RAD_S): the drive at rest while the vehicle coasts or turns (or a component not
    measured). ``wheel_yaw_fit`` leaves them out of the scale, ``_missed_turn`` sums what they missed."""
    g = np.interp(to, tg, gz)
    return g, (wz == 0.0) & (np.abs(g) > ZERO_TURNING_RAD_S)


def wheel_yaw_fit(series: Series) -> tuple[float, float] | None:
    """(scale k, offset) in wheel yaw rate = offset + k gyro rate, least squares over the run; None
    when the robot hardly turns. Rates, not headings: a wheel yaw offset and a scale separate only
    where the turn rate varies."""
    if len(series.odom_t) < 10 or len(series.gyro_t) < 10:
        return None
    to, wz = np.array(series.odom_t), np.array(series.odom_wz)
    tg, hg, gz = np.array(series.gyro_t), np.array(series.gyro_heading), np.array(series.gyro_z)
    m = (to >= tg[0]) & (to <= tg[-1])
    # a wheel reading exactly zero while the gyro turns: no scale information, left out of the fit
    g, zero = zero_while_turning(to, wz, tg, gz)
    m &= ~zero
    g = g[m]
    if m.sum() < 10 or np.ptp(hg) < MIN_TURN_RAD or np.std(g) < 0.02:
        return None
    (offset, k), *_ = np.linalg.lstsq(np.vstack([np.ones_like(g), g]).T, wz[m], rcond=None)
    return float(k), float(offset)


@dataclass(frozen=True)
class WheelOffset:
    """The wheels' yaw rate less the gyro's over a run that hardly turns (``wheel_yaw_offset``), the gyro's
    own bias taken off as far as it is known, and whether that offset is the wheels' beyond what the gyro's
    bias may still be (``significant``)."""

    offset: float  # rad/s: wheel yaw rate - (gyro rate - the gyro's bias at rest, where known)
    se: float  # rad/s: the offset's standard error from the driving (batch means)
    bias_sigma: float  # rad/s: what the gyro's bias may still be (module doc of the check)
    seconds: float  # s of driving compared
    bias_at_rest: float  # rad/s: the gyro's z bias read at the standstills (NaN: none)

    @property
    def bound(self) -> float:
        """The offset a wheel reading the turn exactly would stay within but once in 1 / OFFSET_ALPHA runs."""
        z = NormalDist().inv_cdf(1.0 - OFFSET_ALPHA / 2.0)
        return z * math.hypot(self.se, self.bias_sigma)

    @property
    def significant(self) -> bool:
        return abs(self.offset) > self.bound


def wheel_yaw_offset(series: Series, cfg: Config, imu: ImuSensor) -> WheelOffset | None:
    """The wheels' yaw-rate offset against the gyro where the run hardly turns (``wheel_yaw_fit`` needs turns
    to part a scale from an offset; on a straight road only the offset shows, and it is what bends a heading
    the wheels drive).

    The difference wheel - gyro is taken over the bins where the wheels move (neither at rest nor reading
    exactly zero while the gyro turns), averaged per OFFSET_BLOCK_S and its standard error taken from the
    blocks' scatter, which holds for a drive whose filter correlates neighbouring bins. The gyro's own z bias
    is in that difference: where the run has standstills (``quiet_episodes``) it is their median reading, off
    by at most what its random walk (``gyro_bias_walk``) moves it over the run; without one, anything the
    filter's own prior allows (``gyro_bias_sigma``). None with fewer than OFFSET_MIN_BLOCKS blocks."""
    if len(series.odom_t) < 10 or len(series.gyro_t) < 10:
        return None
    to, wz = np.array(series.odom_t), np.array(series.odom_wz)
    tg, gz = np.array(series.gyro_t), np.array(series.gyro_z)
    g, zero = zero_while_turning(to, wz, tg, gz)
    rest = np.array(series.odom_rest, dtype=bool) if len(series.odom_rest) == len(to) else np.zeros(len(to), bool)
    m = (to >= tg[0]) & (to <= tg[-1]) & ~zero & ~rest & np.isfinite(wz) & np.isfinite(g)
    if m.sum() < 10:
        return None
    t, d = to[m], wz[m] - g[m]
    block = np.floor((t - t[0]) / OFFSET_BLOCK_S).astype(np.int64)
    ids, inverse, counts = np.unique(block, return_inverse=True, return_counts=True)
    if len(ids) < OFFSET_MIN_BLOCKS:
        return None
    means = np.bincount(inverse, weights=d) / counts
    fc = cfg.filter
    stood, _ = quiet_episodes(series, cfg, imu)
    b = rest_bias(stood)
    span = float(t[-1] - t[0])
    bias_sigma = fc.gyro_bias_walk * math.sqrt(span) if math.isfinite(b) else fc.gyro_bias_sigma
    return WheelOffset(float(np.mean(means)) + (b if math.isfinite(b) else 0.0),
                       float(np.std(means, ddof=1) / math.sqrt(len(means))), bias_sigma,
                       float(len(d) * BIN_S), b)
