"""yaw_across_gaps: the IMU's own yaw change across a gap turns the heading (core/sensors/imu/gap_turn.py).

The simulated robot (tests/support/sim.py) turns at 0.3 sin(0.5 t) rad/s; its IMU reports the true yaw with
0.002 rad of noise and its gyro the true rate. What each test removes from the stream is a gap; the
heading after it is judged against the simulation's truth, as a change from before the gap (the
filter's yaw reference in roll_pitch mode is its own start, not the IMU's).
"""

from __future__ import annotations

import math

import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample

from tests.support.sim import SimConfig, arrival_order, simulate
from tests.support.core_samples import make_config

T0 = 1000.0


def truth_turn(a: float, b: float) -> float:
    """The heading the robot turned between relative times a and b: the integral of 0.3 sin(0.5 t)."""
    return 0.6 * (math.cos(0.5 * a) - math.cos(0.5 * b))


def run(samples, extra_imu: str = "", extra_odom: str = ""):
    """The samples through a core with yaw_across_gaps on (the default) unless ``extra_imu`` says."""
    if "yaw_across_gaps" not in extra_imu:
        extra_imu += "\nyaw_across_gaps = true"
    core = FusionCore(make_config("roll_pitch", extra_imu=extra_imu, extra_odom=extra_odom))
    poses = []
    for s in samples:
        if core.ingest(s).publish:
            t, x = core.pose()
            poses.append((t, rot.yaw(tuple(x[3:7].tolist())), x[0:3].tolist()))
    return core, poses


def yaw_at(poses, t: float) -> float:
    return min(poses, key=lambda p: abs(p[0] - t))[1]


def _imu_yaw(samples, yaw_of):
    """The samples with each IMU orientation's yaw replaced by yaw_of(stamp, yaw) (roll/pitch kept)."""
    out = []
    for s in samples:
        if isinstance(s, ImuSample):
            r, p, y = rot.to_rpy(s.orientation)
            s = ImuSample(s.sensor, s.stamp, rot.from_rpy(r, p, yaw_of(s.stamp, y)), s.orientation_covariance,
                          s.angular_velocity, s.angular_velocity_covariance)
        out.append(s)
    return out


def imu_model(core):
    return next(m for m in core.models if hasattr(m, "gap_turns"))


def test_a_logging_gap_turn_is_carried_by_the_imu_yaw_and_missed_without_it():
    """Every sensor silent from 4 s to 12 s: the robot turns by truth_turn(4, 12) = -0.89 rad in the gap. Carried,
    the heading's change from 3 s to 13 s is the truth's to within the IMU yaw's noise (0.002 rad, twice) and the
    gyro's integration over the 2 s around the gap (0.002 rad/s bias-free noise: ~1e-3 rad): 0.02 asserted.
    Turned off, it misses the turn made in the gap but for the held gyro rate (<= 0.3 rad/s x 0.2 s)."""
    gap = (4.0, 12.0)
    samples = [s for s in simulate(SimConfig(duration=20.0)) if not T0 + gap[0] <= s.stamp < T0 + gap[1]]
    turned = truth_turn(3.0, 13.0)
    assert abs(truth_turn(*gap)) > 0.8  # the simulation has the trait
    core, poses = run(samples)
    assert imu_model(core).gap_turns == 1
    carried = rot.wrap(yaw_at(poses, T0 + 13.0) - yaw_at(poses, T0 + 3.0))
    assert abs(rot.wrap(carried - turned)) < 0.02, (carried, turned)
    core, poses = run(samples, "yaw_across_gaps = false")
    assert imu_model(core).gap_turns == 0
    held = rot.wrap(yaw_at(poses, T0 + 13.0) - yaw_at(poses, T0 + 3.0))
    assert abs(rot.wrap(held - turned)) > abs(truth_turn(*gap)) - 0.3 * 0.2 - 0.02


