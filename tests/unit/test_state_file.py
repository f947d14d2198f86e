"""The persisted state: the core's export/resume operation and the file around it (round trip,
stale, foreign, corrupt and truncated files, a failed write that leaves the old file)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.core.resume import ResumeState, state_fingerprint
from fusiond.errors import CoreError
from fusiond.core.sensors import GpsSample, ImuSample, OdomSample
from fusiond.transport import state_file
from fusiond.transport.state_file import StateRefused, StateSaver, load_state, save_state

from tests.support.configs import robot_config

GPS = "datum = [48.0, 11.0, 500.0]\nposition_noise = [0.5, 0.5, 2.0]\n"
TWIST_COV = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
IMU_COV = (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4)
GYRO_COV = (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)


def drive(core: FusionCore, k0: int, n: int) -> float:
    """Steps k0 .. k0+n-1 of 0.02 s on a circle (1 m/s, 0.1 rad/s; the gyro reads 0.002 rad/s of
    bias), IMU each step, a fix of the true position every 25th. Returns the last stamp."""
    t = 0.0
    for k in range(k0, k0 + n):
        t = 100.0 + 0.02 * k
        core.ingest(ImuSample("imu", t - 0.004, (0.0, 0.0, 0.0, 1.0), IMU_COV, (0.0, 0.0, 0.1 + 0.002), GYRO_COV))
        if k % 25 == 0:
            a = 0.1 * (t - 100.0)
            east, north = math.sin(a) / 0.1, (1.0 - math.cos(a)) / 0.1
            core.ingest(GpsSample("gps", t - 0.001, 48.0 + north / 111_200.0, 11.0 + east / 74_400.0, 500.0, 0,
                                  (0.25, 0, 0, 0, 0.25, 0, 0, 0, 4.0), 2))
        core.ingest(OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.1), TWIST_COV))
    return t


@pytest.fixture
def driven() -> FusionCore:
    core = FusionCore(robot_config(gps=GPS))
    drive(core, 0, 600)
    assert core.ready and core.heading_known and core.gyro_bias is not None
    return core


def test_a_resumed_core_is_the_exported_one_and_goes_on_like_it(driven):
    """Export -> resume gives the same state, covariance, world frame and learnt blocks; fed the same
    samples afterwards, the resumed core and a set_pose-like restart track the original closely."""
    saved = driven.export_state()
    fresh = FusionCore(robot_config(gps=GPS))
    fresh.resume(saved)
    assert fresh.ready and fresh.time == saved.stamp
    assert np.array_equal(fresh.state.ekf.x, driven.state.ekf.x)
    assert np.array_equal(fresh.state.ekf.P, driven.state.ekf.P)
    assert fresh.state.enu.datum == (48.0, 11.0, 500.0) and fresh.heading_known == driven.heading_known
    assert np.array_equal(fresh.gyro_bias, driven.gyro_bias) and fresh.scales == driven.scales
    # both go on: after 2 s more of the same drive they agree to centimetres (held inputs re-form)
    t = drive(driven, 600, 100)
    drive(fresh, 600, 100)
    assert fresh.time == driven.time == t
    assert np.linalg.norm(fresh.pose()[1][0:3] - driven.pose()[1][0:3]) < 0.02
    # nothing older than the resumed stamp is placed
    assert not fresh.ingest(OdomSample("wheel", saved.stamp - 0.5, (1.0, 0, 0), (0, 0, 0), TWIST_COV)).accepted


def test_resume_refuses_another_config_a_version_and_unsound_numbers(driven):
    saved = driven.export_state()
    other = FusionCore(robot_config())  # no GPS: another layout and sensor set
    assert other.fingerprint != driven.fingerprint
    with pytest.raises(CoreError, match="another config"):
        other.resume(saved)
    core = FusionCore(robot_config(gps=GPS))
    before = core.state
    bad = [
        ResumeState(**{**_fields(saved), "version": 99}),
        ResumeState(**{**_fields(saved), "x": saved.x[:-1]}),
        ResumeState(**{**_fields(saved), "P": [float("nan")] * len(saved.P)}),
        ResumeState(**{**_fields(saved), "x": [0.0] * len(saved.x)}),  # a zero quaternion
        ResumeState(**{**_fields(saved), "stamp": -1.0}),
    ]
    for state in bad:
        with pytest.raises(CoreError):
            core.resume(state)
        assert core.state is before  # nothing changed
    # retuned noise keeps the fingerprint: a retuned config resumes
    assert state_fingerprint(robot_config(gps=GPS + "mahalanobis_threshold = 3.0\n")) == driven.fingerprint


def _fields(s: ResumeState) -> dict:
    return {f: getattr(s, f) for f in s.__struct_fields__}


def test_the_file_round_trips_and_refuses_stale_foreign_corrupt_and_missing(driven, tmp_path):
    saved = driven.export_state()
    path = tmp_path / "state.msgpack"
    save_state(path, saved, saved_wall=1000.0)
    got = load_state(path, driven.fingerprint, max_age_s=30.0, now_wall=1010.0)
    assert got.state == saved and got.saved_wall == 1000.0

    with pytest.raises(StateRefused) as err:
        load_state(path, driven.fingerprint, max_age_s=30.0, now_wall=1030.5)
    assert err.value.reason == "stale"
    with pytest.raises(StateRefused) as err:
        load_state(path, state_fingerprint(robot_config()), max_age_s=30.0, now_wall=1010.0)
    assert err.value.reason == "foreign"
    data = path.read_bytes()
    for broken in (data[: len(data) // 2], data[:5], b"", b"not msgpack at all"):
        path.write_bytes(broken)
        with pytest.raises(StateRefused) as err:
            load_state(path, driven.fingerprint, max_age_s=30.0, now_wall=1010.0)
        assert err.value.reason == "corrupt"
    with pytest.raises(StateRefused) as err:
        load_state(tmp_path / "none", driven.fingerprint, max_age_s=30.0, now_wall=1010.0)
    assert err.value.reason == "missing"


def test_a_failed_write_leaves_the_old_file_and_no_temporary(driven, tmp_path, monkeypatch):
    saved = driven.export_state()
    path = tmp_path / "state.msgpack"
    save_state(path, saved, saved_wall=1000.0)
    old = path.read_bytes()

    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(state_file.os, "fsync", full_disk)
    later = driven.export_state()
    with pytest.raises(OSError):
        save_state(path, ResumeState(**{**_fields(later), "stamp": later.stamp + 1.0}), saved_wall=1001.0)
    assert path.read_bytes() == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["state.msgpack"]


def test_the_saver_writes_the_newest_state_and_flush_writes_the_last(driven, tmp_path):
    path = tmp_path / "sub" / "state.msgpack"
    path.parent.mkdir()
    saver = StateSaver(path)
    first = driven.export_state()
    saver.offer(first, 1000.0)
    deadline = time.monotonic() + 5.0
    while saver.saved == 0:  # the thread writes it: wait on that, with a deadline
        assert time.monotonic() < deadline, "the saver wrote nothing in 5 s"
        time.sleep(0.01)
    assert load_state(path, driven.fingerprint, 30.0, 1000.0).state == first
    last = ResumeState(**{**_fields(first), "stamp": first.stamp + 5.0})
    saver.flush(last, 1005.0)
    assert load_state(path, driven.fingerprint, 30.0, 1005.0).state.stamp == first.stamp + 5.0
    assert saver.last_stamp == first.stamp + 5.0


def test_a_state_is_as_old_as_its_newest_fused_sample_not_its_write(driven, tmp_path):
    """A daemon idle for five minutes, then stopped cleanly, writes its state at the stop: that state's age
    runs from its newest sample (the robot may have been carried off meanwhile), so a restart refuses it."""
    path = tmp_path / "state.msgpack"
    saver = StateSaver(path)
    fused_at, stopped_at = 1000.0, 1300.0
    saver.flush(driven.export_state(), fused_at)
    with pytest.raises(StateRefused, match="stale"):
        load_state(path, driven.fingerprint, 30.0, stopped_at + 1.0)


def test_export_before_any_sample_is_a_core_error():
    with pytest.raises(CoreError):
        FusionCore(robot_config()).export_state()


def test_resume_from_file_resumes_or_says_why_not(driven, tmp_path):
    """What the daemon does at start: resumed (None), or refused with the reason its log event carries
    (the events themselves: tests/e2e/test_daemon_state.py reads them from a real daemon's log)."""
    from fusiond.transport.state_file import resume_from_file

    path = tmp_path / "state"
    saved = driven.export_state()
    cases = [
        (time.time() - 100.0, robot_config(gps=GPS), "stale"),
        (time.time(), robot_config(), "foreign"),
        (time.time(), robot_config(gps=GPS), None),
    ]
    for wall, cfg, reason in cases:
        save_state(path, saved, saved_wall=wall)
        core = FusionCore(cfg)
        assert resume_from_file(core, path, max_age_s=30.0) == reason
        assert core.initialised is (reason is None)
    path.write_bytes(path.read_bytes()[:-7])  # truncated by something other than save_state
    assert resume_from_file(FusionCore(robot_config(gps=GPS)), path, max_age_s=30.0) == "corrupt"
    assert resume_from_file(FusionCore(robot_config(gps=GPS)), tmp_path / "none", max_age_s=30.0) == "missing"


def test_a_core_resumed_after_the_robot_drove_on_believes_the_first_fix(driven):
    """A daemon restarted while the robot drives: the saved state's held twist ends at its timeout across the
    restart's gap, as in a logging gap, and the position widens by what the robot may have driven at its last
    speed. Taken at rest instead (a state without its held inputs), the resumed filter was sure of a pose 26 m
    behind the robot: the fixes were gated as outliers until the re-acquisition rule gave in, seconds later."""
    saved = driven.export_state()
    assert saved.held is not None and saved.held.linear[0] == pytest.approx(1.0)

    def after_gap(state) -> float:
        core = FusionCore(robot_config(gps=GPS))
        core.resume(state)
        t = drive(core, 600 + 1300, 150)  # 26 s later, 3 s of driving (1 s of it held to confirm the jump)
        a = 0.1 * (t - 100.0)
        return math.dist(core.pose()[1][0:2], (math.sin(a) / 0.1, (1.0 - math.cos(a)) / 0.1))

    assert after_gap(saved) < 2.0  # the first fix taken: the heading the robot turned to is what is left
    import msgspec

    assert after_gap(msgspec.structs.replace(saved, held=None)) > 10.0  # at rest: the fixes gated, 19 m off


def test_a_saved_state_without_held_inputs_still_resumes_and_unsound_ones_are_refused(driven):
    import msgspec

    saved = driven.export_state()
    old = msgspec.json.decode(msgspec.json.encode(msgspec.structs.replace(saved, held=None)), type=ResumeState)
    FusionCore(robot_config(gps=GPS)).resume(old)  # a file from before held inputs were saved
    bad = msgspec.structs.replace(saved, held=msgspec.structs.replace(saved.held, linear=(math.nan, 0.0, 0.0)))
    with pytest.raises(CoreError, match="held motion"):
        FusionCore(robot_config(gps=GPS)).resume(bad)
    late = msgspec.structs.replace(saved, held=msgspec.structs.replace(
        saved.held, last=[saved.stamp + 1.0 if v is not None else None for v in saved.held.last]))
    with pytest.raises(CoreError, match="held motion"):
        FusionCore(robot_config(gps=GPS)).resume(late)
