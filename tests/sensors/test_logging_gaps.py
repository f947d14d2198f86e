"""Logging gaps: no input outlives its sensor, whatever the length of the gap.

A logger that stops every sensor for tens of seconds must not leave the last twist
and gyro rate inside one long prediction step: the pose would jump by speed x gap and
the attitude integrate the last rates. The simulated robot drives at 1 m/s while
turning; every sensor is silent for 26.4 s.
"""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot

from tests.support.sim import SimConfig, simulate
from tests.support.core_samples import make_config

GAP_START, GAP = 1010.0, 26.4  # sim stamps start at 1000 s


@pytest.mark.parametrize("orientation, carry", [("roll_pitch", False), ("roll_pitch", True), ("absolute", False)])
def test_a_long_gap_moves_the_pose_by_at_most_speed_times_timeout(orientation, carry):
    sim = SimConfig(duration=40.0, odom_rate=50.0, imu_rate=100.0, gyro_bias=(0.02, -0.02, 0.0))
    samples = [s for s in simulate(sim) if not GAP_START <= s.stamp < GAP_START + GAP]
    core = FusionCore(make_config(orientation, extra_imu=f"yaw_across_gaps = {str(carry).lower()}"))
    before = [s for s in samples if s.stamp < GAP_START]
    after = [s for s in samples if s.stamp >= GAP_START]
    for s in before:
        core.ingest(s)
    t0, x0 = core.pose()
    x0 = x0.copy()
    for k, s in enumerate(after):
        step = core.ingest(s)
        if step.accepted:  # the new timeline confirmed (held samples applied)
            break
    t1, x1 = core.pose()
    # The robot drives at 1 m/s and turns at |w| <= 0.3 rad/s (tests/support/sim.py). Inputs are held
    # for their timeout (the gyro's 0.2 s at 100 Hz: max(timeout_s, 3 periods); the odometry's twist at
    # least through filter.gap_s, 0.5 s, a shorter silence being jitter); after the gap the filter
    # integrates the held post-gap samples (t1 - (GAP_START + GAP)). Anything beyond that bound is the
    # gap integrated with stale inputs (26.4 m before the fix).
    timeout, odom_hold = 0.2, core.cfg.filter.gap_s
    post = t1 - (GAP_START + GAP)
    assert 0.0 < post < 1.5
    moved = math.dist(x0[0:3], x1[0:3])
    assert moved <= 1.0 * (odom_hold + post) + 0.05
    # Attitude: the gyro's last rates (x/y bias 0.02 rad/s) are held for 0.2 s at most, the yaw
    # rate likewise; before the fix, 26.4 s of them tumbled the attitude by ~0.5 rad.
    r0, p0, y0 = rot.to_rpy(tuple(x0[3:7].tolist()))
    r1, p1, y1 = rot.to_rpy(tuple(x1[3:7].tolist()))
    def yaw_true(t):
        return min(sim.truth, key=lambda r: abs(r[0] - t))[3]

    if orientation == "roll_pitch" and not carry:
        assert abs(rot.wrap(y1 - y0)) <= 0.3 * (timeout + post) + 0.05
    elif carry:  # the IMU's own yaw kept the turn made in the gap: the heading turned by it
        assert abs(rot.wrap((y1 - y0) - (yaw_true(t1) - yaw_true(t0)))) < 0.05
    else:  # the IMU's absolute yaw brings the heading back to the truth after the gap
        yaw_true = min(sim.truth, key=lambda r: abs(r[0] - t1))[3]
        assert abs(rot.wrap(y1 - yaw_true)) < 0.05
    assert abs(r1 - r0) <= 0.03 * (timeout + post) + 0.02 and abs(p1 - p0) <= 0.03 * (timeout + post) + 0.02
    # and the covariance says the filter lost track over the gap (inflated, not over-confident)
    assert core.state.ekf.P[0, 0] >= core.cfg.filter.gap_inflation[0] ** 2 * (GAP - core.cfg.filter.gap_s) * 0.99


