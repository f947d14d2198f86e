"""The fixed-lag smoothed pose (fusiond/core/fixed_lag.py) against the offline smoother over the same window.

Two real FusionCores take the same simulated run (GPS with the heading searched for at the start, late
IMU messages that rewind the filter): one keeps a bounded fixed-lag window, the other records the whole
run for the offline smoother. At every publish moment the lagged pose is the anchor at or just before
newest - lag, and it equals the offline smoother run over the anchors from it to the newest (1e-9),
while the window never holds more than the lag + history's anchors.
"""

from __future__ import annotations

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import POSE
from fusiond.estimator.smoother import smooth
from fusiond.core.sensors import ImuSample

from tests.support import sim_gps
from tests.support.configs import robot_config

LAG = 0.5
WORLD = dict(duration=20.0, odom_rate=20.0, imu_rate=50.0, speed=2.0, gps_rate=5.0, gps_sigma=0.5,
             arcs=((6.0, 14.0, 0.2),))


def _late(samples: list, every: int = 7, by: int = 4) -> list:
    """Every ``every``-th IMU message delivered ``by`` messages late (the core rewinds for it)."""
    out = list(samples)
    i = 0
    n = 0
    while i < len(out) - by:
        if isinstance(out[i], ImuSample):
            n += 1
            if n % every == 0:
                out.insert(i + by, out.pop(i))
                i += by
        i += 1
    return out


def _offline_window(core: FusionCore, stamp: float) -> np.ndarray:
    """The offline smoother over the whole record's anchors from the one at ``stamp`` to the newest."""
    core.smoothed()  # drops what an abandoned timeline recorded
    rec = core._smoothing
    stamps = [a.stamp for a in rec.anchors]
    k = stamps.index(stamp)
    turns = [(before - k, angle) for before, angle in rec.relative_turns()]
    return smooth(rec.layout, rec.anchors[k:], False, turns).x[0]


@pytest.mark.parametrize("late", [False, True], ids=["in_order", "late_imu"])
def test_lagged_pose_equals_the_offline_smoother_over_the_same_window(late):
    samples = sim_gps.simulate(sim_gps.World(**WORLD))
    if late:
        samples = _late(samples)
    cfg = robot_config(gps="")
    lagged, offline = FusionCore(cfg), FusionCore(cfg)
    lagged.smooth_with_lag(LAG)
    offline.record_for_smoothing()
    checked = moved = shown = within = total = 0
    last = None
    most = 0
    period = 1.0 / WORLD["odom_rate"]
    for i, s in enumerate(samples):
        a, b = lagged.ingest(s), offline.ingest(s)
        assert a.publish == b.publish
        if not a.publish:
            continue
        pose = lagged.lagged_pose()
        newest = lagged._smoothing.anchors[-1].stamp if lagged._smoothing.anchors else None
        most = max(most, len(lagged._smoothing.anchors))
        if pose is None:  # the window does not reach back yet, or its moment was returned already
            held = [a.stamp for a in lagged._smoothing.anchors if newest is not None and a.stamp <= newest - LAG]
            assert not held or held[-1] == last
            continue
        assert last is None or pose.stamp > last
        last = pose.stamp
        # the last publish moment at or before newest - lag: within a message period of it where the
        # publish moments are (before the GPS defines the world frame there are none)
        assert pose.stamp <= newest - LAG
        later = [a.stamp for a in offline._smoothing.anchors if a.stamp > pose.stamp]
        assert later and later[0] > newest - LAG
        within += pose.stamp >= newest - LAG - period - 1e-9
        total += 1
        if i % 3:
            continue
        want = _offline_window(offline, pose.stamp)
        got = np.array([*pose.position, *pose.orientation])
        assert np.max(np.abs(got - want[POSE])) < 1e-9, (pose.stamp, got - want[POSE])
        filtered = offline._smoothing.anchors[[a.stamp for a in offline._smoothing.anchors].index(pose.stamp)]
        moved += np.linalg.norm(filtered.x[0:3] - want[0:3]) > 1e-3
        shown += filtered.shown is not None
        checked += 1
    assert checked > 50 and moved > 10, (checked, moved)
    assert within >= total - 2, (within, total)
    # bounded: the lag + the history (1 s) of publish moments, plus the one at or before the window
    assert most <= (LAG + 1.0) * WORLD["odom_rate"] + 3, most


def test_off_by_default_no_recorder():
    core = FusionCore(robot_config())
    assert core._smoothing is None and core.lagged_pose() is None


