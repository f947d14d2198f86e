"""GPS and pose sensors, mounting offsets, scale states; simulated robots with known truth."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rosbags.rosbag2 import Writer

from fusiond.config import ConfigError, GpsSensor, OdomSensor, PoseSensor, loads
from fusiond.core.fusion import FusionCore
from fusiond.estimator import GyroBiasBlock, GyroScaleBlock, PoseBlock, StateLayout, WheelScaleBlock
from fusiond.estimator import observations as obs
from fusiond.estimator import rotation as rot
from fusiond.estimator.geodesy import EnuFrame, WGS84_A, WGS84_E2, enu_to_geodetic, geodetic_to_ecef
from fusiond.estimator.numeric import measurement_jacobian
from fusiond.replay.bag import BagError, iter_raw_cdr, open_bag_samples
from fusiond.replay.run import replay
from fusiond.core.sensors import GpsSample, OdomSample, encode_sample, make_decoder
from fusiond.core.sensors.pose import POSE_MSGTYPES, PoseSample
from fusiond.core.sensors.gps.codec import encode_gps_sample
from fusiond.core.sensors.pose.codec import encode_pose_sample
from fusiond.codecs import NAVSATFIX, ODOMETRY, POSE_STAMPED, TYPESTORE, DecodeError

from tests.support.sim_gps import T0, World, simulate, truth_at
from tests.support.configs import sensor_tables
from tests.support.gps_pose import DATUM, _gps_config, _gps_world, config


def yaw(x) -> float:
    return rot.to_rpy(tuple(x[3:7].tolist()))[2]


def errors(core: FusionCore, w: World) -> tuple[float, float]:
    t, x = core.pose()
    tx, ty, tyaw = truth_at(w, t)
    return math.hypot(x[0] - tx, x[1] - ty), rot.wrap(yaw(x) - tyaw)


# -- geodesy ----------------------------------------------------------------------------------------------------

def test_geodetic_to_ecef_known_values():
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 0.0, 0.0), (WGS84_A, 0.0, 0.0), atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 90.0, 100.0), (0.0, WGS84_A + 100.0, 0.0), atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(90.0, 0.0, 0.0), (0.0, 0.0, 6356752.314245), atol=1e-5)  # b
    # Reference vectors of pymap3d's test suite (MATLAB-generated): 42 N, 82 W, 200 m ...
    np.testing.assert_allclose(geodetic_to_ecef(42.0, -82.0, 200.0),
                               (660675.2518247, -4700948.68316, 4245737.66222), atol=1e-5)
    # ... and (42.1 N, 81.9 W, 300 m) in the ENU frame at that point
    np.testing.assert_allclose(EnuFrame(42.0, -82.0, 200.0).enu(42.1, -81.9, 300.0),
                               (8272.476048, 11112.773942, 84.941624), atol=1e-5)


@pytest.mark.parametrize("lat", [0.0, 45.0, -33.9, 78.0])
def test_enu_of_small_offsets_follows_the_radii_of_curvature(lat):
    """1e-5 deg north / east is M dphi / N cos(phi) dlambda, with the ellipsoid's radii."""
    f = EnuFrame(lat, 11.0, 100.0)
    s2 = math.sin(math.radians(lat)) ** 2
    M = WGS84_A * (1 - WGS84_E2) / (1 - WGS84_E2 * s2) ** 1.5
    N = WGS84_A / math.sqrt(1 - WGS84_E2 * s2)
    d = 1e-5
    e, n, u = f.enu(lat + d, 11.0, 100.0)
    assert n == pytest.approx((M + 100.0) * math.radians(d), rel=1e-6) and abs(e) < 1e-6
    e, n, u = f.enu(lat, 11.0 + d, 100.0)
    assert e == pytest.approx((N + 100.0) * math.cos(math.radians(lat)) * math.radians(d), rel=1e-6)
    assert f.enu(lat, 11.0, 103.5) == pytest.approx((0.0, 0.0, 3.5), abs=1e-6)


@given(e=st.floats(-20000, 20000), n=st.floats(-20000, 20000), u=st.floats(-500, 500))
def test_enu_roundtrip(e, n, u):
    f = EnuFrame(48.137, 11.575, 520.0)
    assert f.enu(*enu_to_geodetic(f, e, n, u)) == pytest.approx((e, n, u), abs=1e-6)


# -- Jacobians of the new models --------------------------------------------------------------------------------

def _layout() -> StateLayout:
    return StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), GyroScaleBlock(0.05, 1e-5),
                        WheelScaleBlock(0.1, 1e-4)])


def _x(layout, rpy, pos=(1.0, -2.0, 0.3)):
    x = layout.initial_state()
    x[0:3] = pos
    x[3:7] = rot.from_rpy(*rpy)
    return x