def test_an_imu_dropout_corrects_only_what_the_wheels_misread():
    """The IMU alone is silent from 2 s to 5 s; the skid-steer wheels read half the yaw rate and drive the
    heading meanwhile, so the filter turns by ~truth_turn / 2. The turn applied after it is the IMU's change
    minus the filter's: the heading ends the truth's (0.03 rad asserted: the wheels' 0.01 rad/s noise over
    3 s and the IMU's yaw noise) instead of half a turn short."""
    sim = SimConfig(duration=10.0, wheel_yaw_scale=0.5)
    drop = (2.0, 5.0)
    samples = [s for s in simulate(sim)
               if not (isinstance(s, ImuSample) and T0 + drop[0] <= s.stamp < T0 + drop[1])]
    turned = truth_turn(1.0, 6.0)
    assert abs(truth_turn(*drop)) > 0.5
    core, poses = run(samples)
    assert imu_model(core).gap_turns == 1
    assert abs(rot.wrap(rot.wrap(yaw_at(poses, T0 + 6.0) - yaw_at(poses, T0 + 1.0)) - turned)) < 0.03
    _, off = run(samples, "yaw_across_gaps = false")
    short = rot.wrap(rot.wrap(yaw_at(off, T0 + 6.0) - yaw_at(off, T0 + 1.0)) - turned)
    assert abs(short) > 0.4 * abs(truth_turn(*drop))


def _with_orientation(samples, q=None, cov=None):
    out = []
    for s in samples:
        if isinstance(s, ImuSample):
            s = ImuSample(s.sensor, s.stamp, q if q is not None else s.orientation,
                          cov if cov is not None else s.orientation_covariance, s.angular_velocity,
                          s.angular_velocity_covariance, s.linear_acceleration, s.linear_acceleration_covariance)
        out.append(s)
    return out


@pytest.mark.parametrize("kind", ["placeholder", "unmeasured"])
def test_a_yaw_that_never_moved_or_is_not_measured_turns_nothing(kind):
    """A driver's constant quaternion (its yaw never moves) would undo the turn the wheels drove in an IMU
    dropout; a yaw marked not measured (variance above orientation_max_sigma^2 = 9) says nothing: either way
    no turn, and the run is exactly the one with yaw_across_gaps off."""
    drop = (2.0, 5.0)
    samples = [s for s in simulate(SimConfig(duration=8.0))
               if not (isinstance(s, ImuSample) and T0 + drop[0] <= s.stamp < T0 + drop[1])]
    if kind == "placeholder":
        samples = _with_orientation(samples, q=(0.0, 0.0, 0.0, 1.0))
    else:
        samples = _with_orientation(samples, cov=(4e-6, 0.0, 0.0, 0.0, 4e-6, 0.0, 0.0, 0.0, 1e6))
    core, on = run(samples)
    assert imu_model(core).gap_turns == 0
    _, off = run(samples, "yaw_across_gaps = false")
    assert on == off


@pytest.mark.parametrize("imu_rate, orientation_rate", [(400.0, 20.0), (100.0, 1.0), (5.0, 100.0)])
def test_thinned_or_slow_orientations_are_not_gaps(imu_rate, orientation_rate):
    """Orientations fused at 20 Hz of 400, at 1 Hz (1 s apart, beyond gap_s = 0.5 s), or an IMU at 5 Hz: a
    silence counts as a gap beyond GAP_PERIODS fused periods as well as gap_s, so a stream without gaps is
    never turned, and the run is exactly the one with yaw_across_gaps off."""
    samples = simulate(SimConfig(duration=12.0, imu_rate=imu_rate))
    extra = f"orientation_rate_hz = {orientation_rate}"
    core, on = run(samples, extra)
    assert imu_model(core).gap_turns == 0
    _, off = run(samples, extra + "\nyaw_across_gaps = false")
    assert on == off


def test_on_by_default_and_an_imu_restarted_in_the_gap_turns_nothing():
    """On by default with roll_pitch: the logging gap's turn is taken. An IMU that reads 0 after the gap,
    having read 0.85 rad before it, restarted in the gap (its yaw now counts from its power-on heading): the
    heading is left as it was, the run exactly the one with the feature off."""
    gap = (4.0, 12.0)
    samples = [s for s in simulate(SimConfig(duration=20.0)) if not T0 + gap[0] <= s.stamp < T0 + gap[1]]
    core = FusionCore(make_config("roll_pitch"))
    for s in samples:
        core.ingest(s)
    assert imu_model(core).gap_turns == 1 and core.cfg.sensors[1].yaw_across_gaps
    after = [s for s in samples if isinstance(s, ImuSample) and s.stamp >= T0 + gap[1]]
    y0 = rot.yaw(after[0].orientation)
    rebooted = _imu_yaw(samples, lambda t, y: y - y0 if t >= T0 + gap[1] else y)
    core, on = run(rebooted)
    assert imu_model(core).gap_turns == 0
    _, off = run(rebooted, "yaw_across_gaps = false")
    assert on == off


