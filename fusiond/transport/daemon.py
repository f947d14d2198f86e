"""The Zenoh side of `fusiond run`: subscribers -> one inbox -> the core, one thread at a time -> publishers.

Kept thin on purpose: the maths is the fusion core's, the wire formats are the
codecs', liveness is health.py's. What lives here is threading and life cycle:

- A callback copies the payload and appends (sensor index, bytes, wall arrival
  time) to ONE bounded inbox (a `collections.deque`), then fuses what the inbox
  holds on its own thread, unless another thread holds the core (`_drain`). A
  full inbox drops the new sample and counts it per sensor as `queue_full`
  (explicit, visible in health as the queue's depth and drops).
- One thread at a time holds the core (`_core`, a lock a callback only tries: it
  never waits for it). The thread that holds it fuses everything in the inbox in
  arrival order, and looks at the inbox again after it lets go, so a sample
  appended while another thread held the core is fused by that thread or by its
  own, never left behind (and the worker looks at least every `CORE_REFRESH_S`).
  The core's history absorbs the arrival order.
- Fusing where the sample arrives saves a hand-off per message: no wake-up of
  another thread, whose caches have gone cold while it slept (on a shared host
  that costs more than the fusion itself), and a pose that leaves as soon as its
  odometry sample is fused. Callbacks run on Zenoh's receive thread
  (`Callback(indirect=False)`) instead of zenoh-python's default thread per
  subscriber: that keeps the arrival order across the keys of one link (a bag
  played at full speed reaches the core in bag order, not hundreds of messages
  apart). Without that option (older zenoh-python) callbacks fall back to the
  default, and the lock keeps one fuser at a time. While a sample is fused the
  link's next messages wait in its buffers, as they would under the GIL for any
  Python work of the daemon's on another thread. So a sender faster than the
  fusion (a bag at `play --rate 0`) is slowed by its link: a blocking publisher
  waits, as `play`'s do; one that drops on congestion drops at its end. The
  inbox fills only while another thread holds the core.
- A pass decodes (`DecodeError` counted per reason), calls `core.ingest`, then
  publishes. Bookkeeping that can wait does (health is handed each accepted
  sample by a deque's append and counts them when a report or the core's
  counters are taken: no lock and no call of health per message), so the
  per-message path is decode, fuse, publish.
- The worker thread keeps time: it puts the diagnostics batch, copies the core's
  counters into health and hands the state to the saver when they are due, and
  fuses what is left at stop. It holds the core for that as any thread does.
- What goes out, in which encoding and on which key, is `outputs.py`'s: the pose,
  odometry, NavSatFix and TF of every estimate the core says to publish (and, with
  `smoothed_key`, the fixed-lag smoothed pose beside it), and the JSON
  diagnostics records. Here: when. Diagnostics are put on the worker's timer, one
  JSON array a put: at 1 kHz IMU 20 puts a second instead of 1,100 encodes and puts
  (6-9 us a message here); the batch is flushed when the worker ends, so a clean stop
  loses no record. Health as
  `diagnostic_msgs/msg/DiagnosticArray` once a period, from the health thread (it
  reads health, never the core). A health queryable, and a liveliness token
  `<health_key>/alive` so remote tools see the daemon come and go (with a namespace
  both are prefixed).
- set_pose: a queryable (and in rmw_zenoh mode the topic /set_pose) whose
  request is decoded on the Zenoh thread, then queued and fused like a sample:
  the thread that holds the core re-initialises it, publishes the new pose and
  replies with the new health (a Zenoh query can be answered from any thread).
  A bad request is answered with an error naming the problem and changes nothing.
- Interop (`[ros] interop`): "bridge" uses zenoh-bridge-ros2dds's plain keys;
  "rmw_zenoh" uses rmw_zenoh's keys, attachments and liveliness tokens for every
  ROS topic in and out (`rmw_zenoh.py`); the JSON health/diagnostics keys stay plain.
- Persisted state (`[state] path`, `state_file.py`): resumed before the first input
  when it fits the config and is fresh; the worker exports the core's state every
  `save_interval_s` while samples are fused and a thread of its own writes it (an
  fsync must not delay a pose); the last state is written when the worker has ended.
- Stop: subscribers first (no new input), then the worker fuses what is queued
  (bounded time; each sample is published completely or not at all), the core is
  closed to any callback still under way, the state is written, then the outputs
  are undeclared; the caller closes the session.
"""

