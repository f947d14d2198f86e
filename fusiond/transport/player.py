"""`fusiond play`: a bag's configured sensor topics onto Zenoh, as zenoh-bridge-ros2dds would.

Each configured sensor's bag topic (`"/" + key`) is published on its Zenoh key as
ROS 2 CDR with the encapsulation header (ROS 1 bags are converted at byte level),
paced by bag (receive) time at `rate` (1.0 recorded pace, 0 as fast as possible).
A sensor configured with `json` or `msgpack` gets that encoding instead, so the
daemon of the same config can be fed without a robot.

A daemon that answered before playing and stops answering (killed, crashed, its link
gone) is said so (``daemon_stopped``: its liveliness token's withdrawal is watched while
playing, its health asked again at the end): messages put after that went nowhere, and
`fusiond play` exits non-zero instead of reporting a clean run.

Publishers use reliable, blocking congestion control: a replay tool should not
lose messages to its own speed (the daemon's queue still counts its own drops).
With `[ros] interop = "rmw_zenoh"` the daemon is an rmw_zenoh node, and so is `play`
(node ``PLAY_NODE``): the topics on rmw_zenoh's keys, each sample with its attachment
(``rmw_zenoh.RmwNode``), as a ROS 2 node on rmw_zenoh would publish the bag.

The bag is opened by the caller (`fusiond.replay.bag.open_bag_samples`) and
handed in as a `RawSource`: transport/ does not import replay/ (nor the reverse);
both share only `fusiond.codecs`.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import msgspec
import zenoh

from ..config import Config
from ..core.sensors import encode_sample, make_decoder
from ..core.sensors.registry import kind_of
from ..errors import PlaybackError
from ..health import decode_report
from ..presence import withdrawn
from ..logs import get_logger
from .daemon import alive_key, sensor_kind
from .rmw_zenoh import RmwNode, topic_name
from .session import query_health

log = get_logger("fusiond.play")

LINGER_S = 0.3  # after the last put, before closing: let the transmit queue drain
PLAY_NODE = "fusiond_play"  # the ROS node `play` is on rmw_zenoh (`[ros] interop = "rmw_zenoh"`)
HEALTH_QUERY_S = 1.0  # how long the daemon's drop count is waited for after playing
SETTLE_S = 10.0  # after playing, how long the daemon gets to account for every sample sent (fused or dropped)
SETTLE_POLL_S = 0.1


class RawSource(Protocol):
    """An open bag as `play` needs it (what `fusiond.replay.bag.BagSamples` provides)."""

    missing: list[str]  # configured sensors whose topic is not in the bag
    total: int  # messages of the configured topics

    def raw_cdr(self) -> Iterator[tuple[int, Any, bytes]]:
        """(bag time ns, sensor config, ROS 2 CDR payload) in bag order."""
        ...


@dataclass
class PlayResult:
    messages: int = 0
    per_sensor: dict[str, int] = field(default_factory=dict)
    bag_seconds: float = 0.0  # bag time span played
    seconds: float = 0.0  # wall time
    interrupted: bool = False
    # samples the daemon's full input queue dropped while this played (its health's queue.dropped before
    # and after); None without exactly one daemon answering on the health key
    daemon_dropped: int | None = None
    # per sensor, the samples sent that the daemon did not fuse, by reason (its health's counts before and
    # after; "unaccounted": neither fused nor dropped when it settled); empty: all fused, or no daemon to ask
    unfused: dict[str, dict[str, int]] = field(default_factory=dict)
    # why the daemon(s) that answered before playing did not after (None: they did, or none was awaited)
    daemon_stopped: str | None = None
    # a daemon was awaited (``wait_s`` > 0) and none answered: nothing sent is known to be fused
    no_daemon: bool = False
    # the daemon answering after playing is another session than before (restarted while this played: its
    # counts started over, so what it fused of this play is not known): "old -> new" Zenoh ids, else None
    daemon_restarted: str | None = None


def wait_for_daemon(session: zenoh.Session, health_key: str, timeout: float) -> list[bytes]:
    """Wait until the daemon answers on its health key; its answers (empty: none within ``timeout``).

    The daemon declares its queryable after its subscribers, and declarations
    reach us in order on the link, so an answer proves our first message will be
    routed. A publisher's `matching_status` is no such proof: right after a
    session opens it can read true while the first messages still go nowhere.
    """
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return []
        answers = query_health(session, health_key, min(0.5, left))
        if answers:
            return answers
        time.sleep(min(0.05, max(deadline - time.monotonic(), 0.0)))


def _transcoder(sensor: Any) -> Callable[[bytes], bytes] | None:
    """None for CDR sensors (bytes pass through); else CDR -> sample -> the sensor's encoding."""
    if sensor.encoding == "ros2-cdr":
        return None
    msgtype = getattr(sensor, "msgtype", None)
    decode = make_decoder(sensor_kind(sensor), "ros2-cdr", sensor.name, msgtype=msgtype)
    return lambda raw: encode_sample(decode(raw), sensor.encoding, msgtype)