def test_a_gap_shorter_than_the_jump_threshold_is_bounded_too():
    """A 3 s gap (below jump_s) is one prediction step: split at each sensor's timeout."""
    sim = SimConfig(duration=20.0, odom_rate=50.0, imu_rate=100.0)
    samples = [s for s in simulate(sim) if not 1010.0 <= s.stamp < 1013.0]
    core = FusionCore(make_config("roll_pitch"))
    for s in samples:
        if s.stamp >= 1013.0:
            t0, x0 = core.pose()
            x0 = x0.copy()
            step = core.ingest(s)
            assert step.accepted
            t1, x1 = core.pose()
            break
        core.ingest(s)
    # the twist held through filter.gap_s (0.5 s) at 1 m/s, then the first sample after the gap is predicted
    # to at zero speed
    assert math.dist(x0[0:3], x1[0:3]) <= 1.0 * core.cfg.filter.gap_s + 1e-6
    assert t1 - t0 > 2.9


# -- a gap in a fast vehicle's recording, with GPS ---------------------------------------------------------------

def _car_with_gps(gate: float | None, filt: str = ""):
    """A car at 30 m/s with 10 Hz GPS of 2 m, wheels reading 1 % slow; every sensor silent for 20 s."""
    from tests.support.configs import robot_config
    from tests.support.sim_gps import World, simulate as simulate_gps, truth_at

    w = World(duration=100.0, speed=30.0, gps_rate=10.0, gps_sigma=2.0, wheel_scale=1.01, odom_rate=50.0,
              imu_rate=100.0, datum=(48.137, 11.575, 520.0))
    gap0 = 1000.0 + 50.0
    samples = [s for s in simulate_gps(w) if not gap0 <= s.stamp < gap0 + 20.0]
    extra = "" if gate is None else f"mahalanobis_threshold = {gate}"
    core = FusionCore(robot_config(gps=f"datum = [48.137, 11.575, 520.0]\n{extra}", filt=filt))
    gps_after = []
    for s in samples:
        step = core.ingest(s)
        if s.stamp >= gap0 + 20.0:
            gps_after += [r for r in step.records if r.sensor == "gps"]
    t, x = core.pose()
    tx, ty, _ = truth_at(w, t)
    return core, gps_after, math.hypot(x[0] - tx, x[1] - ty), samples


@pytest.mark.parametrize("gate", [None, 5.0])
def test_a_gap_in_a_fast_vehicle_widens_the_position_by_its_speed_and_the_gps_takes_it_back(gate):
    core, gps_after, err, _ = _car_with_gps(gate)
    # 20 s at 30 m/s: the car is ~600 m from where the held inputs left it (they stop at the
    # timeout). The position variance must cover that, or the first fixes are gated out (with a
    # gate) or explained as a wheel-scale error through the odometry's correlations.
    assert gps_after and not gps_after[0].rejected
    assert sum(r.rejected for r in gps_after) <= 0.05 * len(gps_after)  # ~ the gate's own false alarms
    # the wheel scale (truth 1.01) is not corrupted by the jump: within the ~1 % a 50 s GPS
    # track of 2 m fixes over 1.5 km resolves (the jump explained as a scale would read 1.195)
    assert core.scales["wheel_scale"] == pytest.approx(1.01, abs=0.01)
    # 30 s of 10 Hz fixes after the gap: back to GPS accuracy (fixes of 2 m per axis, averaged
    # along the track by the odometry; an over-confident filter stays tens to hundreds of metres off)
    assert err < 2.0