from __future__ import annotations

import math
import queue
import signal
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh

from ..estimator.backend import Backend
from ..codecs import POSE_COV_STAMPED, DecodeError, SetPose, decode_set_pose
from ..config import Config
from .. import reasons
from ..core.fusion import FusionCore
from ..core.sensors.registry import kind_of
from ..health import Health, HealthReport, core_counters, ros_statuses
from ..errors import SessionError
from ..logs import bind_process, get_logger
from .answer import HealthAnswer, answer, encode_answer
from .link import LinkWatch
from .outputs import Outputs
from .rmw_zenoh import RmwNode, topic_name
from .session import build_config, open_session
from .state_file import StateSaver, resume_from_file
from .intake import direct, sensor_kind, zero_covariance_check  # noqa: F401  (their import path since the split)

log = get_logger("fusiond.daemon")

QUEUE_SIZE = 1024  # ~1 s of 1 kHz IMU + 100 Hz odometry: as long as the core's default history
HEALTH_LOG_S = 5.0  # period of the `health` log event
HEALTH_POLL_S = 0.1  # how often status changes are looked for (`health_changed`)
CORE_REFRESH_S = 0.1  # the worker copies core counters into health at most this often while samples are fused
DRAIN_S = 2.0  # at stop, time the worker gets to finish what is queued
LOG_EVERY = 1000  # a repeated drop reason is logged on its 1st and every 1000th occurrence
HEALTH_CHUNK = 256  # the most noted samples left for health to count (more: the pass has them counted)

_STOP = object()  # the worker's token: fuse what is queued, then end
SET_POSE_TOPIC = "/set_pose"  # robot_localization's topic (rmw_zenoh mode)


class _SetPoseItem:
    """A decoded set_pose request in the inbox; `query` is None for the /set_pose topic."""

    __slots__ = ("request", "query", "source")

    def __init__(self, request: SetPose, query: zenoh.Query | None, source: str) -> None:
        self.request = request
        self.query = query
        self.source = source


def alive_key(health_key: str) -> str:
    """The daemon's liveliness token: `<health_key>/alive` (strip `/alive` to get the health key)."""
    return f"{health_key}/alive"


