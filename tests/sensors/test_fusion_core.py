"""Fusion-core behaviour: ordering, late data, timeouts, inflation, gating, bias, policies."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.core.fusion import FusionCore
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.sim import SimConfig, arrival_order, simulate
from tests.support.core_samples import imu, make_config, odom


def feed(core, samples):
    return [core.ingest(s) for s in samples]


def yaw_of(core):
    return rot.to_rpy(tuple(core.pose()[1][3:7].tolist()))[2]


def test_body_twist_integrates_along_heading():
    core = FusionCore(make_config(orientation="absolute", gyro=False))
    heading = 0.7
    feed(core, [imu(1.0, rpy=(0.0, 0.0, heading))])
    for k in range(101):
        core.ingest(odom(1.0 + 0.01 * k, v=2.0))
    _, x = core.pose()
    assert x[0] == pytest.approx(2.0 * math.cos(heading), abs=1e-6)
    assert x[1] == pytest.approx(2.0 * math.sin(heading), abs=1e-6)


def test_world_twist_ignores_heading():
    core = FusionCore(make_config(orientation="absolute", gyro=False, extra_odom='twist_frame = "world"'))
    feed(core, [imu(1.0, rpy=(0.0, 0.0, 0.7))])
    for k in range(101):
        core.ingest(odom(1.0 + 0.01 * k, v=2.0))
    assert core.pose()[1][0:2] == pytest.approx([2.0, 0.0], abs=1e-6)


def test_estimate_does_not_depend_on_arrival_order():
    samples = simulate(SimConfig(duration=10.0, gyro_bias=(0.0, 0.0, 0.01)))
    in_order = FusionCore(make_config())
    feed(in_order, samples)
    shuffled = FusionCore(make_config())
    steps = feed(shuffled, arrival_order(samples, {"imu": 0.0, "wheel": 0.03}, jitter=0.02))
    assert sum(s.late for s in steps) > len(samples) // 10  # the history really was exercised
    assert all(s.accepted for s in steps)
    np.testing.assert_array_equal(in_order.pose()[1], shuffled.pose()[1])
    np.testing.assert_array_equal(in_order.state.ekf.P, shuffled.state.ekf.P)


def test_late_sample_is_applied_at_its_own_stamp_and_newest_pose_is_published():
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(1.0, v=1.0), odom(1.1, v=1.0), imu(1.2)])
    step = core.ingest(odom(1.15, v=0.0))  # late: older than the IMU sample already applied
    assert step.accepted and step.late and step.publish
    assert core.time == pytest.approx(1.2)
    # moved 1 m/s for 0.15 s, then stopped for 0.05 s
    assert core.pose()[1][0] == pytest.approx(0.15, abs=1e-9)


def test_sample_older_than_history_is_dropped_and_counted():
    core = FusionCore(make_config(gyro=False, extra_filter="history_s = 0.5"))
    feed(core, [odom(1.0 + 0.1 * k) for k in range(20)])
    step = core.ingest(odom(1.05))
    assert not step.accepted and step.reason == "too_old"
    assert core.stats[0].dropped == {"too_old": 1}


def test_duplicate_stamp_is_dropped():
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(1.0), odom(1.1)])
    step = core.ingest(odom(1.1))
    assert step.reason == "duplicate_stamp"


def test_backwards_jump_resets_after_confirmation_only():
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(100.0 + 0.1 * k, v=1.0) for k in range(30)])
    x_before = core.pose()[1][0]
    assert x_before > 2.0
    # Three stray stamps from the past are held, not applied ...
    assert [core.ingest(odom(1.0 + 0.1 * k)).reason for k in range(3)] == ["held_time_jump"] * 3
    # ... and dropped as a glitch once the stream advances along its own timeline.
    assert core.ingest(odom(103.0, v=1.0)).accepted
    assert core.stats[0].dropped["stale_stamp"] == 3 and core.resets == 0
    # A restart that persists (>= jump_confirm samples over >= jump_persist_s) resets, and the
    # held samples are applied on the new timeline, none lost.
    persist = core.cfg.filter.jump_persist_s
    n = int(math.ceil(persist / 0.1)) + 1
    steps = feed(core, [odom(1.0 + 0.1 * k) for k in range(n)])
    assert all(s.reason == "held_time_jump" for s in steps[:-1]) and steps[-1].accepted
    assert core.resets == 1
    assert core.pose()[1][0] == 0.0 and core.time == pytest.approx(1.0 + 0.1 * (n - 1))
    assert core.stats[0].applied == 31 + n


def test_short_clock_glitch_is_dropped_and_the_pose_carries_on():
    """Five odometry messages stamped an hour ahead (a driver's clock glitch): nothing stamped in
    the glitch is applied or published, the pose stays continuous, no reset."""
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(100.0 + 0.02 * k, v=1.0) for k in range(50)])
    t_last, x_last = core.time, core.pose()[1][0]
    glitch = feed(core, [odom(3700.0 + 0.02 * k, v=1.0) for k in range(5)])
    assert not any(s.publish or s.accepted for s in glitch)
    assert core.time == t_last
    after = feed(core, [odom(t_last + 0.02 * k, v=1.0) for k in range(1, 51)])
    assert all(s.accepted and s.publish for s in after)
    assert core.resets == 0 and core.stats[0].dropped["future_stamp"] == 5
    # 1 m/s for the 50 steps of 0.02 s after the glitch: 1 m further on, continuous
    assert core.pose()[1][0] == pytest.approx(x_last + 1.0, abs=1e-6)



UNIX = 1.65e9  # the odometry's clock
BOOT = 12.5 - UNIX  # an IMU stamped by the clock it counts from boot (12.5 s at the start): decades behind


def _wrong_clock_imu(imu_first: bool, gap: tuple[float, float] | None = None) -> list:
    """Odometry at 50 Hz and an IMU at 100 Hz for 40 s, the IMU on its boot clock; its first sample
    10 ms before the odometry's first (``imu_first``) or after it. ``gap``: every topic silent in (t0, t1)."""
    out = []
    for k in range(4000):
        t = UNIX + 0.01 * k
        if gap is not None and UNIX + gap[0] < t < UNIX + gap[1]:
            continue
        if k % 2 == 1:
            out.append(odom(t, v=1.0))
        if imu_first or k > 1:
            out.append(imu(t - 0.005 + BOOT))
    return out


@pytest.mark.parametrize("imu_first", [True, False])
def test_an_imu_on_its_boot_clock_is_dropped_alone_whichever_comes_first(imu_first):
    """The odometry's clock is the filter's (its poses are what is published): the IMU's far samples are dropped
    as stale and every odometry message after the first second is fused and published. With the IMU's first
    sample first, its clock started the filter and kept the old timeline going, so every odometry message was
    dropped as decades ahead and nothing was published."""
    core = FusionCore(make_config(gyro=False))
    steps = feed(core, _wrong_clock_imu(imu_first))
    wheel, imu_stats = core.stats
    published = sum(len(s.poses or ()) or int(s.publish) for s in steps)  # a confirmed timeline's held ones at once
    assert wheel.applied >= wheel.received - 1 and published >= wheel.received - 1
    assert core.time == pytest.approx(UNIX + 39.99)
    # the IMU: its samples on its own clock until the odometry's timeline was confirmed (jump_persist_s, 1 s, of
    # the odometry's stamps: 100 Hz x 1.01 s at most, its first one 10 ms ahead), the rest dropped as stale
    assert imu_stats.applied <= 102 and imu_stats.dropped.get("stale_stamp", 0) >= imu_stats.received - 102


def test_a_logging_gap_is_taken_beside_an_imu_on_its_boot_clock():
    """Every topic silent for 26 s from 10 s in, the IMU on its boot clock: the odometry's samples after the gap
    are a new timeline forward, confirmed as without the IMU. The IMU's far samples, on yet another timeline,
    replaced the odometry's held cluster one by one, and nothing after the gap was ever fused."""
    core = FusionCore(make_config(gyro=False))
    samples = _wrong_clock_imu(False, gap=(10.0, 36.0))
    steps = feed(core, samples)
    assert core.time == pytest.approx(UNIX + 39.99)
    after = [s for s, x in zip(steps, samples) if isinstance(x, OdomSample) and x.stamp > UNIX + 37.5]
    assert after and all(s.accepted and s.publish for s in after)

def test_single_far_future_stamp_is_rejected():
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(10.0 + 0.1 * k) for k in range(5)])
    assert core.ingest(odom(1e9)).reason == "held_time_jump"
    assert core.ingest(odom(10.5)).accepted
    assert core.stats[0].dropped == {"future_stamp": 1}