def test_the_turn_does_not_depend_on_arrival_order():
    """The mark the turn is measured from lives in the IMU's state slice, so the history re-applies it as it
    was: IMU messages 30 ms (or 100 ms) late, placed by the history with the later samples re-applied, end
    in exactly the state of the in-order run, turn included. (The poses published on the way differ: each
    is what had arrived when its odometry message came.)"""
    gap = (4.0, 9.0)
    samples = [s for s in simulate(SimConfig(duration=14.0)) if not T0 + gap[0] <= s.stamp < T0 + gap[1]]

    def final(order):
        core, _ = run(order)
        assert imu_model(core).gap_turns == 1
        return core.state.t, core.state.ekf.x.tolist(), core.state.ekf.P.tolist()

    ordered = final(samples)
    for lag in (0.03, 0.1):
        assert final(arrival_order(samples, {"imu": lag})) == ordered


def _drifting(samples, rate: float):
    """The IMU's yaw drifting at ``rate`` rad/s from the start (a 6-axis AHRS integrating its gyro's bias)."""
    return _imu_yaw(samples, lambda t, y: rot.wrap(y + rate * (t - T0)))


DRIFT = 0.02  # rad/s: a drifting 6-axis AHRS


def test_in_two_d_mode_the_imu_yaw_still_carries_a_gap_turn():
    """two_d_mode holds roll and pitch at 0, so no orientation row is fused; the IMU's yaw still kept the turn
    made in a logging gap, and turns the heading across it as in three dimensions (the first test's gap)."""
    gap = (4.0, 12.0)
    samples = [s for s in simulate(SimConfig(duration=20.0)) if not T0 + gap[0] <= s.stamp < T0 + gap[1]]
    turned = truth_turn(3.0, 13.0)
    core = FusionCore(make_config("roll_pitch", extra_imu="yaw_across_gaps = true", extra_filter="two_d_mode = true"))
    poses, channels = [], set()
    for s in samples:
        step = core.ingest(s)
        channels.update(r.channel for r in step.records)
        if step.publish:
            poses.append((core.time, rot.yaw(tuple(core.pose()[1][3:7].tolist()))))
    assert imu_model(core).gap_turns == 1 and "orientation" not in channels  # no row fused, the yaw carried
    carried = rot.wrap(yaw_at(poses, T0 + 13.0) - yaw_at(poses, T0 + 3.0))
    assert abs(rot.wrap(carried - turned)) < 0.02, (carried, turned)


REST = 2.0  # s at rest before the robot moves: the gyro's bias is learned, the heading does not drift


def test_a_drifting_imu_yaw_turns_the_heading_by_the_turn_not_by_its_drift():
    """The AHRS yaw drifts 0.02 rad/s; the robot at rest for REST s (the gyro's bias learned), then every sensor
    silent from 60 s to 70 s of its motion, in which it turns by truth_turn(60, 70). Outside gaps the drift is measured in 5 s blocks:
    the slope of one block scatters by the yaw noise at its ends, 0.002 x sqrt(2) / 5 s = 6e-4 rad/s, and ~11
    blocks by 60 s average that to ~2e-4 rad/s, 0.002 rad over the gap; with the yaw noise at both ends, 0.02 rad
    asserted. Taken as the turn, the IMU's change would carry the drift's 0.2 rad, ten times that."""
    gap = (REST + 60.0, REST + 70.0)
    clean = [s for s in simulate(SimConfig(duration=REST + 80.0, standstill=REST))
             if not T0 + gap[0] <= s.stamp < T0 + gap[1]]
    samples = _drifting(clean, DRIFT)
    turned = truth_turn(59.0, 71.0)
    assert abs(truth_turn(60.0, 70.0)) > 0.5 and DRIFT * (gap[1] - gap[0]) >= 10 * 0.02  # the traits
    core, poses = run(samples)
    assert imu_model(core).gap_turns == 1
    carried = rot.wrap(yaw_at(poses, T0 + REST + 71.0) - yaw_at(poses, T0 + REST + 59.0))
    assert abs(rot.wrap(carried - turned)) < 0.02, (carried, turned)