tilts = st.floats(-1.0, 1.0)
angles = st.floats(-math.pi, math.pi)
levers = st.tuples(*[st.floats(-1.0, 1.0)] * 3)


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, lever=levers)
def test_position_jacobian_matches_central_differences(r, p, y, lever):
    layout = _layout()
    x = _x(layout, (r, p, y))
    _, H, _ = obs.position(layout, x, (0.0, 0.0, 0.0), (1.0,) * 9, lever)
    H_num = measurement_jacobian(layout, lambda s: -obs.position(layout, s, (0.0, 0.0, 0.0), (1.0,) * 9, lever)[0],
                                 x, angular=False)
    np.testing.assert_allclose(H, H_num, atol=1e-7)


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, lever=levers)
def test_pose_jacobian_matches_central_differences(r, p, y, lever):
    layout = _layout()
    x = _x(layout, (r, p, y))
    cov = tuple(1.0 if i % 7 == 0 else 0.0 for i in range(36))
    rows = (0, 1, 2, 3, 4, 5)

    def h(s):  # y = z - h: with z = 0 the innovation is -h (angles wrapped by the numeric helper)
        return -obs.pose(layout, s, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), cov, rows, lever)[0]

    _, H, _ = obs.pose(layout, x, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), cov, rows, lever)
    np.testing.assert_allclose(H, measurement_jacobian(layout, h, x), atol=1e-6)
    _, H3, _ = obs.pose(layout, x, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), cov, (0, 1, 5), lever)
    np.testing.assert_array_equal(H3, H[[0, 1, 5]])


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, lever=levers, r0=tilts, y0=angles)
def test_delta_pose_jacobian_matches_central_differences(r, p, y, lever, r0, y0):
    layout = _layout()
    x = _x(layout, (r, p, y))
    x_prev = _x(layout, (r0, 0.1, y0), pos=(0.5, 0.2, -0.1))
    cov = tuple(1.0 if i % 7 == 0 else 0.0 for i in range(36))
    rows = (0, 1, 2, 3, 4, 5)
    # Reference measurement = the prediction at x, so the rotation residual is exactly the
    # Log of the perturbation and its derivative is the model's Jacobian.
    _, dq_ref = obs.relative_pose(tuple((x_prev[0:3] + rot.matrix(tuple(x_prev[3:7].tolist())) @ lever).tolist()),
                                  tuple(x_prev[3:7].tolist()),
                                  tuple((x[0:3] + rot.matrix(tuple(x[3:7].tolist())) @ lever).tolist()),
                                  tuple(x[3:7].tolist()))

    def h(s):
        return -obs.delta_pose(layout, s, x_prev, (0.0, 0.0, 0.0), dq_ref, cov, rows, lever)[0]

    _, H, _ = obs.delta_pose(layout, x, x_prev, (0.0, 0.0, 0.0), dq_ref, cov, rows, lever)
    np.testing.assert_allclose(H, measurement_jacobian(layout, h, x, angular=False), atol=1e-6)


# -- configuration ------------------------------------------------------------------------------------------------

def test_issue_config_keys_parse():
    cfg = config(gps=f"{DATUM}\nposition_noise = [0.5, 0.5, 1.0]\nextrinsic_xyz = [0.36, 0.0, 0.5]",
                 pose='msgtype = "nav_msgs/msg/Odometry"\ndifferential = true\norientation_noise = [0.01, 0.01, 0.02]',
                 odom="scale_estimation = true", imu="gyro_scale_estimation = true")
    gps, pose = cfg.sensors[2], cfg.sensors[3]
    assert isinstance(gps, GpsSensor) and gps.datum == (48.137, 11.575, 520.0) and gps.extrinsic_xyz[0] == 0.36
    assert isinstance(pose, PoseSensor) and pose.differential and pose.msgtype == ODOMETRY
    assert isinstance(cfg.sensors[0], OdomSensor) and cfg.sensors[0].scale_estimation
    core = FusionCore(cfg)
    # gps_error: the vertical wander state a GPS gets by default
    # the twist's pitch is held (pitch_estimation = "auto") beside the altitude's wander state that can release it
    assert [b.name for b in core.layout.blocks] == ["pose", "gyro_bias", "gyro_scale", "wheel_scale", "twist_pitch",
                                                    "gps_error"]


@pytest.mark.parametrize("gps, pose, imu, needle", [
    ("datum = [48.0, 11.0]", None, "", "sensor \"gps\": datum"),
    ("position_noise = -1.0", None, "", "sensor \"gps\": position_noise"),
    ("", 'msgtype = "geometry_msgs/msg/Twist"', "", "sensor \"pose\": msgtype"),
    ("", "differental = true", "", "differental"),
    ("", "", "", "only one absolute sensor"),
    (None, None, "angular_velocity = false\ngyro_scale_estimation = true", "gyro_scale_estimation"),
    ("datum = [95.0, 11.0, 0.0]", None, "", "sensor \"gps\": datum"),
])
def test_bad_new_keys_are_one_line_errors(gps, pose, imu, needle):
    with pytest.raises(ConfigError) as err:
        config(gps=gps, pose=pose, imu=imu.replace("angular_velocity = false\n", ""),
               filt="") if "angular_velocity = false" not in imu else loads(sensor_tables(imu))
    assert needle in str(err.value) and "\n" not in str(err.value)


# -- GPS ------------------------------------------------------------------------------------------------------

