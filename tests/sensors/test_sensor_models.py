"""Sensor kinds are models behind one interface, built from their config and a narrow context.

A model never sees the core: these tests drive models with a context built by hand (plain
functions for its two queries) and a fresh FilterState, and check that what a model keeps
between messages lives in its own slice of the state, where history snapshots carry it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusiond.config import OdomSensor, loads
from fusiond.core.fusion import FusionCore
from fusiond.core.sensors import (
    GpsModel, ImuModel, OdomModel, OdomPolicy, SensorContext, SensorModel, build_models, config_types,
)
from fusiond.core.sensors.imu import ImuOwn
from fusiond.core.state import FilterState
from fusiond.estimator import ErrorStateEKF, GyroBiasBlock, MotionInput, PoseBlock, StateLayout
from fusiond.estimator import rotation as rot
from fusiond.core.sensors import ImuSample, OdomSample

from tests.support.configs import robot_config
from tests.support.sim_gps import World, simulate, truth_at

COV3 = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 1e-4)
GYRO_COV = (1e-6, 0.0, 0.0, 0.0, 1e-6, 0.0, 0.0, 0.0, 1e-6)
COV6 = tuple(1e-4 if i % 7 == 0 else 0.0 for i in range(36))
UNMEASURED = (0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01)


def _context(layout: StateLayout, timeout: float = 1.0) -> SensorContext:
    tilt = np.ones(layout.error_dim, dtype=bool)
    tilt[[0, 1, 2, 5]] = False  # as the core builds it: roll/pitch and the x/y gyro bias only
    if layout.has("gyro_bias"):
        tilt[layout.error["gyro_bias"].start + 2] = False
    position = np.zeros(layout.error_dim, dtype=bool)
    position[0:3] = True
    cfg = robot_config()
    return SensorContext(layout, cfg.filter, two_d=False, absolute_yaw=False, odom_index=0,
                         track_acceleration=False, tilt_mask=tilt,
                         position_mask=position, delta_mask=None, timeout=lambda idx, s: timeout,
                         inputs_at=lambda s: MotionInput(), forward_accel=lambda s: 0.0)


def _fresh(layout: StateLayout, models: list[SensorModel]) -> FilterState:
    s = FilterState.initial(ErrorStateEKF(layout), len(models), UNMEASURED, UNMEASURED)
    for m in models:
        m.on_start(s)
    s.t = 10.0
    return s


def test_models_work_from_their_config_and_a_context_alone():
    cfg = robot_config()
    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5)])
    ctx = _context(layout)
    models = build_models(cfg.sensors, ctx)
    assert [type(m) for m in models] == [OdomModel, ImuModel]
    assert [m.index for m in models] == [0, 1] and [m.name for m in models] == ["wheel", "imu"]
    s = _fresh(layout, models)
    odom, imu = models
    # odometry: the twist becomes the held motion input; reading zero starts a standstill
    inp = odom.convert(OdomSample("wheel", 10.0, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), COV6))
    assert odom.apply(s, inp, 10.0, emit=True, late=False) == []
    assert s.still_since == 10.0 and s.linear == (0.0, 0.0, 0.0)
    # IMU: the first orientation initialises the attitude; after that a roll/pitch reading is an
    # update (through the EKF) that moves roll toward it by the Kalman gain
    s.attitude_ready = True
    roll = 0.05
    inp = imu.convert(ImuSample("imu", 10.0, rot.from_rpy(roll, 0.0, 0.0), COV3, (0.0, 0.0, 0.0), GYRO_COV))
    records = imu.apply(s, inp, 10.0, emit=True, late=False)
    assert [r.channel for r in records] == ["orientation"] and records[0].sensor == "imu"
    got = rot.to_rpy(tuple(s.ekf.x[3:7].tolist()))[0]
    # prior roll sigma 0.1 rad (PoseBlock), reading sigma 0.01: the update takes ~99 % of the way
    assert got == pytest.approx(roll * 0.1**2 / (0.1**2 + 1e-4), rel=1e-6)
    assert s.gyro == (0.0, 0.0, 0.0) and s.gyro_last == (1, 10.0)
    # a re-application (emit False) changes the state alike but builds no record
    assert imu.apply(s, inp, 10.0, emit=False, late=False) == []


def test_a_relative_imu_keeps_its_yaw_offset_in_its_own_slice_and_snapshots_carry_it():
    cfg = robot_config(orientation="relative")
    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5)])
    models = build_models(cfg.sensors, _context(layout))
    s = _fresh(layout, models)
    imu = models[1]
    assert isinstance(s.own[1], ImuOwn) and s.own[1].yaw_offset is None
    inp = imu.convert(ImuSample("imu", 10.0, rot.from_rpy(0.0, 0.0, 0.7), COV3, (0.0, 0.0, 0.0), GYRO_COV))
    imu.apply(s, inp, 10.0, emit=False, late=False)
    assert s.own[1].yaw_offset == pytest.approx(0.7)  # the reading minus the filter's yaw (0) at the first message
    snap = s.copy()
    before = snap.own[1]
    imu.apply(s, imu.convert(ImuSample("imu", 10.0, rot.from_rpy(0.0, 0.0, 0.9), COV3, (0, 0, 0), GYRO_COV)),
              10.0, emit=False, late=False)
    assert snap.own[1] is before  # the snapshot's slice is not touched by what the live state does later
    assert snap.own[1].yaw_offset == pytest.approx(0.7)


def test_every_configured_kind_has_a_model_and_the_core_builds_one_per_sensor():
    cfg = robot_config(gps="datum = [48.137, 11.575, 520.0]", pose="differential = true")
    core = FusionCore(cfg)
    assert {type(s) for s in cfg.sensors} <= set(config_types())
    assert [m.name for m in core.models] == [s.name for s in cfg.sensors]
    assert isinstance(core.models[2], GpsModel)
    # only the kinds that carry something along the prediction are called on every prediction step
    assert [m.name for m in core._predicting] == ["gps", "pose"]


def test_gps_after_set_pose_starts_a_new_track_and_pulls_the_pose_back_to_the_fixes():
    w = World(duration=90.0, start=(10.0, -5.0, 2.0), gps_rate=5.0, gps_sigma=0.3)
    core = FusionCore(robot_config(gps="datum = [48.137, 11.575, 520.0]"))
    samples = simulate(w)
    half = next(i for i, s in enumerate(samples) if s.stamp > 1000.0 + 45.0)
    for s in samples[:half]:
        assert core.ingest(s).accepted
    assert core.heading_known
    t, x = core.pose()
    # an operator puts the robot 5 m off where it is (a wrong set_pose): the GPS must bring it back
    cov = [0.0] * 36
    for i in range(6):
        cov[7 * i] = 1.0 if i < 3 else 0.01
    core.set_pose(t, (float(x[0]) + 5.0, float(x[1]), float(x[2])), tuple(x[3:7].tolist()), cov)
    records = []
    for s in samples[half:]:
        step = core.ingest(s)
        assert step.accepted, step.reason
        records += [r for r in step.records if r.sensor == "gps" and r.channel != "altitude"]  # horizontal
    assert records and records[-1].channel == "position"
    t, x = core.pose()
    tx, ty, _ = truth_at(w, t)
    # 45 s of 0.3 m fixes at 5 Hz after the jump: the 5 m offset is gone to the level of the fixes'
    # noise averaged over the position's correlation time (well under a metre)
    assert math.hypot(x[0] - tx, x[1] - ty) < 1.0


def test_a_new_kind_is_one_model_class():
    """The interface a new kind implements: a config table, a sample, a policy, and ``apply``."""
    class Doubler(SensorModel):  # a toy kind reusing the odometry table and policy: what matters is the wiring
        config_type = OdomSensor
        sample_type = OdomSample
        policy_type = OdomPolicy

        def apply(self, s, inp, stamp, emit, late):
            s.linear = tuple(2.0 * v for v in inp.linear)
            return []

    layout = StateLayout([PoseBlock(0.0, 0.1)])
    cfg = loads('[[sensors]]\nname = "w"\nkind = "odom"\nkey = "odom"\n')
    m = Doubler(cfg.sensors[0], 0, _context(layout))
    s = _fresh(layout, [m])
    m.apply(s, m.convert(OdomSample("w", 10.0, (0.5, 0.0, 0.0), (0.0, 0.0, 0.0), COV6)), 10.0, True, False)
    assert s.linear == (1.0, 0.0, 0.0) and s.own == [None]


# -- covariance memo: a driver's constant covariance is resolved once, a changed one anew ----------------------------

def _imu_sample(stamp: float, oc, gc, q=(0.0, 0.0, 0.0, 1.0)) -> ImuSample:
    return ImuSample("imu", stamp, q, oc, (0.0, 0.0, 0.1), gc)


def test_imu_policy_resolves_each_new_covariance_and_never_reuses_a_stale_one():
    from fusiond.config import ImuSensor
    from fusiond.core.sensors.checks import Rejected
    from fusiond.core.sensors.imu import ImuPolicy

    # a 90 deg yaw mount: the base-frame covariance is the IMU's turned, so a stale one would show
    policy = ImuPolicy(ImuSensor(name="imu", key="imu", orientation="absolute", angular_velocity=True,
                                 extrinsic_rpy=(0.0, 0.0, math.pi / 2)))
    a = (1e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 9e-4)
    g = (1e-6, 0.0, 0.0, 0.0, 4e-6, 0.0, 0.0, 0.0, 9e-6)
    first = policy.convert(_imu_sample(1.0, a, g))
    assert first.rpy_cov[0] == pytest.approx(4e-4) and first.rpy_cov[4] == pytest.approx(1e-4)
    assert first.gyro_cov[0] == pytest.approx(4e-6) and first.gyro_cov[4] == pytest.approx(1e-6)
    again = policy.convert(_imu_sample(1.1, tuple(a), tuple(g)))  # equal values, new tuples
    assert again.rpy_cov == first.rpy_cov and again.gyro_cov == first.gyro_cov and again.rows == (0, 1, 2)
    # the yaw row reported unmeasured (huge variance): the rows change with the covariance
    b = (1e-4, 0.0, 0.0, 0.0, 4e-4, 0.0, 0.0, 0.0, 1e6)
    changed = policy.convert(_imu_sample(1.2, b, (2e-6,) + g[1:]))
    assert changed.rows == (0, 1) and changed.gyro_cov[4] == pytest.approx(2e-6)
    # a bad covariance after good ones is refused whatever was seen before: the orientation's rows (counted), the
    # gyro of the same message kept
    kept = policy.convert(_imu_sample(1.3, (math.nan,) + a[1:], g))
    assert kept.rows == () and kept.gyro is not None and policy.orientation_dropped == {"non_finite": 1}
    with pytest.raises(Rejected) as r:
        policy.convert(_imu_sample(1.4, a, (-1e-6,) + g[1:]))
    assert r.value.reason == "negative_covariance"
    # a list (mutable) is resolved each time: changing it in place changes the next result
    mutable = list(a)
    policy.convert(_imu_sample(1.5, mutable, g))
    mutable[0] = 1.0e-2
    assert policy.convert(_imu_sample(1.6, mutable, g)).rpy_cov[4] == pytest.approx(1e-2)


def test_odom_policy_resolves_each_new_covariance_and_zeroes_unmeasured_components():
    from fusiond.core.sensors.checks import Rejected

    policy = OdomPolicy(OdomSensor(name="wheel", key="odom"))
    cov = list(COV6)
    first = policy.convert(OdomSample("wheel", 1.0, (1.0, 0.2, 0.0), (0.0, 0.0, 0.5), tuple(cov)))
    assert first.linear == (1.0, 0.2, 0.0) and first.angular == (0.0, 0.0, 0.5) and first.yaw_rate_measured
    assert first.linear_cov[0] == pytest.approx(1e-4)
    cov[35] = 1e9  # the yaw rate reported unmeasured: its value is not used
    cov[0] = 4e-4
    second = policy.convert(OdomSample("wheel", 1.1, (1.0, 0.2, 0.0), (0.0, 0.0, 0.5), tuple(cov)))
    assert second.angular == (0.0, 0.0, 0.0) and not second.yaw_rate_measured
    assert second.linear_cov[0] == pytest.approx(4e-4) and second.linear == (1.0, 0.2, 0.0)
    third = policy.convert(OdomSample("wheel", 1.2, (1.0, 0.2, 0.0), (0.0, 0.0, 0.5), COV6))
    assert third.angular == (0.0, 0.0, 0.5) and third.linear_cov == first.linear_cov
    cov[0] = -1.0
    with pytest.raises(Rejected) as r:
        policy.convert(OdomSample("wheel", 1.3, (1.0, 0.0, 0.0), (0.0, 0.0, 0.0), tuple(cov)))
    assert r.value.reason == "negative_covariance"


def test_an_imu_sample_of_zeros_without_orientation_is_dropped_as_lost():
    """A driver that lost a sample and sent zeros: rates and specific force exactly 0 (at rest the
    accelerometer reads gravity, so no real sample is all zeros). Fused, its gyro would stop the turn
    for a sample; dropped, the previous rate stays held and the drop is counted."""
    from fusiond import reasons

    core = FusionCore(robot_config(orientation="off"))
    no_orientation = (-1.0,) + (0.0,) * 8
    turning = ImuSample("imu", 10.0, (0.0, 0.0, 0.0, 1.0), no_orientation, (0.0, 0.0, 0.3), GYRO_COV,
                        (0.0, 0.0, 9.81), COV3)
    lost = ImuSample("imu", 10.01, (0.0, 0.0, 0.0, 1.0), no_orientation, (0.0, 0.0, 0.0), (0.0,) * 9,
                     (0.0, 0.0, 0.0), (0.0,) * 9)
    assert core.ingest(turning).accepted
    step = core.ingest(lost)
    assert not step.accepted and step.reason == reasons.NOTHING_TO_FUSE
    assert core.state.gyro == (0.0, 0.0, 0.3)
    # with its orientation fused, a sample of zero rates is a measurement (an IMU at rest, accelerometer unset)
    core = FusionCore(robot_config(orientation="roll_pitch"))
    core.ingest(turning)
    at_rest = ImuSample("imu", 10.01, (0.0, 0.0, 0.0, 1.0), COV3, (0.0, 0.0, 0.0), GYRO_COV)
    assert core.ingest(at_rest).accepted and core.state.gyro == (0.0, 0.0, 0.0)


def _reference_fit(window: tuple, linear_var: float) -> float:
    """The forward-speed slope written over the pairs, as the model's docstring states it."""
    import math

    from fusiond.core.sensors.odom.model import ACCEL_FIT_FLOOR, ACCEL_FIT_SIGMAS, ACCEL_WINDOW_S

    n = len(window)
    if n < 3 or window[-1][0] - window[0][0] < 0.5 * ACCEL_WINDOW_S:
        last = window[-1][1]
        return 0.0 if all(p[1] == last for p in window) else math.nan
    tm = sum(p[0] for p in window) / n
    vm = sum(p[1] for p in window) / n
    stt = sum((p[0] - tm) ** 2 for p in window)
    slope = sum((p[0] - tm) * (p[1] - vm) for p in window) / stt
    misfit = math.sqrt(sum((p[1] - vm - slope * (p[0] - tm)) ** 2 for p in window) / (n - 2))
    return slope if misfit <= max(ACCEL_FIT_SIGMAS * math.sqrt(linear_var), ACCEL_FIT_FLOOR) else math.nan


def test_the_forward_speed_fit_is_the_pairs_formula_to_the_bit():
    import math
    import random

    from fusiond.core.sensors.odom.model import _fitted_accel
    from fusiond.estimator import COMPILED_BACKEND, PYTHON_BACKEND

    BACKENDS = [b for b in (PYTHON_BACKEND, COMPILED_BACKEND) if b is not None]  # either: the same bits

    rng = random.Random(3)
    for k in range(300):
        n = rng.randint(1, 60)
        t0, dt = rng.uniform(0.0, 2e9), rng.uniform(0.005, 0.05)
        v0, a, noise = rng.uniform(-30, 30), rng.uniform(-3, 3), rng.choice([0.0, 1e-3, 0.05, 1.0])
        window = tuple((t0 + i * dt, v0 + a * i * dt + rng.gauss(0.0, noise)) for i in range(n))
        var = rng.choice([0.0, 1e-4, 0.01])
        expected = _reference_fit(window, var)
        for backend in BACKENDS:
            got = _fitted_accel(window, var, backend)
            assert got == expected or (math.isnan(got) and math.isnan(expected)), (k, backend, got, expected)
