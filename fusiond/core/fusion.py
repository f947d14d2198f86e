"""The fusion core: time, ordering, prediction and counters around the estimator.

What each kind of sample does to the state lives in ``core/sensors/`` (one model per
kind); the state in ``core/state.py``; the late-data history in ``core/history.py``; the
held motion inputs and their timeouts in ``core/inputs.py``; the state blocks and update
masks a configuration needs in ``core/layout.py``; far stamps in ``core/time_jumps.py``.
This module owns time: validation, jumps, ordering, prediction to each stamp, counters.

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
from collections.abc import Sequence
from dataclasses import dataclass, field

import msgspec
import numpy as np

from ..config_tables import Config
from .. import reasons
from ..errors import CoreError
from ..estimator import (DEFAULT_BACKEND, POSE, POSE_ERR, POSITION, POSITION_ERR, Backend, ErrorStateEKF,
                         PredictWorkspace, corrected_inputs)
from ..errors import EstimatorError
from ..estimator.geodesy import EnuFrame, enu_to_geodetic
from ..estimator.smoother import Smoothed, SmoothingRecorder
from .fixed_lag import FixedLag, LaggedPose
from ..logs import get_logger
from ..samples import Sample
from .diagnostics import DiagnosticsRecord, NisWindow
from .history import History, snapshots_read, unrecorded_from
from .inputs import HeldInputs, next_expiry, note_period
from .layout import absolute_sensor, idle_keys, state_layout, update_masks
from .resume import RESUME_VERSION, HeldMotion, ResumeState, state_fingerprint
from .time_jumps import HeldTimeline
from .sensors import Rejected, SensorContext, build_models, kind_of
from .state import FilterState

log = get_logger("fusiond.core")


class Estimate(msgspec.Struct, gc=False):
    """What the service publishes: pose with covariance and twist, ROS row-major 6x6 layouts."""

    stamp: float
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    pose_covariance: list[float]
    linear: tuple[float, float, float]
    angular: tuple[float, float, float]
    twist_covariance: list[float]


class Step(msgspec.Struct, gc=False):
    """What one ingested sample did. A Struct: one is made per message, and its C constructor costs a
    fifth of a dataclass's. Nothing it holds refers back to it (no cycles for the collector to find)."""

    sensor: str
    accepted: bool
    reason: str = ""  # drop reason when not accepted
    late: bool = False
    publish: bool = False  # an odometry sample: the daemon publishes the newest estimate now
    measured: bool = True  # False: applied, but it measured nothing (``SensorModel.unmeasured``): no sign of life
    records: list[DiagnosticsRecord] = msgspec.field(default_factory=list)
    # Samples held for a time jump and applied at once: (stamp, [x y z qx qy qz qw]) of the estimate
    # after each odometry sample among them, in order (a replay writes one pose per odometry message).
    poses: list[tuple[float, np.ndarray]] | None = None
    # ... and, for each of those, whether the heading was known then (``heading_known``): a reset learns it anew
    poses_heading_known: list[bool] | None = None


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


def _twist_covariance(linear: tuple[float, ...], angular: tuple[float, ...]) -> list[float]:
    """The 6x6 row-major twist covariance of two row-major 3x3 blocks (linear, angular), zero between
    them: written out, as the daemon publishes it with every pose (numpy's 6x6 costs five times more)."""
    z = (0.0, 0.0, 0.0)
    return [*linear[0:3], *z, *linear[3:6], *z, *linear[6:9], *z,
            *z, *angular[0:3], *z, *angular[3:6], *z, *angular[6:9]]