def test_gps_wrong_initial_heading_converges_and_scales_reach_the_truth():
    w = _gps_world()
    core = FusionCore(_gps_config())
    assert not core.ready and "no sample" in core.not_ready_reason
    unaligned, channels, published_before_fix = 0, set(), 0
    known_at = None
    for s in simulate(w):
        step = core.ingest(s)
        assert step.accepted
        if not core.ready:
            published_before_fix += step.publish
            assert "first GPS fix" in core.not_ready_reason
        for r in step.records:
            channels.add(r.channel)
            if r.sensor == "gps" and r.channel != "altitude":  # the fix's vertical: its own block
                assert (r.channel == "position") == core.heading_known or r.channel == "position_unaligned"
                unaligned += r.channel == "position_unaligned"
        if known_at is None and core.heading_known:
            known_at = s.stamp
    assert published_before_fix == 0
    assert unaligned > 0 and {"position", "position_unaligned"} <= channels
    assert known_at is not None and known_at - 1000.0 < 15.0  # the first metres of travel
    pos_err, yaw_err = errors(core, w)
    assert pos_err < 0.3 and abs(yaw_err) < 0.03  # started 2 rad off
    assert core.scales["wheel_scale"] == pytest.approx(1.1, abs=0.01)
    assert core.scales["gyro_scale"] == pytest.approx(1.04, abs=0.01)
    assert core.gyro_bias[2] == pytest.approx(0.003, abs=5e-4)


def test_gps_heading_is_not_taken_while_standing_and_publish_waits_for_the_first_fix():
    w = _gps_world(duration=20.0, standstill=15.0, gps_sigma=1.0)  # GPS wanders while the robot stands
    core = FusionCore(_gps_config())
    first_fix, first_publish = None, None
    for s in simulate(w):
        step = core.ingest(s)
        if isinstance(s, GpsSample) and first_fix is None:
            first_fix = s.stamp
        if step.publish and first_publish is None:
            first_publish = s.stamp
        if s.stamp < 1000.0 + 15.0:
            assert not core.heading_known
    assert first_publish is not None and first_publish >= first_fix
    assert core.ready and core.not_ready_reason == ""


def test_gps_one_fix_in_ten_tracks_the_fixes_it_never_saw():
    w = _gps_world(duration=120.0, gps_sigma=0.5, gps_dropout=(60.0, 75.0))
    core = FusionCore(_gps_config())
    n, unseen, track = 0, set(), {}
    for s in simulate(w):
        if isinstance(s, GpsSample):
            n += 1
            if n % 10:
                unseen.add(s.stamp)
                continue
        step = core.ingest(s)
        if step.publish:
            t, x = core.pose()
            track[round(t, 6)] = x.copy()
    lever = np.array(w.gps_lever)
    to_fix, to_truth = [], []
    for t, e, nn in w.fixes:
        x = track.get(round(t, 6))
        if t in unseen and x is not None and t > 1000.0 + 45.0:  # heading and scales have had 45 s
            a = x[0:3] + rot.matrix(tuple(x[3:7].tolist())) @ lever
            to_fix.append(math.hypot(a[0] - e, a[1] - nn))
            tx, ty, _ = truth_at(w, t)
            to_truth.append(math.hypot(x[0] - tx, x[1] - ty))
    rms = math.sqrt(sum(v * v for v in to_fix) / len(to_fix))
    rms_truth = math.sqrt(sum(v * v for v in to_truth) / len(to_truth))
    # the unseen fixes are 0.5 m noisy per axis (0.71 m rms horizontal from their noise alone)
    assert len(to_fix) > 250 and rms < 0.95 and rms_truth < 0.6
    pos_err, yaw_err = errors(core, w)
    assert pos_err < 0.7 and abs(yaw_err) < 0.05


@pytest.mark.parametrize("bad, reason", [
    (GpsSample("gps", 1000.5, 48.137, 11.575, 520.0, -1, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), 2), "no_fix"),
    (GpsSample("gps", 1000.5, math.nan, 11.575, 520.0, 0, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), 2), "non_finite"),
    (GpsSample("gps", 1000.5, 48.137, 200.0, 520.0, 0, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), 2), "implausible_value"),
    (GpsSample("gps", 1000.5, 48.137, 11.575, 520.0, 0, (-1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0), 2), "negative_covariance"),
    (PoseSample("pose", 1000.5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 0.0)), "zero_quaternion"),
    (PoseSample("pose", 1000.5, (math.nan, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)), "non_finite"),
    (PoseSample("pose", 1000.5, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (1e9,) * 36), "nothing_to_fuse"),
    (OdomSample("gps", 1000.5, (0.0,) * 3, (0.0,) * 3, (0.0,) * 36), "wrong_type"),
])
def test_bad_gps_and_pose_samples_are_dropped_with_a_reason(bad, reason):
    cfg = config(gps=DATUM, pose="differential = true")
    core = FusionCore(cfg)
    core.ingest(OdomSample("wheel", 1000.0, (0.0,) * 3, (0.0,) * 3, tuple(1e-4 if i % 7 == 0 else 0.0
                                                                        for i in range(36))))
    step = core.ingest(bad)
    assert not step.accepted and step.reason == reason
    assert sum(st.dropped.get(reason, 0) for st in core.stats) == 1
    assert np.isfinite(core.state.ekf.P).all()


def test_status_minus_one_fixes_are_skipped_and_counted_in_a_run():
    w = _gps_world(duration=40.0, gps_bad_every=3)
    core = FusionCore(_gps_config())
    for s in simulate(w):
        core.ingest(s)
    gps = core.stats[core.index["gps"]]
    assert gps.dropped == {"no_fix": len([1 for k in range(1, gps.received + 1) if k % 3 == 0])}
    pos_err, yaw_err = errors(core, w)
    assert pos_err < 0.3 and abs(yaw_err) < 0.05