class Daemon:
    """Subscribers, queue, worker and outputs on an open session (which the caller owns)."""

    def __init__(self, cfg: Config, session: zenoh.Session, *, queue_size: int = QUEUE_SIZE,
                 health_log_s: float = HEALTH_LOG_S, express: bool = False, direct_callbacks: bool = True,
                 monitor: bool = True, clock: Callable[[], float] = time.monotonic,
                 base_dir: Path | None = None, backend: Backend | None = None) -> None:
        self.cfg = cfg
        self.session = session
        self.core = FusionCore(cfg, backend)
        if cfg.output.smoothed_key:  # the fixed-lag window is recorded only when its pose is published
            self.core.smooth_with_lag(cfg.output.smooth_lag_s)
        # Samples and set_pose requests in arrival order (callbacks append, the thread holding the core
        # pops), the lock that thread holds (module doc), and the worker's stop token.
        self.inbox: deque[Any] = deque()
        self._core = threading.Lock()
        self._wake: queue.SimpleQueue[Any] = queue.SimpleQueue()
        self.capacity = queue_size
        self.health = Health([(s.name, s.timeout_s) for s in cfg.sensors], clock=clock,
                             queue_capacity=queue_size, queue_depth=self.inbox.__len__,
                             publishing=[kind_of(s).prompts_publish for s in cfg.sensors], gap_s=cfg.filter.gap_s)
        self._clock = clock
        self._express = express
        self._direct = direct_callbacks
        self._monitor_on = monitor
        self._health_log_s = health_log_s
        self._decoders = [kind_of(s).decoder(s) for s in cfg.sensors]
        self._zero_cov = [zero_covariance_check(s) for s in cfg.sensors]
        self._subscribers: list[Any] = []
        self._declared: list[Any] = []  # everything undeclared at stop, in reverse
        self.outputs: Outputs | None = None  # the publishers (outputs.py), declared by start
        self.node: RmwNode | None = None
        self.set_poses = 0  # set_pose requests applied
        self._worker: threading.Thread | None = None
        self._monitor: threading.Thread | None = None
        self._stopping = threading.Event()
        self._abort = False
        self.errors = 0
        self._batch_s = cfg.output.diagnostics_batch_s
        self.worker_cpu_s = 0.0  # CPU time of the worker thread (its timers, not the fusion), set when it ends
        self.passes = 0  # passes that fused what the inbox held (each one sample or more)
        self._dirty = False  # fused since the core's counters were last copied into health
        self._unsaved = False  # fused since the state was last handed to the saver
        # `[state] path`: resumed at start, written by a thread of its own every save_interval_s (state_file.py)
        self.state_path: Path | None = None
        if cfg.state.path:
            path = Path(cfg.state.path).expanduser()
            self.state_path = path if path.is_absolute() else (base_dir or Path.cwd()) / path
        self._saver: StateSaver | None = None
        self._fused_wall = time.time()  # wall time of the newest pass that fused samples (the saved state's age)
        self.resumed = False
        self.link: LinkWatch | None = None  # the session's link to routers and peers (link.py), from start
        self.metrics: Any = None  # the /metrics server (metrics.py) when [metrics] listen is set
        self.zid = ""

    # -- life cycle ----------------------------------------------------------------------
    def start(self) -> None:
        out = self.cfg.output
        s = self.session
        self.zid = str(s.zid())
        self._start_metrics()  # first: an address in use fails the start before anything is declared
        z = self.cfg.zenoh  # a link the config asks for is announced and counted (link.py)
        self.link = LinkWatch(s, watched=z.mode == "client" or bool(z.connect))
        self.link.start()
        if self.state_path is not None:
            self.resumed = resume_from_file(self.core, self.state_path, self.cfg.state.max_age_s) is None
            self._saver = StateSaver(self.state_path)
        if self.cfg.ros.interop == "rmw_zenoh":
            self.node = RmwNode(s, self.cfg.ros.domain_id, self.cfg.ros.node_name)
        self.outputs = Outputs(self.cfg, s, self.node, self._express)
        self._refresh()  # health says what the core knows from the start (heading_known false before a GPS fix)
        self._worker = threading.Thread(target=self._work, name="fusiond-worker", daemon=True)
        self._worker.start()
        for idx, sensor in enumerate(self.cfg.sensors):
            cb = self._callback(idx)
            handler = direct(cb) if self._direct else cb
            if self.node is not None:
                msgtype = kind_of(sensor).ros_type(sensor)
                self._subscribers.append(self.node.subscriber(topic_name(sensor.key), msgtype, handler))
            else:
                self._subscribers.append(s.declare_subscriber(sensor.key, handler))
            log.info("sensor_subscribed", sensor=sensor.name, key=sensor.key, kind=sensor_kind(sensor),
                     encoding=sensor.encoding, timeout_s=sensor.timeout_s, interop=self.cfg.ros.interop)
        # set_pose requests are input too: undeclared with the subscribers when stopping
        self._subscribers.append(s.declare_queryable(out.set_pose_key, self._on_set_pose_query))
        if self.node is not None:
            self._subscribers.append(self.node.subscriber(SET_POSE_TOPIC, POSE_COV_STAMPED, self._on_set_pose_topic))
        # Last, so that an answer to a health query (or the token) proves the subscribers exist:
        # a peer's declarations reach a client in order on the link, before the reply. Tools
        # (`play`, tests) wait for that answer; a publisher's matching status is no such proof.
        self._queryable = s.declare_queryable(out.health_key, self._on_query)
        self._token = s.liveliness().declare_token(alive_key(out.health_key))
        self._declared = [o for o in (self.node, *self.outputs.declared, self._queryable, self._token)
                          if o is not None]
        if self._monitor_on or self.outputs.ros_diagnostics is not None:
            self._monitor = threading.Thread(target=self._watch, name="fusiond-health", daemon=True)
            self._monitor.start()

    def _start_metrics(self) -> None:
        listen = self.cfg.metrics.listen
        if not listen:
            return
        from ..config import metrics_address
        from .metrics import MetricsServer

        host, port = metrics_address(listen)
        try:
            self.metrics = MetricsServer(self.answer, host, port)
        except OSError as err:
            raise SessionError(f"metrics.listen {listen}: cannot serve /metrics there: {err.strerror or err}") from None
        log.info("metrics_listening", url=f"http://{listen.rpartition(':')[0]}:{self.metrics.port}/metrics")

    def answer(self) -> HealthAnswer:
        """The health answer: the report, the daemon's namespace and Zenoh id, its link (answer.py)."""
        return answer(self.health.report(), self.cfg.zenoh.namespace, self.zid,
                      self.link.health() if self.link is not None else None)

    def _save_state(self) -> None:
        """The core held: hand its state to the saver thread."""
        if self._saver is not None and self.core.initialised:
            self._saver.offer(self.core.export_state(), self._fused_wall)

    def stop(self, drain_s: float = DRAIN_S) -> None:
        """Stop input, let the worker finish what is queued (bounded), undeclare outputs."""
        if self._stopping.is_set():
            return
        self._stopping.set()
        for sub in self._subscribers:
            sub.undeclare()
        self._subscribers.clear()
        deadline = time.monotonic() + drain_s
        worker = self._worker
        if worker is not None and worker.is_alive():
            self._wake.put(_STOP)
            worker.join(max(deadline - time.monotonic(), 0.05))
            if worker.is_alive():  # still busy: stop between samples, never inside one
                self._abort = True
                worker.join(1.0)
        # A callback still under way (an undeclared subscriber's last one) finishes its sample; none fuses after.
        got = self._core.acquire(timeout=1.0)
        self._abort = True
        try:
            left = len(self.inbox)
            if left:
                log.warning("samples_discarded_at_stop", count=left)
            if self._saver is not None:  # the worker has ended (or was abandoned between samples): the last state
                self._saver.flush(self.core.export_state() if self.core.initialised else None, self._fused_wall)
        finally:
            if got:
                self._core.release()
        if self._monitor is not None:
            self._monitor.join(1.0)
        for obj in reversed(self._declared):  # the node's token last: rmw_zenoh undeclares entities first
            try:
                obj.undeclare()
            except zenoh.ZError:
                pass
        self._declared.clear()
        if self.link is not None:
            self.link.stop()
        if self.metrics is not None:
            self.metrics.stop()
            self.metrics = None

    @property
    def published(self) -> int:
        """Estimates published."""
        return self.outputs.published if self.outputs is not None else 0

    @property
    def diagnostics_puts(self) -> int:
        """Puts on the diagnostics key (one per batch, or per record with diagnostics_batch_s = 0)."""
        return self.outputs.diagnostics_puts if self.outputs is not None else 0

    @property
    def tf_published(self) -> int:
        """TF messages put (one per estimate whose stamp advanced)."""
        return self.outputs.tf_published if self.outputs is not None else 0

    def report(self) -> HealthReport:
        return self.answer()

    def queued(self) -> int:
        """Samples and requests waiting for the worker."""
        return len(self.inbox)

    # -- subscriber side (Zenoh threads): never block ------------------------------------
    def _callback(self, idx: int) -> Callable[[zenoh.Sample], None]:
        inbox = self.inbox
        append = inbox.append
        drain = self._drain  # taken when subscribing: tools may wrap it before (scripts/profile_daemon_cpu.py)
        capacity = self.capacity
        clock = self._clock
        health = self.health
        name = self.cfg.sensors[idx].name

        def on_sample(sample: zenoh.Sample) -> None:
            arrival = clock()
            health.on_received(idx)
            if len(inbox) < capacity:
                append((idx, sample.payload.to_bytes(), arrival))
                drain()
                return
            n = health.on_dropped(idx, reasons.QUEUE_FULL)
            if n == 1 or n % LOG_EVERY == 0:
                log.warning("sample_dropped", sensor=name, reason=reasons.QUEUE_FULL, count=n)

        return on_sample

    def _enqueue_set_pose(self, item: _SetPoseItem) -> None:
        """A set_pose request joins the samples in arrival order and is applied at once."""
        self.inbox.append(item)
        self._drain()

    def _on_query(self, query: zenoh.Query) -> None:
        query.reply(self.cfg.output.health_key, encode_answer(self.answer()), encoding=zenoh.Encoding.APPLICATION_JSON)

    def _on_set_pose_query(self, query: zenoh.Query) -> None:
        """Decode here (no core access); the worker applies it and replies."""
        payload = query.payload
        try:
            if payload is None:
                raise DecodeError("empty_payload", "no payload: send a PoseWithCovarianceStamped (CDR) or JSON "
                                                   "{\"stamp\", \"position\", \"orientation\", \"covariance\"}")
            request = decode_set_pose(payload.to_bytes())
        except DecodeError as err:
            log.warning("set_pose_refused", source="query", reason=err.reason, detail=err.detail)
            query.reply_err(f"set_pose refused: {err}")
            return
        self._enqueue_set_pose(_SetPoseItem(request, query, "query"))

    def _on_set_pose_topic(self, sample: zenoh.Sample) -> None:
        try:
            request = decode_set_pose(sample.payload.to_bytes())
        except DecodeError as err:
            log.warning("set_pose_refused", source="topic", reason=err.reason, detail=err.detail)
            return
        self._enqueue_set_pose(_SetPoseItem(request, None, "topic"))

    # -- fusing (any thread that holds the core) and the worker's timers ----------------
    def _drain(self) -> None:
        """Fuse what waits in the inbox on the calling thread, unless another thread holds the core: that one
        fuses it before it lets go, or looks again after (module doc). Called after every append."""
        inbox = self.inbox
        core = self._core
        while inbox and not self._abort and core.acquire(False):
            try:
                self._fuse_inbox()
            finally:
                core.release()

    def _work(self) -> None:
        """The daemon's clock: the diagnostics batch, the core's counters for health and the saved state when
        they are due, each with the core held (then what arrived meanwhile is fused); at stop, what is queued."""
        wait_for = self._wake.get
        monotonic = time.monotonic
        core = self._core
        outputs = self.outputs
        batch_s = self._batch_s
        save_every = self.cfg.state.save_interval_s
        now = monotonic()
        next_flush, next_refresh, next_save = now + batch_s, now, now + save_every
        stopping = False
        try:
            while not stopping:
                wait = min(next_refresh, next_flush if batch_s > 0.0 else math.inf) - monotonic()
                try:
                    stopping = wait_for(timeout=max(wait, 0.0)) is _STOP
                except queue.Empty:
                    pass
                with core:
                    now = monotonic()
                    if now >= next_flush:
                        if outputs.pending:
                            self._flush_diagnostics()
                        next_flush = now + batch_s
                    if now >= next_refresh:
                        if self._dirty:
                            self._dirty = False
                            self._refresh()
                        next_refresh = now + CORE_REFRESH_S
                    if self._unsaved and now >= next_save:
                        self._unsaved = False
                        self._save_state()
                        next_save = now + save_every
                self._drain()  # what arrived while this thread held the core; at stop, what is queued
            with core:
                if self._dirty:
                    self._refresh()
        except BaseException:
            log.exception("worker_crashed")
            self.health.set_worker_alive(False)
            raise
        finally:
            with core:
                if outputs.pending:  # at stop (or a crash): the records of samples already fused go out
                    self._flush_diagnostics()
            self.worker_cpu_s = time.thread_time()
        if not self._stopping.is_set():
            self.health.set_worker_alive(False)

    def _flush_diagnostics(self) -> None:
        """Publish the collected records (an attribute of the daemon, for profiling tools to wrap)."""
        self.outputs.flush_diagnostics()

    def _publish_estimate(self) -> None:
        """Publish the core's newest estimate (an attribute of the daemon, for profiling tools to wrap)."""
        self.outputs.publish_estimate(self.core)

    def _refresh(self) -> None:
        self.health.set_core(core_counters(self.core, self.published))

    def _fuse_inbox(self) -> None:
        """The core held: fuse everything in the inbox in arrival order: decode, `core.ingest`, publish, collect
        records.

        The per-message path of the daemon, so written for it: health is only noted each accepted
        sample (a deque's append; it counts them when a report or the core's counters are taken, so a
        set_pose's reply counts what was fused before it), and what it calls is looked up once per
        pass. A failure on one sample is counted and logged; the rest go on.
        """
        inbox = self.inbox
        if not inbox or self._abort:
            return
        self.passes += 1
        self._dirty = self._unsaved = True
        self._fused_wall = time.time()  # the state's age runs from here (transport/state_file.py)
        take = inbox.popleft
        decoders = self._decoders  # looked up per pass: tools may wrap them (scripts/profile_daemon_cpu.py)
        ingest = self.core.ingest
        zero_cov = self._zero_cov
        collect = self.outputs.collect
        noted = self.health.noted
        note = noted.append  # (sensor, arrival, floored)
        while inbox and not self._abort:
            item = take()
            try:
                if type(item) is _SetPoseItem:
                    self._set_pose(item)
                    continue
                idx, payload, arrival = item
                try:
                    sample = decoders[idx](payload)
                except DecodeError as err:
                    self._decode_dropped(idx, err)
                    continue
                step = ingest(sample)
                if not step.accepted:
                    continue  # counted (and logged) by the core
                if step.measured:  # a frozen receiver's repeat is applied but is no sign of its life (health)
                    check = zero_cov[idx]
                    note((idx, arrival, check is not None and check(sample)))
                    if len(noted) >= HEALTH_CHUNK:  # a long pass that nobody asks about: they stay few
                        self.health.count_noted()
                if step.publish:
                    self._publish_estimate()
                records = step.records
                if records:
                    collect(records)
            except Exception:  # a bug on one sample must not stop the service
                self.errors += 1
                if self.errors == 1 or self.errors % LOG_EVERY == 0:
                    log.exception("worker_error", count=self.errors)

    def _decode_dropped(self, idx: int, err: DecodeError) -> None:
        n = self.health.on_dropped(idx, err.reason)
        if n == 1 or n % LOG_EVERY == 0:
            log.warning("sample_dropped", sensor=self.cfg.sensors[idx].name, reason=err.reason,
                        detail=err.detail, count=n)

    def _set_pose(self, item: _SetPoseItem) -> None:
        """The core held: re-initialise it at the requested pose, publish that pose, answer with the new health."""
        req = item.request
        stamp = req.stamp if req.stamp > 0.0 else self.core.time
        try:
            if stamp is None:
                raise ValueError("stamp 0 means the filter's current time, but nothing has been fused yet: "
                                 "give the stamp the pose holds at")
            self.core.set_pose(stamp, req.position, req.orientation, list(req.covariance))
        except ValueError as err:
            log.warning("set_pose_refused", source=item.source, reason="invalid", detail=str(err))
            if item.query is not None:
                item.query.reply_err(f"set_pose refused: {err}")
                item.query.drop()
            return
        self.set_poses += 1
        log.info("set_pose", source=item.source, stamp=stamp, position=req.position, orientation=req.orientation)
        if self.core.ready:
            self._publish_estimate()
        self._refresh()
        if item.query is not None:
            item.query.reply(self.cfg.output.set_pose_key, encode_answer(self.answer()),
                             encoding=zenoh.Encoding.APPLICATION_JSON)
            item.query.drop()

    # -- health monitor ----------------------------------------------------------------
    def _watch(self) -> None:
        """Health thread: status-change and periodic health logs; /diagnostics once a period."""
        last_status = None
        last_problems: list[str] = []
        next_log = time.monotonic() + self._health_log_s
        period = self.cfg.output.ros_diagnostics_period_s
        next_diag = time.monotonic()
        hardware_ids = {s.name: s.key for s in self.cfg.sensors}
        while not self._stopping.wait(HEALTH_POLL_S):
            rep = self.health.report()
            now = time.monotonic()
            if self.outputs.ros_diagnostics is not None and now >= next_diag:
                next_diag = now + period
                self.outputs.put_ros_diagnostics(time.time(), ros_statuses(rep, self.cfg.ros.node_name, hardware_ids))
            if not self._monitor_on:
                continue
            names = [p.split(":")[0] for p in rep.problems]
            if rep.status != last_status or names != [p.split(":")[0] for p in last_problems]:
                log.log(_LEVEL[rep.status], "health_changed", status=rep.status, previous=last_status,
                        problems=rep.problems)
                last_status, last_problems = rep.status, rep.problems
            if now >= next_log:
                next_log = now + self._health_log_s
                log.info("health", status=rep.status, problems=rep.problems, published=rep.published,
                         queue_depth=rep.queue.depth, queue_dropped=rep.queue.dropped,
                         filter_time=rep.filter.time, sensors={
                             k: {"alive": v.alive, "rate_hz": round(v.rate_hz, 1), "received": v.received,
                                 "dropped": v.dropped, "rejected": v.rejected} for k, v in rep.sensors.items()})


