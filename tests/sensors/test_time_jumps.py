"""The held-timeline bookkeeping on its own: what confirms a new timeline, what is a glitch."""

from __future__ import annotations

from fusiond.core.time_jumps import HeldTimeline


def test_a_cluster_is_confirmed_by_count_and_persistence_together():
    h = HeldTimeline(jump_s=5.0, confirm=3, persist_s=1.0, capacity=100)
    assert h.far(20.0, 10.0) and h.far(4.0, 10.0) and not h.far(14.9, 10.0) and not h.far(20.0, None)
    # three samples within 0.2 s: enough by count, not by persistence
    assert [h.hold(20.0 + 0.1 * k, 0, k) for k in range(3)] == [([], False)] * 3
    dropped, confirmed = h.hold(21.0, 1, "x")  # 1.0 s after the first: confirmed
    assert dropped == [] and confirmed
    c = h.take()
    assert [(s, i) for s, i, _ in c.in_order()] == [(20.0, 0), (20.1, 0), (20.2, 0), (21.0, 1)]
    assert h.cluster is None and h.counts(2) == [0, 0]


def test_a_different_far_timeline_replaces_the_held_one_and_capacity_is_bounded():
    h = HeldTimeline(jump_s=5.0, confirm=3, persist_s=1.0, capacity=2)
    h.hold(100.0, 0, "a")
    h.hold(100.1, 1, "b")
    assert h.counts(2) == [1, 1]
    assert h.full(100.2)  # beyond capacity: the caller drops it instead of holding it
    assert not h.full(500.0)  # a different far timeline would replace the held one
    dropped, confirmed = h.hold(500.0, 0, "d")  # far from the held cluster: that one did not persist
    assert [s for s, _, _ in dropped] == [100.0, 100.1] and not confirmed and h.counts(2) == [1, 0]
    assert [s for s, _, _ in h.abandon()] == [500.0] and h.cluster is None


def test_a_cluster_holding_the_anchors_samples_is_left_only_by_the_anchor():
    """The anchor (sensor 0, the odometry) jumped: its held cluster is not replaced by another sensor's far
    samples on yet another timeline (those are dropped alone) and not left when another sensor goes on along
    the old timeline; the anchor going on along the old one leaves it."""
    h = HeldTimeline(jump_s=5.0, confirm=3, persist_s=1.0, capacity=100, anchor=0)
    h.hold(100.0, 0, "odom")
    dropped, confirmed = h.hold(-40000.0, 1, "imu")  # the IMU on its boot clock
    assert [(s, i) for s, i, _ in dropped] == [(-40000.0, 1)] and not confirmed and h.counts(2) == [1, 0]
    assert not h.left_by(1) and h.left_by(0)
    h.hold(100.5, 1, "imu on the anchor's timeline")  # joins it
    assert h.hold(101.0, 0, "odom")[1]  # three samples over 1 s: confirmed
    unanchored = HeldTimeline(jump_s=5.0, confirm=3, persist_s=1.0, capacity=100, anchor=0)
    unanchored.hold(-40000.0, 1, "imu")
    assert unanchored.left_by(0) and unanchored.left_by(1)  # any sensor's old timeline leaves it


def test_poses_of_a_held_timeline_say_the_heading_known_as_it_was_at_each():
    """The IMU on a clock 1e6 s ahead and first in the recording: the filter's time follows it, the wheels and the
    fixes are held as a jump back for jump_persist_s (4 s here), then reset onto and applied at once, the GPS
    heading searched for afresh among them. Each pose of that cluster says whether the heading was known at it,
    as the same drive without the IMU says (every one of them read "known", the state's after the cluster)."""
    from tests.support import sim_gps
    from tests.support.configs import robot_config
    from tests.support.sim_faults import shift_stamps
    from fusiond.replay.run import run_samples

    samples = sim_gps.simulate(sim_gps.World(duration=30.0, speed=10.0, gps_rate=10.0))
    start = samples[0].stamp + 0.5  # the IMU's alone
    cfg = robot_config(gps="", filt="jump_persist_s = 4.0")
    shifted = run_samples(shift_stamps([s for s in samples if s.sensor == "imu" or s.stamp >= start], "imu", 1e6), cfg)
    alone = run_samples([s for s in samples if s.sensor != "imu" and s.stamp >= start], cfg)
    assert shifted.core.resets == 1
    unknown = list(alone.heading_known).count(False)
    assert unknown > 10 and list(shifted.heading_known).count(False) == unknown