def test_gps_duplicate_and_late_fixes_do_not_depend_on_arrival_order():
    from tests.support.sim import arrival_order

    w = _gps_world(duration=40.0)
    samples = simulate(w)
    cfg = _gps_config()
    cfg.filter.history_s = 3.0
    a = FusionCore(cfg)
    for s in samples:
        a.ingest(s)
    b = FusionCore(cfg)
    steps = [b.ingest(s) for s in arrival_order(samples, {"gps": 1.5, "imu": 0.02}, jitter=0.02)]
    assert sum(s.late for s in steps) > 100 and all(s.accepted for s in steps)
    np.testing.assert_array_equal(a.pose()[1], b.pose()[1])
    np.testing.assert_array_equal(a.state.ekf.P, b.state.ekf.P)
    assert a.heading_known and b.heading_known
    fix = [s for s in samples if isinstance(s, GpsSample)][-3]
    assert b.ingest(fix).reason == "duplicate_stamp"


# -- pose sensors -------------------------------------------------------------------------------------------------

def _pose_world(**kw) -> World:
    base = dict(duration=60.0, start=(1.0, 2.0, 0.5), pose_rate=10.0, wheel_scale=1.1, gyro_scale=1.04,
                gyro_bias=0.003, pose_lever=(0.36, 0.0, 1.0), hand_turn=(20.0, 25.0, 0.8))
    base.update(kw)
    return World(**base)


def test_absolute_pose_defines_the_frame_and_holds_heading_through_hand_turning():
    """A ceiling camera fused 1 in 10 keeps heading within a degree of all its poses, while a
    5 s hand-turn (wheels at rest) happens and the gyro is 4 % off."""
    w = _pose_world()
    core = FusionCore(config(pose="extrinsic_xyz = [0.36, 0.0, 1.0]\nmahalanobis_threshold = 6.0",
                             odom="scale_estimation = true", imu="gyro_scale_estimation = true"))
    n, yaw_errs, published = 0, [], 0
    for s in simulate(w):
        if isinstance(s, PoseSample):
            n += 1
            if core.ready:
                yaw_errs.append(abs(rot.wrap(yaw(core.pose()[1]) - rot.to_rpy(s.orientation)[2])))
            if n % 10:
                continue
        step = core.ingest(s)
        if not core.ready:
            assert not step.publish and "first pose" in core.not_ready_reason
        published += step.publish
    assert published > 1000
    assert max(yaw_errs[100:]) < math.radians(2.0)
    pos_err, yaw_err = errors(core, w)
    assert pos_err < 0.05 and abs(yaw_err) < 0.01
    assert core.scales["gyro_scale"] == pytest.approx(1.04, abs=0.01)
    assert core.scales["wheel_scale"] == pytest.approx(1.1, abs=0.02)
    assert core.stats[2].rejected == 0


def test_lever_arm_turning_in_place_is_not_motion():
    """A marker 0.36 m ahead traces a circle while the robot turns in place: with extrinsic_xyz
    the base stays put; without it the filter is dragged around the circle."""
    w = _pose_world(duration=12.0, start=(0.0, 0.0, 0.0), hand_turn=(2.0, 12.0, 0.6), wheel_scale=1.0,
                    gyro_scale=1.0, gyro_bias=0.0)
    samples = simulate(w)
    with_lever = FusionCore(config(pose="extrinsic_xyz = [0.36, 0.0, 1.0]"))
    without = FusionCore(config(pose=""))
    for s in samples:
        with_lever.ingest(s)
        without.ingest(s)
    assert np.hypot(*with_lever.pose()[1][0:2]) < 0.02
    assert np.hypot(*without.pose()[1][0:2]) > 0.2


def test_late_poses_seconds_old_give_the_same_estimate():
    from tests.support.sim import arrival_order

    w = _pose_world(duration=30.0)
    samples = simulate(w)
    cfg = config(pose="extrinsic_xyz = [0.36, 0.0, 1.0]", odom="scale_estimation = true",
                 filt="history_s = 3.0")
    a = FusionCore(cfg)
    for s in samples:
        a.ingest(s)
    b = FusionCore(cfg)
    steps = [b.ingest(s) for s in arrival_order(samples, {"pose": 2.0}, jitter=0.3, seed=4)]
    assert all(s.accepted for s in steps) and sum(s.late for s in steps if s.sensor == "pose") > 250
    np.testing.assert_allclose(a.pose()[1], b.pose()[1], atol=1e-12)
    dup = [s for s in samples if isinstance(s, PoseSample)][-5]
    assert b.ingest(dup).reason == "duplicate_stamp"


def test_differential_pose_ignores_the_drifting_origin_and_learns_the_scales():
    w = _pose_world(start=(0.0, 0.0, 0.0), pose_lever=(0.0, 0.0, 0.0), pose_origin_drift=0.02,
                    pose_origin_jump=(30.0, 1.5, -1.0, 0.4), pose_increment_noise=True, pose_sigma=(0.005, 0.002),
                    hand_turn=(20.0, 24.0, 0.8))
    samples = simulate(w)
    # This world's wheel noise is white per message, which twist_correlation_s = 0 states exactly;
    # the default (a velocity error lasting 0.5 s) would trust the wheels 20x less than they deserve
    # here and follow the visual odometry's accumulating increments instead.
    vo = FusionCore(config(pose="differential = true\nmahalanobis_threshold = 6.0",
                           odom="scale_estimation = true\ntwist_correlation_s = 0.0",
                           imu="gyro_scale_estimation = true"))
    dead_reckoning = FusionCore(config())
    deltas = []
    for s in samples:
        step = vo.ingest(s)
        assert vo.ready  # a differential sensor does not define a frame: publishing starts at once
        deltas += [r for r in step.records if r.channel == "pose_delta"]
        dead_reckoning.ingest(s)
    assert len(deltas) > 500 and sum(r.rejected for r in deltas) == 1  # the relocalisation jump
    assert deltas[0].components == ["dx", "dy", "dz", "drx", "dry", "drz"]
    pos_err, yaw_err = errors(vo, w)
    dr_pos, dr_yaw = errors(dead_reckoning, w)
    assert pos_err < 0.7 and abs(yaw_err) < 0.03
    assert dr_pos > 4.0 and abs(dr_yaw) > 0.15
    assert vo.scales["wheel_scale"] == pytest.approx(1.1, abs=0.02)
    assert vo.scales["gyro_scale"] == pytest.approx(1.04, abs=0.01)