def test_gap_inflates_covariance_up_to_the_cap():
    cfg = "gap_s = 0.5\ngap_inflation = [0.5, 0.1]\ncovariance_cap = [4.0, 1.0]"
    core = FusionCore(make_config(gyro=False, extra_filter=cfg))
    feed(core, [odom(1.0), odom(1.02)])
    p_before = core.state.ekf.P[0, 0]
    core.ingest(odom(3.02))  # 2 s gap
    p_gap = core.state.ekf.P[0, 0]
    assert p_gap - p_before >= 0.5**2 * 1.5 * 0.999
    feed(core, [odom(103.0 + 0.1 * k) for k in range(12)])  # absurd gap, confirmed (1.1 s > jump_persist_s)
    # the cap is enforced on every gap and once per second of message time, so between caps P may
    # exceed it by at most one second of growth: twist variance 1e-4 (m/s)^2 x 0.1 s period x 1 s
    # + process noise 0.002^2 m^2/s x 1 s < 1e-4
    assert core.state.ekf.P[0, 0] <= 4.0 + 1e-4
    assert core.state.ekf.P[3, 3] <= 1.0 + 1e-4


def test_silent_sensor_in_message_time_and_slow_odometry_does_not_flap():
    core = FusionCore(make_config(gyro=False))
    # 5 Hz odometry with the odd 0.4 s gap, IMU at 100 Hz
    t_odom = [1.0 + 0.2 * k for k in range(10)] + [3.2, 3.6, 3.8]
    events = sorted([(t, "o") for t in t_odom] + [(1.0 + 0.01 * k, "i") for k in range(300)])
    alive = []
    for t, kind in events:
        core.ingest(odom(t) if kind == "o" else imu(t))
        if t > 1.5:
            alive.append(core.fresh("wheel"))
    assert all(alive)
    feed(core, [imu(3.8 + 0.01 * k) for k in range(1, 300)])
    assert not core.fresh("wheel") and core.fresh("imu")


