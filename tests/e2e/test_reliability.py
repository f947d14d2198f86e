"""Reliability of `fusiond run`: bad input and faults against a live daemon.

Real `fusiond run` subprocesses on real Zenoh sessions over loopback, no mocks.
Every wait has a deadline, every process is killed in a `finally`, and no
assertion is about speed: recovery is measured by poses arriving, not by a clock.

Each test records what it fed the daemon and what it observed (`reliability_log`,
tests/conftest.py); with FUSIOND_WRITE_RELIABILITY=1 the session renders
docs/RELIABILITY.md from those records.
"""

from __future__ import annotations

import math
import random
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import pytest
import zenoh

from fusiond.config import ZenohConfig, load
from fusiond.replay.bag import open_bag_samples
from fusiond.core.sensors import ImuSample, OdomSample, encode_sample, make_decoder
from fusiond.codecs import MAX_PAYLOAD, DecodeError
from fusiond.transport.session import build_config, open_session

from tests.support.daemon import (
    ROOT,
    client_session,
    daemon_process,
    free_port,
    health,
    log_events,
    wait_daemon_ready,
    wait_until,
    write_config,
)
from tests.support.reliability import IMU_KEY, WHEEL_KEY, Poses, _cov_diag, imu_payload, odom_payload

GAP_S, GAP_INFLATION_POS = 0.5, 0.05  # config.toml defaults of [filter] gap_s and gap_inflation[0]


# --------------------------------------------------------------------------- helpers


def publishers(session: zenoh.Session, keys: dict[str, str]) -> dict[str, zenoh.Publisher]:
    """Blocking publishers: every put reaches the daemon, which then counts it (nothing lost on our side)."""
    return {name: session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
            for name, key in keys.items()}


def counters(h: dict) -> dict:
    """What a case is judged on: per-sensor drops by reason, applied, late, floored; published; resets."""
    return {
        "sensors": {n: {"received": s["received"], "applied": s["applied"], "late": s["late"],
                        "dropped": dict(s["dropped_by_reason"]),
                        "floored": s.get("zero_covariance_floored", 0)} for n, s in h["sensors"].items()},
        "published": h["published"],
        "time_resets": h["filter"]["time_resets"],
        "finite": h["filter"]["finite"],
    }


def delta(before: dict, after: dict, name: str) -> dict:
    b, a = before["sensors"][name], after["sensors"][name]
    drops = {k: v - b["dropped"].get(k, 0) for k, v in a["dropped"].items() if v != b["dropped"].get(k, 0)}
    return {"drops": drops, "applied": a["applied"] - b["applied"], "late": a["late"] - b["late"],
            "floored": a["floored"] - b["floored"], "published": after["published"] - before["published"],
            "time_resets": after["time_resets"] - before["time_resets"]}


def settle(session: zenoh.Session, proc: subprocess.Popen, sent: dict[str, int], poses: Poses,
           timeout: float = 10.0) -> dict:
    """Health once the daemon has received and processed all `sent` and its poses have arrived here."""
    last: list = [None]

    def done():
        if proc.poll() is not None:
            raise AssertionError(f"daemon exited with {proc.returncode}")
        h = health(session, 1.0)
        last[0] = h
        if not h or h["queue"]["depth"]:
            return None
        for name, n in sent.items():
            s = h["sensors"][name]
            if s["received"] != n or s["applied"] + s["dropped"] + s.get("held", 0) != n:
                return None
        return h if len(poses) >= h["published"] else None

    try:
        return wait_until(done, timeout, "the daemon to process what was sent", step=0.03)
    except AssertionError:
        raise AssertionError(f"not settled: sent {sent}, last health {last[0]}, poses {len(poses)}") from None


def describe(d: dict) -> str:
    parts = [f"dropped {k} x{v}" for k, v in sorted(d["drops"].items())]
    if d["applied"]:
        parts.append(f"applied x{d['applied']}" + (f" ({d['late']} late, at its own stamp)" if d["late"] else ""))
    if d["floored"]:
        parts.append(f"zero_covariance_floored +{d['floored']}")
    if d["time_resets"]:
        parts.append(f"filter reset x{d['time_resets']}")
    if d["published"]:
        parts.append(f"{d['published']} pose(s) published")
    return "; ".join(parts) or "nothing counted"


# --------------------------------------------------------------------------- bad inputs


@dataclass
class Case:
    """One bad input on one sensor key: its payloads (built from the current stream) and what must happen."""

    sensor: str
    name: str
    expected: str  # the handling, in words (table)
    build: Callable[["Stream"], list[bytes]]
    drops: dict[str, int] = field(default_factory=dict)  # exact drop counters by reason
    drop_any_of: tuple[str, ...] = ()  # or: one drop with any of these reasons
    applied: int = 0
    late: int = 0
    floored: int = 0
    time_resets: int = 0
    mixable: bool = True  # usable in the free-running mixed stream (no state left behind)


@dataclass
class Stream:
    """The valid stream so far: newest raw message and decoded sample per sensor, newest stamp overall."""

    raw: dict[str, bytes]
    sample: dict[str, OdomSample | ImuSample]
    newest: float = 0.0
    rng: random.Random = field(default_factory=lambda: random.Random(5))

    def enc(self, name: str, **changes) -> bytes:
        s = msgspec.structs.replace(self.sample[name], **changes)
        return encode_sample(s, "ros2-cdr")

    def other(self, name: str) -> str:
        return "imu" if name == "wheel" else "wheel"