class FusionCore:
    def __init__(self, cfg: Config, backend: Backend | None = None) -> None:
        self.cfg = cfg
        # the estimator's numerics (estimator/backend.py; None: compiled when built): every filter built here runs it
        self.backend = DEFAULT_BACKEND if backend is None else backend
        fc = cfg.filter
        self.sensors = list(cfg.sensors)
        self.index = {s.name: i for i, s in enumerate(self.sensors)}
        self._stamp_offset = [s.stamp_offset_s for s in self.sensors]  # added to each sensor's header stamps
        kinds = [kind_of(s) for s in self.sensors]  # what each sensor's kind means here (core/sensors/kind.py)
        self.odom_index = next((i for i, k in enumerate(kinds) if k.drives_prediction), -1)
        self.layout = state_layout(cfg)
        # keys the configuration leaves without effect (an estimate nothing observes): said once, here
        self.idle_keys = idle_keys(cfg)
        for sensor, key, why in self.idle_keys:
            log.warning("key_without_effect", sensor=sensor, key=key, reason=why)
        self._predict_ws = PredictWorkspace(self.layout)  # F and Q, rewritten in place by every prediction
        self.has_bias = self.layout.has("gyro_bias")
        # The sensor that defines the world frame (GPS: ENU at the datum; an absolute pose
        # sensor: its own frame); nothing is published before its first message.
        self.frame_index = next((i for i, s in enumerate(self.sensors) if absolute_sensor(s)), -1)
        self.gps_index = next((i for i, k in enumerate(kinds) if k.geodetic), -1)
        yaw_fused = any(k.fuses_yaw(s) for s, k in zip(self.sensors, kinds))
        masks = update_masks(self.layout, self.frame_index >= 0,
                             heading_observed=self.frame_index >= 0 or yaw_fused or not fc.continuous_odom)
        self.tilt_mask, self.position_mask, self.delta_mask = masks.tilt, masks.position, masks.delta
        self.rest_mask = masks.rest
        # An IMU with absolute yaw (REP-103: ENU, yaw 0 = east): trusted as the GPS frame's heading when
        # yaw_offset_sigma = 0; otherwise read as heading + an estimated offset (the yaw_offset block).
        self.absolute_yaw = any(k.absolute_yaw(s) for s, k in zip(self.sensors, kinds))
        self.noise_density = self.layout.noise_density(
            np.array([fc.process_noise[0] ** 2] * 3 + [fc.process_noise[1] ** 2] * 3)
        )
        self.gap_var = np.zeros(self.layout.error_dim)
        self.gap_var[0:3] = fc.gap_inflation[0] ** 2
        self.gap_var[3:6] = fc.gap_inflation[1] ** 2
        self.caps = np.full(self.layout.error_dim, math.inf)
        self.caps[0:3] = fc.covariance_cap[0]
        self.caps[3:6] = fc.covariance_cap[1]
        # Two-D mode: z, roll, pitch (and the x/y gyro bias they alone would reveal) held at 0.
        self.two_d = fc.two_d_mode
        nominal_zero, error_zero = [2], [2, 3, 4]
        if self.has_bias:
            nb, eb = self.layout.nominal["gyro_bias"].start, self.layout.error["gyro_bias"].start
            nominal_zero += [nb, nb + 1]
            error_zero += [eb, eb + 1]
        self._planar_nominal = tuple(nominal_zero)
        self._planar_error = tuple(error_zero)  # indices: the compiled backend holds them in one call
        self.inputs = HeldInputs(self.sensors, self.odom_index, self.two_d, self.layout, self.cfg.filter.gap_s)
        # The sensor models, with the narrow view of the core they are allowed (core/sensors/base.py).
        self.context = SensorContext(
            self.layout, fc, two_d=self.two_d, absolute_yaw=self.absolute_yaw, odom_index=self.odom_index,
            track_acceleration=any(k.tracks_acceleration(s) for s, k in zip(self.sensors, kinds)),
            tilt_mask=self.tilt_mask, position_mask=self.position_mask, delta_mask=self.delta_mask,
            rest_mask=self.rest_mask, timeout=self.inputs.timeout, inputs_at=self.inputs.at, forward_accel=self._forward_accel)
        self.models = build_models(self.sensors, self.context)
        if self.context.track_acceleration and self.odom_index >= 0:  # asked at every IMU sample: no forwarding
            self.context.forward_accel = self.models[self.odom_index].forward_accel
        self._predicting = [m for m in self.models if m.predicts]  # on_predict hooks (GPS track, pose anchors)
        self._showing = [m for m in self.models if m.shows_position]  # shown_position hooks (GPS heading search)
        if self.two_d:
            for m in self.models:
                m.planar()
        # Without any tilt reference (no IMU roll/pitch, no accelerometer, no absolute pose) the
        # gyro's x/y rates would integrate their biases into tens of degrees of tilt: the robot is
        # taken as planar instead (roll/pitch rates not integrated), and the summary says so.
        self.tilt_reference = self.two_d or any(m.gives_tilt for m in self.models)
        self.context.tilt_reference = self.inputs.tilt_reference = self.tilt_reference
        self._publishes = [k.prompts_publish for k in kinds]  # an applied sample of these is a publish moment
        self.stats = [SensorStats() for _ in self.sensors]
        self.windows: dict[tuple[int, str], NisWindow] = {}
        # the windowed NIS verdicts (``consistency``, each record's ``consistency``): off for a caller that reads
        # neither (the likelihood's replays score a record's NIS, never its verdict)
        self.judge_consistency = True
        self.state: FilterState | None = None
        self._reset_history()
        self._held = HeldTimeline(fc.jump_s, fc.jump_confirm, fc.jump_persist_s, fc.history_max, self.odom_index)
        self._history_s, self._history_max, self._gap_s = fc.history_s, fc.history_max, fc.gap_s
        self.fingerprint = state_fingerprint(cfg)  # which saved states fit this config (core/resume.py)
        self.resets = 0
        self.covariance_resets = 0
        self.glitches = 0  # bursts of far stamps dropped as a clock glitch
        self._smoothing: SmoothingRecorder | None = None  # record_for_smoothing: off unless asked
        self._lag: FixedLag | None = None  # smooth_with_lag: off unless asked

    # -- smoothing (an offline replay's --smooth) -----------------------------------------------------
    def record_for_smoothing(self, covariance: bool = False) -> None:
        """Keep what the smoother needs (``fusiond.estimator.smoother``): an anchor at every publish moment
        of the final timeline (the moments a replay writes a pose), the filter's steps between them
        composed. Asked before the first sample; the estimates themselves do not change."""
        if self.state is not None:
            raise CoreError("record_for_smoothing must be called before the first sample")
        self._smoothing = SmoothingRecorder(self.layout, covariance)

    def smooth_with_lag(self, lag_s: float) -> None:
        """Keep the window a fixed-lag smoothed pose needs (``core/fixed_lag.py``, ``lagged_pose``): the
        anchors of the last ``lag_s`` + ``history_s``. Asked before the first sample; the estimates
        themselves do not change. Not together with ``record_for_smoothing`` (one recorder a filter)."""
        if self.state is not None:
            raise CoreError("smooth_with_lag must be called before the first sample")
        if self._smoothing is not None:
            raise CoreError("smooth_with_lag: the core already records for the offline smoother")
        self._lag = FixedLag(self.layout, lag_s, self._history_s)
        self._smoothing = self._lag.recorder

    def lagged_pose(self) -> LaggedPose | None:
        """The pose of ``lag_s`` before the newest publish moment, smoothed over the window since, once
        per publish moment it reaches (None until the record reaches that far back, when that moment's
        was returned already, or without ``smooth_with_lag``)."""
        if self._lag is None or self.state is None:
            return None
        return self._lag.pose(self.state.ekf.recording)

    def lagged_poses(self) -> list[LaggedPose]:
        """Every publish moment's pose the lag has reached and not returned yet, in order, each smoothed over
        the window since (``FixedLag.poses``: several where the newest stamp leapt, a logging gap); empty
        without ``smooth_with_lag``."""
        if self._lag is None or self.state is None:
            return []
        return self._lag.poses(self.state.ekf.recording)

    def smoothed(self) -> Smoothed:
        """The smoothed estimates at the publish moments so far (RTS over each segment: a time jump, a
        gap longer than ``gap_s``, a covariance reset or a re-set state ends one)."""
        rec = self._smoothing
        if rec is None:
            raise CoreError("smoothing was not recorded (record_for_smoothing)")
        seg = self.state.ekf.recording if self.state is not None else None
        # what a timeline abandoned by a rewind recorded goes
        rec.keep(seg.count if seg is not None else 0, seg.turns if seg is not None else 0)
        return rec.smooth()

    # -- public API ---------------------------------------------------------
    def snapshot_plan(self, samples: Sequence[Sample]) -> list[bool | None]:
        """For samples to be ingested in this order, the ``keep`` each is ingested with: False where no
        later one of them can land right after it (``history.snapshots_read``), so its history snapshot,
        never read, is not taken; None from where every sample comes after all before it
        (``history.unrecorded_from``), so none needs a history entry at all. The estimates are the same as
        with every snapshot kept; a replay of a recording held in memory saves a snapshot a message where its
        samples come in order, and the history's upkeep where none comes late any more."""
        index, offsets = self.index, self._stamp_offset
        keys: list[tuple[float, int] | None] = []
        for sample in samples:
            idx = index.get(sample.sensor)
            stamp = sample.stamp + offsets[idx] if idx is not None else math.nan
            keys.append((stamp, idx) if 0.0 < stamp < math.inf else None)
        read = snapshots_read(keys)
        start = unrecorded_from(keys)
        return [*read[:start], *([None] * (len(read) - start))]

    def ingest(self, sample: Sample, keep: bool | None = True) -> Step:
        """Fuse one sample. ``keep``: ``snapshot_plan``'s word for it (False: no later sample lands right
        after it; None: none is placed before it, so it takes no history entry; an entry of a timeline held
        for a time jump keeps its snapshot whatever it says)."""
        idx = self.index.get(sample.sensor)
        if idx is None:
            return Step(sample.sensor, False, reasons.UNKNOWN_SENSOR)
        st = self.stats[idx]
        st.received += 1
        stamp = sample.stamp + self._stamp_offset[idx]  # the sensor's stamp_offset_s (0.0: the same float)
        if not 0.0 < stamp < math.inf:  # NaN fails it too
            return self._drop(idx, reasons.INVALID_STAMP, stamp)
        model = self.models[idx]
        try:
            if type(sample) is not model.sample_type:
                raise Rejected(reasons.WRONG_TYPE, f"expected {model.sample_type.__name__}")
            inp = model.convert(sample)
        except Rejected as r:
            return self._drop(idx, r.reason, stamp)

        if self.state is None:
            self._start()
        assert self.state is not None
        t = self.state.t
        if self._held.far(stamp, t):
            return self._hold_jump(idx, inp, stamp)
        if self._held.left_by(idx) and stamp > t:  # (a held cluster: t is set)
            self._abandon_jump()  # the stream moved on along the old timeline: the far stamps were a glitch
        return self._place(idx, inp, stamp, keep)

    def _place(self, idx: int, inp, stamp: float, keep: bool | None = True) -> Step:
        """Apply a sample at its own stamp (re-applying later ones when it is late) and count it."""
        st = self.stats[idx]
        resets = self.state.ekf.resets  # the newest timeline's covariance resets before this sample
        key = (stamp, idx)
        h = self.history
        if keep is None:  # nothing is placed before it later (``snapshot_plan``): no history entry
            h.pass_by(key)
            late = False
            records = self._apply(self.state, idx, inp, stamp, emit=True, late=False)
        else:
            pos, duplicate = h.slot(key)
            if duplicate:
                return self._drop(idx, reasons.DUPLICATE_STAMP, stamp)
            late = pos < len(h.keys)  # placed before the newest applied sample
            if late:
                if h.too_old(stamp):
                    return self._drop(idx, reasons.TOO_OLD, stamp)
                self.state = h.state_before(pos, self._reapply)
            records = self._apply(self.state, idx, inp, stamp, emit=True, late=late)
            h.insert(pos, key, (idx, inp, stamp), self.state, keep)
            if late:
                h.reapply_after(pos, self.state, self._reapply)
            h.trimmed()
        if self.state.ekf.resets > resets:
            self._covariance_reset(self.state.ekf.resets - resets)
        st.applied += 1
        if late:
            st.late += 1
        if st.newest_stamp is None or stamp > st.newest_stamp:
            st.newest_stamp = stamp
        if records:
            self._judge(idx, st, records)
        publish = self._publishes[idx] and (self.frame_index < 0 or self.state.frame_ready)
        unmeasured = self.models[idx].unmeasured
        measured = not (unmeasured and any(r.channel in unmeasured for r in records))
        return Step(self.sensors[idx].name, True, late=late, publish=publish, records=records, measured=measured)

    # -- time jumps ------------------------------------------------------------------------------------
    def _hold_jump(self, idx: int, inp, stamp: float) -> Step:
        """A stamp far from filter time: a clock glitch, or a new timeline (see ``time_jumps``).
        Nothing stamped in it is applied or published until its timeline is confirmed; a burst
        the stream leaves again is dropped whole, and the filter carries on from its history
        instead of resetting."""
        if self._held.full(stamp):
            return self._drop(idx, self._far_reason(stamp), stamp)
        dropped, confirmed = self._held.hold(stamp, idx, inp)
        self._drop_held(dropped)
        if confirmed:
            return self._confirm_jump()
        return Step(self.sensors[idx].name, False, reasons.HELD_TIME_JUMP)

    def _confirm_jump(self) -> Step:
        cluster = self._held.take()
        assert self.state is not None
        t = self.state.t
        if cluster.first < t:
            log.warning("time_jump_reset", stamp=cluster.first, filter_time=t, held=len(cluster.samples))
            self.resets += 1
            self._start()
        else:
            # Not a reset: the pose carries across the gap (inputs end at their sensors'
            # timeouts, covariance inflated); the history before the jump stays, so a sensor
            # lagging the jump is still applied at its stamp.
            log.warning("time_jump_forward", stamp=cluster.first, filter_time=t, held=len(cluster.samples))
        steps, poses, known = [], [], []
        for stamp, i, inp in cluster.in_order():
            steps.append(self._place(i, inp, stamp))
            if steps[-1].publish:
                poses.append((self.state.t, self._shown_pose()))
                known.append(self.heading_known)
        last = steps[-1]
        return Step(last.sensor, last.accepted, last.reason, late=any(s.late for s in steps),
                    publish=bool(poses), records=[r for s in steps for r in s.records], poses=poses,
                    poses_heading_known=known)

    def _abandon_jump(self) -> None:
        self._drop_held(self._held.abandon())

    def _drop_held(self, samples: list) -> None:
        if not samples:
            return
        for stamp, idx, _ in samples:
            self._drop(idx, self._far_reason(stamp), stamp)
        self.glitches += 1
        if self.glitches == 1 or self.glitches % 100 == 0:  # a sensor whose clock is offset makes one a message
            log.warning("time_glitch_dropped", samples=len(samples), first_stamp=samples[0][0],
                        filter_time=self.state.t if self.state is not None else None, glitches=self.glitches)

    def _far_reason(self, stamp: float) -> str:
        t = self.state.t if self.state is not None else None
        return reasons.FUTURE_STAMP if t is None or stamp > t else reasons.STALE_STAMP

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
        return f"waiting for the first {kind_of(s).frame_message} from {s.name!r} to define the world frame"

    @property
    def heading_known(self) -> bool:
        """False while a GPS-referenced heading is not yet measured (no travel since the first fix)."""
        if self.gps_index < 0:
            return True
        return self.state is not None and self.state.heading_ready

    @property
    def scales(self) -> dict[str, float]:
        """Estimated scale factors (wheel_scale, gyro_scale) that are in the state and observed (a gyro scale
        with nothing telling the heading stays at its prior: ``idle_keys``)."""
        if not self.initialised:
            return {}
        idle = {key for _, key, _ in self.idle_keys}
        return {n: float(self.state.ekf.x[self.layout.nominal[n]][0])
                for n in ("wheel_scale", "gyro_scale") if self.layout.has(n) and f"{n}_estimation" not in idle}

    @property
    def still_since(self) -> float | None:
        """The stamp since which the filter takes the robot for standing still (None: moving, or not started)."""
        return None if self.state is None else self.state.still_since

    @property
    def time(self) -> float | None:
        return None if self.state is None else self.state.t

    def estimate(self) -> Estimate:
        """The newest estimate (at filter time)."""
        s = self.state
        if s is None or s.t is None:
            raise CoreError("no sample has been fused yet")
        x, P = s.ekf.x, s.ekf.P
        u = self.inputs.at(s)
        linear, angular = corrected_inputs(self.layout, x, u.linear, u.angular, u.from_gyro)
        if u.planar:
            angular = (0.0, 0.0, angular[2])
        return Estimate(
            stamp=s.t,
            position=self._published_position(),
            orientation=s.ekf.attitude(),
            pose_covariance=P[POSE_ERR, POSE_ERR].ravel().tolist(),
            linear=tuple(linear),
            angular=tuple(angular),
            twist_covariance=_twist_covariance(u.linear_cov, u.angular_cov),
        )

    def pose_variances(self) -> list[float]:
        """The variances of the newest estimate's x y z roll pitch yaw: ``estimate().pose_covariance``'s
        diagonal, without building the estimate."""
        s = self.state
        if s is None or s.t is None:
            raise CoreError("no sample has been fused yet")
        return s.ekf.P.diagonal()[POSE_ERR].tolist()

    def geodetic(self) -> tuple[float, float, float, list[float]] | None:
        """The fused base position in WGS84 (lat, lon, alt) with its ENU covariance (row-major 3x3),
        once a GPS has defined the ENU frame; None otherwise."""
        s = self.state
        if s is None or s.t is None or s.enu is None or not s.frame_ready:
            return None
        lat, lon, alt = enu_to_geodetic(s.enu, *self._published_position())
        return lat, lon, alt, s.ekf.P[POSITION_ERR, POSITION_ERR].ravel().tolist()

    def pose(self) -> tuple[float, np.ndarray]:
        """(filter time, nominal [x y z qx qy qz qw]) without building a full Estimate."""
        if not self.initialised:
            raise CoreError("no sample has been fused yet")
        return self.state.t, self._shown_pose()

    def _shown_position(self, s: FilterState | None = None) -> tuple[float, float, float] | None:
        """The position to publish when a sensor model says the state's (``s``, the newest by default) is
        not it (``shown_position``: the GPS while the heading is searched for), else None."""
        s = self.state if s is None else s
        for m in self._showing:
            shown = m.shown_position(s)
            if shown is not None:
                return shown[0], shown[1], s.ekf.position()[2]
        return None

    def _shown_origin(self, s: FilterState) -> tuple[float, float] | None:
        """Where the state's position is dead-reckoned from while another is shown (``shown_origin``)."""
        for m in self._showing:
            origin = m.shown_origin(s)
            if origin is not None:
                return origin
        return None

    def _published_position(self) -> tuple[float, float, float]:
        """The state's position, or the one ``_shown_position`` publishes instead."""
        shown = self._shown_position() if self._showing else None
        return self.state.ekf.position() if shown is None else shown

    def _shown_pose(self) -> np.ndarray:
        """The state's nominal pose [x y z qx qy qz qw], its position as ``_shown_position`` says (a
        copy then; else a view of the state)."""
        x = self.state.ekf.x[POSE]
        shown = self._shown_position() if self._showing else None
        if shown is None:
            return x
        x = x.copy()
        x[POSITION] = shown
        return x

    @property
    def gyro_bias(self) -> np.ndarray | None:
        if not self.initialised or not self.has_bias:
            return None
        return self.state.ekf.x[self.layout.nominal["gyro_bias"]].copy()

    def estimated_keys(self) -> dict[str, float]:
        """Config keys whose value the filter estimated, as "sensor.key": each as the key states it
        (``SensorModel.estimated_keys``); empty before the filter starts."""
        if not self.initialised:
            return {}
        return {f"{m.cfg.name}.{k}": v for m in self.models for k, v in m.estimated_keys(self.state).items()}

    def lost_components(self) -> list[tuple[str, ...]]:
        """Per sensor: the components the filter found at run time not to be measurements
        (``SensorModel.lost_components``); none before the filter starts."""
        if self.state is None:
            return [()] * len(self.models)
        return [m.lost_components(self.state) for m in self.models]

    @property
    def twist_pitch(self) -> float | None:
        """The estimated pitch of the wheels' twist in the body (rad), when it is in the state and estimated (not
        held at the mount as configured: ``pitch_estimation = "auto"`` until released)."""
        if not self.initialised or not self.layout.has("twist_pitch"):
            return None
        e = self.layout.error["twist_pitch"].start
        if self.state.ekf.P[e, e] == 0.0:
            return None
        return float(self.state.ekf.x[self.layout.nominal["twist_pitch"].start])

    def held(self) -> list[int]:
        """Per sensor: samples held while a far-off time jump is unconfirmed (later applied or dropped)."""
        return self._held.counts(len(self.sensors))

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
        """How long sensor idx's input is held after its last message (``HeldInputs.timeout``)."""
        return self.inputs.timeout(idx, self.state if s is None else s)

    def set_pose(self, stamp: float, position: tuple[float, float, float],
                 orientation: tuple[float, float, float, float], covariance: list[float]) -> None:
        """Re-initialise the filter at this pose and stamp (robot_localization's set_pose).

        The pose (position, quaternion x y z w, normalised here) becomes the state at
        ``stamp`` with ``covariance`` (36 numbers, ROS row-major over x y z roll pitch yaw)
        as its uncertainty and no correlation to anything else; the history is cleared, so
        a sample older than ``stamp`` is dropped as too old, and held inputs are forgotten
        (the robot is taken to be at rest until the next odometry, as robot_localization
        zeroes the twist). What describes the sensors rather than the pose survives:
        gyro bias and scale estimates with their covariance, observed rates, and a
        GPS-defined world frame. A relative IMU re-measures its yaw offset, a differential
        pose sensor restarts its deltas, so neither pulls the estimate back to the old pose.
        Raises ValueError, naming the problem, and changes nothing if a value is unusable.
        """
        p = np.asarray(position, dtype=float).reshape(-1)
        q = np.asarray(orientation, dtype=float).reshape(-1)
        cov = np.asarray(covariance, dtype=float).reshape(-1)
        if not (math.isfinite(stamp) and stamp > 0.0):
            raise ValueError(f"stamp must be finite and positive, got {stamp}")
        if p.size != 3 or not np.isfinite(p).all():
            raise ValueError(f"position must be 3 finite numbers, got {p.tolist()}")
        norm = float(np.linalg.norm(q)) if q.size == 4 and np.isfinite(q).all() else 0.0
        if norm < 1e-6:
            raise ValueError(f"orientation must be a finite quaternion of non-zero norm, got {q.tolist()}")
        if cov.size != 36 or not np.isfinite(cov).all():
            raise ValueError("covariance must be 36 finite numbers")
        cov = cov.reshape(6, 6)
        cov = 0.5 * (cov + cov.T)
        if (np.diagonal(cov) < 0.0).any():
            raise ValueError(f"covariance has a negative variance: {np.diagonal(cov).tolist()}")
        old = self.state if self.initialised else None
        self._start()
        s = self.state
        assert s is not None
        if old is not None:
            s.ekf.keep_beyond_pose(old.ekf)  # biases, scales, offsets: what the filter has learnt
            s.period, s.longest = list(old.period), list(old.longest)
            s.frame_ready, s.enu, s.heading_ready = old.frame_ready, old.enu, old.heading_ready
        s.t = stamp
        s.tilt_seen = stamp
        s.ekf.set_position(p.tolist())
        s.ekf.set_attitude(q / norm)
        s.ekf.reset_covariance(list(range(6)), cov)
        s.attitude_ready = True
        self._anchor(stamp)
        log.info("pose_set", stamp=stamp, position=p.tolist(), orientation=(q / norm).tolist())

    def export_state(self) -> ResumeState:
        """The filter now, as a restarted core resumes it (``resume``; what it holds: core/resume.py).

        A copy: the caller may keep it, encode it or hand it to another thread while this core goes on.
        Raises CoreError before anything has been fused (there is nothing to resume)."""
        if not self.initialised:
            raise CoreError("no sample has been fused yet")
        s = self.state
        x, P = s.ekf.snapshot()
        held = HeldMotion(
            last=[None if v is None else float(v) for v in s.last], linear=_floats(s.linear),
            linear_cov=_floats(s.linear_cov), linear_world=bool(s.linear_world), wheel_angular=_floats(s.wheel_angular),
            wheel_angular_cov=_floats(s.wheel_angular_cov), wheel_yaw_measured=bool(s.wheel_yaw_measured),
            gyro=None if s.gyro is None else _floats(s.gyro),
            gyro_cov=None if s.gyro_cov is None else _floats(s.gyro_cov),
            gyro_sensor=-1 if s.gyro_last is None else int(s.gyro_last[0]))
        return ResumeState(
            fingerprint=self.fingerprint, stamp=float(s.t), x=x.tolist(), P=P.ravel().tolist(),
            frame_ready=bool(s.frame_ready), heading_ready=bool(s.heading_ready),
            datum=tuple(s.enu.datum) if s.enu is not None else None, period=[float(v) for v in s.period], held=held)

    def resume(self, saved: ResumeState) -> None:
        """Go on from a state ``export_state`` gave, typically the previous run's.

        As ``set_pose`` does, the filter is re-initialised at the saved stamp with the history cleared
        (nothing older is placed), but here every block of the state and its full covariance are the
        saved ones, and so are the world frame and the motion inputs held then (core/resume.py: across
        the restart they end where their holds end, as in a logging gap). Raises CoreError, with
        nothing changed, for a state of another version or config (fingerprint) or one that does not
        fit or is not sound (``ErrorStateEKF.restore``)."""
        if saved.version != RESUME_VERSION:
            raise CoreError(f"saved state has version {saved.version}, this fusiond reads {RESUME_VERSION}")
        if saved.fingerprint != self.fingerprint:
            raise CoreError(f"saved state belongs to another config (fingerprint {saved.fingerprint}, "
                            f"this config {self.fingerprint})")
        if not (math.isfinite(saved.stamp) and saved.stamp > 0.0) or len(saved.period) != len(self.sensors):
            raise CoreError("saved state has no valid stamp or does not list this config's sensors")
        held = saved.held
        if held is not None and not _usable(held, len(self.sensors), saved.stamp):
            raise CoreError("saved state's held motion inputs do not fit this config's sensors or are not sound")
        ekf = ErrorStateEKF(self.layout, backend=self.backend)
        try:
            ekf.restore(saved.x, saved.P)
            enu = EnuFrame(*saved.datum) if saved.datum is not None else None
        except (EstimatorError, TypeError, ValueError) as err:
            raise CoreError(f"saved state is not usable: {err}") from err
        self._start()
        s = self.state
        assert s is not None
        ekf.resets = s.ekf.resets
        ekf.record(s.ekf.recording)
        s.ekf = ekf
        s.t = saved.stamp
        s.tilt_seen = saved.stamp
        s.period = [float(v) for v in saved.period]
        s.frame_ready, s.heading_ready = saved.frame_ready, saved.heading_ready
        if enu is not None:
            s.enu = enu
        s.attitude_ready = True
        if held is not None:
            s.last = list(held.last)
            s.linear, s.linear_cov, s.linear_world = held.linear, held.linear_cov, held.linear_world
            s.wheel_angular, s.wheel_angular_cov = held.wheel_angular, held.wheel_angular_cov
            s.wheel_yaw_measured = held.wheel_yaw_measured
            if held.gyro is not None and held.gyro_cov is not None and held.last[held.gyro_sensor] is not None:
                s.gyro, s.gyro_cov = held.gyro, held.gyro_cov
                s.gyro_last = (held.gyro_sensor, held.last[held.gyro_sensor])
        if self.two_d:
            s.ekf.hold_planar(self._planar_nominal, self._planar_error)
        self._anchor(saved.stamp)
        log.info("state_restored", stamp=saved.stamp, position=saved.x[POSITION], frame_ready=saved.frame_ready)

    def _anchor(self, stamp: float) -> None:
        """After a re-initialisation at ``stamp``: the history starts at that state."""
        self._abandon_jump()  # samples held for a time jump belong to the timeline before the reset
        self._reset_history()  # its base is this state: nothing older can be placed ...
        # ... once the history holds an entry at the set stamp (with an empty history an older
        # sample would not count as late). The marker (sensor index -1) is never re-applied:
        # a sample is only re-applied after one inserted before it, and nothing older than the
        # set stamp is accepted.
        self.history.insert(0, (stamp, -1), (-1, None, stamp), self.state)

    # -- internals ------------------------------------------------------------
    def _drop(self, idx: int, reason: str, stamp: float) -> Step:
        st = self.stats[idx]
        n = st.dropped.get(reason, 0) + 1
        st.dropped[reason] = n
        if n == 1 or n % 1000 == 0:
            log.warning("sample_dropped", sensor=self.sensors[idx].name, reason=reason, stamp=stamp, count=n)
        return Step(self.sensors[idx].name, False, reason)

    def _judge(self, idx: int, st: SensorStats, records: list[DiagnosticsRecord]) -> None:
        """Count the gated updates among a sample's records and, with ``judge_consistency``, give each record
        its channel window's verdict."""
        judge = self.judge_consistency
        for r in records:
            if judge:
                w = self._window(idx, r.channel)
                if not r.learning:
                    r.consistency = w.add(r.nis, r.dof, r.rejected)
            if r.rejected and r.channel != "yaw_rate":
                st.rejected += 1

    def _window(self, idx: int, channel: str) -> NisWindow:
        w = self.windows.get((idx, channel))
        if w is None:
            w = NisWindow(self.cfg.filter.nis_window, self.cfg.filter.nis_confidence)
            self.windows[(idx, channel)] = w
        return w

    def _start(self) -> None:
        """A fresh state with no time yet: the first sample in stamp order sets it, so the
        start does not depend on which sensor happened to arrive first."""
        ekf = ErrorStateEKF(self.layout, backend=self.backend)
        if self._smoothing is not None:  # the new filter's anchors follow the ones recorded so far
            old = self.state.ekf.recording if self.state is not None else None
            ekf.record(self._smoothing.open(old.count if old is not None else 0))
            if old is not None:
                ekf.recording.turns = old.turns
            if self._lag is not None and old is not None:
                self._lag.restart(old)
        s = FilterState.initial(ekf, len(self.sensors), self.inputs.default_linear_cov,
                                self.inputs.default_angular_cov)
        for m in self.models:
            m.on_start(s)
        self.state = s
        self._reset_history()

    def _reset_history(self) -> None:
        fc = self.cfg.filter
        self.history = History(self.state, history_s=fc.history_s, history_max=fc.history_max)

    def _reapply(self, s: FilterState, idx: int, inp, stamp: float) -> None:
        self._apply(s, idx, inp, stamp, emit=False, late=False)

    def _predict(self, s: FilterState, dt: float) -> None:
        """Predict over dt from s.t, in segments: no input outlives its sensor.

        Each input (odometry twist, gyro rate) is held only until its sensor's timeout after
        its last message; a step that crosses that moment is split there and the rest runs
        without it (zero twist, no rotation), so a logging gap of any length moves the pose
        by at most speed x timeout and cannot integrate the last gyro rate into a tumble. The
        covariance grows by the gap inflation (added once per step longer than gap_s) and, past
        the odometry's timeout (in a gap, or while the IMU streams on), by the motion the held
        inputs no longer describe (``HeldInputs.unheld_motion_var``).
        """
        t0 = s.t
        t_end = t0 + dt
        gap = dt > self._gap_s
        if gap:  # the gap's inflation and unheld motion are not a model the smoother can run backwards
            s.ekf.end_segment()
        held = self.inputs
        ekf = s.ekf
        # fixed while predicting: nothing here moves a sensor's newest stamp
        timeouts, expiries = held.timeouts_and_expiries(s)
        while True:
            t1 = next_expiry(expiries, t0, t_end)
            seg = t1 - t0
            u = held.at(s, 0.5 * (t0 + t1), timeouts)  # fresh throughout the segment iff fresh at its middle
            x, F, Q = ekf.backend.predict(self.layout, ekf.x, u, seg, self.noise_density, self._predict_ws)
            if not u.from_gyro and u.angular_period > 0.0:  # the wheels' yaw rate turns the heading
                s.wheel_turn += u.angular[2] * seg
            for m in self._predicting:  # the sensors' own bookkeeping (GPS track, pose anchors)
                extra = m.on_predict(s, ekf.x, x)
                if extra is not None:  # what the linearised model leaves out of this step's horizontal motion
                    ekf.backend.add_motion_noise(Q, *extra)
            if t1 >= t_end:
                if gap:
                    Q[np.diag_indices_from(Q)] += self.gap_var * (dt - self.cfg.filter.gap_s)
                    if u.angular_period == 0.0:  # no yaw rate held at the gap's end: its turn was not seen
                        s.turn_unseen = t_end
                if t_end > expiries[0]:  # past the odometry's timeout, in a gap or between other sensors' samples
                    pos_var, yaw_var = held.unheld_motion_var(s, t_end, timeouts, expiries)
                    if pos_var > 0.0 or yaw_var > 0.0:
                        ekf.backend.add_motion_noise(Q, pos_var, 0.0, pos_var, yaw_var)
            ekf.propagate(x, F, Q)  # a reset is counted in _place, once: re-applications repeat it
            if t1 >= t_end:
                break
            t0 = t1
        # Without a gap P grows slowly: capping once per second of message time is enough, and
        # depends on the stamps only (so re-applied samples cap exactly where they did before).
        if gap or math.floor(s.t) != math.floor(t_end):
            s.ekf.cap_covariance(self.caps)
        if self.two_d:
            s.ekf.hold_planar(self._planar_nominal, self._planar_error)

    def _forward_accel(self, s: FilterState) -> float:
        """The odometry's forward acceleration (``OdomModel.forward_accel``), 0.0 when none is tracked."""
        if not self.context.track_acceleration or self.odom_index < 0:
            return 0.0
        return self.models[self.odom_index].forward_accel(s)

    def _covariance_reset(self, n: int) -> None:
        """Count resets (propagate's and update's) by the EKF's own counter, which snapshots carry:
        the resets a sample added to the newest timeline, so a prediction re-applied after a late
        sample does not count its reset again."""
        self.covariance_resets += n
        log.error("covariance_reset", stamp=self.state.t, count=n, reason="non-finite covariance")

    def _apply(self, s: FilterState, idx: int, inp, stamp: float, emit: bool, late: bool) -> list[DiagnosticsRecord]:
        if s.t is None:
            s.t = stamp
            s.tilt_seen = stamp
        elif stamp > s.t:
            self._predict(s, stamp - s.t)
            s.t = stamp
        note_period(s, idx, stamp, self._gap_s)
        records = self.models[idx].apply(s, inp, stamp, emit, late)
        if self.two_d:
            s.ekf.hold_planar(self._planar_nominal, self._planar_error)
        if self._smoothing is not None and self._publishes[idx] and (self.frame_index < 0 or s.frame_ready):
            # a publish moment (as _place decides it), re-applications included, with what it publishes
            shown = self._shown_position(s) if self._showing else None
            s.ekf.anchor(stamp, shown, None if shown is None else self._shown_origin(s))
        return records


def _floats(v) -> tuple[float, ...]:
    """Numpy or tuple inputs as a tuple of plain floats (what a saved state encodes)."""
    return tuple(float(a) for a in v)


def _usable(held: HeldMotion, sensors: int, stamp: float) -> bool:
    """Held inputs that fit ``sensors`` and a state at ``stamp``: finite, no stamp after it."""
    vectors = (held.linear, held.wheel_angular, *(() if held.gyro is None else (held.gyro,)))
    covs = (held.linear_cov, held.wheel_angular_cov, *(() if held.gyro_cov is None else (held.gyro_cov,)))
    return (len(held.last) == sensors and all(v is None or (math.isfinite(v) and v <= stamp) for v in held.last)
            and all(len(v) == 3 and all(map(math.isfinite, v)) for v in vectors)
            and all(len(c) == 9 and all(map(math.isfinite, c)) for c in covs)
            and (held.gyro is None or 0 <= held.gyro_sensor < sensors))