_LEVEL = {"ok": 20, "starting": 20, "degraded": 30, "failed": 40}


def run(cfg: Config, *, base_dir: Path | None = None, stop: threading.Event | None = None,
        backend: Backend | None = None) -> int:
    """`fusiond run`: open the session, serve until SIGINT/SIGTERM (or `stop`), shut down cleanly.

    Raises ConfigError (bad Zenoh value or file) and SessionError (cannot open) before anything starts.
    """
    conf = build_config(cfg.zenoh, base_dir=base_dir)
    stop = stop or threading.Event()
    received: list[str] = []

    def on_signal(signum: int, _frame: Any) -> None:
        received.append(signal.Signals(signum).name)
        stop.set()

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, on_signal)
    bind_process(namespace=cfg.zenoh.namespace)  # every line of the daemon names its robot
    session = open_session(conf)
    try:
        daemon = Daemon(cfg, session, base_dir=base_dir, backend=backend)
        try:
            daemon.start()
        except SessionError:
            daemon.stop(0.5)
            raise
        z = cfg.zenoh
        log.info("daemon_started", zid=str(session.zid()), mode=z.mode, listen=z.listen, connect=z.connect,
                 namespace=z.namespace or None, sensors=[s.name for s in cfg.sensors],
                 pose_key=cfg.output.pose_key, odometry_key=cfg.output.odometry_key,
                 diagnostics_key=cfg.output.diagnostics_key, health_key=cfg.output.health_key,
                 alive_key=alive_key(cfg.output.health_key), set_pose_key=cfg.output.set_pose_key,
                 tf_key=cfg.output.tf_key if cfg.output.publish_tf else None,
                 ros_diagnostics_key=cfg.output.ros_diagnostics_key or None, interop=cfg.ros.interop,
                 smoothed_key=cfg.output.smoothed_key or None,
                 node=daemon.node.token_key if daemon.node is not None else None,
                 state_path=str(daemon.state_path) if daemon.state_path is not None else None)
        while not stop.wait(0.5):
            pass
        log.info("daemon_stopping", signal=received[0] if received else None)
        daemon.stop()
        rep = daemon.report()
    finally:
        session.close()
    log.info("daemon_stopped", published=daemon.published, errors=daemon.errors,
             sensors={k: {"received": v.received, "applied": v.applied, "dropped": v.dropped,
                          "rejected": v.rejected} for k, v in rep.sensors.items()})
    return 0