def play(bag: RawSource, cfg: Config, session: zenoh.Session, *, rate: float = 1.0,
         duration: float | None = None, wait_s: float = 5.0, stop: threading.Event | None = None,
         clock: Callable[[], float] = time.monotonic, names: Sequence[str] = ()) -> PlayResult:
    """Publish an open bag (the caller closes it); returns counts. `duration` limits the bag
    seconds played (from its start); `names` (the bag files) only label the log."""
    if rate < 0:
        raise PlaybackError("rate must be >= 0")
    stop = stop or threading.Event()
    result = PlayResult(per_sensor={s.name: 0 for s in cfg.sensors})
    if bag.missing:
        log.warning("play_missing_topics", sensors=bag.missing)
    node = None
    if cfg.ros.interop == "rmw_zenoh":  # the daemon subscribes as an rmw_zenoh node: publish as one (keys, attachments)
        node = RmwNode(session, cfg.ros.domain_id, PLAY_NODE)
        pubs: dict[str, Any] = {s.name: node.publisher(topic_name(s.key), kind_of(s).ros_type(s))
                                for s in cfg.sensors if s.name not in bag.missing}
    else:
        pubs = {s.name: session.declare_publisher(s.key, encoding=_encoding(s.encoding),
                                                  congestion_control=zenoh.CongestionControl.BLOCK)
                for s in cfg.sensors if s.name not in bag.missing}
    transcode = {s.name: _transcoder(s) for s in cfg.sensors}
    watch = None
    try:
        answers = wait_for_daemon(session, cfg.output.health_key, wait_s) if wait_s > 0 else []
        if wait_s > 0 and not answers:
            result.no_daemon = True
            log.warning("play_no_daemon", waited_s=wait_s, health_key=cfg.output.health_key,
                        keys=[s.key for s in cfg.sensors if s.name in pubs])
        dropped_before = _queue_dropped(answers)
        counts_before = _sensor_counts(answers)
        log.info("play_started", bag=list(names), rate=rate, messages=bag.total)
        t0_bag: int | None = None
        t0 = clock()
        gone: list[float] = []  # wall seconds into the play when a daemon's liveliness token went
        if answers:
            watch = session.liveliness().declare_subscriber(
                alive_key(cfg.output.health_key), lambda s: gone.append(clock() - t0) if withdrawn(s) else None)
        for bag_ns, sensor, raw in bag.raw_cdr():
            if stop.is_set():
                result.interrupted = True
                break
            if t0_bag is None:
                t0_bag = bag_ns
            offset = (bag_ns - t0_bag) * 1e-9
            if duration is not None and offset > duration:
                break
            if rate > 0:
                delay = t0 + offset / rate - clock()
                if delay > 0 and stop.wait(delay):
                    result.interrupted = True
                    break
            conv = transcode[sensor.name]
            pubs[sensor.name].put(raw if conv is None else conv(raw))
            result.messages += 1
            result.per_sensor[sensor.name] += 1
            result.bag_seconds = offset
        result.seconds = clock() - t0
        stop.wait(LINGER_S)
        after = query_health(session, cfg.output.health_key, HEALTH_QUERY_S) if answers else []
        if dropped_before is not None:  # a daemon that could not keep up says so in its health: nothing lost silently
            dropped_after = _queue_dropped(after)
            if dropped_after is not None:
                result.daemon_dropped = dropped_after - dropped_before
        if len(after) < len(answers):
            went = f"; its liveliness token went {gone[0]:.1f} s into the play" if gone else ""
            result.daemon_stopped = (f"{len(answers)} answered before playing, {len(after)} after "
                                     f"{result.messages} messages{went}")
            log.error("play_daemon_stopped", detail=result.daemon_stopped, health_key=cfg.output.health_key)
        elif (was := _daemon_id(answers)) != (now := _daemon_id(after)) and was and now:
            result.daemon_restarted = f"{was} -> {now}"
            log.error("play_daemon_restarted", zids=result.daemon_restarted, health_key=cfg.output.health_key)
        elif counts_before is not None and not result.interrupted:
            result.unfused = _unfused(session, cfg.output.health_key, counts_before, result.per_sensor, stop)
    finally:
        if watch is not None:
            watch.undeclare()
        for p in pubs.values():
            p.undeclare()
        if node is not None:
            node.undeclare()
    log.info("play_finished", messages=result.messages, per_sensor=result.per_sensor,
             seconds=round(result.seconds, 3), interrupted=result.interrupted, daemon_dropped=result.daemon_dropped)
    return result