def test_config_keys_off_by_default_and_the_lag_must_be_positive():
    from fusiond.config import ConfigError, loads

    from tests.support.configs import robot_config_text

    cfg = robot_config()
    assert cfg.output.smoothed_key == "" and cfg.output.smooth_lag_s == 1.0
    on = loads('[output]\nsmoothed_key = "odom_smoothed"\nsmooth_lag_s = 2.5\n' + robot_config_text())
    assert on.output.smoothed_key == "odom_smoothed" and on.output.smooth_lag_s == 2.5
    for bad in ("0", "-1.0", "nan"):
        with pytest.raises(ConfigError, match="smooth_lag_s"):
            loads(f'[output]\nsmooth_lag_s = {bad}\n' + robot_config_text())


def test_the_daemon_records_the_window_only_with_the_key():
    """Off (the default) costs nothing: no recorder in the daemon's core; on, the window's recorder."""
    from fusiond.config import loads
    from fusiond.transport.daemon import Daemon

    from tests.support.configs import robot_config_text

    off = Daemon(robot_config(), session=None, monitor=False)
    assert off.core._smoothing is None and off.core._lag is None
    on = Daemon(loads('[output]\nsmoothed_key = "odom_smoothed"\nsmooth_lag_s = 2.0\n' + robot_config_text()),
                session=None, monitor=False)
    assert on.core._lag is not None and on.core._lag.lag_s == 2.0 and on.core._smoothing is on.core._lag.recorder


def test_a_time_jump_back_starts_the_window_again():
    """A recording played twice: the second pass's stamps jump back, the core starts over, and the lagged
    poses follow the new timeline (none of the old one's later stamps in between), lag_s behind it."""
    samples = sim_gps.simulate(sim_gps.World(**{**WORLD, "duration": 8.0}))
    core = FusionCore(robot_config(gps=""))
    core.smooth_with_lag(LAG)
    out = []
    for s in samples + samples:
        if core.ingest(s).publish:
            pose = core.lagged_pose()
            if pose is not None:
                out.append((pose.stamp, core._smoothing.anchors[-1].stamp))
    assert core.resets == 1
    back = [i for i in range(1, len(out)) if out[i][0] < out[i - 1][0]]
    assert len(back) == 1, back  # one jump back, where the second pass begins
    second = out[back[0]:]
    assert len(second) > 0.5 * (len(out) - len(second))
    assert all(np.diff([t for t, _ in second]) > 0)
    assert all(newest - LAG - 0.1 <= t <= newest - LAG for t, newest in second)
    stamps = [a.stamp for a in core._smoothing.anchors]
    assert stamps == sorted(stamps)


def test_every_publish_moment_the_lag_reaches_is_returned_once_across_a_logging_gap():
    """A consumer of the lagged stream gets each publish moment once, in order: where the newest stamp leaps (a
    logging gap of 5 s), the moments the lag passed over in one step come all at once, not the last alone (a
    second's hole before every gap), and at 20 Hz odometry with 50 Hz IMU messages none is skipped between."""
    samples = [s for s in sim_gps.simulate(sim_gps.World(**WORLD)) if not 1008.0 <= s.stamp < 1013.0]
    core = FusionCore(robot_config(gps=""))
    core.smooth_with_lag(LAG)
    published, lagged = [], []
    for s in samples:
        step = core.ingest(s)
        if step.poses:  # the gap is held as a jump forward: its samples' poses come at once
            published += [t for t, _ in step.poses]
        elif step.publish:
            published.append(core.pose()[0])
        if step.publish:
            lagged += [p.stamp for p in core.lagged_poses()]
    assert lagged == sorted(set(lagged)), "each moment once, in order"
    reached = [t for t in published if t <= published[-1] - LAG]
    assert lagged == reached[:len(lagged)] and len(reached) - len(lagged) <= 1, (len(reached), len(lagged))
    assert any(b - a > 4.0 for a, b in zip(lagged, lagged[1:]))  # the gap is in it


def test_a_reset_returns_the_ended_timelines_last_lag_of_moments():
    """A recording played twice: at the jump back the core starts over, and the last lag_s of the first
    pass's publish moments, which no later anchor of that timeline would reach, come out of lagged_poses
    before the second pass's (smoothed over the anchors to the timeline's end, the last of them the filtered
    pose itself): every publish moment of the first pass is in the lagged stream once, in order."""
    samples = sim_gps.simulate(sim_gps.World(**{**WORLD, "duration": 8.0}))
    core = FusionCore(robot_config(gps=""))
    core.smooth_with_lag(LAG)
    published, lagged = [], []
    for s in samples + samples:
        step = core.ingest(s)
        if step.publish:
            if core.resets == 0:
                published.append(core.pose())
            lagged += core.lagged_poses()
    assert core.resets == 1
    back = next(i for i in range(1, len(lagged)) if lagged[i].stamp < lagged[i - 1].stamp)
    assert [p.stamp for p in lagged[:back]] == [t for t, _ in published]
    t_end, x_end = published[-1]
    assert np.allclose(lagged[back - 1].position, x_end[:3], atol=1e-9)
    assert all(np.diff([p.stamp for p in lagged[back:]]) > 0)
