"""Health of the running service: per-sensor liveness, counters, filter sanity.

Pure logic with an injected clock, so it is testable without Zenoh. Liveness is
wall clock (the core's time is message time, which stops when input stops): a
sensor is alive while its newest *accepted* sample arrived less than
`max(timeout_s, 3 x its observed wall-clock period, 1.5 x its longest recent interval
under gap_s)` ago (core/inputs.py's rule), so a 5 Hz sensor with jitter, or a drive
whose logger pauses 0.4 s every 2 s, does not flap, and a sensor sending only garbage,
stale stamps or a frozen receiver's repeats (``Step.measured``) is not counted as alive.

Threads: subscriber callbacks count arrivals and queue drops, the thread holding the
daemon's core reports accepted samples and core counters, the queryable reads a report.
One lock guards it all; every call is a few dict/list updates. That thread notes each accepted
sample without the lock (`noted`, a deque's append: the daemon's per-message
path takes no lock and makes no call for health); they are counted, in the order noted,
by the next report or core counters, so a report counts every sample accepted before it.

Status: `starting` while the daemon waits for its first samples (nothing accepted of
the sensors whose samples prompt a publish, the odometry, and nothing dropped yet: not
an error, though nothing is published yet); `failed` when no sensor is alive, none of
those publishing ones is (nothing is published: a daemon whose odometry died serves no
pose however alive its IMU), the filter state is non-finite or the worker has stopped;
`degraded` when any configured sensor is not alive; else `ok`.

`ros_statuses` turns a report into diagnostic_msgs DiagnosticStatus entries (one
per sensor, one for the filter) for ROS's rqt_robot_monitor / diagnostic_aggregator.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from itertools import chain
from typing import Any, Literal

import msgspec

from .core.inputs import NO_RECENT, recent_longest, silent_after, smoothed_period
from .health_pose import PoseHealth, pose_health
from .reasons import QUEUE_FULL
from .codecs.ros_messages import ERROR, OK, WARN, DiagnosticStatus


Status = Literal["ok", "degraded", "starting", "failed"]


class SensorHealth(msgspec.Struct, kw_only=True):
    """One sensor in the health answer (the documented fields that clients rely on first, extensions after)."""

    alive: bool
    age_s: float | None  # wall seconds since its newest accepted sample; null before the first
    rate_hz: float  # observed wall-clock rate while alive, 0 otherwise
    received: int  # payloads the subscriber got
    dropped: int  # all drops: queue full, undecodable, refused by the core
    rejected: int  # updates refused by the Mahalanobis gate
    applied: int = 0
    late: int = 0  # applied at their own stamp from the history
    held: int = 0  # held while a far-off time jump is unconfirmed (later applied or dropped)
    timeout_s: float = 0.0  # liveness timeout in force
    dropped_by_reason: dict[str, int] = {}
    zero_covariance_floored: int = 0  # accepted samples with a zero variance that the floor replaced (not a drop)


class FilterHealth(msgspec.Struct, kw_only=True):
    initialised: bool = False
    time: float | None = None  # filter (message) time of the newest estimate
    finite: bool = True
    covariance_resets: int = 0
    time_resets: int = 0  # backwards time jumps that reset the filter
    # a pose can be published: a sample fused, and the world frame defined (a GPS/absolute pose sensor's first
    # message, where one is configured); not_ready_reason says which is missing
    ready: bool = True
    not_ready_reason: str = ""
    heading_known: bool = True  # False while a GPS-referenced heading waits for the first metres of travel
    scales: dict[str, float] = {}  # estimated wheel_scale / gyro_scale, when in the state


class QueueHealth(msgspec.Struct, kw_only=True):
    depth: int = 0
    capacity: int = 0
    dropped: int = 0  # samples dropped because the queue was full (all sensors)


class HealthReport(msgspec.Struct, kw_only=True):
    """The health queryable's JSON answer."""

    status: Status
    sensors: dict[str, SensorHealth]
    problems: list[str]  # one phrase per reason the status is not ok, naming the sensor
    filter: FilterHealth
    queue: QueueHealth
    consistency: dict[str, dict[str, Any]]  # windowed NIS verdict per sensor channel (core.consistency())
    published: int = 0  # fused poses published
    uptime_s: float = 0.0
    pose: PoseHealth | None = None  # the latest published pose (health_pose.py); null before the first


class CoreCounters(msgspec.Struct, kw_only=True):
    """What the daemon copies out of the fusion core (with the core held: health never touches it)."""

    applied: list[int]
    late: list[int]
    held: list[int]
    rejected: list[int]
    dropped: list[dict[str, int]]
    filter: FilterHealth
    consistency: dict[str, dict[str, Any]]
    published: int = 0
    pose: PoseHealth | None = None