def _queue_dropped(answers: list[bytes]) -> int | None:
    """The daemon's count of samples its full input queue dropped, from the health answers, or None
    unless exactly one daemon answered with a readable report."""
    if len(answers) != 1:
        return None
    try:
        return decode_report(answers[0]).queue.dropped
    except msgspec.DecodeError:
        return None


def _daemon_id(answers: list[bytes]) -> str:
    """The Zenoh id of the one daemon that answered ("" unless exactly one answered, with a readable id)."""
    if len(answers) != 1:
        return ""
    try:
        return str(msgspec.json.decode(answers[0], type=_Identity).zid)
    except msgspec.DecodeError:
        return ""


class _Identity(msgspec.Struct):
    """The part of a health answer that names its daemon (``transport.answer.HealthAnswer``)."""

    zid: str = ""


Counts = dict[str, tuple[int, dict[str, int]]]  # per sensor: (applied, dropped by reason)


def _sensor_counts(answers: list[bytes]) -> Counts | None:
    """Per sensor, the daemon's applied count and drops by reason, from exactly one readable health answer."""
    if len(answers) != 1:
        return None
    try:
        report = decode_report(answers[0])
    except msgspec.DecodeError:
        return None
    return {name: (h.applied, dict(h.dropped_by_reason)) for name, h in report.sensors.items()}


def _unfused(session: zenoh.Session, health_key: str, before: Counts, sent: dict[str, int],
             stop: threading.Event) -> dict[str, dict[str, int]]:
    """What the daemon did not fuse of what was sent, per sensor and reason: its health is asked until every
    sample sent is counted as applied or dropped (its queue worked through) or SETTLE_S passed; what is
    then neither is "unaccounted" (held for a time jump, lost on the way, or still queued)."""
    deadline = time.monotonic() + SETTLE_S
    while True:
        after = _sensor_counts(query_health(session, health_key, HEALTH_QUERY_S))
        if after is None:
            return {}
        missing: dict[str, dict[str, int]] = {}
        for name, n in sent.items():
            if not n or name not in before or name not in after:
                continue
            applied = after[name][0] - before[name][0]
            if applied >= n:
                continue
            reasons = {k: v - before[name][1].get(k, 0) for k, v in after[name][1].items()}
            reasons = {k: v for k, v in reasons.items() if v > 0}
            left = n - applied - sum(reasons.values())
            if left > 0:
                reasons["unaccounted"] = left
            missing[name] = reasons
        if not any("unaccounted" in r for r in missing.values()) or time.monotonic() > deadline:
            return missing
        if stop.wait(SETTLE_POLL_S):
            return missing


def _encoding(name: str) -> zenoh.Encoding:
    return {"ros2-cdr": zenoh.Encoding.APPLICATION_CDR, "json": zenoh.Encoding.APPLICATION_JSON}.get(
        name, zenoh.Encoding.ZENOH_BYTES)
