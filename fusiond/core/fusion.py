"""The fusion core: time, ordering, sensor policies and diagnostics around the estimator.

Fed by the live daemon and by bag replay alike. Time is message time (header
stamps) only; wall clock never enters here.

Ordering. Sensors' stamps lag differently and Zenoh delivers per key, so samples
arrive in any order. Every applied sample is kept in a bounded history together
with the complete filter state after it. A sample older than the newest is
inserted at its own stamp: the state just before it is restored and the later
samples are re-applied (robot_localization's lagged-data smoothing). Because all
filter-affecting state is in the snapshot and events are ordered by
(stamp, sensor), the estimate does not depend on arrival order as long as nothing
falls out of the history, which is what makes replay and live agree.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import msgspec
import numpy as np
import structlog

from ..config import Config, ImuSensor, OdomSensor
from ..estimator import ErrorStateEKF, GyroBiasBlock, MotionInput, PoseBlock, StateLayout, predict
from ..estimator import mat3
from ..estimator import observations as obs
from ..estimator import rotation as rot
from ..samples import ImuSample, OdomSample, Sample
from .diagnostics import DiagnosticsRecord, NisWindow
from .sensors import ImuInput, ImuPolicy, OdomInput, OdomPolicy, Rejected

log = structlog.get_logger("fusiond.core")

ZERO_RATE_GATE = 5.0  # sqrt(NIS) gate of the standstill bias update: a hand-turned robot is not at rest
PERIOD_SMOOTHING = 0.1  # EMA weight of a new inter-message interval
TIMEOUT_PERIODS = 3.0  # a sensor is silent after max(timeout_s, this many typical periods)
_GYRO_COMPONENTS = ["gyro_x", "gyro_y", "gyro_z"]


class Estimate(msgspec.Struct, gc=False):
    """What the service publishes: pose with covariance and twist, ROS row-major 6x6 layouts."""

    stamp: float
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    pose_covariance: list[float]
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    twist_covariance: list[float]


@dataclass(slots=True)
class Step:
    """What one ingested sample did."""

    sensor: str
    accepted: bool
    reason: str = ""  # drop reason when not accepted
    late: bool = False
    publish: bool = False  # an odometry sample: the daemon publishes the newest estimate now
    records: list[DiagnosticsRecord] = field(default_factory=list)


@dataclass(slots=True)
class SensorStats:
    received: int = 0
    applied: int = 0
    late: int = 0
    rejected: int = 0  # gated updates
    dropped: dict[str, int] = field(default_factory=dict)
    newest_stamp: float | None = None

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())


class FilterState:
    """Everything that affects the estimate; copied into the history after each event."""

    __slots__ = (
        "t", "ekf", "last", "period",
        "linear", "linear_cov", "wheel_angular", "wheel_angular_cov", "wheel_yaw_measured",
        "gyro", "gyro_cov", "gyro_last",
        "still_since", "attitude_ready", "yaw_offset", "adaptive",
    )

    def copy(self) -> "FilterState":
        c = FilterState.__new__(FilterState)
        c.t = self.t
        c.ekf = self.ekf.copy()
        c.last = list(self.last)
        c.period = list(self.period)
        # numpy inputs are replaced on update, never mutated, so sharing them is safe
        c.linear, c.linear_cov = self.linear, self.linear_cov
        c.wheel_angular, c.wheel_angular_cov = self.wheel_angular, self.wheel_angular_cov
        c.wheel_yaw_measured = self.wheel_yaw_measured
        c.gyro, c.gyro_cov, c.gyro_last = self.gyro, self.gyro_cov, self.gyro_last
        c.still_since = self.still_since
        c.attitude_ready = self.attitude_ready
        c.yaw_offset = dict(self.yaw_offset)
        c.adaptive = {k: list(v) for k, v in self.adaptive.items()}
        return c


class FusionCore:
    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        fc = cfg.filter
        self.sensors = list(cfg.sensors)
        self.index = {s.name: i for i, s in enumerate(self.sensors)}
        self.policies: list[OdomPolicy | ImuPolicy] = [
            OdomPolicy(s) if isinstance(s, OdomSensor) else ImuPolicy(s) for s in self.sensors
        ]
        self.odom_index = next((i for i, s in enumerate(self.sensors) if isinstance(s, OdomSensor)), -1)
        gyro_imus = [i for i, s in enumerate(self.sensors) if isinstance(s, ImuSensor) and s.angular_velocity]
        blocks = [PoseBlock(fc.initial_sigma[0], fc.initial_sigma[1])]
        if gyro_imus:
            blocks.append(GyroBiasBlock(fc.gyro_bias_sigma, fc.gyro_bias_walk))
        self.layout = StateLayout(blocks)
        self.has_bias = self.layout.has("gyro_bias")
        # A roll/pitch-only update may correct roll, pitch and the x/y gyro bias, never
        # position, heading or the z bias (which drives heading).
        self.tilt_mask = np.ones(self.layout.error_dim, dtype=bool)
        self.tilt_mask[[0, 1, 2, 5]] = False
        if self.has_bias:
            self.tilt_mask[self.layout.error["gyro_bias"].start + 2] = False
        self.noise_density = self.layout.noise_density(
            np.array([fc.process_noise[0] ** 2] * 3 + [fc.process_noise[1] ** 2] * 3)
        )
        self.gap_var = np.zeros(self.layout.error_dim)
        self.gap_var[0:3] = fc.gap_inflation[0] ** 2
        self.gap_var[3:6] = fc.gap_inflation[1] ** 2
        self.caps = np.full(self.layout.error_dim, math.inf)
        self.caps[0:3] = fc.covariance_cap[0]
        self.caps[3:6] = fc.covariance_cap[1]
        odom = self.sensors[self.odom_index] if self.odom_index >= 0 else None
        unmeasured = odom.twist_unmeasured_sigma if isinstance(odom, OdomSensor) else [0.1, 0.1]
        self.default_linear_cov = mat3.diag(*[unmeasured[0] ** 2] * 3)
        self.default_angular_cov = mat3.diag(*[unmeasured[1] ** 2] * 3)
        self._u = MotionInput()
        self._u.world_frame = isinstance(odom, OdomSensor) and odom.twist_frame == "world"
        self.stats = [SensorStats() for _ in self.sensors]
        self.windows: dict[tuple[int, str], NisWindow] = {}
        self.state: FilterState | None = None
        self._reset_history()
        self._suspect = 0  # consecutive samples far from filter time
        self.resets = 0
        self.covariance_resets = 0

    # -- public API ---------------------------------------------------------
    def ingest(self, sample: Sample) -> Step:
        idx = self.index.get(sample.sensor)
        if idx is None:
            return Step(sample.sensor, False, "unknown_sensor")
        st = self.stats[idx]
        st.received += 1
        stamp = sample.stamp
        if not (math.isfinite(stamp) and stamp > 0.0):
            return self._drop(idx, "invalid_stamp", stamp)
        policy = self.policies[idx]
        try:
            if isinstance(policy, OdomPolicy):
                if not isinstance(sample, OdomSample):
                    raise Rejected("wrong_type", "expected odometry")
            elif not isinstance(sample, ImuSample):
                raise Rejected("wrong_type", "expected imu")
            inp = policy.convert(sample)  # type: ignore[arg-type]
        except Rejected as r:
            return self._drop(idx, r.reason, stamp)

        if self.state is None:
            self._start()
        assert self.state is not None
        jump = self.cfg.filter.jump_s
        t = self.state.t
        if t is not None and (stamp < t - jump or stamp > t + jump):
            self._suspect += 1
            if self._suspect < self.cfg.filter.jump_confirm:
                return self._drop(idx, "stale_stamp" if stamp < t else "future_stamp", stamp)
            self._suspect = 0
            if stamp < t:
                log.warning("time_jump_reset", sensor=sample.sensor, stamp=stamp, filter_time=t)
                self.resets += 1
                self._start()
            else:
                log.warning("time_jump_forward", sensor=sample.sensor, stamp=stamp, filter_time=t)
        else:
            self._suspect = 0

        key = (stamp, idx)
        pos = bisect.bisect_right(self._keys, key)
        if pos > 0 and self._keys[pos - 1] == key:
            return self._drop(idx, "duplicate_stamp", stamp)
        late = pos < len(self._keys)
        if late:
            if self._base.t is not None and stamp < self._base.t:
                return self._drop(idx, "too_old", stamp)
            self.state = (self._after[pos - 1] if pos > 0 else self._base).copy()
        records = self._apply(self.state, idx, inp, stamp, emit=True, late=late)
        self._keys.insert(pos, key)
        self._events.insert(pos, (idx, inp, stamp))
        self._after.insert(pos, self.state.copy())
        if late:
            for j in range(pos + 1, len(self._events)):
                jdx, jinp, jstamp = self._events[j]
                self._apply(self.state, jdx, jinp, jstamp, emit=False, late=False)
                self._after[j] = self.state.copy()
        self._trim()
        st.applied += 1
        if late:
            st.late += 1
        if st.newest_stamp is None or stamp > st.newest_stamp:
            st.newest_stamp = stamp
        for r in records:
            w = self._window(idx, r.channel)
            r.consistency = w.add(r.nis, r.dof, r.rejected)
            if r.rejected and r.channel != "yaw_rate":
                st.rejected += 1
        return Step(sample.sensor, True, late=late, publish=idx == self.odom_index, records=records)

    @property
    def initialised(self) -> bool:
        return self.state is not None and self.state.t is not None

    @property
    def time(self) -> float | None:
        return None if self.state is None else self.state.t

    def estimate(self) -> Estimate:
        """The newest estimate (at filter time)."""
        s = self.state
        if s is None or s.t is None:
            raise RuntimeError("no sample has been fused yet")
        x, P = s.ekf.x, s.ekf.P
        u = self._inputs(s)
        angular = u.angular
        if u.from_gyro and self.has_bias:
            b = x[self.layout.nominal["gyro_bias"]].tolist()
            angular = (angular[0] - b[0], angular[1] - b[1], angular[2] - b[2])
        twist_cov = np.zeros((6, 6))
        twist_cov[0:3, 0:3] = np.reshape(u.linear_cov, (3, 3))
        twist_cov[3:6, 3:6] = np.reshape(u.angular_cov, (3, 3))
        return Estimate(
            stamp=s.t,
            position=(float(x[0]), float(x[1]), float(x[2])),
            orientation=(float(x[3]), float(x[4]), float(x[5]), float(x[6])),
            pose_covariance=P[0:6, 0:6].ravel().tolist(),
            linear=tuple(u.linear),
            angular=tuple(angular),
            twist_covariance=twist_cov.ravel().tolist(),
        )

    def pose(self) -> tuple[float, np.ndarray]:
        """(filter time, nominal [x y z qx qy qz qw]) without building a full Estimate."""
        if not self.initialised:
            raise RuntimeError("no sample has been fused yet")
        return self.state.t, self.state.ekf.x[0:7]

    @property
    def gyro_bias(self) -> np.ndarray | None:
        if not self.initialised or not self.has_bias:
            return None
        return self.state.ekf.x[self.layout.nominal["gyro_bias"]].copy()

    def consistency(self) -> dict[str, dict]:
        return {f"{self.sensors[i].name}/{ch}": w.summary() for (i, ch), w in sorted(self.windows.items())}

    def fresh(self, name: str) -> bool:
        """Is the sensor alive in message time (stamp of its newest sample vs filter time)?"""
        idx = self.index[name]
        s = self.state
        if s is None or s.t is None or s.last[idx] is None:
            return False
        return s.t - s.last[idx] <= self.timeout(idx, s)

    def timeout(self, idx: int, s: FilterState | None = None) -> float:
        s = s or self.state
        base = self.sensors[idx].timeout_s
        if s is None or s.period[idx] <= 0.0:
            return base
        return max(base, TIMEOUT_PERIODS * s.period[idx])

    # -- internals ------------------------------------------------------------
    def _drop(self, idx: int, reason: str, stamp: float) -> Step:
        st = self.stats[idx]
        n = st.dropped.get(reason, 0) + 1
        st.dropped[reason] = n
        if n == 1 or n % 1000 == 0:
            log.warning("sample_dropped", sensor=self.sensors[idx].name, reason=reason, stamp=stamp, count=n)
        return Step(self.sensors[idx].name, False, reason)

    def _window(self, idx: int, channel: str) -> NisWindow:
        w = self.windows.get((idx, channel))
        if w is None:
            w = NisWindow(self.cfg.filter.nis_window, self.cfg.filter.nis_confidence)
            self.windows[(idx, channel)] = w
        return w

    def _start(self) -> None:
        """A fresh state with no time yet: the first sample in stamp order sets it, so the
        start does not depend on which sensor happened to arrive first."""
        s = FilterState()
        s.t = None
        s.ekf = ErrorStateEKF(self.layout)
        n = len(self.sensors)
        s.last = [None] * n
        s.period = [0.0] * n
        s.linear = _ZERO3
        s.linear_cov = self.default_linear_cov
        s.wheel_angular = _ZERO3
        s.wheel_angular_cov = self.default_angular_cov
        s.wheel_yaw_measured = False
        s.gyro = None
        s.gyro_cov = None
        s.gyro_last = None
        s.still_since = None
        s.attitude_ready = False
        s.yaw_offset = {}
        s.adaptive = {}
        self.state = s
        self._reset_history()

    def _reset_history(self) -> None:
        self._keys: list[tuple[float, int]] = []
        self._events: list[tuple[int, OdomInput | ImuInput, float]] = []
        self._after: list[FilterState] = []
        self._base = self.state.copy() if self.state is not None else None

    def _trim(self) -> None:
        fc = self.cfg.filter
        horizon = self._keys[-1][0] - fc.history_s
        n = 0
        while len(self._keys) - n > fc.history_max or (n < len(self._keys) and self._keys[n][0] < horizon):
            n += 1
        if n:
            self._base = self._after[n - 1]
            del self._keys[:n], self._events[:n], self._after[:n]

    def _inputs(self, s: FilterState) -> MotionInput:
        """Motion inputs held at time s.t; a silent sensor's input is not held forever."""
        u = self._u
        odom = self.odom_index
        odom_fresh = odom >= 0 and s.last[odom] is not None and s.t - s.last[odom] <= self.timeout(odom, s)
        if odom_fresh:
            u.linear, u.linear_cov, u.linear_period = s.linear, s.linear_cov, s.period[odom]
        else:
            u.linear, u.linear_cov, u.linear_period = _ZERO3, self.default_linear_cov, 0.0
        gyro_fresh = s.gyro is not None and s.t - s.gyro_last[1] <= self.timeout(s.gyro_last[0], s)
        if gyro_fresh:
            u.angular, u.angular_cov, u.angular_period = s.gyro, s.gyro_cov, s.period[s.gyro_last[0]]
            u.from_gyro = True
        elif odom_fresh:
            u.angular, u.angular_cov, u.angular_period = s.wheel_angular, s.wheel_angular_cov, s.period[odom]
            u.from_gyro = False
        else:
            u.angular, u.angular_cov, u.angular_period = _ZERO3, self.default_angular_cov, 0.0
            u.from_gyro = False
        return u

    def _predict(self, s: FilterState, dt: float) -> None:
        u = self._inputs(s)
        x, F, Q = predict(self.layout, s.ekf.x, u, dt, self.noise_density)
        if dt > self.cfg.filter.gap_s:
            Q[np.diag_indices_from(Q)] += self.gap_var * (dt - self.cfg.filter.gap_s)
        if not s.ekf.propagate(x, F, Q):
            self._covariance_reset(s)
        s.ekf.cap_covariance(self.caps)

    def _covariance_reset(self, s: FilterState) -> None:
        self.covariance_resets += 1
        log.error("covariance_reset", stamp=s.t, reason="non-finite covariance")

    def _note_period(self, s: FilterState, idx: int, stamp: float) -> None:
        last = s.last[idx]
        if last is not None and stamp > last:
            d = min(stamp - last, 1.0)
            s.period[idx] = d if s.period[idx] <= 0.0 else s.period[idx] + PERIOD_SMOOTHING * (d - s.period[idx])
        s.last[idx] = stamp if last is None else max(last, stamp)

    def _apply(self, s: FilterState, idx: int, inp, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        if s.t is None:
            s.t = stamp
        elif stamp > s.t:
            self._predict(s, stamp - s.t)
            s.t = stamp
        self._note_period(s, idx, stamp)
        if isinstance(inp, OdomInput):
            return self._apply_odom(s, idx, inp, stamp, emit, late)
        return self._apply_imu(s, idx, inp, stamp, emit, late)

    def _apply_odom(self, s: FilterState, idx: int, inp: OdomInput, stamp: float, emit: bool, late: bool):
        s.linear, s.linear_cov = inp.linear, inp.linear_cov
        s.wheel_angular, s.wheel_angular_cov = inp.angular, inp.angular_cov
        s.wheel_yaw_measured = inp.yaw_rate_measured
        if inp.stationary:
            if s.still_since is None:
                s.still_since = stamp
        else:
            s.still_since = None
        if not emit or s.gyro is None or not inp.yaw_rate_measured:
            return []
        if stamp - s.gyro_last[1] > self.timeout(s.gyro_last[0], s):
            return []
        # The wheels' yaw rate is not fused once the gyro drives heading; it only
        # checks the gyro, so that skid and hand-turning show up as slip.
        bias_z = s.ekf.x[self.layout.nominal["gyro_bias"]][2] if self.has_bias else 0.0
        gyro_z = s.gyro[2] - float(bias_z)
        var = inp.angular_cov[8] + s.gyro_cov[8]
        if self.has_bias:
            e = self.layout.error["gyro_bias"].start + 2
            var += float(s.ekf.P[e, e])
        r = inp.angular[2] - gyro_z
        slip = abs(r) > self.sensors[idx].slip_threshold
        return [
            DiagnosticsRecord(stamp, self.sensors[idx].name, ["yaw_rate"], [r], [var], r * r / var, 1, slip,
                              channel="yaw_rate", late=late)
        ]

    def _apply_imu(self, s: FilterState, idx: int, inp: ImuInput, stamp: float, emit: bool, late: bool):
        cfg: ImuSensor = self.sensors[idx]  # type: ignore[assignment]
        records: list[DiagnosticsRecord] = []
        if inp.gyro is not None:
            s.gyro, s.gyro_cov, s.gyro_last = inp.gyro, inp.gyro_cov, (idx, stamp)
            odom = self.odom_index
            resting = (
                self.has_bias
                and s.still_since is not None
                and stamp - s.still_since >= self.cfg.filter.standstill_s
                and s.last[odom] is not None
                and stamp - s.last[odom] <= self.timeout(odom, s)
            )
            if resting:
                y, H, R = obs.zero_rate(self.layout, s.ekf.x, inp.gyro, inp.gyro_cov)
                res = s.ekf.update(y, H, R, ZERO_RATE_GATE)
                if emit:
                    records.append(DiagnosticsRecord(stamp, cfg.name, _GYRO_COMPONENTS, y.tolist(), res.innovation_var,
                                                     res.nis, 3, res.rejected, channel="gyro_bias", late=late))
        if inp.rpy is not None and inp.rows:
            rpy = inp.rpy
            if not s.attitude_ready:
                self._initialise_attitude(s, rpy, cfg.orientation == "absolute")
            if cfg.orientation == "relative":
                off = s.yaw_offset.get(cfg.name)
                if off is None:
                    off = rot.wrap(rpy[2] - rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2])
                    s.yaw_offset[cfg.name] = off
                rpy = (rpy[0], rpy[1], rot.wrap(rpy[2] - off))
            y, H, R = obs.orientation(self.layout, s.ekf.x, rpy, inp.rpy_cov, inp.rows)
            scale = self._adaptive_scale(s, cfg, "orientation")
            tilt_only = 2 not in inp.rows
            if tilt_only:
                heading = rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2]
            res = s.ekf.update(y, H, R * scale if scale != 1.0 else R, cfg.mahalanobis_threshold,
                               self.tilt_mask if tilt_only else None)
            if tilt_only and not res.rejected:
                # A world-x/y correction of a tilted body still turns its Euler yaw a
                # little (second order); put the heading back exactly.
                r, p, _ = rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))
                s.ekf.x[3:7] = rot.from_rpy(r, p, heading)
            if cfg.adaptive:
                self._adapt(s, cfg, "orientation", res.nis, len(inp.rows))
            if emit:
                records.append(DiagnosticsRecord(stamp, cfg.name, [obs.RPY_NAMES[i] for i in inp.rows], y.tolist(),
                                                 res.innovation_var, res.nis, len(inp.rows), res.rejected,
                                                 channel="orientation", late=late))
        return records

    def _initialise_attitude(self, s: FilterState, rpy: tuple[float, float, float], with_yaw: bool) -> None:
        """Take roll/pitch (and yaw when absolute) from the first orientation sample."""
        yaw = rpy[2] if with_yaw else rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[2]
        s.ekf.x[3:7] = rot.from_rpy(rpy[0], rpy[1], yaw)
        s.attitude_ready = True

    def _adaptive_scale(self, s: FilterState, cfg: ImuSensor, channel: str) -> float:
        if not cfg.adaptive:
            return 1.0
        return s.adaptive.get(f"{cfg.name}/{channel}", [1.0, 0.0, 0])[0]

    def _adapt(self, s: FilterState, cfg: ImuSensor, channel: str, nis: float, dof: int) -> None:
        """Window of NIS/dof; at its end R's scale moves by the window mean (bounded)."""
        if not math.isfinite(nis):
            return
        a = s.adaptive.setdefault(f"{cfg.name}/{channel}", [1.0, 0.0, 0])
        a[1] += nis / dof
        a[2] += 1
        if a[2] >= cfg.adaptive_window:
            a[0] = min(max(a[0] * (a[1] / a[2]), ADAPTIVE_MIN), ADAPTIVE_MAX)
            a[1], a[2] = 0.0, 0


ADAPTIVE_MIN, ADAPTIVE_MAX = 0.1, 100.0
_ZERO3 = (0.0, 0.0, 0.0)