def test_silent_odometry_stops_the_robot():
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(1.0 + 0.02 * k, v=1.0) for k in range(11)])
    x_stop = core.pose()[1][0]
    feed(core, [imu(1.2 + 0.01 * k) for k in range(1, 300)])
    # the last velocity is held only while the odometry's silence may be jitter (its timeout_s 0.2 s, at
    # least filter.gap_s 0.5 s, a shorter silence being no logging gap): the step that crosses it is split there
    assert core.pose()[1][0] - x_stop == pytest.approx(1.0 * 0.5, abs=1e-9)


def test_roll_pitch_update_does_not_move_heading_or_position():
    core = FusionCore(make_config(orientation="roll_pitch", gyro=True,
                                  extra_filter="initial_sigma = [1.0, 1.0]\ngyro_bias_sigma = 0.1"))
    feed(core, [odom(1.0, v=1.0, w=0.5), imu(1.0, rpy=(0.2, -0.1, 0.0), gyro=(0.3, 0.2, 0.5))])
    feed(core, [odom(1.5, v=1.0, w=0.5)])  # builds correlations between all attitude components
    x_before = core.pose()[1].copy()
    step = core.ingest(imu(1.5, rpy=(0.25, -0.05, 2.0), gyro=(0.3, 0.2, 0.5)))
    assert step.records and not step.records[-1].rejected
    x_after = core.pose()[1]
    assert x_after[0:3].tolist() == x_before[0:3].tolist()
    yaw_b = rot.to_rpy(tuple(x_before[3:7].tolist()))[2]
    yaw_a = rot.to_rpy(tuple(x_after[3:7].tolist()))[2]
    assert yaw_a == pytest.approx(yaw_b, abs=1e-12)
    assert rot.to_rpy(tuple(x_after[3:7].tolist()))[0] != pytest.approx(rot.to_rpy(tuple(x_before[3:7].tolist()))[0])