def test_a_drift_measured_against_a_heading_whose_gyro_bias_is_unknown_is_weighed_against_it():
    """As above, but moving from the first sample: the gyro's bias never learned, so the filter's heading may
    itself drift by gyro_bias_sigma (0.01 rad/s), as much as an IMU's yaw may (GAP_YAW_DRIFT), and the 0.02 rad/s
    the blocks measure is either's. The turn takes off the least-variance share of it (about half: 0.1 rad
    left over the gap) and says so: the heading's variance grows by that share's uncertainty over the gap,
    (0.01^2 / 2) x 10^2 = 0.005 rad^2, and the truth is within 3 sigma of it."""
    from fusiond.core.sensors.imu.gap_turn import GAP_YAW_DRIFT

    gap = (60.0, 70.0)
    samples = _drifting([s for s in simulate(SimConfig(duration=80.0)) if not T0 + gap[0] <= s.stamp < T0 + gap[1]],
                        DRIFT)
    core = FusionCore(make_config("roll_pitch", extra_imu="yaw_across_gaps = true"))
    poses = []
    for s in samples:
        if core.ingest(s).publish:
            poses.append((core.time, rot.yaw(tuple(core.pose()[1][3:7].tolist())), core.state.ekf.yaw_variance()))
    model = imu_model(core)
    assert model.gap_turns == 1
    bias_var = float(core.state.ekf.P[model.bias_z_error, model.bias_z_error])
    assert bias_var == pytest.approx(0.01**2, rel=0.2)  # never learned: about its prior
    (_, yaw0, var0), (_, yaw1, var1) = (min(poses, key=lambda p: abs(p[0] - (T0 + t))) for t in (59.0, 71.0))
    error = rot.wrap(rot.wrap(yaw1 - yaw0) - truth_turn(59.0, 71.0))
    shared = GAP_YAW_DRIFT**2 * bias_var / (GAP_YAW_DRIFT**2 + bias_var) * (gap[1] - gap[0]) ** 2
    assert var1 - var0 >= 0.9 * shared
    assert 0.05 < abs(error) < 3.0 * math.sqrt(var1 - var0), (error, var1 - var0)


def test_an_imu_dropout_beside_good_wheels_keeps_their_turn_not_the_imu_drift():
    """Only the IMU silent from 60 s to 75 s, the wheels (true scale, 0.01 rad/s noise at 50 Hz) driving
    the heading meanwhile, the AHRS yaw drifting 0.02 rad/s. The wheels' heading wanders by 0.01 x sqrt(15 s /
    50 Hz) = 0.005 rad; the IMU's turn, less its measured drift, is as good (~2e-4 rad/s x 15 s): weighed
    together, 0.03 asserted. The IMU's change taken whole (the drift turned in) would be 0.3 rad off."""
    drop = (60.0, 75.0)
    samples = [s for s in _drifting(simulate(SimConfig(duration=85.0)), DRIFT)
               if not (isinstance(s, ImuSample) and T0 + drop[0] <= s.stamp < T0 + drop[1])]
    turned = truth_turn(59.0, 76.0)
    core, poses = run(samples)
    assert imu_model(core).gap_turns == 1
    fused = rot.wrap(yaw_at(poses, T0 + 76.0) - yaw_at(poses, T0 + 59.0))
    assert abs(rot.wrap(fused - turned)) < 0.03, (fused, turned)


