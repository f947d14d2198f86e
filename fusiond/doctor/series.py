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

import math
from operator import attrgetter

import msgspec
import numpy as np

from ..config import Config
from ..core.sensors.registry import kind_of
from ..estimator import rotation as rot
from ..estimator.geodesy import EnuFrame
from ..core.sensors import GpsSample, ImuSample, OdomSample
from .bins import BIN_S
from .streams import MAX_STEP_S, ImuStream, OdomStream

_STAMP = attrgetter("stamp")

__all__ = ["BIN_S", "MAX_STEP_S", "REORDER_S", "Series", "SeriesCollector"]

REORDER_S = 1.0  # samples are integrated in stamp order once they are this much older than the newest
CHUNK = 8192  # samples integrated at once (bounded memory; large enough that numpy's per-call cost vanishes)
_KINDS = frozenset((OdomSample, ImuSample, GpsSample))


class Series(msgspec.Struct):
    """Binned series (one row per BIN_S of each stream) and gaps; NaN where a value is absent."""

    odom_t: list[float] = []
    odom_v: list[float] = []  # mean forward speed, m/s
    odom_wz: list[float] = []  # mean wheel yaw rate, rad/s
    odom_heading: list[float] = []  # integrated wheel yaw rate, rad (unwrapped, starts at 0)
    # The instant each odom_heading holds at: about the bin's END (the heading reached when the bin closed),
    # not odom_t (the middle, where the bin's means hold). A heading compared with another source is
    # interpolated at these instants (see streams._closing_headings).
    odom_heading_at: list[float] = []
    odom_zero_wz: list[int] = []  # samples reporting a yaw rate of exactly 0 with variance 0
    odom_n: list[int] = []
    # samples whose yaw rate the core takes as "not measured" (declared so in twist_measured, or a variance
    # at or above twist_max_sigma^2, NaN or inf: the 1e6 of a driver that has none), so not used
    odom_wz_unmeasured: list[int] = []
    # samples whose stated yaw-rate variance lay below twist_min_sigma's floor (the core used the floor),
    # and the sum of their stated sigmas
    odom_wz_floored: int = 0
    odom_wz_floored_sigma_sum: float = 0.0
    odom_rest: list[bool] = []  # every sample of the bin exactly at rest
    # The filter's own standstills, (first, last stamp), as a replay reports them (``Doctor.add_rest``; a
    # live doctor has none): the odometry's rest test (core/sensors/odom/rest.py), which also finds a drive
    # that reads noise at rest
    rest_spans: list[tuple[float, float]] = []
    odom_gaps: list[tuple[float, float]] = []  # (stamp, length s) of silences longer than gap_s
    # Where an integrated heading was NOT integrated (a step longer than MAX_STEP_S): the stamp of the
    # first sample after the silence. A comparison of integrated headings must not span one (the turn
    # made in the silence is missing from one side only and would look like wander).
    odom_breaks: list[float] = []
    imu_t: list[float] = []
    imu_yaw: list[float] = []  # the IMU's own yaw in base_link (unwrapped), NaN when not measured
    imu_yaw_at: list[float] = []  # the instant each imu_yaw (a mean over the bin) holds at: its samples' mean stamp
    imu_breaks: list[float] = []  # silences of the IMU yaw longer than MAX_STEP_S (its unwrap may skip a turn)
    gyro_t: list[float] = []
    gyro_z: list[float] = []  # mean base-frame gyro z, rad/s
    gyro_var: list[float] = []  # its variance within the bin
    gyro_n: list[int] = []
    gyro_heading: list[float] = []  # integrated raw gyro z (no bias removed), rad
    gyro_heading_at: list[float] = []  # the instant each gyro_heading holds at (about the bin's end, as odom's)
    gyro_breaks: list[float] = []  # silences of the gyro longer than MAX_STEP_S: not integrated across
    gyro_stated_sigma: float = float("nan")  # the noise the filter assumes for the gyro z, rad/s (mean)
    acc_t: list[float] = []
    acc_x: list[float] = []  # accelerometer specific force minus gravity, base_link x through the configured
    acc_y: list[float] = []  # extrinsic_rpy (so a mounting missing from it shows), m/s^2
    acc_level: list[float] = []  # fraction of the bin's samples whose gravity was removed with the IMU's attitude
    acc_samples: int = 0  # the accelerometer samples binned ...
    acc_in_g: int = 0  # ... and of them, those whose magnitude reads as g units (G_UNITS_BAND: a driver in g)
    gps_t: list[float] = []
    gps_e: list[float] = []
    gps_n: list[float] = []
    gps_sigma: list[float] = []  # stated horizontal sigma, m
    gps_u: list[float] = []  # up, m (ENU at the first fix)
    gps_sigma_up: list[float] = []  # stated vertical sigma, m (NaN: not stated)
    gps_origin: tuple[float, float, float] | None = None  # the first valid fix (lat deg, lon deg, alt m)
    est_t: list[float] = []
    est_yaw: list[float] = []
    est_roll: list[float] = []
    est_pitch: list[float] = []
    est_bias_z: list[float] = []
    est_pos_var: list[float] = []  # largest position variance, m^2
    est_att_var: list[float] = []  # largest attitude variance, rad^2


# The series' fields the filter's output fills (``SeriesCollector.add_rest``, ``add_estimate``: the standstills and
# the ``est_`` fields); every other field is the samples'.
FILTER_FIELDS = ("rest_spans", *(f for f in Series.__struct_fields__ if f.startswith("est_")))