def core_counters(core: Any, published: int = 0) -> CoreCounters:
    """Snapshot of a FusionCore's counters and sanity; call it from the thread that feeds the core."""
    finite = True
    est = None
    if core.initialised:
        est = core.estimate()  # built once: the pose below is read from it too
        finite = all(map(math.isfinite, chain(est.position, est.orientation, est.pose_covariance)))
    return CoreCounters(
        applied=[s.applied for s in core.stats],
        late=[s.late for s in core.stats],
        held=core.held(),
        rejected=[s.rejected for s in core.stats],
        dropped=[dict(s.dropped) for s in core.stats],
        filter=FilterHealth(initialised=core.initialised, time=core.time, finite=finite,
                            covariance_resets=core.covariance_resets, time_resets=core.resets,
                            ready=core.ready, not_ready_reason=core.not_ready_reason,
                            heading_known=core.heading_known, scales=core.scales),
        consistency=core.consistency(),
        published=published,
        pose=pose_health(core, est) if finite else None,
    )


class _Tracker:
    __slots__ = ("name", "timeout_s", "gap_s", "received", "dropped", "last", "period", "longest", "floored")

    def __init__(self, name: str, timeout_s: float, gap_s: float) -> None:
        self.name = name
        self.timeout_s = timeout_s
        self.gap_s = gap_s
        self.received = 0
        self.dropped: dict[str, int] = {}
        self.last: float | None = None  # wall arrival of the newest accepted sample
        self.period = 0.0  # EMA of wall-clock intervals between accepted samples
        self.longest = NO_RECENT  # the longest recent interval under gap_s (``recent_longest``), as the core's
        self.floored = 0  # accepted samples whose covariance was floored (all-zero covariances of real drivers)

    def timeout(self) -> float:
        return silent_after(self.timeout_s, self.period, longest=self.longest[0])


def _accept(s: _Tracker, arrival: float) -> None:
    """A sample of `s` received at wall time `arrival` was used: its newest arrival and period EMA (lock held)."""
    last = s.last
    if last is not None:
        if arrival <= last:
            return
        s.period = smoothed_period(s.period, arrival - last)
        s.longest = recent_longest(s.longest, arrival - last, arrival, s.gap_s)
    s.last = arrival