def test_pose_without_covariance_uses_the_configured_noise():
    cfg = config(pose="position_noise = [0.2, 0.2, 0.2]\norientation_noise = [0.1, 0.1, 0.1]")
    core = FusionCore(cfg)
    core.ingest(PoseSample("pose", 1000.0, (1.0, 2.0, 0.0), rot.from_rpy(0.0, 0.0, 1.0)))
    assert core.ready and yaw(core.pose()[1]) == pytest.approx(1.0)
    assert core.state.ekf.P[0, 0] == pytest.approx(0.04) and core.state.ekf.P[5, 5] == pytest.approx(0.01)
    rec = core.ingest(PoseSample("pose", 1000.1, (1.0, 2.0, 0.0), rot.from_rpy(0.0, 0.0, 1.0))).records[0]
    assert rec.channel == "pose" and rec.dof == 6 and rec.innovation_var[0] > 0.04


# -- codecs and bags ------------------------------------------------------------------------------------------

GPS = GpsSample("gps", 12.5, 48.137, 11.575, 520.25, 1, (0.5, 0.01, 0.0, 0.01, 0.6, 0.0, 0.0, 0.0, 2.0), 3)
POSE = PoseSample("pose", 3.25, (1.0, -2.0, 0.5), (0.0, 0.0, 0.6, 0.8), tuple(float(i) for i in range(36)))


@pytest.mark.parametrize("encoding", ["ros2-cdr", "json", "msgpack"])
def test_gps_and_pose_codecs_roundtrip(encoding):
    assert make_decoder("gps", encoding, "gps")(encode_gps_sample(GPS, encoding)) == GPS
    for msgtype in POSE_MSGTYPES:
        raw = encode_pose_sample(POSE, encoding, msgtype)
        got = make_decoder("pose", encoding, "pose", msgtype=msgtype)(raw)
        expect = POSE if msgtype != POSE_STAMPED or encoding != "ros2-cdr" else PoseSample(
            "pose", 3.25, POSE.position, POSE.orientation)
        assert got == expect
        assert make_decoder("pose", encoding, "pose")(raw) == expect  # the daemon's call, without msgtype
        assert encode_sample(got, encoding, msgtype) == raw


def test_pose_decoder_names_the_type_actually_sent():
    with pytest.raises(DecodeError) as err:
        make_decoder("pose", "ros2-cdr", "pose", msgtype=POSE_STAMPED)(encode_gps_sample(GPS, "ros2-cdr"))
    assert err.value.reason == "wrong_type" and NAVSATFIX in str(err.value)
    with pytest.raises(DecodeError) as err:
        make_decoder("gps", "json", "gps")(b'{"stamp": 1.0, "latitude": "north"}')
    assert err.value.reason == "schema_invalid"
    with pytest.raises(ValueError):
        make_decoder("gps", "ros2-cdr", "gps", msgtype=POSE_STAMPED)


def _write_bag(path: Path, samples, pose_type: str) -> None:
    with Writer(path, version=9) as writer:
        conns = {}
        for s in samples:
            if isinstance(s, OdomSample):
                topic, msgtype, data = "/odom", ODOMETRY, encode_sample(s, "ros2-cdr")
            elif isinstance(s, GpsSample):
                topic, msgtype, data = "/gps/fix", NAVSATFIX, encode_gps_sample(s, "ros2-cdr")
            elif isinstance(s, PoseSample):
                topic, msgtype, data = "/mocap", pose_type, encode_pose_sample(s, "ros2-cdr", pose_type)
            else:
                continue
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=TYPESTORE)
            writer.write(conns[topic], int(s.stamp * 1e9), data)


def test_a_pose_topic_of_odometry_messages_in_a_bag_reads_as_poses(tmp_path):
    """The bag reader's struct fast path is the odometry kind's: a pose sensor whose `msgtype` is
    nav_msgs/msg/Odometry reads its topic through its own codec, as poses."""
    w = _gps_world(duration=5.0, pose_rate=10.0, pose_lever=(0.0, 0.0, 0.0), pose_increment_noise=True,
                   pose_sigma=(0.01, 0.002))
    samples = [s for s in simulate(w) if not isinstance(s, GpsSample)]
    _write_bag(tmp_path / "bag", samples, ODOMETRY)
    cfg = loads(f"""
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
[[sensors]]
name = "pose"
kind = "pose"
key = "mocap"
msgtype = "{ODOMETRY}"
""")
    with open_bag_samples([tmp_path / "bag"], cfg.sensors) as bag:
        got = [s for s in bag if s.sensor == "pose"]
    sent = [s for s in samples if isinstance(s, PoseSample)]
    assert got and all(type(s) is PoseSample for s in got) and len(got) == len(sent)
    assert [s.position for s in got] == [s.position for s in sent]


