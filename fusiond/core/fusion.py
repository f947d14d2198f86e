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

from ..config import Config, GpsSensor, ImuSensor, OdomSensor, PoseSensor
from ..estimator import (
    ErrorStateEKF, GyroBiasBlock, GyroScaleBlock, MotionInput, PoseBlock, StateLayout, WheelScaleBlock, predict,
)
from ..estimator import mat3
from ..estimator import observations as obs
from ..estimator import rotation as rot
from ..estimator.geodesy import EnuFrame
from ..samples import GpsSample, ImuSample, OdomSample, PoseSample, Sample
from .diagnostics import DiagnosticsRecord, NisWindow
from .sensors import (
    GpsInput, GpsPolicy, ImuInput, ImuPolicy, OdomInput, OdomPolicy, PoseInput, PosePolicy, Rejected,
)

log = structlog.get_logger("fusiond.core")

ZERO_RATE_GATE = 5.0  # sqrt(NIS) gate of the standstill bias update: a hand-turned robot is not at rest
PERIOD_SMOOTHING = 0.1  # EMA weight of a new inter-message interval
TIMEOUT_PERIODS = 3.0  # a sensor is silent after max(timeout_s, this many typical periods)
_GYRO_COMPONENTS = ["gyro_x", "gyro_y", "gyro_z"]
HEADING_MIN_TRAVEL = 0.3  # odometry chord / GPS chord below this: pushed, slipping or a GPS jump, start over
HEADING_SIGMA_FLOOR = 0.02  # rad added to the chord-angle uncertainty of the initial GPS heading
_POLICIES = {OdomSensor: (OdomPolicy, OdomSample), ImuSensor: (ImuPolicy, ImuSample),
             GpsSensor: (GpsPolicy, GpsSample), PoseSensor: (PosePolicy, PoseSample)}


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
        "frame_ready", "enu", "heading_ready", "gps_anchor", "travel", "pose_anchor",
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
        # world frame: flags and immutable values (tuples, EnuFrame) only, so sharing is safe
        c.frame_ready, c.enu, c.heading_ready = self.frame_ready, self.enu, self.heading_ready
        c.gps_anchor, c.travel = self.gps_anchor, self.travel
        c.pose_anchor = self.pose_anchor  # copy-on-write: replaced, never mutated
        return c