def release_order(stamps: np.ndarray, newest: float, final: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """The order in which a reorder buffer releases samples, computed in bulk.

    The buffer (a heap on (stamp, arrival)) releases a sample once one stamped more than REORDER_S after
    it has arrived (a sample already that old on arrival at once), and the rest at the end (``final``).
    Since the newest stamp only grows, each sample's release is one binary search, and the release order
    sorts by (release, stamp, arrival). ``stamps``: the samples still held plus the new ones, in arrival
    order; ``newest``: the newest stamp before them. Returns (positions released, in order; held mask;
    the newest stamp after them)."""
    n = len(stamps)
    if not n:
        return np.empty(0, dtype=np.intp), np.zeros(0, dtype=bool), newest
    running = np.maximum.accumulate(np.concatenate(([newest], stamps)))[1:]
    arrival = np.arange(n)
    release = np.maximum(arrival, np.searchsorted(running - REORDER_S, stamps, side="right"))
    order = np.lexsort((arrival, stamps, release))
    held = np.zeros(n, dtype=bool) if final else release >= n
    return order[~held[order]], held, float(running[-1])


class SeriesCollector:
    """Feeds a :class:`Series` from raw samples (pre-policy: what the sensors said) and estimates.

    Feeding only keeps the sample (the replay calls it for every message); the samples are integrated a
    chunk at a time (``streams``), in the order the reorder buffer releases them, and at :meth:`finish`.
    """

    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        self.series = Series()
        # the streams the cross-source checks compare: the wheels', the IMUs' and the fixes'
        imus = [s for s in cfg.sensors if kind_of(s).inertial]
        odoms = [s for s in cfg.sensors if kind_of(s).drives_prediction]
        gps = [s for s in cfg.sensors if kind_of(s).geodetic]
        self._odom = OdomStream(odoms, cfg.filter.gap_s)
        self._imu = ImuStream(imus)
        self._names = {OdomSample: set(self._odom.index), ImuSample: set(self._imu.index),
                       GpsSample: {s.name for s in gps}}
        # the filter's ENU frame: the configured datum, else the first valid fix (as the core does)
        self._enu: EnuFrame | None = EnuFrame(*gps[0].datum) if gps and gps[0].datum is not None else None
        self._pending: list = []  # samples not integrated yet, in arrival order
        self._due = CHUNK  # integrate when this many are pending
        self._newest = -math.inf  # newest stamp of the samples taken into the reorder buffer so far
        self._est_next = -math.inf

    # -- feeding --------------------------------------------------------------
    def add_sample(self, sample) -> None:
        """Any sample, in arrival order."""
        self.extend((sample,))

    def extend(self, samples) -> None:
        """Samples, in arrival order (the kinds the series has, with a finite stamp; others are skipped)."""
        pending = self._pending
        pending.extend(s for s in samples if type(s) in _KINDS and math.isfinite(s.stamp))
        if len(pending) >= self._due:
            self._integrate(final=False)

    def add_rest(self, stamp: float, since: float) -> None:
        """An odometry message the filter took at rest, since ``since`` (``Series.rest_spans``): one span per
        value of ``since``, reaching the last message at rest."""
        spans = self.series.rest_spans
        if spans and spans[-1][0] == since:
            if stamp > spans[-1][1]:
                spans[-1] = (since, stamp)
        else:
            spans.append((since, stamp))

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

    def take_estimates(self, other: SeriesCollector) -> None:
        """``other``'s estimates and standstills (``add_estimate``, ``add_rest``) as this collector's, which was fed
        none: the samples were collected here and the filter's output there (``Doctor.adopt``)."""
        for name in FILTER_FIELDS:
            setattr(self.series, name, getattr(other.series, name))
        self._est_next = other._est_next

    def wants_estimate(self, t: float) -> bool:
        return t >= self._est_next

    def finish(self) -> Series:
        """Integrates every pending sample and closes the open bins (more samples may follow: they open
        new bins)."""
        self._integrate(final=True)
        return self.series

    # -- internals --------------------------------------------------------------
    def _integrate(self, final: bool) -> None:
        """Integrates the pending samples the reorder buffer has released, in its release order; the
        others stay pending."""
        rows = self._pending
        stamps = np.fromiter(map(_STAMP, rows), dtype=float, count=len(rows))
        order, held, self._newest = release_order(stamps, self._newest, final)
        self._pending = [s for s, h in zip(rows, held.tolist()) if h]
        self._due = len(self._pending) + CHUNK
        released = [rows[i] for i in order.tolist()]
        names = self._names
        odom = [s for s in released if type(s) is OdomSample and s.sensor in names[OdomSample]]
        imu = [s for s in released if type(s) is ImuSample and s.sensor in names[ImuSample]]
        self._odom.take(odom, self.series, final)
        self._imu.take(imu, self.series, final)
        for s in released:
            if type(s) is GpsSample and s.sensor in names[GpsSample]:
                self._gps(s)

    def _gps(self, s: GpsSample) -> None:
        if s.status < 0 or not all(map(math.isfinite, (s.latitude, s.longitude, s.altitude))):
            return
        if self._enu is None:
            self._enu = EnuFrame(s.latitude, s.longitude, s.altitude)
        if self.series.gps_origin is None:
            self.series.gps_origin = (s.latitude, s.longitude, s.altitude)
        e, n, u = self._enu.enu(s.latitude, s.longitude, s.altitude)
        c = s.position_covariance
        sigma = math.sqrt(max(0.5 * (c[0] + c[4]), 0.0)) if len(c) == 9 and s.covariance_type > 0 else math.nan
        ser = self.series
        ser.gps_t.append(s.stamp)
        ser.gps_e.append(e)
        ser.gps_n.append(n)
        ser.gps_sigma.append(sigma)
        ser.gps_u.append(u)
        ser.gps_sigma_up.append(math.sqrt(max(c[8], 0.0)) if len(c) == 9 and s.covariance_type > 0 else math.nan)