def bad_cases() -> list[Case]:
    nan, inf = math.nan, math.inf
    cases: list[Case] = []
    for name in ("wheel", "imu"):
        add = cases.append
        # -- the wire: bytes that are no message of the key's type
        add(Case(name, "random bytes (300)", "dropped: not CDR", lambda st, n=name: [st.rng.randbytes(300)],
                 drop_any_of=("cdr_invalid", "wrong_type")))
        add(Case(name, "empty payload", "dropped", lambda st, n=name: [b""], drops={"empty_payload": 1}))
        add(Case(name, "truncated CDR (half)", "dropped: not CDR",
                 lambda st, n=name: [st.raw[n][: len(st.raw[n]) // 2]], drops={"cdr_invalid": 1}))
        add(Case(name, "truncated CDR (last 8 bytes cut)", "dropped: not CDR",
                 lambda st, n=name: [st.raw[n][:-8]], drops={"cdr_invalid": 1}))
        add(Case(name, "oversized CDR (valid + 100 trailing bytes)", "dropped: not exactly one message",
                 lambda st, n=name: [st.raw[n] + bytes(100)], drops={"cdr_invalid": 1}))
        add(Case(name, f"oversized payload (> {MAX_PAYLOAD // 1024} KiB)", "dropped before parsing",
                 lambda st, n=name: [st.raw[n] + bytes(MAX_PAYLOAD)], drops={"oversized": 1}))
        other = "sensor_msgs/Imu" if name == "wheel" else "nav_msgs/Odometry"
        add(Case(name, f"wrong message type ({other} on this key)", "dropped, the type named in the log",
                 lambda st, n=name: [st.raw[st.other(n)]], drops={"wrong_type": 1}))
        add(Case(name, "JSON on a CDR key", "dropped: not CDR", lambda st, n=name: [b'{"stamp": 1.0}'],
                 drops={"cdr_invalid": 1}))
        # -- values
        add(Case(name, "timestamp 0", "dropped", lambda st, n=name: [st.enc(n, stamp=0.0)],
                 drops={"invalid_stamp": 1}))
        if name == "wheel":
            add(Case(name, "NaN in twist.linear", "dropped", lambda st: [st.enc("wheel", linear=(nan, 0.0, 0.0))],
                     drops={"non_finite": 1}))
            add(Case(name, "+Inf in twist.angular", "dropped",
                     lambda st: [st.enc("wheel", angular=(0.0, 0.0, inf))], drops={"non_finite": 1}))
            add(Case(name, "-Inf in twist.linear.y", "dropped",
                     lambda st: [st.enc("wheel", linear=(0.1, -inf, 0.0))], drops={"non_finite": 1}))
            add(Case(name, "twist 1e3 m/s", "dropped: implausible",
                     lambda st: [st.enc("wheel", linear=(1e3, 0.0, 0.0))], drops={"implausible_value": 1}))
            add(Case(name, "negative twist covariance", "dropped",
                     lambda st: [st.enc("wheel", stamp=st.newest + 0.001,
                                        twist_covariance=_cov_diag(6, [-0.01, 0.001, 0.001, 1e6, 1e6, 0.03]))],
                     drops={"negative_covariance": 1}))
            add(Case(name, "NaN twist covariance", "accepted: that component 'not measured' (default noise)",
                     lambda st: [st.enc("wheel", stamp=st.newest + 0.001,
                                        twist_covariance=_cov_diag(6, [nan, 0.001, 0.001, 1e6, 1e6, inf]))],
                     applied=1))
            add(Case(name, "all-zero twist covariance", "accepted with floors (robot_pose_ekf 'zero covariance')",
                     lambda st: [st.enc("wheel", stamp=st.newest + 0.001, twist_covariance=(0.0,) * 36)],
                     applied=1, floored=1))
            add(Case(name, "NaN/Inf in pose (unused by fusion)", "accepted: the odometry pose is not fused",
                     lambda st: [st.enc("wheel", stamp=st.newest + 0.001, position=(nan, inf, 0.0),
                                        orientation=(nan, 0.0, 0.0, 0.0))],
                     applied=1))
        else:
            # a bad orientation costs its own rows (counted by the model, logged), not the gyro of the same message
            add(Case(name, "NaN in orientation", "accepted: the gyro of the message (its orientation refused)",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001, orientation=(nan, 0.0, 0.0, 1.0))],
                     applied=1))
            add(Case(name, "NaN in orientation, no angular velocity (covariance -1)", "dropped",
                     lambda st: [st.enc("imu", orientation=(nan, 0.0, 0.0, 1.0),
                                        angular_velocity_covariance=(-1.0,) + (0.0,) * 8)],
                     drops={"non_finite": 1}))
            add(Case(name, "+Inf in angular_velocity", "dropped",
                     lambda st: [st.enc("imu", angular_velocity=(0.0, inf, 0.0))], drops={"non_finite": 1}))
            add(Case(name, "NaN in orientation covariance", "accepted: the gyro of the message (its orientation refused)",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001,
                                        orientation_covariance=_cov_diag(3, [nan, 1e-4, 1e-4]))],
                     applied=1))
            add(Case(name, "zero quaternion", "accepted: the gyro of the message (its orientation refused)",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001, orientation=(0.0, 0.0, 0.0, 0.0))],
                     applied=1))
            add(Case(name, "non-unit quaternion (norm 2)", "accepted: the gyro of the message (its orientation refused)",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001, orientation=(0.0, 0.0, 0.0, 2.0))],
                     applied=1))
            add(Case(name, "gyro 1e3 rad/s", "dropped: implausible",
                     lambda st: [st.enc("imu", angular_velocity=(0.0, 0.0, 1e3))], drops={"implausible_value": 1}))
            add(Case(name, "negative orientation covariance", "accepted: the gyro of the message (its orientation refused)",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001,
                                        orientation_covariance=_cov_diag(3, [1e-4, -1e-4, 1e-4]))],
                     applied=1))
            add(Case(name, "all-zero covariances", "accepted with floors (robot_pose_ekf 'zero covariance')",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001, orientation_covariance=(0.0,) * 9,
                                        angular_velocity_covariance=(0.0,) * 9)],
                     applied=1, floored=1))
            add(Case(name, "orientation_covariance[0] = -1 ('no orientation')", "accepted: gyro only",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001,
                                        orientation_covariance=(-1.0,) + (0.0,) * 8)],
                     applied=1))
            add(Case(name, "NaN in linear_acceleration (unused)", "accepted: acceleration is not fused",
                     lambda st: [st.enc("imu", stamp=st.newest + 0.001, linear_acceleration=(nan, nan, inf))],
                     applied=1))
        # -- time
        # a far stamp is held until the stream shows whether it starts a new timeline: the next
        # valid message on the old timeline makes it a glitch (dropped); nothing of it is published
        add(Case(name, "timestamp far in the future (+1e6 s), then the stream goes on",
                 "held, then dropped as a glitch by the next valid message",
                 lambda st, n=name: [st.enc(n, stamp=st.newest + 1e6), st.enc(n, stamp=st.newest + 0.001)],
                 drops={"future_stamp": 1}, applied=1))
        add(Case(name, "duplicated message", "dropped",
                 lambda st, n=name: [st.raw[n]], drops={"duplicate_stamp": 1}))
        add(Case(name, "out of order (-50 ms)", "accepted late: applied at its own stamp from the history",
                 lambda st, n=name: [st.enc(n, stamp=st.newest - 0.0503)], applied=1, late=1, mixable=False))
        add(Case(name, "backwards jump beyond the history (-2 s)", "dropped: older than the 1 s history",
                 lambda st, n=name: [st.enc(n, stamp=st.newest - 2.0)], drops={"too_old": 1}, mixable=False))
        add(Case(name, "backwards jump (-30 s), once, then the stream goes on",
                 "held, then dropped as a glitch by the next valid message",
                 lambda st, n=name: [st.enc(n, stamp=st.newest - 30.0), st.enc(n, stamp=st.newest + 0.001)],
                 drops={"stale_stamp": 1}, applied=1, mixable=False))
        # three held samples spanning jump_persist_s (1 s) confirm the jump: the filter resets and
        # applies them; the stream then jumps forward again, confirmed the same way: nothing lost
        add(Case(name, "backwards jump (-30 s), confirmed (3 over 1 s), then forward again",
                 "filter reset at the 3rd, the held samples applied; forward again likewise; estimate finite",
                 lambda st, n=name: [st.enc(n, stamp=st.newest - 30.0 + 0.5 * k) for k in range(3)]
                 + [st.enc(n, stamp=st.newest + 0.001 + 0.5 * k) for k in range(3)],
                 applied=6, time_resets=1, mixable=False))
    # the resets last: right after one, the history still reaches back to the old stamps for a second
    return sorted(cases, key=lambda c: c.time_resets)