def test_replay_of_a_ros2_bag_with_gps_and_pose(tmp_path):
    w = _gps_world(duration=30.0, pose_rate=5.0, pose_lever=(0.0, 0.0, 0.0), pose_increment_noise=True,
                   pose_sigma=(0.01, 0.002))
    samples = simulate(w)
    _write_bag(tmp_path / "bag", samples, POSE_STAMPED)
    cfg = loads(f"""
[[sensors]]
name = "wheel"
kind = "odom"
key = "odom"
scale_estimation = true
[[sensors]]
name = "gps"
kind = "gps"
key = "gps/fix"
{DATUM}
extrinsic_xyz = [0.3, 0.1, 0.5]
[[sensors]]
name = "pose"
kind = "pose"
key = "mocap"
msgtype = "{POSE_STAMPED}"
differential = true
position_noise = [0.01, 0.01, 0.01]
orientation_noise = [0.002, 0.002, 0.002]
""")
    with open_bag_samples([tmp_path / "bag"], cfg.sensors) as bag:
        got = list(bag)
    fixes = [s for s in samples if isinstance(s, GpsSample)]
    assert [(s.latitude, s.longitude, s.altitude, s.status) for s in got if isinstance(s, GpsSample)] == [
        (s.latitude, s.longitude, s.altitude, s.status) for s in fixes]
    assert [s.stamp for s in got if isinstance(s, GpsSample)] == pytest.approx([s.stamp for s in fixes], abs=1e-9)
    assert len([s for s in got if isinstance(s, PoseSample)]) == len([s for s in samples if isinstance(s, PoseSample)])
    assert len(list(iter_raw_cdr([tmp_path / "bag"], cfg.sensors))) == len(got)
    result = replay([tmp_path / "bag"], cfg, tum=tmp_path / "out.tum", progress=False)
    assert all(st.dropped == {} for st in result.core.stats)
    assert result.core.heading_known
    lines = (tmp_path / "out.tum").read_text().splitlines()
    assert 0 < len(lines) < len([s for s in samples if isinstance(s, OdomSample)])  # nothing before the first fix
    t, x, y = (float(v) for v in lines[-1].split()[:3])
    tx, ty, _ = truth_at(w, t)
    assert math.hypot(x - tx, y - ty) < 0.5
    wrong = cfg.sensors[2].__class__(name="pose", key="mocap")  # default msgtype: PoseWithCovarianceStamped
    with pytest.raises(BagError, match="set its msgtype"):
        open_bag_samples([tmp_path / "bag"], [cfg.sensors[0], wrong])


def test_differential_pose_beside_gps_does_not_lock_the_gps_out():
    """A 1 cm pose delta fused against the filter's previous pose would pin the absolute
    position; beside the GPS it may only correct tilt, biases and scales."""
    w = _gps_world(duration=40.0, pose_rate=10.0, pose_lever=(0.0, 0.0, 0.0), pose_increment_noise=True,
                   pose_sigma=(0.01, 0.002))
    samples = simulate(w)
    both = FusionCore(config(
        gps=f"{DATUM}\nextrinsic_xyz = [0.3, 0.1, 0.5]", pose="differential = true", odom="scale_estimation = true",
        imu="gyro_scale_estimation = true"))
    gps_only = FusionCore(_gps_config())
    for s in samples:
        both.ingest(s)
        if not isinstance(s, PoseSample):
            gps_only.ingest(s)
    pos_both, yaw_both = errors(both, w)
    pos_gps, _ = errors(gps_only, w)
    assert pos_both < 0.3 and pos_both < pos_gps + 0.2 and abs(yaw_both) < 0.03  # was 7 m when it locked out
    assert both.scales["wheel_scale"] == pytest.approx(1.1, abs=0.04)  # 40 s of driving


def test_config_toml_documents_the_gps_and_pose_tables_and_their_examples_parse():
    import re

    root = Path(__file__).resolve().parents[2] / "config.toml"
    text = root.read_text()
    for cls in (GpsSensor, PoseSensor):
        for field in cls.__struct_fields__:
            assert f"{field} =" in text, f"config.toml does not document {cls.__name__}.{field}"
    base, _, examples = text.partition("# At most one absolute sensor")
    lines = [m.group(1) for m in re.finditer(r"^# (\[\[sensors\]\]|[a-z_]+ = .*)$", examples, re.M)]
    with pytest.raises(ConfigError, match="only one absolute sensor"):  # as written: gps and an absolute pose
        loads(base + "\n".join(lines))
    lines = [line.replace("differential = false", "differential = true") for line in lines]
    cfg = loads(base + "\n".join(lines))
    assert [type(s).__name__ for s in cfg.sensors] == ["OdomSensor", "ImuSensor", "GpsSensor", "PoseSensor"]