class Health:
    """Thread-safe health state; `report()` is the queryable's answer."""

    def __init__(self, sensors: Sequence[tuple[str, float]], *, clock: Callable[[], float] = time.monotonic,
                 queue_capacity: int = 0, queue_depth: Callable[[], int] | None = None,
                 publishing: Sequence[bool] | None = None, gap_s: float = 0.5) -> None:
        """``sensors``: (name, timeout_s) each; ``publishing``: per sensor, whether its samples prompt a publish
        (``SensorKind.prompts_publish``; None: every sensor's do); ``gap_s``: the filter's, the longest
        interval a sensor's timeout learns from (``core.inputs.recent_longest``), as the core's held inputs."""
        self._clock = clock
        self._lock = threading.Lock()
        self._sensors = [_Tracker(name, timeout, gap_s) for name, timeout in sensors]
        self._publishing = list(publishing) if publishing is not None else [True] * len(self._sensors)
        if len(self._publishing) != len(self._sensors) or (self._sensors and not any(self._publishing)):
            raise ValueError("publishing: one flag per sensor, and at least one sensor whose samples publish")
        self._core: CoreCounters | None = None
        self._queue_capacity = queue_capacity
        self._queue_depth = queue_depth or (lambda: 0)
        self._worker_alive = True
        self._started = clock()
        # (sensor index, arrival, floored) of the samples the filter used, not counted yet: the daemon appends
        # (module doc), `count_noted` counts them
        self.noted: deque[tuple[int, float, bool]] = deque()

    @property
    def names(self) -> list[str]:
        return [s.name for s in self._sensors]

    # -- writers ---------------------------------------------------------------------
    def on_received(self, idx: int) -> None:
        with self._lock:
            self._sensors[idx].received += 1

    def on_dropped(self, idx: int, reason: str) -> int:
        """Count a drop outside the core (queue full, undecodable); returns that reason's count."""
        with self._lock:
            d = self._sensors[idx].dropped
            n = d.get(reason, 0) + 1
            d[reason] = n
            return n

    def on_floored(self, idx: int) -> None:
        """An accepted sample had a zero variance that the sensor's floor replaced (robot_pose_ekf's zero covariance)."""
        with self._lock:
            self._count_noted()
            self._sensors[idx].floored += 1

    def on_accepted(self, idx: int, arrival: float) -> None:
        """A sample the filter used, received at wall time `arrival` (the subscriber's clock)."""
        with self._lock:
            self._count_noted()
            _accept(self._sensors[idx], arrival)

    def count_noted(self) -> None:
        """Count the samples noted since the last count (the daemon, in a long pass, so they stay few)."""
        with self._lock:
            self._count_noted()

    def _count_noted(self) -> None:
        """Count the samples appended to `noted` since the last count, in the order noted (lock held).
        Only what was noted when it starts: the daemon may note more meanwhile, for the next count."""
        noted = self.noted
        if not noted:
            return
        take, sensors = noted.popleft, self._sensors
        for _ in range(len(noted)):
            idx, arrival, floored = take()
            s = sensors[idx]
            if floored:
                s.floored += 1
            _accept(s, arrival)

    def set_core(self, counters: CoreCounters) -> None:
        """The core's counters (the daemon's worker): the noted samples are counted too, so that they wait no
        longer than its refresh period when nobody asks for a report."""
        with self._lock:
            self._count_noted()
            self._core = counters

    def set_worker_alive(self, alive: bool) -> None:
        with self._lock:
            self._worker_alive = alive

    # -- reader -------------------------------------------------------------------------
    def report(self, now: float | None = None) -> HealthReport:
        with self._lock:
            self._count_noted()
            now = self._clock() if now is None else now
            core = self._core
            sensors: dict[str, SensorHealth] = {}
            problems: list[str] = []
            queue_full = 0
            for i, s in enumerate(self._sensors):
                timeout = s.timeout()
                age = None if s.last is None else max(now - s.last, 0.0)
                alive = age is not None and age <= timeout
                reasons = dict(s.dropped)
                queue_full += reasons.get(QUEUE_FULL, 0)
                if core is not None:
                    for k, v in core.dropped[i].items():
                        reasons[k] = reasons.get(k, 0) + v
                sensors[s.name] = SensorHealth(
                    alive=alive,
                    age_s=age,
                    rate_hz=1.0 / s.period if alive and s.period > 0.0 else 0.0,
                    received=s.received,
                    dropped=sum(reasons.values()),
                    rejected=core.rejected[i] if core else 0,
                    applied=core.applied[i] if core else 0,
                    late=core.late[i] if core else 0,
                    held=core.held[i] if core else 0,
                    timeout_s=timeout,
                    dropped_by_reason=reasons,
                    zero_covariance_floored=s.floored,
                )
                if not alive:
                    if age is None:
                        problems.append(f"{s.name}: no sample yet" if not s.received
                                        else f"{s.name}: no usable sample yet ({s.received} received)")
                    elif core is not None and core.held[i]:  # arriving, stamped far from the filter's time
                        problems.append(f"{s.name}: {core.held[i]} samples held for a clock jump, not applied for "
                                        f"{age:.2f} s (the jump is taken once they persist: filter.jump_persist_s)")
                    else:
                        problems.append(f"{s.name}: silent for {age:.2f} s (timeout {timeout:.2f} s)")
            filt = core.filter if core is not None else FilterHealth()
            any_alive = any(v.alive for v in sensors.values())
            publishers = [s for s, p in zip(self._sensors, self._publishing) if p]
            publishing = any(sensors[s.name].alive for s in publishers)
            # Waiting for the first samples is not a failure: nothing of a publishing sensor was accepted and
            # nothing dropped yet (a sample in the queue is not a drop; garbage is, and fails).
            starting = (self._worker_alive and filt.finite and all(s.last is None for s in publishers)
                        and not any(v.dropped for v in sensors.values()))
            failed = not starting and (not publishing or not filt.finite or not self._worker_alive)
            if not filt.finite:
                problems.append("filter: non-finite state")
            if not self._worker_alive:
                problems.append("worker: stopped")
            if starting:
                problems.append("starting: waiting for the first samples")
            elif not any_alive:
                problems.append("no sensor alive")
            elif not publishing:
                names = ", ".join(s.name for s in publishers)
                problems.append(f"nothing is published: {names}, whose samples prompt every publish, not alive")
            waiting = filt.initialised and not filt.ready
            if waiting:
                problems.append(f"filter: {filt.not_ready_reason} (nothing is published until then)")
            if filt.initialised and not filt.heading_known:
                problems.append("filter: heading not yet known (GPS heading waits for the first metres of travel)")
            degraded = waiting or any(not v.alive for v in sensors.values())
            status: Status = "failed" if failed else "starting" if starting else "degraded" if degraded else "ok"
            return HealthReport(
                status=status,
                sensors=sensors,
                problems=problems,
                filter=filt,
                queue=QueueHealth(depth=self._queue_depth(), capacity=self._queue_capacity, dropped=queue_full),
                consistency=core.consistency if core is not None else {},
                published=core.published if core is not None else 0,
                uptime_s=max(now - self._started, 0.0),
                pose=core.pose if core is not None else None,
            )


_encoder = msgspec.json.Encoder()


def encode_report(report: HealthReport) -> bytes:
    return _encoder.encode(report)


def decode_report(payload: bytes) -> HealthReport:
    return msgspec.json.decode(payload, type=HealthReport)