def test_the_drift_average_leaves_out_a_heading_correction_and_follows_a_changed_drift():
    """_learn_drift on a noiseless difference drifting 0.01 rad/s: after a few blocks the rate is 0.01 with the
    floor's standard error; a 0.5 rad jump of the heading (a GPS fit) makes one block an outlier, left out;
    the drift turning to -0.01 rad/s is taken up after DRIFT_REOPEN blocks in a row disagree."""
    from fusiond.core.sensors.imu.gap_turn import (DRIFT_BLOCK_S, DRIFT_FLOOR, DRIFT_MIN_BLOCKS, DRIFT_REOPEN,
                                               _learn_drift, drift_rate)

    assert drift_rate(None)[0] == 0.0
    drift, t = None, 0.0
    for k in range(int(60 / 0.1)):
        t = k * 0.1
        drift = _learn_drift(drift, t, rot.wrap(0.01 * t))
    rate, var = drift_rate(drift)  # weighed against GAP_YAW_DRIFT: a pull of var / prior ~ 1e-5 of it
    assert drift[3] >= DRIFT_MIN_BLOCKS and rate == pytest.approx(0.01, rel=1e-4) and var <= DRIFT_FLOOR**2
    for k in range(1, int(2 * DRIFT_BLOCK_S / 0.1)):  # the heading jumps by 0.5 rad at once
        drift = _learn_drift(drift, t + k * 0.1, rot.wrap(0.01 * (t + k * 0.1) - 0.5))
    assert drift_rate(drift)[0] == pytest.approx(0.01, rel=1e-4)
    t0, r0 = t + 2 * DRIFT_BLOCK_S, 0.01 * (t + 2 * DRIFT_BLOCK_S) - 0.5
    for k in range(int((DRIFT_REOPEN + 2) * DRIFT_BLOCK_S / 0.1) + 1):
        drift = _learn_drift(drift, t0 + k * 0.1, rot.wrap(r0 - 0.01 * k * 0.1))
    assert drift_rate(drift)[0] == pytest.approx(-0.01, rel=1e-4)


def test_the_wheels_yaw_scale_is_their_rate_over_the_gyro_s():
    """wheel_yaw_scale on pairs w = 0.7 g + noise (sd 0.01) over gyro rates of +-0.3 rad/s: k within three of
    its standard errors (0.01 / sqrt(sum g^2)) of 0.7; the relative variance of a rescaled turn is the misfit
    against what the fit explains, 0.01^2 / (0.7^2 mean g^2), within half of it; (1, 0) before enough
    turning samples."""
    import numpy as np

    from fusiond.core.sensors.imu.gap_turn import WHEEL_YAW_MIN_SAMPLES, _learn_wheel_yaw, wheel_yaw_scale

    rng = np.random.default_rng(5)
    sums = None
    g = 0.3 * np.sin(np.arange(500) * 0.05)
    for k, gk in enumerate(g):
        sums = _learn_wheel_yaw(sums, k * 0.01, float(gk), float(0.7 * gk + rng.normal(0, 0.01)))
        if k + 1 < WHEEL_YAW_MIN_SAMPLES:
            assert wheel_yaw_scale(sums) == (1.0, 0.0)
    scale, relative = wheel_yaw_scale(sums)
    se = 0.01 / math.sqrt(float((g**2).sum()))
    expected = 0.01**2 / (0.7**2 * float((g**2).mean()))
    assert abs(scale - 0.7) < 3 * se and 0.5 * expected < relative < 1.5 * expected, (scale, relative, expected)


def _truth_yaw(cfg: SimConfig, t: float) -> float:
    return min(cfg.truth, key=lambda row: abs(row[0] - t))[3]


def test_an_imu_turn_far_from_the_good_wheels_is_not_fused():
    """The AHRS reboots inside an IMU-only silence (2 s to 5 s) and integrates from there, so after it
    its yaw sits 2 rad away and not at 0. The wheels (true scale) drove the heading through the silence; the
    IMU's "turn" is ~2 rad beyond theirs, far past both turns' uncertainty (WHEELS_GATE sigma): nothing is
    turned, and the run is exactly the one with the feature off."""
    drop = (2.0, 5.0)
    samples = [s for s in simulate(SimConfig(duration=10.0))
               if not (isinstance(s, ImuSample) and T0 + drop[0] <= s.stamp < T0 + drop[1])]
    rebooted = _imu_yaw(samples, lambda t, y: rot.wrap(y + 2.0) if t >= T0 + drop[1] else y)
    core, on = run(rebooted)
    assert imu_model(core).gap_turns == 0
    _, off = run(rebooted, "yaw_across_gaps = false")
    assert on == off