def test_a_gps_locked_out_by_its_gate_is_reacquired():
    """A position cap of 10 m std dev (a user's setting) hides the ~600 m the gap may have moved the
    car: the fixes after it are gated out (5 sigma). They agree with each other (a constant offset,
    not a multipath burst), so after REACQUIRE_S of them the filter takes the GPS position again and
    searches the heading anew, instead of staying locked out for good (805 m off at the end)."""
    core, gps_after, err, samples = _car_with_gps(5.0, filt="covariance_cap = [100.0, 10.0]")
    channels = [r.channel for r in gps_after]
    assert channels[0] == "position" and gps_after[0].rejected  # locked out at first ...
    assert channels.count("position_reacquired") == 1  # ... re-acquired once ...
    k = channels.index("position_reacquired")
    from fusiond.core.sensors.gps import REACQUIRE_S
    assert gps_after[k].stamp - gps_after[0].stamp == pytest.approx(REACQUIRE_S, abs=0.15)  # ... after REACQUIRE_S
    assert not any(r.rejected for r in gps_after[k + 1:] if r.channel == "position")
    assert err < 2.0  # and back to GPS accuracy by the end, as without the cap
    # the doctor says the filter lost the GPS once and why that happens, not a bare "no_updates"
    from tests.support.verdicts import one, verdicts_of

    v = one(verdicts_of(core.cfg, samples), "gps", "position_reacquired")
    assert v.level == "warn" and "lost this GPS 1 time" in v.message and v.evidence["reacquired"] == 1.0, v
    # one cause named: the logging gap just before it, not "a gap or the motion model"
    assert "just after a logging gap (the longest 20.0 s)" in v.message and "motion model" not in v.message, v


def test_a_filter_driving_along_a_wrong_heading_takes_the_gps_back():
    """The car at 30 m/s, set to its true position but a heading 0.5 rad off (a wrong set_pose, its
    covariance tight): the fixes fall behind the dead-reckoning by 15 m more each second, so they are gated
    out and their innovations do not stay at one offset. They are the dead-reckoned track turned and
    shifted, though: the filter is what is wrong, and after the run's wait it takes the GPS again and finds
    the heading from it. Judged by one constant offset, the fixes agree only once the drive's turns happen to
    line them up (here 41.5 s and 409 fixes later)."""
    from fusiond.estimator import rotation as rot
    from tests.support.configs import robot_config
    from tests.support.sim_gps import World, simulate as simulate_gps, truth_at

    w = World(duration=100.0, speed=30.0, gps_rate=10.0, gps_sigma=2.0, odom_rate=50.0, imu_rate=100.0,
              datum=(48.137, 11.575, 520.0))
    core = FusionCore(robot_config(gps="datum = [48.137, 11.575, 520.0]\nmahalanobis_threshold = 5.0"))
    t_set, gps_after = 1050.0, []
    for s in simulate_gps(w):
        if t_set is not None and s.stamp >= t_set:
            t, x = core.pose()
            tx, ty, tyaw = truth_at(w, t)
            cov = [0.0] * 36
            for i, v in enumerate((0.01, 0.01, 0.01, 1e-4, 1e-4, 1e-6)):
                cov[7 * i] = v
            core.set_pose(t, (tx, ty, float(x[2])), tuple(rot.from_rpy(0.0, 0.0, tyaw + 0.5)), cov)
            t_set = None
        step = core.ingest(s)
        if t_set is None:
            gps_after += [r for r in step.records if r.sensor == "gps" and r.channel.startswith("position")]
    channels = [r.channel for r in gps_after]
    assert gps_after[10].rejected and channels.count("position_reacquired") == 1, channels[:40]
    k = channels.index("position_reacquired")
    # within the jump rule's REACQUIRE_JUMP_S after the first gated fix at most
    assert gps_after[k].stamp - 1050.0 < 12.0 and sum(r.rejected for r in gps_after) < 120
    t, x = core.pose()
    tx, ty, _ = truth_at(w, t)
    assert math.hypot(x[0] - tx, x[1] - ty) < 2.0  # back to the fixes' accuracy by the end


def test_after_a_long_gap_every_odometry_message_still_gets_its_pose():
    """A 26.4 s gap is beyond jump_s: the samples after it are held until the new timeline is
    confirmed (jump_persist_s), then applied at once. The replay's contract is one TUM line per
    odometry message, the estimate just after it: the held odometry messages are no exception."""
    from fusiond.core.sensors import OdomSample
    from fusiond.replay.run import Runner

    sim = SimConfig(duration=40.0, odom_rate=50.0, imu_rate=100.0)
    samples = [s for s in simulate(sim) if not GAP_START <= s.stamp < GAP_START + GAP]
    runner = Runner(make_config("roll_pitch"), keep_trace=False)
    for s in samples:
        runner.feed(s)
    stamps = list(runner.trajectory[0::8])
    odom = [s.stamp for s in samples if isinstance(s, OdomSample)]
    assert stamps == odom  # one pose per odometry message, at its stamp, in order (50 held ones included)