def test_doctor_flags_an_understated_gps_noise():
    from fusiond.doctor import Doctor

    w = _gps_world(duration=60.0, gps_sigma=0.3)
    cfg = _gps_config("position_noise = [0.03, 0.03, 0.03]")  # the receiver is ten times noisier than stated
    core, doctor = FusionCore(cfg), Doctor(cfg)
    for s in simulate(w):
        for r in core.ingest(s).records:
            doctor.add(r)
    verdicts = [v for v in doctor.verdicts() if v.sensor == "gps" and v.channel == "position"]
    assert verdicts and verdicts[0].level == "problem" and verdicts[0].key == "sensors.gps.position_noise"
    # The default gate (sqrt(NIS) 5) rejects most of those fixes: the doctor names the noise, not the gate,
    # with the innovations' rms, an upper bound of the receiver's 0.3 m. Pasted, the channel is consistent.
    line = verdicts[0].suggestion
    suggested = [float(v) for v in line.split("[")[1].rstrip("]").split(",")]
    assert line.startswith("position_noise = [") and min(suggested[:2]) >= w.gps_sigma
    cfg = _gps_config(line)
    core, doctor = FusionCore(cfg), Doctor(cfg)
    fixes = []
    for s in simulate(w):
        for r in core.ingest(s).records:
            doctor.add(r)
            if r.sensor == "gps" and r.channel == "position":
                fixes.append(r.rejected)
    again = [v for v in doctor.verdicts() if v.sensor == "gps" and v.channel == "position"]
    # pasted, the fixes are no longer gated out (the horizontal block: the altitude is judged apart)
    assert again[0].level != "problem" and fixes and sum(fixes) < 0.1 * len(fixes), again


# -- Gauss-Markov GPS error state -------------------------------------------------------------------------------

GM = "error_tau_s = 30.0\nerror_sigma = [1.0, 1.0, 1.0]"


@pytest.mark.parametrize("gps, needle", [
    ("error_tau_s = -1.0\nerror_sigma = [1.0, 1.0, 1.0]", "sensor \"gps\": error_tau_s"),
    ("error_tau_s = 30.0\nerror_sigma = [1.0, -1.0, 1.0]", "sensor \"gps\": error_sigma"),
    ("error_tau_s = 30.0", "sensor \"gps\": error_sigma"),
    ("error_tau_s = 30.0\nerror_sigma = [1.0, 1.0]", "sensor \"gps\": error_sigma"),
])
def test_gps_error_keys_are_validated(gps, needle):
    with pytest.raises(ConfigError) as err:
        config(gps=gps)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_gps_error_state_is_vertical_only_by_default_and_a_block_when_configured():
    default = FusionCore(_gps_config())  # the altitude's wander only: horizontal stays white
    assert default.layout.blocks[-1].name == "gps_error" and default.layout.blocks[-1].sigma == (0.0, 0.0, 5.0)
    assert not FusionCore(_gps_config("vertical_error_sigma = 0.0")).layout.has("gps_error")
    off = FusionCore(_gps_config("error_tau_s = 0.0\nerror_sigma = [1.0, 1.0, 1.0]\nvertical_error_sigma = 0.0"))
    assert not off.layout.has("gps_error")
    core = FusionCore(_gps_config(GM))
    assert [b.name for b in core.layout.blocks][-1] == "gps_error" and core.layout.error_dim == 15  # twist_pitch held
    # neither roll/pitch nor an unaligned fix may write the GPS error
    es = core.layout.error["gps_error"]
    assert not core.tilt_mask[es].any() and not core.position_mask[es].any()


def test_gauss_markov_gps_error_state_tracks_truth_better_through_wander_and_frozen_fixes():
    """GPS error = Gauss-Markov (tau 30 s, 1 m) + 0.3 m white, two frozen stretches, 1 fix in 10 fused.

    The receiver reports only its white noise (as real ones do). Without the state the filter
    follows each fix's slow error; with it the odometry-tied track averages the error over tau.
    Measured on this world (seed 8, 6000 poses): RMS vs truth 1.49 m without, 0.94 m with (0.63x); the
    frozen stretches are recognised and not fused either way.
    """
    w = _gps_world(duration=360.0, gps_sigma=0.3, gps_error_tau=30.0, gps_error_sigma=1.0,
                   gps_freeze=((50.0, 54.0), (150.0, 153.0), (250.0, 256.0)), seed=8)
    samples = simulate(w)
    truth = {round(t, 6): (x, y) for t, x, y, _ in w.truth}

    def rms(extra: str) -> float:
        core = FusionCore(_gps_config(extra))
        n, err = 0, []
        for s in samples:
            if isinstance(s, GpsSample):
                n += 1
                if n % 10:
                    continue
            if core.ingest(s).publish and s.stamp > 1000.0 + 60.0:  # heading and scales have had a minute
                t, x = core.pose()
                tx, ty = truth[round(t, 6)]
                err.append(math.hypot(x[0] - tx, x[1] - ty))
        assert len(err) > 5000
        return math.sqrt(sum(v * v for v in err) / len(err))

    without, with_state = rms(""), rms(GM)
    assert with_state < 0.75 * without, (with_state, without)
    assert with_state < math.sqrt(2.0) * 1.0  # below the error's own horizontal RMS (sqrt(2) sigma_b)


def test_navsat_output_needs_a_gps_sensor():
    import pytest as _pytest

    from fusiond.config import ConfigError, loads

    with _pytest.raises(ConfigError, match="output.navsat_key"):
        loads('[output]\nnavsat_key = "fix"\n[[sensors]]\nname = "w"\nkind = "odom"\nkey = "odom"\n')