class FusionCore:
    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        fc = cfg.filter
        self.sensors = list(cfg.sensors)
        self.index = {s.name: i for i, s in enumerate(self.sensors)}
        self.policies = [_POLICIES[type(s)][0](s) for s in self.sensors]
        self._sample_types = [_POLICIES[type(s)][1] for s in self.sensors]
        self.odom_index = next((i for i, s in enumerate(self.sensors) if isinstance(s, OdomSensor)), -1)
        gyro_imus = [i for i, s in enumerate(self.sensors) if isinstance(s, ImuSensor) and s.angular_velocity]
        blocks = [PoseBlock(fc.initial_sigma[0], fc.initial_sigma[1])]
        if gyro_imus:
            blocks.append(GyroBiasBlock(fc.gyro_bias_sigma, fc.gyro_bias_walk))
        if any(isinstance(s, ImuSensor) and s.gyro_scale_estimation for s in self.sensors):
            blocks.append(GyroScaleBlock(fc.gyro_scale_sigma, fc.gyro_scale_walk))
        if any(isinstance(s, OdomSensor) and s.scale_estimation for s in self.sensors):
            blocks.append(WheelScaleBlock(fc.wheel_scale_sigma, fc.wheel_scale_walk))
        self.layout = StateLayout(blocks)
        self.has_bias = self.layout.has("gyro_bias")
        self.has_gyro_scale = self.layout.has("gyro_scale")
        # A roll/pitch-only update may correct roll, pitch and the x/y gyro bias, never
        # position, heading, the z bias or a scale (which drive heading and position).
        self.tilt_mask = np.ones(self.layout.error_dim, dtype=bool)
        self.tilt_mask[[0, 1, 2, 5]] = False
        if self.has_bias:
            self.tilt_mask[self.layout.error["gyro_bias"].start + 2] = False
        for name in ("gyro_scale", "wheel_scale"):
            if self.layout.has(name):
                self.tilt_mask[self.layout.error[name]] = False
        # While the GPS heading is unknown a fix may only move position: a wrong heading
        # must not be "explained" by attitude, biases or scales.
        self.position_mask = np.zeros(self.layout.error_dim, dtype=bool)
        self.position_mask[0:3] = True
        # The sensor that defines the world frame (GPS: ENU at the datum; an absolute pose
        # sensor: its own frame); nothing is published before its first message.
        self.frame_index = next((i for i, s in enumerate(self.sensors) if isinstance(s, GpsSensor)
                                 or (isinstance(s, PoseSensor) and not s.differential)), -1)
        self.gps_index = next((i for i, s in enumerate(self.sensors) if isinstance(s, GpsSensor)), -1)
        # A pose delta fused against the filter's previous pose acts on the absolute pose as
        # if that previous pose were exact, which collapses P of position and heading. Alone
        # that is robot_pose_ekf's behaviour; beside an absolute sensor it would lock the GPS
        # out, so there the delta may correct tilt, biases and scales only (Schmidt update).
        # The exact treatment, cloning the previous pose into the state, is not done yet.
        self.delta_mask = None
        if self.frame_index >= 0:
            self.delta_mask = np.ones(self.layout.error_dim, dtype=bool)
            self.delta_mask[[0, 1, 2, 5]] = False
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
            if type(sample) is not self._sample_types[idx]:
                raise Rejected("wrong_type", f"expected {self._sample_types[idx].__name__}")
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
        publish = idx == self.odom_index and (self.frame_index < 0 or self.state.frame_ready)
        return Step(sample.sensor, True, late=late, publish=publish, records=records)

    @property
    def initialised(self) -> bool:
        return self.state is not None and self.state.t is not None

    @property
    def ready(self) -> bool:
        """Is the world frame defined? False until an absolute sensor's first message (health: not_ready_reason)."""
        return self.initialised and (self.frame_index < 0 or self.state.frame_ready)

    @property
    def not_ready_reason(self) -> str:
        if self.ready:
            return ""
        if not self.initialised:
            return "no sample fused yet"
        s = self.sensors[self.frame_index]
        what = "GPS fix" if isinstance(s, GpsSensor) else "pose"
        return f"waiting for the first {what} from {s.name!r} to define the world frame"

    @property
    def heading_known(self) -> bool:
        """False while a GPS-referenced heading is not yet measured (no travel since the first fix)."""
        if self.gps_index < 0:
            return True
        return self.state is not None and self.state.heading_ready

    @property
    def scales(self) -> dict[str, float]:
        """Estimated scale factors (wheel_scale, gyro_scale) that are in the state."""
        if not self.initialised:
            return {}
        return {n: float(self.state.ekf.x[self.layout.nominal[n]][0])
                for n in ("wheel_scale", "gyro_scale") if self.layout.has(n)}

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
        linear, angular = u.linear, u.angular
        if self.layout.input_blocks:
            xl = x.tolist()
            for blk, n0, n1, _ in self.layout.input_blocks:
                if blk.applies(u.from_gyro):
                    if blk.corrects == "linear":
                        linear = blk.correct(xl[n0:n1], linear)
                    else:
                        angular = blk.correct(xl[n0:n1], angular)
        twist_cov = np.zeros((6, 6))
        twist_cov[0:3, 0:3] = np.reshape(u.linear_cov, (3, 3))
        twist_cov[3:6, 3:6] = np.reshape(u.angular_cov, (3, 3))
        return Estimate(
            stamp=s.t,
            position=(float(x[0]), float(x[1]), float(x[2])),
            orientation=(float(x[3]), float(x[4]), float(x[5]), float(x[6])),
            pose_covariance=P[0:6, 0:6].ravel().tolist(),
            linear=tuple(linear),
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
        s.frame_ready = False
        gps = self.sensors[self.gps_index] if self.gps_index >= 0 else None
        s.enu = EnuFrame(*gps.datum) if isinstance(gps, GpsSensor) and gps.datum is not None else None
        s.heading_ready = False
        s.gps_anchor = None  # (first fix in ENU, filter antenna lever R t then) for the heading
        s.travel = _ZERO3  # dead-reckoned base motion since that fix
        s.pose_anchor = {}  # differential pose: name -> (measured position, q, predicted motion since (dp, dq))
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
        if s.gps_anchor is not None:  # GPS heading pending: accumulate the dead-reckoned motion
            x0 = s.ekf.x
            t = s.travel
            s.travel = (t[0] + float(x[0] - x0[0]), t[1] + float(x[1] - x0[1]), t[2] + float(x[2] - x0[2]))
        if s.pose_anchor:
            s.pose_anchor = _accumulate_motion(s.pose_anchor, s.ekf.x, x)
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
        if isinstance(inp, ImuInput):
            return self._apply_imu(s, idx, inp, stamp, emit, late)
        if isinstance(inp, GpsInput):
            return self._apply_gps(s, idx, inp, stamp, emit, late)
        return self._apply_pose(s, idx, inp, stamp, emit, late)

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
        if self.has_gyro_scale:
            gyro_z *= float(s.ekf.x[self.layout.nominal["gyro_scale"]][0])
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

    # -- absolute and relative position sensors ---------------------------------------------------------------
    def _apply_gps(self, s: FilterState, idx: int, inp: GpsInput, stamp: float, emit: bool, late: bool):
        cfg: GpsSensor = self.sensors[idx]  # type: ignore[assignment]
        if s.enu is None:
            s.enu = EnuFrame(*inp.lla)  # no datum configured: the first valid fix (in stamp order)
        z = s.enu.enu(*inp.lla)
        ekf = s.ekf
        if not s.frame_ready:
            self._set_position(s, z, inp.cov, cfg.extrinsic_xyz)
            s.frame_ready = True
            s.pose_anchor = {}
            s.gps_anchor = (z, _lever(ekf.x, cfg.extrinsic_xyz))
            s.travel = _ZERO3
            return []
        if not s.heading_ready:
            self._gps_heading(s, cfg, z, inp.cov)
        y, H, R = obs.position(self.layout, ekf.x, z, inp.cov, cfg.extrinsic_xyz)
        if s.heading_ready:
            res = ekf.update(y, H, R, cfg.mahalanobis_threshold)
            channel = "position"
        else:
            # Heading unknown: the fix may move position only, and is not gated (a dead-reckoned
            # track along a wrong heading must not lock the filter out of the GPS).
            res = ekf.update(y, H, R, math.inf, self.position_mask)
            channel = "position_unaligned"
        if not emit:
            return []
        return [DiagnosticsRecord(stamp, cfg.name, list(_ENU_NAMES), y.tolist(), res.innovation_var, res.nis, 3,
                                  res.rejected, channel=channel, late=late)]

    def _gps_heading(self, s: FilterState, cfg: GpsSensor, z: tuple[float, float, float], cov) -> None:
        """Initial heading from the first metres of travel: the angle between the GPS chord and
        the dead-reckoned chord of the antenna since the first fix. A wrong initial yaw rotates
        the whole dead-reckoned track about its start, so the chord angles differ by exactly
        the yaw error, whatever the path's shape."""
        z0, l0 = s.gps_anchor
        gx, gy = z[0] - z0[0], z[1] - z0[1]
        d = math.hypot(gx, gy)
        sigma = math.sqrt(max(cov[0], cov[4]))
        if d < max(cfg.heading_init_m, 4.0 * sigma):
            return
        l1 = _lever(s.ekf.x, cfg.extrinsic_xyz)
        fx, fy = s.travel[0] + l1[0] - l0[0], s.travel[1] + l1[1] - l0[1]
        if math.hypot(fx, fy) < HEADING_MIN_TRAVEL * d:
            s.gps_anchor, s.travel = (z, l1), _ZERO3  # GPS wander or a pushed robot: start over
            return
        dyaw = rot.wrap(math.atan2(gy, gx) - math.atan2(fy, fx))
        ekf = s.ekf
        q = (float(ekf.x[3]), float(ekf.x[4]), float(ekf.x[5]), float(ekf.x[6]))
        ekf.x[3:7] = rot.normalize(rot.mul(rot.exp(0.0, 0.0, dyaw), q))
        sig = math.sqrt(2.0) * sigma / d + HEADING_SIGMA_FLOOR
        P = ekf.P.copy()
        P[5, :] = 0.0
        P[:, 5] = 0.0
        P[5, 5] = sig * sig
        ekf.P = P
        s.heading_ready = True
        s.gps_anchor, s.travel = None, _ZERO3
        s.pose_anchor = {}  # the frame turned under them: deltas restart from the next message
        log.info("gps_heading_initialised", sensor=cfg.name, yaw_correction=dyaw, sigma=sig, chord_m=d)

    def _set_position(self, s: FilterState, z, cov9, lever, rows: tuple[int, ...] = (0, 1, 2)) -> None:
        """Put the base where the sensor says (p = z - R t), with the sensor's position covariance."""
        ekf = s.ekf
        a = _lever(ekf.x, lever)
        P = ekf.P.copy()
        for i in rows:
            ekf.x[i] = z[i] - a[i]
            P[i, :] = 0.0
            P[:, i] = 0.0
        for i in rows:
            for j in rows:
                P[i, j] = cov9[3 * i + j]
        ekf.P = P

    def _apply_pose(self, s: FilterState, idx: int, inp: PoseInput, stamp: float, emit: bool, late: bool):
        cfg: PoseSensor = self.sensors[idx]  # type: ignore[assignment]
        if cfg.differential:
            return self._apply_pose_delta(s, idx, cfg, inp, stamp, emit, late)
        ekf = s.ekf
        if not s.frame_ready:
            self._initialise_from_pose(s, cfg, inp)
            return []
        y, H, R = obs.pose(self.layout, ekf.x, inp.position, inp.rpy, inp.cov, inp.rows, cfg.extrinsic_xyz)
        res = ekf.update(y, H, R, cfg.mahalanobis_threshold)
        if not emit:
            return []
        return [DiagnosticsRecord(stamp, cfg.name, [obs.POSE_NAMES[i] for i in inp.rows], y.tolist(),
                                  res.innovation_var, res.nis, len(inp.rows), res.rejected, channel="pose", late=late)]

    def _initialise_from_pose(self, s: FilterState, cfg: PoseSensor, inp: PoseInput) -> None:
        """The first absolute pose defines the world frame: position and heading (and roll/pitch
        when no IMU has set them) are taken from it, with its variances."""
        ekf = s.ekf
        r, p, y = rot.to_rpy((float(ekf.x[3]), float(ekf.x[4]), float(ekf.x[5]), float(ekf.x[6])))
        mr, mp, my = inp.rpy
        rows = inp.rows
        if not s.attitude_ready:
            r = mr if 3 in rows else r
            p = mp if 4 in rows else p
        y = my if 5 in rows else y
        ekf.x[3:7] = rot.from_rpy(r, p, y)
        var = [inp.cov[7 * i] for i in range(6)]
        pos_rows = tuple(i for i in rows if i < 3)
        self._set_position(s, inp.position, (var[0], 0.0, 0.0, 0.0, var[1], 0.0, 0.0, 0.0, var[2]),
                           cfg.extrinsic_xyz, pos_rows)
        if 5 in rows:
            P = ekf.P.copy()
            P[5, :] = 0.0
            P[:, 5] = 0.0
            P[5, 5] = var[5]
            ekf.P = P
        s.frame_ready = True
        s.pose_anchor = {}  # differential sensors restart in the new frame

    def _apply_pose_delta(self, s: FilterState, idx: int, cfg: PoseSensor, inp: PoseInput, stamp: float,
                          emit: bool, late: bool):
        """Fuse the sensor's motion since its previous message against the filter's motion since
        then (accumulated by the predictions, kept with the anchor in the snapshot): the
        sensor's drifting origin never enters. The stated noise (message covariance or override) is
        that of one delta, as robot_pose_ekf reads visual odometry's covariance: VO's error
        lives in its increments."""
        ekf = s.ekf
        anchor = s.pose_anchor.get(cfg.name)
        s.pose_anchor = {**s.pose_anchor, cfg.name: (inp.position, inp.q, _NO_MOTION)}
        if anchor is None:
            return []
        pos0, q0, (dp, dqf) = anchor
        # The filter's pose at the previous message, moved along with every correction made
        # since (x_now o D^-1): the delta then checks only the predicted motion D, and does
        # not undo what other sensors (GPS, heading initialisation) corrected meanwhile.
        qn = (float(ekf.x[3]), float(ekf.x[4]), float(ekf.x[5]), float(ekf.x[6]))
        qa = rot.mul(qn, rot.conj(dqf))
        a = mat3.apply(rot.matrix9(qa), dp)
        x_prev = (float(ekf.x[0]) - a[0], float(ekf.x[1]) - a[1], float(ekf.x[2]) - a[2], *qa)
        dpos, dq = obs.relative_pose(pos0, q0, inp.position, inp.q)
        y, H, R = obs.delta_pose(self.layout, ekf.x, x_prev, dpos, dq, inp.cov, inp.rows, cfg.extrinsic_xyz)
        res = ekf.update(y, H, R, cfg.mahalanobis_threshold, self.delta_mask)
        if not emit:
            return []
        return [DiagnosticsRecord(stamp, cfg.name, [obs.DELTA_NAMES[i] for i in inp.rows], y.tolist(),
                                  res.innovation_var, res.nis, len(inp.rows), res.rejected, channel="pose_delta",
                                  late=late)]

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
_ENU_NAMES = ("east", "north", "up")


_NO_MOTION = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0))