def test_a_drive_that_pauses_briefly_and_often_keeps_its_twist_through_the_pauses():
    """A drive at 50 Hz whose logger pauses 0.4 s every 2 s (below gap_s = 0.5 s: jitter, not a logging gap).
    Its typical period is 20 ms, so 3 periods and the 0.2 s timeout expire the twist halfway through each pause
    and the filter stops a vehicle doing 5 m/s for 0.2 s a pause (10 % of the distance). Holding the input for
    1.5 x the longest recent interval (core/inputs.py), every pause after the first is bridged: the distance
    driven is the truth's within the first pause's loss and the wheels' noise."""
    sim = SimConfig(duration=30.0, odom_rate=50.0, imu_rate=100.0, speed=5.0, turn_amplitude=0.0)
    pauses = [(1000.0 + 2.0 * k + 1.6, 1000.0 + 2.0 * k + 2.0) for k in range(15)]
    samples = [s for s in simulate(sim) if not (s.sensor == "wheel" and any(a < s.stamp < b for a, b in pauses))]
    core = FusionCore(make_config("roll_pitch"))
    for s in samples:
        core.ingest(s)
    t, x = core.pose()
    truth = min(sim.truth, key=lambda r: abs(r[0] - t))
    lost_in_first = 5.0 * (0.4 - 0.2)
    assert abs(math.hypot(x[0], x[1]) - math.hypot(truth[1], truth[2])) < lost_in_first + 0.5


def test_the_longest_recent_interval_keeps_a_recurring_pause_and_forgets_a_single_one():
    """``recent_longest`` over 100 Hz intervals: a 0.4 s pause every 2 s stays the longest as long as it recurs;
    a single one is forgotten within RECENT_S (two halves of 15 s); a 0.8 s silence (beyond gap_s) is a logging
    gap, never learned."""
    from fusiond.core.inputs import NO_RECENT, RECENT_S, recent_longest

    def run(intervals, t=1000.0, recent=NO_RECENT):
        seen = []
        for d in intervals:
            t += d
            recent = recent_longest(recent, d, t, 0.5)
            seen.append(recent[0])
        return seen, t, recent

    recurring = ([0.01] * 160 + [0.4]) * 40  # 80 s
    seen, t, recent = run(recurring)
    assert min(seen[200:]) == 0.4
    quiet, _, _ = run([0.01] * int(RECENT_S / 0.01 + 10), t, recent)  # then 30 s without a pause
    assert quiet[-1] == pytest.approx(0.01)
    assert max(run([0.01] * 100 + [0.8] + [0.01] * 100)[0]) == pytest.approx(0.01)


def test_the_rigid_residual_is_what_no_turn_and_shift_of_the_track_explains():
    from fusiond.core.sensors.gps.model import _fitted_residual

    def _rigid_residual(fixes, track):  # the fit without the wheels' scale: a turn and a shift
        return _fitted_residual(fixes, track, False)[0]

    track = [(3.0 * k, 0.5 * k * k) for k in range(10)]  # a curved dead-reckoned track
    turn, (ox, oy) = 0.7, (40.0, -12.0)
    fixes = [(ox + math.cos(turn) * x - math.sin(turn) * y, oy + math.sin(turn) * x + math.cos(turn) * y)
             for x, y in track]
    assert _rigid_residual(fixes, track) == pytest.approx(0.0, abs=1e-9)
    bumped = [(x, y + (1.0 if k % 2 else -1.0)) for k, (x, y) in enumerate(fixes)]  # +-1 m that no turn explains
    assert 0.8 < _rigid_residual(bumped, track) <= 1.0


# -- the odometry silent while the IMU streams on -------------------------------------------------------------------