def test_gyro_bias_is_learned_at_standstill():
    sim = SimConfig(duration=8.0, standstill=6.0, gyro_bias=(0.001, -0.002, 0.003), gyro_sigma=0.002)
    core = FusionCore(make_config())
    feed(core, simulate(sim))
    assert core.gyro_bias == pytest.approx([0.001, -0.002, 0.003], abs=3e-4)


def test_hand_turned_robot_does_not_corrupt_bias():
    core = FusionCore(make_config())
    t = 1.0
    for k in range(200):  # wheels at rest, robot turned by hand at 0.8 rad/s
        core.ingest(odom(t))
        core.ingest(imu(t + 0.005, gyro=(0.0, 0.0, 0.8)))
        t += 0.01
    assert abs(core.gyro_bias[2]) < 1e-3
    assert yaw_of(core) == pytest.approx(0.8 * 2.0, abs=0.05)  # the gyro, not the wheels, drives heading


def test_gyro_heading_beats_skid_steer_wheels():
    sim = SimConfig(duration=30.0, wheel_yaw_scale=0.6, gyro_bias=(0.0, 0.0, 0.002), standstill=3.0)
    samples = simulate(sim)
    core = FusionCore(make_config(extra_odom="slip_threshold = 0.05"))
    steps = feed(core, samples)
    t, x, y, yaw = sim.truth[-1]
    assert core.pose()[1][0:2] == pytest.approx([x, y], abs=0.5)
    slip = [r for s in steps for r in s.records if r.channel == "yaw_rate"]
    assert any(r.rejected for r in slip)  # the consistency check sees the wheels lie


def test_relative_mode_removes_the_imu_yaw_offset():
    sim = SimConfig(duration=10.0, imu_yaw_offset=1.3)
    core = FusionCore(make_config(orientation="relative", gyro=False))
    feed(core, simulate(sim))
    t, x, y, yaw = sim.truth[-1]
    assert rot.wrap(yaw_of(core) - yaw) == pytest.approx(0.0, abs=0.02)


def test_extrinsic_rotation_applies_to_orientation_and_rates():
    # IMU mounted upside down and turned 90 degrees: its readings are base readings rotated
    ext = (math.pi, 0.0, math.pi / 2)
    q_ext = rot.from_rpy(*ext)
    core = FusionCore(make_config(orientation="absolute", gyro=True, extra_imu=f"extrinsic_rpy = {list(ext)}"))
    q_base = rot.from_rpy(0.05, -0.02, 0.4)
    w_base = np.array([0.0, 0.0, 0.2])
    R_ext = rot.matrix(q_ext)
    w_imu = tuple((R_ext.T @ w_base).tolist())
    q_imu = rot.mul(q_base, q_ext)
    # The same readings into a core that is not told of the mounting: what the test would see if
    # the extrinsic were ignored. It must be far from the truth, or the checks below prove nothing.
    unmounted = FusionCore(make_config(orientation="absolute", gyro=True))
    for k in range(50):
        t = 1.0 + 0.02 * k
        q_true = rot.mul(rot.from_rpy(0.0, 0.0, 0.2 * 0.02 * k), q_base)
        for c in (core, unmounted):
            c.ingest(odom(t))
            c.ingest(ImuSample("imu", t + 0.001, rot.mul(q_true, q_ext), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4),
                               w_imu, (1e-6, 0, 0, 0, 1e-6, 0, 0, 0, 1e-6)))
    r, p, yw = rot.to_rpy(tuple(core.pose()[1][3:7].tolist()))
    assert (r, p) == pytest.approx((0.05, -0.02), abs=1e-3)
    assert yw == pytest.approx(0.4 + 0.2 * 0.02 * 49, abs=5e-3)
    assert core.estimate().angular[2] == pytest.approx(0.2, abs=1e-3)
    # The mounting is far from the identity: the IMU's own attitude is about pi from the base's
    # (upside down), its z rate has the opposite sign, and ignoring the extrinsic shows it.
    dot = abs(sum(a * b for a, b in zip(q_imu, q_base)))
    assert 2.0 * math.acos(min(dot, 1.0)) > 3.0
    assert w_imu[2] == pytest.approx(-0.2, abs=1e-9)
    r_u, _, _ = rot.to_rpy(tuple(unmounted.pose()[1][3:7].tolist()))
    assert abs(rot.wrap(r_u - 0.05)) > 3.0
    assert unmounted.estimate().angular[2] == pytest.approx(-0.2, abs=1e-3)