def _check_case(case: Case, d: dict) -> str:
    """'' when the observed delta is what the case expects, else what differs."""
    want_drops = dict(case.drops)
    if case.drop_any_of:
        got = [k for k in d["drops"] if k in case.drop_any_of]
        if len(got) != 1 or d["drops"][got[0]] != 1:
            return f"expected one drop among {case.drop_any_of}"
        want_drops = {got[0]: 1}
    problems = []
    if d["drops"] != want_drops:
        problems.append(f"drops {d['drops']} != {want_drops}")
    for k in ("applied", "late", "floored", "time_resets"):
        if d[k] != getattr(case, k):
            problems.append(f"{k} {d[k]} != {getattr(case, k)}")
    return "; ".join(problems)


@pytest.mark.e2e
def test_bad_input_on_every_key_is_counted_and_the_estimate_stays_finite(jackal_bag, tmp_path, reliability_log):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    cfg = load(config)
    log = tmp_path / "daemon.log"
    with open_bag_samples([jackal_bag], cfg.sensors) as bag:
        messages = [(s.name, raw) for _, s, raw in bag.raw_cdr()]
    decoders = {"wheel": make_decoder("odom", "ros2-cdr", "wheel"), "imu": make_decoder("imu", "ros2-cdr", "imu")}
    cases = bad_cases()
    sensors_covered = {c.sensor for c in cases}
    assert sensors_covered == {s.name for s in cfg.sensors}  # every sensor key gets every bad input

    with daemon_process(config, log) as proc, client_session(port) as session:
        poses = Poses(session)
        wait_daemon_ready(session, proc, log)
        pubs = publishers(session, {"wheel": WHEEL_KEY, "imu": IMU_KEY})
        sent = {"wheel": 0, "imu": 0}
        pos = 0
        stream = Stream(raw={}, sample={})

        def put(name: str, payload: bytes) -> None:
            pubs[name].put(payload)
            sent[name] += 1

        def valid(n: int) -> None:
            """The next n bag messages (both keys), as fast as the blocking publisher goes."""
            nonlocal pos
            for _ in range(n):
                name, raw = messages[pos]
                pos += 1
                sample = decoders[name](raw)
                put(name, raw)
                stream.raw[name], stream.sample[name] = raw, sample
                stream.newest = max(stream.newest, sample.stamp)

        valid(60)
        before = counters(settle(session, proc, sent, poses))
        failures = []
        # -- phase A: every case between chunks of valid messages; a barrier after each attributes its counters
        for case in cases:
            for payload in case.build(stream):
                put(case.sensor, payload)
            after = counters(settle(session, proc, sent, poses))
            d = delta(before, after, case.sensor)
            other = delta(before, after, stream.other(case.sensor))
            problem = _check_case(case, d)
            if other["drops"]:
                problem += f"; the other sensor dropped {other['drops']}"
            bad_poses = poses.non_finite() + poses.undecodable
            crashed = proc.poll() is not None
            reliability_log.record(
                group="bad input", sensor=case.sensor, input=case.name, expected=case.expected, observed=describe(d),
                passed=not problem and not crashed and after["finite"] and not bad_poses, crashed=crashed,
                non_finite=not after["finite"] or bad_poses > 0, test="test_bad_input_on_every_key")
            if problem:
                failures.append(f"{case.sensor} / {case.name}: {problem}")
            before = after
            valid(20)  # the stream goes on: valid messages are fused and published between bad ones
            after = counters(settle(session, proc, sent, poses))
            for name in ("wheel", "imu"):
                dv = delta(before, after, name)
                if dv["drops"]:
                    failures.append(f"valid messages after {case.sensor} / {case.name}: {name} dropped {dv['drops']}")
            before = after
        assert not failures, "\n".join(failures)
        assert proc.poll() is None
        h = health(session)
        assert h["filter"]["finite"] and poses.non_finite() == 0 and poses.undecodable == 0
        # one pose per applied odometry message, except that the held samples of a confirmed time
        # jump are applied together and answered by one pose (the newest): the wheel's
        # confirmed-jump case confirms twice (back, then forward) 3 held samples each: 4 poses fewer
        assert len(poses) == h["published"] == h["sensors"]["wheel"]["applied"] - 4
        for name in ("wheel", "imu"):  # health reports the rejections per sensor and reason
            reasons = h["sensors"][name]["dropped_by_reason"]
            for c in cases:
                for reason in c.drops:
                    if c.sensor == name:
                        assert reasons.get(reason, 0) >= c.drops[reason], (name, reason, reasons)

        # -- phase B: a free-running stream at 10x the bag's pace, a random bad input every 5th message
        mixable = [c for c in cases if c.mixable]
        rng = random.Random(7)
        injected: dict[tuple[str, str], int] = {}
        floored = applied_extra = 0
        start = counters(h)
        t0 = time.monotonic()
        for i in range(1500 // 4):
            delay = t0 + i * 4 * 0.01 / 10.0 - time.monotonic()  # the bag's ~100 messages/s, at 10x
            if delay > 0:
                time.sleep(delay)
            valid(4)
            case = rng.choice(mixable)
            payloads = case.build(stream)
            reason = case.drop_any_of and _local_reason(decoders[case.sensor], payloads[0])
            for p in payloads:
                put(case.sensor, p)
            for r, n in ({reason: 1} if reason else case.drops).items():
                injected[(case.sensor, r)] = injected.get((case.sensor, r), 0) + n
            floored += case.floored
            applied_extra += case.applied
        end = counters(settle(session, proc, sent, poses, timeout=20))
        mismatches = {}
        for name in ("wheel", "imu"):
            d = delta(start, end, name)
            want = {r: n for (s, r), n in injected.items() if s == name}
            if d["drops"] != want:
                mismatches[name] = {r: (d["drops"].get(r, 0), want.get(r, 0)) for r in sorted({*d["drops"], *want})
                                    if d["drops"].get(r, 0) != want.get(r, 0)}  # reason: (observed, injected)
        sum_floored = sum(delta(start, end, n)["floored"] for n in ("wheel", "imu"))
        crashed = proc.poll() is not None
        n_bad = sum(injected.values()) + applied_extra
        reliability_log.record(
            group="bad input", sensor="both", input=f"mixed stream: 1500 valid + {n_bad} bad, random order, 10x pace",
            expected="every drop counted by its reason; valid odometry -> one finite pose each",
            observed=(f"drop counters match exactly: {not mismatches}; {end['published'] - start['published']} poses "
                      f"for {delta(start, end, 'wheel')['applied']} applied odometry messages"),
            passed=not mismatches and not crashed and end["finite"] and poses.non_finite() == 0,
            crashed=crashed, non_finite=not end["finite"] or poses.non_finite() > 0,
            test="test_bad_input_on_every_key")
        assert not mismatches, str(mismatches)
        assert sum_floored == floored
        assert end["finite"] and poses.non_finite() == 0 and poses.undecodable == 0
        assert len(poses) == end["published"]

        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    assert log_events(log)[-1]["event"] == "daemon_stopped"


def _local_reason(decoder, payload: bytes) -> str:
    try:
        decoder(payload)
    except DecodeError as err:
        return err.reason
    raise AssertionError("a random payload decoded")


# --------------------------------------------------------------------------- synthetic stream for the fault tests


class Synthetic:
    """A robot driving a circle: 50 Hz odometry, 100 Hz IMU (5 ms behind), stamps = wall clock + offset.

    A thread publishes while `wheel_on` / `imu_on` are set, so message time and wall time advance together
    (health liveness is wall clock, the filter's time is the stamps).
    """

    def __init__(self, session: zenoh.Session, t0: float = 1000.0, odom_hz: float = 50.0, imu_hz: float = 100.0):
        self.pubs = publishers(session, {"wheel": WHEEL_KEY, "imu": IMU_KEY})
        self.t0 = t0
        self.odom_dt, self.imu_dt = 1.0 / odom_hz, 1.0 / imu_hz
        self.wheel_on = threading.Event()
        self.imu_on = threading.Event()
        self.stop = threading.Event()
        self.sent = {"wheel": 0, "imu": 0}
        self.wheel_stamps: list[float] = []
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.error: BaseException | None = None

    def odom(self, stamp: float) -> bytes:
        return odom_payload(stamp)

    def imu(self, stamp: float) -> bytes:
        return imu_payload(stamp, self.t0)

    def start(self) -> "Synthetic":
        self.wall0 = time.monotonic()
        self.thread.start()
        return self

    def _run(self) -> None:
        try:
            k_odom = k_imu = 0
            while not self.stop.is_set():
                now = time.monotonic() - self.wall0
                while k_imu * self.imu_dt <= now:
                    if self.imu_on.is_set():
                        self.pubs["imu"].put(self.imu(self.t0 + k_imu * self.imu_dt - 0.005))
                        self.sent["imu"] += 1
                    k_imu += 1
                while k_odom * self.odom_dt <= now:
                    if self.wheel_on.is_set():
                        stamp = self.t0 + k_odom * self.odom_dt
                        self.pubs["wheel"].put(self.odom(stamp))
                        self.wheel_stamps.append(stamp)
                        self.sent["wheel"] += 1
                    k_odom += 1
                time.sleep(0.002)
        except BaseException as err:  # surfaced by the test
            self.error = err

    def close(self) -> None:
        self.stop.set()
        self.thread.join(5)


def wait_status(session, proc, status: str, timeout: float, what: str) -> dict:
    def check():
        if proc.poll() is not None:
            raise AssertionError(f"daemon exited with {proc.returncode}")
        h = health(session, 0.5)
        return h if h and h["status"] == status else None

    return wait_until(check, timeout, what, step=0.05)


@pytest.mark.e2e
def test_dropout_and_silence_degrade_then_recover(tmp_path, reliability_log):
    """IMU drops out and returns (degraded -> ok, roll/pitch variance up then down); both sensors silent
    (failed), then back (ok; the prediction gap inflates the position covariance)."""
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    log = tmp_path / "daemon.log"
    gen = None
    with daemon_process(config, log) as proc, client_session(port) as session:
        poses = Poses(session)
        wait_daemon_ready(session, proc, log)
        gen = Synthetic(session)
        try:
            gen.wheel_on.set()
            gen.imu_on.set()
            gen.start()
            wait_status(session, proc, "ok", 10, "ok with both sensors")
            # a steady state of the roll/pitch variance: 1 s of 50 Hz odometry = 50 more poses
            n_ok = len(poses)
            n_steady = wait_until(lambda: len(poses) >= n_ok + 50 and len(poses), 10, "1 s of poses")
            gen.imu_on.clear()  # -- IMU drops out
            h = wait_status(session, proc, "degraded", 5, "degraded once the IMU is silent")
            assert not h["sensors"]["imu"]["alive"] and h["sensors"]["wheel"]["alive"]
            imu_problems = [p for p in h["problems"] if p.startswith("imu:")]
            n_degraded = len(poses)  # 1 s more of the dropout: 50 poses
            n_dropout = wait_until(lambda: len(poses) >= n_degraded + 50 and len(poses), 10, "1 s of dropout")
            gen.imu_on.set()  # -- and returns
            wait_status(session, proc, "ok", 5, "ok once the IMU is back")
            n_imu_back = len(poses)  # 1.5 s to recover: 75 poses
            n_back = wait_until(lambda: len(poses) >= n_imu_back + 75 and len(poses), 10, "1.5 s with the IMU")
            gen.wheel_on.clear()  # -- both silent
            gen.imu_on.clear()
            hf = wait_status(session, proc, "failed", 5, "failed with both sensors silent")
            assert "no sensor alive" in hf["problems"]
            time.sleep(0.5)
            n_silent = len(poses)
            time.sleep(0.5)
            assert len(poses) == n_silent  # nothing published while nothing arrives
            gen.wheel_on.set()  # -- both back
            gen.imu_on.set()
            wait_status(session, proc, "ok", 5, "ok once both are back")
            wait_until(lambda: len(poses) > n_silent + 10, 5, "poses after the silence")
        finally:
            gen.close()
        assert gen.error is None, gen.error
        h = settle(session, proc, gen.sent, poses)
        assert proc.poll() is None
        items = list(poses.items)
        roll = [c[21] for _, _, _, c in items]
        xvar = [c[0] for _, _, _, c in items]
        steady = sorted(roll[max(n_steady - 20, 0):n_steady])[10]
        peak = max(roll[n_steady:n_dropout])
        recovered = roll[n_back - 1]
        # silence: first pose after it vs last before it; the gap term alone is gap_inflation^2 (dt - gap_s)
        dt = items[n_silent][1] - items[n_silent - 1][1]
        gap_term = GAP_INFLATION_POS**2 * (dt - GAP_S)
        jump = xvar[n_silent] - xvar[n_silent - 1]
        finite = h["filter"]["finite"] and poses.non_finite() == 0
        row = dict(group="fault", sensor="imu", test="test_dropout_and_silence", crashed=proc.poll() is not None,
                   non_finite=not finite)
        reliability_log.record(
            **row, input="IMU silent for 1 s, then back",
            expected="degraded (imu not alive), roll/pitch variance grows; ok again, variance recovers",
            observed=(f"degraded ({imu_problems[0] if imu_problems else ''}); roll variance {steady:.2e} -> "
                      f"{peak:.2e} during the dropout -> {recovered:.2e} after; ok again"),
            passed=peak > 2 * steady and recovered < 0.5 * peak and finite)
        row["sensor"] = "both"
        reliability_log.record(
            **row, input=f"both sensors silent ({dt:.2f} s of stamps), then back",
            expected="failed ('no sensor alive'), nothing published; ok again, position covariance inflated by the gap",
            observed=(f"failed; no pose while silent; x variance {xvar[n_silent - 1]:.3e} -> {xvar[n_silent]:.3e} "
                      f"(+{jump:.2e} >= gap term {gap_term:.2e}); ok again"),
            passed=jump >= gap_term > 0 and finite)
        assert peak > 2 * steady, (steady, peak)
        assert recovered < 0.5 * peak, (peak, recovered)
        assert jump >= gap_term > 0, (jump, gap_term, dt)
        assert finite
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0


# --------------------------------------------------------------------------- the router on the other end restarts

ROUTER_SCRIPT = """
import sys, time, zenoh
conf = zenoh.Config()
conf.insert_json5("mode", '"router"')
conf.insert_json5("listen/endpoints", '["%s"]' % sys.argv[1])
conf.insert_json5("scouting/multicast/enabled", "false")
session = zenoh.open(conf)
print("ready", flush=True)
try:
    sys.stdin.read()  # until the test closes our stdin (or kills us)
finally:
    session.close()
"""


def start_router(script: Path, endpoint: str) -> subprocess.Popen:
    proc = subprocess.Popen([sys.executable, str(script), endpoint], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    line: list[str] = []
    reader = threading.Thread(target=lambda: line.append(proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(20)
    if not line or "ready" not in line[0]:
        proc.kill()
        raise AssertionError(f"the router did not start on {endpoint}")
    return proc


def router_client(endpoint: str) -> zenoh.Session:
    return open_session(build_config(ZenohConfig(mode="client", connect=[endpoint], multicast_scouting=False)))


def send_odom_until_pose(pub: zenoh.Publisher, poses: Poses, stamps: list[float], timeout: float) -> float:
    """Put odometry (new stamps) every 50 ms until a pose with one of those stamps arrives; its stamp."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        stamp = stamps[-1] + 0.02
        stamps.append(stamp)
        pub.put(odom_payload(stamp))
        time.sleep(0.05)
        got = {round(s, 6) for s in poses.stamps()} & {round(s, 6) for s in stamps}
        if got:
            return max(got)
    raise AssertionError(f"no pose within {timeout} s")


@pytest.mark.e2e
def test_router_restart_daemon_reconnects_without_restart(tmp_path, reliability_log):
    router_port = free_port()
    endpoint = f"tcp/127.0.0.1:{router_port}"
    script = tmp_path / "router.py"
    script.write_text(ROUTER_SCRIPT)
    config = tmp_path / "client.toml"
    config.write_text(f'[zenoh]\nmode = "client"\nconnect = ["{endpoint}"]\nmulticast_scouting = false\n\n'
                      + (ROOT / "examples" / "jackal.toml").read_text())
    log = tmp_path / "daemon.log"
    router = router2 = None
    sessions: list[zenoh.Session] = []
    try:
        router = start_router(script, endpoint)
        with daemon_process(config, log) as proc:
            s1 = router_client(endpoint)
            sessions.append(s1)
            poses1 = Poses(s1)
            wait_daemon_ready(s1, proc, log)
            pub = s1.declare_publisher(WHEEL_KEY)
            stamps = [1000.0]
            send_odom_until_pose(pub, poses1, stamps, 10)
            before = health(s1)["published"]

            router.kill()  # -- the router dies (no goodbye) ...
            router.wait(5)
            # The loss is seen: our client of that router has dropped it (the daemon, a client of the
            # same router over the same kind of link, sees the same closed socket).
            wait_until(lambda: not list(s1.info.routers_zid()), 10, "the clients to lose the router")
            assert proc.poll() is None, "the daemon died with its router"
            router2 = start_router(script, endpoint)  # ... and comes back on the same port
            s2 = router_client(endpoint)
            sessions.append(s2)
            poses2 = Poses(s2)
            t_restart = time.monotonic()
            h = wait_daemon_ready(s2, proc, log, timeout=20)  # the daemon re-declared its queryable there
            pub2 = s2.declare_publisher(WHEEL_KEY)
            first = send_odom_until_pose(pub2, poses2, stamps, 15)
            reconnect_s = time.monotonic() - t_restart
            h = health(s2)
            pid_same = proc.poll() is None
            reliability_log.record(
                group="fault", sensor="zenoh", input="the router the daemon (client mode) is connected to is killed "
                                                      "and restarted on the same port",
                expected="the daemon keeps running, reconnects by itself, resumes publishing",
                observed=(f"daemon process unchanged, health answered again and poses resumed "
                          f"{reconnect_s:.1f} s after the restart ({before} poses before, {h['published']} now)"),
                passed=pid_same and h["published"] > before and h["filter"]["finite"],
                crashed=not pid_same, non_finite=not h["filter"]["finite"], test="test_router_restart")
            assert pid_same and h["published"] > before
            assert first in {round(s, 6) for s in poses2.stamps()}
            proc.send_signal(signal.SIGTERM)
            assert proc.wait(15) == 0
    finally:
        for s in sessions:
            s.close()
        for r in (router, router2):
            if r is not None and r.poll() is None:
                r.kill()
                r.wait(5)


# --------------------------------------------------------------------------- SIGTERM mid-stream


@pytest.mark.e2e
def test_sigterm_mid_stream_exits_0_and_publishes_the_last_pose(tmp_path, reliability_log):
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        poses = Poses(session)
        wait_daemon_ready(session, proc, log)
        gen = Synthetic(session, odom_hz=200.0, imu_hz=400.0)
        try:
            gen.wheel_on.set()
            gen.imu_on.set()
            gen.start()
            wait_until(lambda: len(poses) > 100, 10, "poses flowing")
            proc.send_signal(signal.SIGTERM)  # while messages keep coming
            code = proc.wait(15)
        finally:
            gen.close()
        # The daemon's last log event says how many poses it published; some are still in flight on
        # the loopback link when it exits: wait for that many here (the asserts below say if not).
        target = log_events(log)[-1].get("published", 0)
        deadline = time.monotonic() + 5.0
        while len(poses) < target and time.monotonic() < deadline:
            time.sleep(0.02)
    stopped = log_events(log)[-1]
    assert stopped["event"] == "daemon_stopped", stopped
    published = stopped["published"]
    wheel = stopped["sensors"]["wheel"]
    stamps = poses.stamps()
    last_ok = bool(stamps) and published >= 1 and stamps[-1] == pytest.approx(gen.wheel_stamps[published - 1], abs=1e-9)
    reliability_log.record(
        group="fault", sensor="process", input="SIGTERM while 200 Hz odometry + 400 Hz IMU keep arriving",
        expected="exit 0; the pose of the last processed odometry message is published",
        observed=(f"exit {code}; {wheel['applied']} odometry processed, {published} poses published, "
                  f"{len(stamps)} received; last pose stamp = the {published}th odometry stamp: {last_ok}"),
        passed=code == 0 and last_ok and len(stamps) == published, crashed=code != 0, non_finite=poses.non_finite() > 0,
        test="test_sigterm_mid_stream")
    assert code == 0
    assert wheel["applied"] == published and wheel["dropped"] == 0
    assert len(stamps) == published, (len(stamps), published)
    assert last_ok, (stamps[-1:], gen.wheel_stamps[published - 1])
    assert poses.non_finite() == 0


# --------------------------------------------------------------------------- burst far above the rate


@pytest.mark.e2e
def test_burst_far_above_rate_is_bounded_counted_and_recovers(tmp_path, reliability_log):
    """A burst far faster than the daemon fuses, from a blocking sender: the daemon fuses each sample on the
    thread that receives it, so the burst is paced by the link (the sender waits) rather than lost; whatever
    meets a full inbox (only while another thread holds the core) is counted as queue_full; nothing is lost
    uncounted and poses resume at once. The queue's overflow itself: tests/e2e/test_daemon_inproc.py."""
    port = free_port()
    config = write_config(tmp_path / "jackal.toml", port)
    # Every burst sample costs a full roll/pitch update (not thinned to orientation_rate_hz): the burst is
    # far above the rate the daemon fuses, so the link paces it.
    text = config.read_text()
    assert 'orientation = "roll_pitch"' in text
    config.write_text(text.replace('orientation = "roll_pitch"', 'orientation = "roll_pitch"\norientation_rate_hz = 0', 1))
    log = tmp_path / "daemon.log"
    with daemon_process(config, log) as proc, client_session(port) as session:
        poses = Poses(session)
        wait_daemon_ready(session, proc, log)
        gen = Synthetic(session)
        pubs = gen.pubs
        # a normal start: 1 s at 50 Hz odometry + 100 Hz IMU
        stamps: list[float] = []
        for k in range(50):
            stamps.append(1000.0 + 0.02 * k)
            pubs["imu"].put(gen.imu(stamps[-1] - 0.005))
            pubs["imu"].put(gen.imu(stamps[-1] + 0.005))
            pubs["wheel"].put(gen.odom(stamps[-1]))
            time.sleep(0.02)
        wait_until(lambda: len(poses) >= 50, 10, "the first poses")
        # the burst: 30000 IMU messages (10 kHz of stamps) as fast as the client can put them
        template = bytearray(gen.imu(stamps[-1]))
        n_burst, start = 30000, stamps[-1] + 0.0061  # after the last IMU stamp (+5 ms)
        sent = {"wheel": 50, "imu": 100}
        t0 = time.monotonic()
        for k in range(n_burst):
            stamp = start + k * 1e-4
            sec = math.floor(stamp)
            struct.pack_into("<iI", template, 4, sec, round((stamp - sec) * 1e9))
            pubs["imu"].put(bytes(template))
        burst_s = time.monotonic() - t0
        sent["imu"] += n_burst
        settle(session, proc, sent, poses, timeout=30)
        # recovery, measured by poses arriving: odometry resumes at 50 Hz after the burst's stamps, and
        # every message gets its pose.
        base = start + n_burst * 1e-4 + 0.01
        tail = [base + 0.02 * k for k in range(25)]
        again = [tail[-1] + 0.02 * (k + 1) for k in range(25)]

        def steady(stamps_: list[float]) -> None:
            for s in stamps_:
                pubs["wheel"].put(gen.odom(s))
                pubs["imu"].put(gen.imu(s + 0.005))
                sent["wheel"] += 1
                sent["imu"] += 1
                time.sleep(0.02)

        steady(tail)
        settle(session, proc, sent, poses, timeout=30)
        steady(again)
        h = settle(session, proc, sent, poses, timeout=30)
        got = {round(s, 6) for s in poses.stamps()}  # stamps went through (sec, nanosec)
        tail_posed = sum(round(s, 6) in got for s in tail)
        resumed = sum(round(s, 6) in got for s in again)
        after = again
        q = h["queue"]
        imu = h["sensors"]["imu"]
        full = imu["dropped_by_reason"].get("queue_full", 0)
        others = {k: v for k, v in imu["dropped_by_reason"].items() if k != "queue_full"}
        reliability_log.record(
            group="fault", sensor="imu", input=f"burst: {n_burst} IMU messages in {burst_s:.1f} s "
                                                f"(~{n_burst / burst_s:.0f}/s; normal 100/s)",
            expected="paced by the link (a blocking sender waits), queue bounded (capacity 1024), any overflow "
                     "counted as queue_full, nothing lost uncounted, poses resume after the burst",
            observed=(f"queue_full {full}, queue depth back to {q['depth']}/{q['capacity']}; received "
                      f"{imu['received']} = applied {imu['applied']} + dropped {imu['dropped']}; "
                      f"{tail_posed}/{len(tail)} odometry messages right after the burst and "
                      f"{resumed}/{len(after)} once drained got their pose"),
            passed=(resumed == len(after) == tail_posed and q["depth"] == 0 and h["filter"]["finite"]
                    and imu["received"] == sent["imu"] == imu["applied"] + imu["dropped"] and not others),
            crashed=proc.poll() is not None, non_finite=not h["filter"]["finite"] or poses.non_finite() > 0,
            test="test_burst")
        wheel = h["sensors"]["wheel"]
        assert not others, imu["dropped_by_reason"]
        assert q["dropped"] == full + wheel["dropped_by_reason"].get("queue_full", 0)
        assert imu["received"] == sent["imu"] == imu["applied"] + imu["dropped"]
        assert q["depth"] == 0 and q["capacity"] == 1024
        assert resumed == len(after) == tail_posed  # no backlog left behind the burst: the tail posed at once
        assert set(wheel["dropped_by_reason"]) <= {"queue_full"}, wheel
        assert wheel["received"] == sent["wheel"] == wheel["applied"] + wheel["dropped"]
        assert h["filter"]["finite"] and poses.non_finite() == 0
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0


# --------------------------------------------------------------------------- router outages of 1, 3 and 10 s

OUTAGE_RATE_HZ = 50.0  # odometry put through the router, as `fusiond play` of a 50 Hz robot would


@pytest.mark.e2e
@pytest.mark.parametrize("outage_s", [1.0, 3.0, 10.0])
def test_router_outage_loses_about_the_outage(tmp_path, reliability_log, outage_s):
    """The router between a player and the daemon (both clients, the config's retry defaults) is down for
    ``outage_s``: what the daemon never received, in seconds of data, and how soon poses resumed."""
    from tests.support.fleet import client, robot_config, start_daemon, start_router

    port = free_port()
    router = start_router(port, tmp_path / "router.log")
    routers = [router]
    log = tmp_path / "robot.log"
    proc = start_daemon(robot_config(tmp_path / "robot.toml", port, "robot1"), log)
    sessions = []
    try:
        feed = client(port, "robot1")
        sessions.append(feed)
        poses = Poses(feed)
        wait_daemon_ready(feed, proc, log)
        pub = feed.declare_publisher(WHEEL_KEY)
        sent: list[tuple[float, float]] = []  # (wall, stamp)
        stop = threading.Event()

        def put_odometry() -> None:
            t0, k = time.monotonic(), 0
            while not stop.wait(max(t0 + k / OUTAGE_RATE_HZ - time.monotonic(), 0.0)):
                stamp = 2000.0 + k / OUTAGE_RATE_HZ
                pub.put(odom_payload(stamp))
                sent.append((time.monotonic(), stamp))
                k += 1

        feeder = threading.Thread(target=put_odometry, daemon=True)
        feeder.start()
        wait_until(lambda: len(poses) > 25, 10, "poses before the outage")
        before = health(feed)["sensors"]["wheel"]["received"]
        n_before = len(sent)
        router.kill()
        router.wait(5)
        stop.wait(outage_s)  # the fault's length, not a wait for a result
        routers.append(start_router(port, tmp_path / "router.log"))
        restarted = time.monotonic()
        n_at_restart = len(sent)

        def first_pose_after() -> float | None:
            with poses.lock:
                return next((arrival for arrival, *_ in poses.items if arrival > restarted), None)

        resumed = wait_until(first_pose_after, 20, "poses after the outage")
        resume_s = resumed - restarted
        wait_until(lambda: len(sent) >= n_at_restart + 2 * OUTAGE_RATE_HZ, 10, "2 s more of odometry")
        stop.set()
        feeder.join(5)
        n_sent = len(sent) - n_before
        h = wait_until(lambda: (lambda x: x if x and x["sensors"]["wheel"]["received"] >= before else None)(
            health(feed)), 10, "the daemon's health after the outage")
        lost = n_sent - (h["sensors"]["wheel"]["received"] - before)
        lost_s = lost / OUTAGE_RATE_HZ
        events = [e["event"] for e in log_events(log)]
        seen = "zenoh_link_lost" in events and "zenoh_link_restored" in events
        reliability_log.record(
            group="fault", sensor="zenoh",
            input=f"the router between player and daemon (both clients) down {outage_s:g} s, odometry put at "
                  f"{OUTAGE_RATE_HZ:g} Hz through it",
            expected="the daemon logs the link lost and restored; data lost about the outage (connect_retry "
                     "0.25 s growing to 0.5 s), not seconds more",
            observed=(f"{lost} of {n_sent} odometry messages never received ({lost_s:.1f} s of data); poses "
                      f"resumed {resume_s:.1f} s after the restart; link reconnections "
                      f"{h['link_stats']['reconnections']}"),
            passed=seen and lost_s <= outage_s + 1.5 and h["link_stats"]["reconnections"] >= 1,
            crashed=proc.poll() is not None, non_finite=not h["filter"]["finite"], test="test_router_outage")
        assert seen, events
        assert lost_s <= outage_s + 1.5, (lost, n_sent)
        assert h["link_stats"]["reconnections"] >= 1 and h["link"] == "connected"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
    finally:
        for s in sessions:
            s.close()
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        for r in routers:
            if r.poll() is None:
                r.kill()
                r.wait(5)