def _accumulate_motion(anchors: dict, x0: np.ndarray, x1: np.ndarray) -> dict:
    """Compose one prediction step's relative motion (x0^-1 x1) onto each differential anchor (a new dict).

    The motion is expressed in the body frame at the anchor, so corrections of the
    world pose (updates, heading initialisation) between messages do not enter it.
    """
    q0 = (float(x0[3]), float(x0[4]), float(x0[5]), float(x0[6]))
    step_p, step_q = obs.relative_pose((float(x0[0]), float(x0[1]), float(x0[2])), q0,
                                       (float(x1[0]), float(x1[1]), float(x1[2])),
                                       (float(x1[3]), float(x1[4]), float(x1[5]), float(x1[6])))
    out = {}
    for name, (mp, mq, (dp, dq)) in anchors.items():
        a = mat3.apply(rot.matrix9(dq), step_p)
        out[name] = (mp, mq, ((dp[0] + a[0], dp[1] + a[1], dp[2] + a[2]), rot.normalize(rot.mul(dq, step_q))))
    return out


def _lever(x: np.ndarray, t: tuple[float, float, float]) -> tuple[float, float, float]:
    """R(q) t: the sensor's offset from base_link, in the world."""
    return mat3.apply(rot.matrix9((float(x[3]), float(x[4]), float(x[5]), float(x[6]))), t)