def test_outlier_is_gated_and_counted():
    core = FusionCore(make_config(orientation="absolute", gyro=False, extra_imu="mahalanobis_threshold = 5.0"))
    feed(core, [odom(1.0), imu(1.0)] + [imu(1.0 + 0.01 * k) for k in range(1, 20)])
    step = core.ingest(imu(1.2, rpy=(0.0, 0.0, 2.5)))
    rec = step.records[-1]
    assert rec.rejected and rec.nis > 25 and rec.dof == 3
    assert core.stats[1].rejected == 1
    assert abs(yaw_of(core)) < 1e-3


@pytest.mark.parametrize("bad, reason", [
    (odom(1.1, v=math.nan), "non_finite"),
    (OdomSample("wheel", 1.1, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (-1.0,) + (0.0,) * 35), "negative_covariance"),
    (OdomSample("wheel", 1.1, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0,) * 3), "bad_covariance"),
    (ImuSample("imu", 1.1, (0.0, 0.0, 0.0, 0.0), (1e-4,) * 9, (0.0,) * 3, (1e-6,) * 9), "zero_quaternion"),
    (ImuSample("imu", 1.1, (0.0, 0.0, 0.0, 3.0), (1e-4,) * 9, (0.0,) * 3, (1e-6,) * 9), "non_unit_quaternion"),
    (odom(0.0), "invalid_stamp"),
    (odom(math.inf), "invalid_stamp"),
])
def test_bad_samples_are_rejected_with_a_reason(bad, reason):
    core = FusionCore(make_config(orientation="absolute"))
    feed(core, [odom(1.0), imu(1.0)])
    step = core.ingest(bad)
    assert not step.accepted and step.reason == reason
    assert sum(st.dropped.get(reason, 0) for st in core.stats) == 1
    assert np.isfinite(core.state.ekf.P).all() and np.isfinite(core.pose()[1]).all()


def test_lying_covariances_are_floored_or_ignored():
    core = FusionCore(make_config(orientation="absolute", gyro=False))
    zero = OdomSample("wheel", 1.0, (1.0, 0.0, 0.0), (0.0, 0.0, 0.1), (0.0,) * 36)
    huge_cov = [0.0] * 36
    for i in range(6):
        huge_cov[7 * i] = 1e6
    huge = OdomSample("wheel", 1.02, (1.0, 5.0, 5.0), (3.0, 3.0, 0.1), tuple(huge_cov))
    assert core.ingest(zero).accepted and core.ingest(huge).accepted
    core.ingest(imu(1.04))
    assert np.isfinite(core.state.ekf.P).all()
    assert core.state.ekf.P[0, 0] < 1.0  # a 1e6 "not measured" variance did not explode P
    est = core.estimate()
    assert est.linear == (0.0, 0.0, 0.0)  # "not measured" components are not used