def _straight_then_odometry_silent(imu_rate: float, speed: float = 10.0, silent: float = 0.8):
    """A straight drive at ``speed`` (odometry 50 Hz, IMU at ``imu_rate``), then the odometry silent for
    ``silent`` s while the IMU goes on (no prediction step longer than gap_s: no logging gap). (core, the
    odometry's timeout, the position variances east and north when it expired and just before the next
    odometry message)."""
    from tests.support.core_samples import imu, odom

    core = FusionCore(make_config("roll_pitch"))
    t0, end = 1000.0, 1002.0
    stamps = sorted({(round(t0 + k / 50.0, 6), "odom") for k in range(int(2.0 * 50) + 1)}
                    | {(round(t0 + k / imu_rate, 6), "imu") for k in range(int((end + silent - t0) * imu_rate))})
    at_expiry = None
    for t, kind in stamps:
        if kind == "odom":
            core.ingest(odom(t, v=speed))
            continue
        timeout = core.inputs.timeouts(core.state)[0] if core.initialised else math.inf  # the twist's hold
        if at_expiry is None and t > end + timeout:
            P = core.state.ekf.P
            at_expiry = (P[0, 0], P[1, 1])
        core.ingest(imu(t))
    P = core.state.ekf.P
    return core, timeout, at_expiry, (P[0, 0], P[1, 1]), core.state.t


@pytest.mark.parametrize("imu_rate", [100.0, 400.0])
def test_an_odometry_silent_past_its_timeout_widens_the_position_by_its_speed_while_the_imu_streams(imu_rate):
    """Past the odometry's timeout the prediction holds no twist (the robot may have stopped), and the position
    widens by what it may have driven at its last speed, v T per axis after T s, as across a logging gap. The
    IMU streaming on splits the silence into many short predictions: they add up to (v T)^2 whatever their
    number, not to the sum of each one's (v dt)^2 (which leaves the filter sure of a car it stopped), so a
    fix after a brief pause of the wheels is believed instead of being taken for a receiver's step."""
    core, timeout, before, after, t_end = _straight_then_odometry_silent(imu_rate)
    unheld = t_end - (1002.0 + timeout)
    assert unheld > 0.1
    expected = (10.0 * unheld) ** 2
    for axis in (0, 1):
        assert after[axis] - before[axis] == pytest.approx(expected, rel=0.05)


def test_the_fixes_after_a_first_brief_pause_of_the_wheels_are_believed():
    """A car at 17 m/s with 10 Hz fixes of 0.1 m: the wheels pause once for 0.7 s (longer than the twist's hold,
    filter.gap_s; no recent pause to hold it longer, as core/inputs.py does for recurring ones), the IMU
    streams on. The filter stops the car for the 0.2 s past the hold, 3.4 m short; the fixes in the pause and
    after it say so, and the position's widening lets them: none gated, and the track back on the fixes within
    a few of them."""
    from tests.support.configs import robot_config
    from tests.support.sim_gps import World, simulate as simulate_gps, truth_at

    w = World(duration=30.0, speed=17.0, gps_rate=10.0, gps_sigma=0.1, odom_rate=50.0, imu_rate=100.0)
    pause = (1000.0 + 20.0, 1000.0 + 20.7)
    samples = [s for s in simulate_gps(w) if not (s.sensor == "wheel" and pause[0] <= s.stamp < pause[1])]
    core = FusionCore(robot_config(gps="datum = [48.137, 11.575, 520.0]\nmahalanobis_threshold = 5.0"))
    gated, errors = 0, []
    for s in samples:
        step = core.ingest(s)
        if pause[0] <= s.stamp < pause[1] + 2.0:
            gated += sum(r.rejected for r in step.records if r.sensor == "gps")
            if s.sensor == "wheel" and s.stamp > pause[1] + 0.5:
                t, x = core.pose()
                tx, ty, _ = truth_at(w, t)
                errors.append(math.hypot(x[0] - tx, x[1] - ty))
    assert gated == 0
    assert max(errors) < 0.5