# --------------------------------------------------------------------------- ROS diagnostics

_LEVEL_OF_STATUS = {"ok": OK, "degraded": WARN, "starting": WARN, "failed": ERROR}
_BAD_VERDICTS = {"nis_high": "NIS high (R too small, or the sensor lies)",
                 "nis_low": "NIS low (R too large)"}
# A channel that is a consistency check, not an update: the wheels' yaw rate against the fused gyro. Its NIS is
# slip (a skid-steer's scale, a driver's offset), which is only reported: a ROS status saying "R too small" of it
# sent users to raise a noise the doctor says not to; a NIS low of it is a stated wheel noise nothing uses
_CHECK_VERDICTS = {"yaw_rate": {"nis_high": "disagrees with the gyro (slip, or a driver's scale or offset): only "
                                            "reported, the gyro drives heading; see the doctor"}}


def _said(channel: str, v: dict) -> str:
    """What a sensor's ROS status says of one of its channels' consistency (``v``), "" when nothing: a verdict
    out of its bounds that persists, in the words of its kind of channel (an update's noise, a check's slip)."""
    words = _CHECK_VERDICTS.get(channel, _BAD_VERDICTS).get(v.get("verdict"), "")
    return words if words and _persists(v) else ""


def _persists(v: dict) -> bool:
    """Is a channel's windowed verdict the whole run's too (where the answer carries it)? A coloured error (an
    AHRS's orientation, a skid-steer's turns) moves one window's NIS out of its bounds and back: a status that
    followed each window flapped between OK and WARN twenty times a minute while the doctor read the channel
    consistent."""
    run = v.get("run_verdict")
    return run is None or run == "warming_up" or run == v.get("verdict")


def _num(v: float | None, digits: int = 3) -> str:
    return "" if v is None else f"{v:.{digits}f}"


def ros_statuses(report: HealthReport, node_name: str, hardware_ids: dict[str, str]) -> list[DiagnosticStatus]:
    """The health report as DiagnosticStatus entries: `<node>: filter` first, then `<node>: <sensor>`.

    Levels: the filter is OK / WARN (degraded, starting) / ERROR (failed). A sensor is
    OK while alive, WARN while alive with a windowed NIS verdict out of its bounds that the
    whole run's shares (the live doctor's signal, ``_persists``) or before its first sample,
    ERROR when it has gone silent.
    Key-values carry rates, ages and counters as strings (DiagnosticStatus has no numbers).
    """
    f, q = report.filter, report.queue
    out = [DiagnosticStatus(
        level=_LEVEL_OF_STATUS[report.status], name=f"{node_name}: filter",
        message=report.status if not report.problems else f"{report.status}: " + "; ".join(report.problems),
        hardware_id=node_name,
        values=[("status", report.status), ("initialised", str(f.initialised).lower()),
                ("filter_time", _num(f.time, 9)), ("published", str(report.published)),
                ("uptime_s", _num(report.uptime_s, 1)), ("covariance_resets", str(f.covariance_resets)),
                ("time_resets", str(f.time_resets)), ("world_frame_ready", str(f.ready).lower()),
                ("queue_depth", str(q.depth)), ("queue_capacity", str(q.capacity)),
                ("queue_dropped", str(q.dropped))],
    )]
    for name, s in report.sensors.items():
        channels = {k.split("/", 1)[1]: v for k, v in report.consistency.items() if k.split("/", 1)[0] == name}
        bad = [f"{ch}: {said}" for ch, v in channels.items() if (said := _said(ch, v))]
        if s.alive:
            level, message = (WARN, "; ".join(bad)) if bad else (OK, "alive")
        elif s.age_s is None:
            level = WARN
            message = "no sample yet" if not s.received else f"no usable sample yet ({s.received} received)"
        else:
            level, message = ERROR, f"silent for {s.age_s:.2f} s (timeout {s.timeout_s:.2f} s)"
        values = [("alive", str(s.alive).lower()), ("rate_hz", _num(s.rate_hz, 2)), ("age_s", _num(s.age_s)),
                  ("timeout_s", _num(s.timeout_s)), ("received", str(s.received)), ("applied", str(s.applied)),
                  ("late", str(s.late)), ("dropped", str(s.dropped)), ("rejected", str(s.rejected)),
                  ("zero_covariance_floored", str(s.zero_covariance_floored))]
        values += [(f"dropped_{reason}", str(n)) for reason, n in sorted(s.dropped_by_reason.items())]
        values += [(f"nis_{ch}", f"{_num(v.get('nis_mean'))} ({v.get('verdict')})")
                   for ch, v in sorted(channels.items())]
        out.append(DiagnosticStatus(level=level, name=f"{node_name}: {name}", message=message,
                                    hardware_id=hardware_ids.get(name, name), values=values))
    return out