def test_a_gyro_stating_an_unknown_noise_is_capped():
    """A driver stating 1e6 on the gyro's diagonal ("unknown"): taken as gyro_max_sigma (0.2 rad/s), the
    attitude's variance after 10 s of 100 Hz rates stays under a fraction of a radian squared, where 1e6 taken
    literally (a variance growth of 1e6 rad^2/s) had it at the covariance cap."""
    core = FusionCore(make_config(orientation="off"))
    unknown = (1e6, 0.0, 0.0, 0.0, 1e6, 0.0, 0.0, 0.0, 1e6)
    for k in range(1000):
        t = 1.0 + 0.01 * k
        if k % 2 == 0:
            core.ingest(odom(t, v=1.0))
        core.ingest(ImuSample("imu", t + 0.001, (0.0, 0.0, 0.0, 1.0), (-1.0,) + (0.0,) * 8, (0.0, 0.0, 0.01),
                              unknown, (0.0, 0.0, 9.81), (0.01, 0, 0, 0, 0.01, 0, 0, 0, 0.01)))
    att = core.state.ekf.P[3:6, 3:6]
    assert np.isfinite(att).all() and float(np.max(np.diag(att))) < 0.2**2 * 10.0 + 0.01, np.diag(att)


def test_noise_override_replaces_message_covariance():
    core = FusionCore(make_config(orientation="absolute", gyro=False, extra_imu="orientation_noise = [0.1, 0.1, 0.3]"))
    feed(core, [odom(1.0), imu(1.0, ovar=1e-12)])
    rec = core.ingest(imu(1.01)).records[-1]
    assert rec.innovation_var[2] > 0.3**2


def test_diagnostics_record_schema():
    core = FusionCore(make_config(orientation="roll_pitch"))
    rec = feed(core, [odom(1.0), imu(1.0)])[1].records[0]
    assert set(["stamp", "sensor", "components", "innovation", "innovation_var", "nis", "dof", "rejected"]) <= set(
        rec.__struct_fields__)
    assert rec.sensor == "imu" and rec.components == ["roll", "pitch"] and rec.dof == 2
    assert len(rec.innovation) == len(rec.innovation_var) == 2


def test_windowed_nis_flags_understated_noise():
    # the IMU says 0.002 rad but is ten times noisier: NIS must read high
    rng = np.random.default_rng(0)
    core = FusionCore(make_config(orientation="absolute", gyro=False))
    verdict = None
    for k in range(400):
        t = 1.0 + 0.01 * k
        core.ingest(odom(t))
        step = core.ingest(imu(t + 0.001, rpy=tuple(rng.normal(0, 0.02, 3)), ovar=0.002**2))
        verdict = step.records[-1].consistency
    assert verdict == "nis_high"


def test_adaptive_noise_scales_r_towards_the_truth():
    rng = np.random.default_rng(1)
    core = FusionCore(make_config(orientation="absolute", gyro=False, extra_imu="adaptive = true\nadaptive_window = 30"))
    for k in range(1500):
        t = 1.0 + 0.01 * k
        core.ingest(odom(t))
        core.ingest(imu(t + 0.001, rpy=tuple(rng.normal(0, 0.02, 3)), ovar=0.002**2))
    scale = core.state.own[core.index["imu"]].adaptive[0]
    assert 20.0 < scale < 400.0  # true/stated variance ratio is 100; adaptive lands in the vicinity


def test_confirmed_forward_jump_keeps_the_pose_and_a_lagging_sensor():
    core = FusionCore(make_config(gyro=False))
    feed(core, [odom(10.0 + 0.1 * k, v=1.0) for k in range(10)])
    x_before = core.pose()[1][0]
    # 8 s > jump_s ahead: held until 3 samples over >= jump_persist_s (1 s) confirm it
    steps = feed(core, [odom(18.9 + 0.1 * k, v=1.0) for k in range(11)])
    assert [s.accepted for s in steps] == [False] * 10 + [True]
    assert steps[-1].publish and core.resets == 0 and core.time == pytest.approx(19.9)
    assert core.pose()[1][0] >= x_before  # not a reset: the pose carried over the gap
    step = core.ingest(imu(19.05))  # a sensor lagging the jump is still applied at its own stamp
    assert step.accepted and step.late