def test_an_imu_dropout_while_the_drive_reads_zero_takes_the_imu_turn():
    """The drive reads exactly zero from 2 s to 5.5 s while the robot turns at 0.3 rad/s (a false standstill),
    and the IMU is silent from 2 s to 5 s: the wheels' zero is no measurement of the turn (the gyro reads the
    turn when the IMU is back, so the vehicle is not parked), so the IMU's turn is taken whole. The heading's change over
    1-6 s is the truth's to within the yaw noise and 1 s of gyro on either side (0.03 asserted); turned off,
    the 0.9 rad made in the silence is missed (but for the held gyro rate's 0.2 s)."""
    sim = SimConfig(duration=10.0, false_stops=((2.0, 5.5, 0.3),))
    drop = (2.0, 5.0)
    samples = [s for s in simulate(sim)
               if not (isinstance(s, ImuSample) and T0 + drop[0] <= s.stamp < T0 + drop[1])]
    turned = rot.wrap(_truth_yaw(sim, T0 + 6.0) - _truth_yaw(sim, T0 + 1.0))
    core, poses = run(samples)
    assert imu_model(core).gap_turns == 1
    assert abs(rot.wrap(rot.wrap(yaw_at(poses, T0 + 6.0) - yaw_at(poses, T0 + 1.0)) - turned)) < 0.03
    _, off = run(samples, "yaw_across_gaps = false")
    missed = rot.wrap(rot.wrap(yaw_at(off, T0 + 6.0) - yaw_at(off, T0 + 1.0)) - turned)
    assert abs(missed) > 0.9 - 0.3 * 0.2 - 0.1


def test_a_bad_orientation_costs_its_own_rows_and_the_gap_turn_not_the_gyro():
    """Read only for the gap turn in two-D mode, an orientation that is no rotation (all zeros, its covariance not
    marked absent) leaves the sample's gyro fused; in three dimensions, where its rows would be fused, they are
    refused (their reason counted) and the gyro of the sample is fused all the same."""
    from tests.support.core_samples import odom

    def zeroed(t: float) -> ImuSample:
        return ImuSample("imu", t, (0.0, 0.0, 0.0, 0.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4), (0.0, 0.0, 0.1),
                         (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6))

    planar = FusionCore(make_config("roll_pitch", extra_imu="yaw_across_gaps = true", extra_filter="two_d_mode = true"))
    spatial = FusionCore(make_config("roll_pitch", extra_imu="yaw_across_gaps = true"))
    for core in (planar, spatial):
        core.ingest(odom(T0, v=0.5))
    assert planar.ingest(zeroed(T0 + 0.01)).accepted and planar.state.gyro == (0.0, 0.0, 0.1)
    step = spatial.ingest(zeroed(T0 + 0.01))
    assert step.accepted and spatial.state.gyro == (0.0, 0.0, 0.1), step
    assert imu_model(spatial).policy.orientation_dropped == {"zero_quaternion": 1}


def test_an_imu_dropout_beside_wheels_that_measure_no_yaw_rate_takes_the_imu_turn():
    """The IMU silent from 2 s to 5 s beside wheels whose yaw rate is marked not measured (a race car's drive):
    nothing turned the heading through the silence, so the filter's standing heading is no measurement of the
    turn, and the IMU's is taken whole (it was refused as disagreeing with the wheels' 0, and the heading stayed
    0.9 rad behind for good). The heading's change over 1-6 s is the truth's to within 0.03 rad, as beside a
    logging gap."""
    from tests.support.sim_faults import mark_yaw_rate_unmeasured

    drop = (2.0, 5.0)
    samples = mark_yaw_rate_unmeasured([s for s in simulate(SimConfig(duration=10.0))
                                        if not (isinstance(s, ImuSample) and T0 + drop[0] <= s.stamp < T0 + drop[1])])
    turned = truth_turn(1.0, 6.0)
    assert abs(truth_turn(*drop)) > 0.5
    core, poses = run(samples)
    assert imu_model(core).gap_turns == 1
    assert abs(rot.wrap(rot.wrap(yaw_at(poses, T0 + 6.0) - yaw_at(poses, T0 + 1.0)) - turned)) < 0.03