def test_gps_with_a_trusted_absolute_imu_yaw_takes_heading_from_the_imu():
    """REP-103 absolute yaw trusted as ENU (yaw_offset_sigma = 0): no heading initialisation to fight it."""
    from fusiond.config import loads
    from fusiond.core.fusion import FusionCore
    from fusiond.estimator import rotation as rot
    from fusiond.core.sensors import ImuSample

    cfg = loads(sensor_tables('orientation = "absolute"\nyaw_offset_sigma = 0.0', gps="datum = [48.0, 11.0, 500.0]",
                              gps_key="fix"))
    core = FusionCore(cfg)
    cov36 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
    q = rot.from_rpy(0.0, 0.0, 1.0)
    for k in range(50):
        t = 10.0 + 0.02 * k
        core.ingest(OdomSample("wheel", t, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), cov36))
        core.ingest(ImuSample("imu", t + 0.001, q, (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4), (0.0,) * 3, (1e-6,) * 9))
        if k % 10 == 0:
            # distinct coordinates (bit-identical repeats while moving would be a frozen receiver)
            steps = core.ingest(GpsSample("gps", t + 0.002, 48.0 + 1e-7 * k, 11.0, 500.0, 0,
                                          (1.0, 0, 0, 0, 1.0, 0, 0, 0, 4.0), 2))
    assert core.heading_known
    assert steps.records and steps.records[0].channel == "position"
    assert rot.to_rpy(tuple(core.pose()[1][3:7].tolist()))[2] == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("restarts", [True, False], ids=["restarted_at_the_origin", "went_on"])
def test_a_visual_odometry_silent_beyond_its_timeout_may_restart_its_chain(restarts):
    """Visual odometry (no gate configured, the default) silent for 3 s, beyond its 1 s timeout: a VO that lost
    tracking and starts again from a new origin (its pose 1.5 m and 0.4 rad away) is no motion: the delta across
    the silence, far beyond anything the wheels and gyro allow (chi-square, RESTART_FALSE_ALARM), starts a new
    chain and is said; one that went on through the silence is fused. Fused as motion, the restart's jump put
    the pose metres and 0.4 rad off."""
    from structlog.testing import capture_logs

    from fusiond.logs import configure

    jump = (33.0, 1.5, -1.0, 0.4) if restarts else None
    w = _pose_world(start=(0.0, 0.0, 0.0), pose_lever=(0.0, 0.0, 0.0), pose_origin_jump=jump,
                    pose_increment_noise=True, pose_sigma=(0.005, 0.002), hand_turn=(20.0, 24.0, 0.8))
    samples = [s for s in simulate(w) if not (isinstance(s, PoseSample) and T0 + 30.0 <= s.stamp < T0 + 33.0)]
    vo = FusionCore(config(pose="differential = true", odom="scale_estimation = true\ntwist_correlation_s = 0.0",
                           imu="gyro_scale_estimation = true"))
    configure("warning")  # capture_logs keeps the level's filter: an earlier test's --quiet would drop warnings
    with capture_logs() as logs:
        across = [r for s in samples for r in vo.ingest(s).records
                  if r.channel == "pose_delta" and T0 + 30.0 <= r.stamp < T0 + 33.05]
    restarted = [e for e in logs if e["event"] == "pose_chain_restarted"]
    assert len(restarted) == (1 if restarts else 0), restarted
    assert len(across) == (0 if restarts else 1)  # the delta across the silence: fused, or none (a new chain)
    pos_err, yaw_err = errors(vo, w)
    assert pos_err < 0.7 and abs(yaw_err) < 0.03, (pos_err, yaw_err)


@pytest.mark.parametrize("differential", [False, True], ids=["absolute", "differential"])
def test_a_pose_sensor_turned_in_its_mount_is_read_through_extrinsic_rpy(differential):
    """A camera 0.36 m ahead of base_link looking 90 deg to the left: its poses (absolute: a marker's; differential:
    visual odometry's deltas, in the camera's own axes) are base_link's turned by the mount. Stated as
    extrinsic_rpy, the estimate holds as with an aligned camera; unstated, the sensor's forward is base_link's
    left and the heading (absolute) or the motion (differential) is read 90 deg off."""
    mount = math.pi / 2
    kw = dict(start=(0.0, 0.0, 0.0), pose_lever=(0.36, 0.0, 0.0), pose_mount_yaw=mount, hand_turn=(20.0, 24.0, 0.8))
    if differential:
        kw.update(pose_increment_noise=True, pose_sigma=(0.005, 0.002))
    w = _pose_world(**kw)
    samples = simulate(w)
    base = "differential = true\n" if differential else ""
    odom = "scale_estimation = true\ntwist_correlation_s = 0.0" if differential else ""
    imu = "gyro_scale_estimation = true" if differential else ""  # the world's gyro is 4 % off
    stated = FusionCore(config(pose=base + f"extrinsic_xyz = [0.36, 0.0, 0.0]\nextrinsic_rpy = [0.0, 0.0, {mount}]",
                               odom=odom, imu=imu))
    unstated = FusionCore(config(pose=base + "extrinsic_xyz = [0.36, 0.0, 0.0]", odom=odom, imu=imu))
    for s in samples:
        stated.ingest(s)
        unstated.ingest(s)
    pos_err, yaw_err = errors(stated, w)
    assert pos_err < 0.7 and abs(yaw_err) < 0.03, (pos_err, yaw_err)
    off_pos, off_yaw = errors(unstated, w)
    assert off_pos > 2.0 or abs(off_yaw) > 0.5, (off_pos, off_yaw)
