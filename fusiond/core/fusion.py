"""The fusion core: time, ordering, sensor policies and diagnostics around the estimator.

What each kind of sample does to the state lives in ``core/updates/``; the state
in ``core/state.py``; the late-data history in ``core/history.py``. This module
owns time: validation, jumps, ordering, prediction to each stamp, counters.

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

import math
from dataclasses import dataclass, field

import msgspec
import numpy as np
import structlog

from ..config import Config, GpsSensor, ImuSensor, OdomSensor, PoseSensor
from ..estimator import (
    ErrorStateEKF, GpsErrorBlock, GyroBiasBlock, GyroScaleBlock, MotionInput, PoseBlock, StateLayout, WheelScaleBlock,
    YawOffsetBlock, predict,
)
from ..estimator import mat3
from ..estimator.geodesy import EnuFrame, enu_to_geodetic
from ..samples import GpsSample, ImuSample, OdomSample, PoseSample, Sample
from .diagnostics import DiagnosticsRecord, NisWindow
from .history import History
from .sensors import GpsPolicy, ImuPolicy, OdomPolicy, PosePolicy, Rejected
from .state import FilterState
from .updates import accumulate_motion, apply_gps, apply_imu, apply_odom, apply_pose

log = structlog.get_logger("fusiond.core")

PERIOD_SMOOTHING = 0.1  # EMA weight of a new inter-message interval
TIMEOUT_PERIODS = 3.0  # a sensor is silent after max(timeout_s, this many typical periods)
# sensor kind -> (sample policy, sample type, what an applied sample does)
_KINDS = {OdomSensor: (OdomPolicy, OdomSample, apply_odom), ImuSensor: (ImuPolicy, ImuSample, apply_imu),
          GpsSensor: (GpsPolicy, GpsSample, apply_gps), PoseSensor: (PosePolicy, PoseSample, apply_pose)}


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


class FusionCore:
    def __init__(self, cfg: Config) -> None:
        self.cfg = cfg
        fc = cfg.filter
        self.sensors = list(cfg.sensors)
        self.index = {s.name: i for i, s in enumerate(self.sensors)}
        self.policies = [_KINDS[type(s)][0](s) for s in self.sensors]
        self._sample_types = [_KINDS[type(s)][1] for s in self.sensors]
        self._handlers = [_KINDS[type(s)][2] for s in self.sensors]
        self.odom_index = next((i for i, s in enumerate(self.sensors) if isinstance(s, OdomSensor)), -1)
        gyro_imus = [i for i, s in enumerate(self.sensors) if isinstance(s, ImuSensor) and s.angular_velocity]
        blocks = [PoseBlock(fc.initial_sigma[0], fc.initial_sigma[1])]
        if gyro_imus:
            blocks.append(GyroBiasBlock(fc.gyro_bias_sigma, fc.gyro_bias_walk))
        if any(isinstance(s, ImuSensor) and s.gyro_scale_estimation for s in self.sensors):
            blocks.append(GyroScaleBlock(fc.gyro_scale_sigma, fc.gyro_scale_walk))
        # A wheel scale is observable once an absolute position is fused: on by default there.
        absolute = any(isinstance(s, GpsSensor) or (isinstance(s, PoseSensor) and not s.differential)
                       for s in self.sensors)
        if any(isinstance(s, OdomSensor) and (s.scale_estimation or (s.scale_estimation is None and absolute))
               for s in self.sensors):
            blocks.append(WheelScaleBlock(fc.wheel_scale_sigma, fc.wheel_scale_walk))
        # An absolute IMU yaw beside an absolute position or pose: heading + an estimated offset.
        yaw_imu = next((s for s in self.sensors if isinstance(s, ImuSensor) and s.orientation == "absolute"
                        and s.yaw_offset_sigma > 0.0), None)
        if yaw_imu is not None and absolute:
            blocks.append(YawOffsetBlock(yaw_imu.yaw_offset_sigma, yaw_imu.yaw_offset_walk))
        for sc in self.sensors:  # at most one GPS (it defines the world frame)
            if isinstance(sc, GpsSensor) and sc.error_tau_s > 0.0 and sc.error_sigma is not None:
                blocks.append(GpsErrorBlock(sc.error_tau_s, sc.error_sigma))
            elif isinstance(sc, GpsSensor) and sc.vertical_error_sigma > 0.0:  # the altitude's wander alone
                blocks.append(GpsErrorBlock(sc.vertical_error_tau_s, (0.0, 0.0, sc.vertical_error_sigma)))
        self.layout = StateLayout(blocks)
        self.has_bias = self.layout.has("gyro_bias")
        self.has_gyro_scale = self.layout.has("gyro_scale")
        # A roll/pitch-only update may correct roll, pitch and the x/y gyro bias, never
        # position, heading, the z bias or a scale (which drive heading and position).
        self.tilt_mask = np.ones(self.layout.error_dim, dtype=bool)
        self.tilt_mask[[0, 1, 2, 5]] = False
        if self.has_bias:
            self.tilt_mask[self.layout.error["gyro_bias"].start + 2] = False
        for name in ("gyro_scale", "wheel_scale", "gps_error", "yaw_offset"):
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
        # An IMU with absolute yaw (REP-103: ENU, yaw 0 = east): trusted as the GPS frame's heading when
        # yaw_offset_sigma = 0; otherwise read as heading + an estimated offset (the yaw_offset block).
        self.absolute_yaw = any(isinstance(s, ImuSensor) and s.orientation == "absolute" for s in self.sensors)
        # A pose delta fused against the filter's previous pose acts on the absolute pose as
        # if that previous pose were exact, which collapses P of position and heading. Alone
        # that is robot_pose_ekf's behaviour; beside an absolute sensor it would lock the GPS
        # out, so there the delta may correct tilt, biases and scales only (Schmidt update).
        # The exact treatment, cloning the previous pose into the state, is not done yet.
        self.delta_mask = None
        if self.frame_index >= 0:
            self.delta_mask = np.ones(self.layout.error_dim, dtype=bool)
            self.delta_mask[[0, 1, 2, 5]] = False
            for name in ("gps_error", "yaw_offset"):  # a pose delta says nothing about these
                if self.layout.has(name):
                    self.delta_mask[self.layout.error[name]] = False
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
        self._u.twist_correlation = odom.twist_correlation_s if isinstance(odom, OdomSensor) else 0.0
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
                # Not a reset: the pose carries across the gap (inflated); the history before
                # the jump stays, so a sensor lagging the jump is still applied at its stamp.
                log.warning("time_jump_forward", sensor=sample.sensor, stamp=stamp, filter_time=t)
        else:
            self._suspect = 0

        key = (stamp, idx)
        h = self.history
        pos, duplicate = h.slot(key)
        if duplicate:
            return self._drop(idx, "duplicate_stamp", stamp)
        late = h.is_late(pos)
        if late:
            if h.too_old(stamp):
                return self._drop(idx, "too_old", stamp)
            self.state = h.state_before(pos)
        records = self._apply(self.state, idx, inp, stamp, emit=True, late=late)
        h.insert(pos, key, (idx, inp, stamp), self.state)
        if late:
            h.reapply_after(pos, self.state, self._reapply)
        h.trim(self.cfg.filter.history_s, self.cfg.filter.history_max)
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

    def geodetic(self) -> tuple[float, float, float, list[float]] | None:
        """The fused base position in WGS84 (lat, lon, alt) with its ENU covariance (row-major 3x3),
        once a GPS has defined the ENU frame; None otherwise."""
        s = self.state
        if s is None or s.t is None or s.enu is None or not s.frame_ready:
            return None
        x = s.ekf.x
        lat, lon, alt = enu_to_geodetic(s.enu, float(x[0]), float(x[1]), float(x[2]))
        return lat, lon, alt, s.ekf.P[0:3, 0:3].ravel().tolist()

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
        self.history = History(self.state)

    def _reapply(self, s: FilterState, idx: int, inp, stamp: float) -> None:
        self._apply(s, idx, inp, stamp, emit=False, late=False)

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
            s.pose_anchor = accumulate_motion(s.pose_anchor, s.ekf.x, x)
        gap = dt > self.cfg.filter.gap_s
        if gap:
            Q[np.diag_indices_from(Q)] += self.gap_var * (dt - self.cfg.filter.gap_s)
        if not s.ekf.propagate(x, F, Q):
            self._covariance_reset(s)
        # Without a gap P grows slowly: capping once per second of message time is enough, and
        # depends on the stamps only (so re-applied samples cap exactly where they did before).
        if gap or math.floor(s.t) != math.floor(s.t + dt):
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
        return self._handlers[idx](self, s, idx, inp, stamp, emit, late)

    # -- absolute and relative position sensors ---------------------------------------------------------------
_ZERO3 = (0.0, 0.0, 0.0)
