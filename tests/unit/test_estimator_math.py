"""Estimator maths: analytic Jacobians against central differences, manifold hygiene.

The tests that run the filter's numerics take the ``backend`` fixture (tests/conftest.py): each passes
on the Python reference and on the compiled kernels (estimator/backend.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond.estimator import ErrorStateEKF, GyroBiasBlock, MotionInput, PoseBlock, PredictWorkspace, StateLayout
from fusiond.estimator import observations as obs
from fusiond.estimator import rotation as rot
from fusiond.estimator.motion import propagate_state
from fusiond.estimator.numeric import measurement_jacobian, transition_jacobian

angles = st.floats(-math.pi, math.pi)


def _predict(backend, layout: StateLayout, x: np.ndarray, u: MotionInput, dt: float, density: np.ndarray,
             ws: PredictWorkspace | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The motion model's (x', F, Q) through ``backend``, in ``ws`` or a fresh workspace."""
    return backend.predict(layout, x, u, dt, density, PredictWorkspace(layout) if ws is None else ws)
tilts = st.floats(-1.2, 1.2)


def _layout(bias: bool = True) -> StateLayout:
    blocks = [PoseBlock(0.1, 0.1)] + ([GyroBiasBlock(0.01, 1e-4)] if bias else [])
    return StateLayout(blocks)


def _state(layout: StateLayout, rpy: tuple[float, float, float], bias=(0.01, -0.02, 0.005)) -> np.ndarray:
    x = layout.initial_state()
    x[0:3] = (1.0, -2.0, 0.3)
    x[3:7] = rot.from_rpy(*rpy)
    if layout.has("gyro_bias"):
        x[layout.nominal["gyro_bias"]] = bias
    return x


def _input(world: bool = False, gyro: bool = True, planar: bool = False) -> MotionInput:
    u = MotionInput()
    u.planar = planar
    u.linear = (0.8, 0.1, -0.05)
    u.angular = (0.2, -0.3, 0.9)
    u.linear_cov = (1e-3, 1e-4, 0.0, 1e-4, 2e-3, 0.0, 0.0, 0.0, 3e-3)
    u.angular_cov = (1e-4, 0.0, 0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 4e-4)
    u.linear_period = u.angular_period = 0.02
    u.from_gyro = gyro
    u.world_frame = world
    return u


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, dt=st.floats(0.001, 0.5), world=st.booleans(), gyro=st.booleans(),
       planar=st.booleans())
def test_transition_jacobian_matches_central_differences(r, p, y, dt, world, gyro, planar, backend):
    layout = _layout()
    x = _state(layout, (r, p, y))
    u = _input(world, gyro, planar)
    _, F, _ = _predict(backend, layout, x, u, dt, np.zeros(9))
    F_num = transition_jacobian(layout, lambda s: propagate_state(layout, s, u, dt), x)
    np.testing.assert_allclose(F, F_num, atol=2e-7, rtol=1e-6)


@settings(max_examples=60, deadline=None)
@given(r=tilts, p=tilts, y=angles)
def test_rpy_jacobian_matches_central_differences(r, p, y):
    layout = _layout()
    x = _state(layout, (r, p, y))

    def h(s: np.ndarray) -> np.ndarray:
        return np.array(rot.to_rpy(tuple(s[3:7].tolist())))

    _, H3 = obs.rpy_jacobian(tuple(x[3:7].tolist()))
    H_num = measurement_jacobian(layout, h, x)
    np.testing.assert_allclose(np.array(H3), H_num[:, 3:6], atol=1e-6, rtol=1e-5)
    np.testing.assert_allclose(H_num[:, [0, 1, 2, 6, 7, 8]], 0.0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(r=tilts, p=tilts, y=angles)
def test_roll_pitch_observation_has_no_yaw_column(r, p, y, backend):
    layout = _layout()
    x = _state(layout, (r, p, y))
    _, H, _ = obs.orientation(layout, x, (0.0, 0.0, 0.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4),
                              obs.ORIENTATION_ROWS["roll_pitch"], backend)
    assert H.shape == (2, layout.error_dim)
    assert np.all(H[:, 5] == 0.0)  # global yaw error column
    assert np.all(H[:, 0:3] == 0.0)  # position


def test_zero_rate_jacobian_matches_central_differences():
    layout = _layout()
    x = _state(layout, (0.1, 0.2, 0.3))
    gyro = (0.01, 0.02, -0.03)
    _, H, _ = obs.zero_rate(layout, x, gyro, (1.0, 0, 0, 0, 1.0, 0, 0, 0, 1.0))
    H_num = measurement_jacobian(layout, lambda s: s[layout.nominal["gyro_bias"]], x, angular=False)
    np.testing.assert_allclose(H, H_num, atol=1e-9)


@given(v=st.tuples(*[st.floats(-3.0, 3.0)] * 3))
def test_exp_log_roundtrip_and_sign_ambiguity(v):
    q = rot.exp(*v)
    assert math.isclose(sum(c * c for c in q), 1.0, rel_tol=1e-12)
    back = rot.log(q)
    back_neg = rot.log(tuple(-c for c in q))
    np.testing.assert_allclose(back, back_neg, atol=1e-12)
    np.testing.assert_allclose(rot.matrix(rot.exp(*back)), rot.matrix(q), atol=1e-12)


@given(r=tilts, p=tilts, y=angles)
def test_rpy_roundtrip(r, p, y):
    rr, pp, yy = rot.to_rpy(rot.from_rpy(r, p, y))
    assert abs(rot.wrap(rr - r)) < 1e-9 and abs(pp - p) < 1e-9 and abs(rot.wrap(yy - y)) < 1e-9


def test_right_jacobian_definition():
    phi = np.array([0.3, -0.2, 0.5])
    d = np.array([1e-6, -2e-6, 3e-6])
    lhs = rot.exp(*(phi + d))
    from fusiond.estimator.motion import _right_jacobian

    Jr = np.array(_right_jacobian(*phi)).reshape(3, 3)
    rhs = rot.mul(rot.exp(*phi), rot.exp(*(Jr @ d)))
    np.testing.assert_allclose(rot.log(rot.mul(lhs, rot.conj(rhs))), 0.0, atol=1e-11)


def test_long_random_run_keeps_covariance_psd_and_quaternion_unit(backend):
    rng = np.random.default_rng(7)
    layout = _layout()
    ekf = ErrorStateEKF(layout, backend=backend)
    for k in range(5000):
        u = _input(gyro=bool(k % 2))
        u.linear = tuple(rng.normal(0, 1, 3).tolist())
        u.angular = tuple(rng.normal(0, 0.5, 3).tolist())
        x, F, Q = _predict(backend, layout, ekf.x, u, float(rng.uniform(0.0, 0.05)), np.full(9, 1e-6))
        ekf.propagate(x, F, Q)
        if k % 3 == 0:
            z = tuple(rng.uniform(-0.5, 0.5, 3)) if k % 2 else tuple(rng.uniform(-math.pi, math.pi, 3))
            var = rng.uniform(1e-6, 1e-1, 3).tolist()
            y, H, R = obs.orientation(layout, ekf.x, z, (var[0], 0, 0, 0, var[1], 0, 0, 0, var[2]), (0, 1, 2),
                                      backend)
            ekf.update(y, H, R)
        q = ekf.x[3:7]
        assert abs(float(q @ q) - 1.0) < 1e-12
        assert np.allclose(ekf.P, ekf.P.T, atol=0.0)
        assert np.linalg.eigvalsh(ekf.P).min() > -1e-12
        assert np.isfinite(ekf.P).all()


def test_non_finite_covariance_is_reset_not_raised(backend):
    layout = _layout()
    ekf = ErrorStateEKF(layout, backend=backend)
    F = np.eye(layout.error_dim)
    Q = np.zeros_like(F)
    Q[0, 0] = math.nan
    assert ekf.propagate(ekf.x.copy(), F, Q) is False
    assert ekf.resets == 1
    np.testing.assert_array_equal(ekf.P, layout.initial_covariance())


def test_gate_rejects_outlier_and_leaves_state(backend):
    layout = _layout()
    ekf = ErrorStateEKF(layout, backend=backend)
    before = ekf.snapshot()
    y, H, R = obs.orientation(layout, ekf.x, (0.0, 0.0, 2.0), (1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4), (0, 1, 2),
                              backend)
    res = ekf.update(y, H, R, threshold=5.0)
    assert res.rejected and res.nis > 25.0
    np.testing.assert_array_equal(ekf.x, before[0])
    np.testing.assert_array_equal(ekf.P, before[1])


def test_kalman_update_matches_textbook_inverse(backend):
    layout = _layout()
    rng = np.random.default_rng(1)
    A = rng.normal(size=(9, 9))
    P = A @ A.T * 1e-2 + np.eye(9) * 1e-3
    ekf = ErrorStateEKF(layout, P=P, backend=backend)
    y, H, R = obs.orientation(layout, ekf.x, (0.05, -0.02, 0.1), (1e-3, 0, 0, 0, 2e-3, 0, 0, 0, 3e-3), (0, 1, 2),
                              backend)
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    res = ekf.update(y, H, R)
    assert res.nis == pytest.approx(float(y @ np.linalg.inv(S) @ y), rel=1e-10)
    IKH = np.eye(9) - K @ H
    np.testing.assert_allclose(ekf.P, IKH @ P @ IKH.T + K @ R @ K.T, atol=1e-12)
    np.testing.assert_allclose(ekf.x[layout.nominal["gyro_bias"]], (K @ y)[6:9], atol=1e-14)


def test_masked_update_equals_joseph_form_with_zeroed_gain_rows(backend):
    layout = _layout()
    rng = np.random.default_rng(2)
    A = rng.normal(size=(9, 9))
    P = A @ A.T * 1e-2 + np.eye(9) * 1e-3
    ekf = ErrorStateEKF(layout, x=_state(layout, (0.2, -0.1, 0.5)), P=P, backend=backend)
    x0 = ekf.x.copy()
    y, H, R = obs.orientation(layout, ekf.x, (0.25, -0.12, 0.0), (1e-3, 0, 0, 0, 2e-3, 0, 0, 0, 3e-3), (0, 1),
                              backend)
    mask = np.ones(9, dtype=bool)
    mask[[0, 1, 2, 5, 8]] = False
    ekf.update(y, H, R, mask=mask)
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R) * mask[:, None]
    IKH = np.eye(9) - K @ H
    np.testing.assert_allclose(ekf.P, IKH @ P @ IKH.T + K @ R @ K.T, atol=1e-12)
    dx = layout.boxminus(ekf.x, x0)
    np.testing.assert_allclose(dx, K @ y, atol=1e-12)
    assert np.abs(dx[~mask]).max() < 1e-15


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles)
def test_a_tilt_update_holding_heading_keeps_the_yaw_exactly_and_roll_pitch_as_updated(r, p, y, backend):
    """A masked roll/pitch update of a tilted body moves its Euler yaw (second order); with
    hold_heading the yaw stays (to rounding), and roll/pitch stay what the update made them
    (the turn back is about world z, which the roll/pitch of a yaw-free rotation ignore)."""
    layout = _layout()
    rng = np.random.default_rng(3)
    A = rng.normal(size=(9, 9))
    P = A @ A.T * 1e-2 + np.eye(9) * 1e-3
    mask = np.ones(9, dtype=bool)
    mask[[0, 1, 2, 5, 8]] = False
    cov = (1e-3, 0, 0, 0, 2e-3, 0, 0, 0, 3e-3)
    results = []
    for hold in (False, True):
        ekf = ErrorStateEKF(layout, x=_state(layout, (r, p, y)), P=P.copy(), backend=backend)
        yaw0 = rot.yaw(tuple(ekf.x[3:7].tolist()))
        yv, H, R = obs.orientation(layout, ekf.x, (r + 0.1, p - 0.08, 0.0), cov, (0, 1), backend)
        assert not ekf.update(yv, H, R, mask=mask, hold_heading=hold).rejected
        results.append((yaw0, rot.to_rpy(tuple(ekf.x[3:7].tolist())), ekf.x.copy(), ekf.P.copy()))
    (yaw0, free, x_free, P_free), (_, held, x_held, P_held) = results
    assert abs(rot.wrap(held[2] - yaw0)) < 1e-12
    np.testing.assert_allclose(held[0:2], free[0:2], atol=1e-9)
    np.testing.assert_array_equal(x_held[[0, 1, 2, 7, 8, 9]], x_free[[0, 1, 2, 7, 8, 9]])
    np.testing.assert_array_equal(P_held, P_free)  # the covariance update does not depend on it
    if abs(r) > 0.3 and abs(p) > 0.3:  # tilted enough for the free update to have turned the yaw
        assert abs(rot.wrap(free[2] - yaw0)) > 1e-4


@settings(max_examples=50, deadline=None)
@given(m=st.integers(1, 5), seed=st.integers(0, 10_000))
def test_cholesky_whitening_matches_numpy(m, seed):
    from fusiond.estimator.cholesky import whiten

    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, m))
    S = A @ A.T + np.eye(m) * 1e-3
    y = rng.normal(size=m)
    Linv, z = whiten(S.tolist(), y.tolist())
    L = np.linalg.cholesky(S)
    np.testing.assert_allclose(np.array(Linv) @ L, np.eye(m), atol=1e-9)
    assert float(np.dot(z, z)) == pytest.approx(float(y @ np.linalg.solve(S, y)), rel=1e-9)
    assert whiten((-S).tolist(), y.tolist()) is None


# -- scale states -----------------------------------------------------------------------------------------------

def _scale_layout(bias: bool = True) -> StateLayout:
    from fusiond.estimator import GyroScaleBlock, WheelScaleBlock

    blocks = [PoseBlock(0.1, 0.1)] + ([GyroBiasBlock(0.01, 1e-4)] if bias else [])
    return StateLayout(blocks + [GyroScaleBlock(0.05, 1e-5), WheelScaleBlock(0.1, 1e-4)])


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, dt=st.floats(0.001, 0.5), world=st.booleans(), gyro=st.booleans(),
       k=st.floats(0.7, 1.3), s=st.floats(0.7, 1.3), bias=st.booleans())
def test_scale_blocks_transition_jacobian_matches_central_differences(r, p, y, dt, world, gyro, k, s, bias, backend):
    """Bias then scale correct the same gyro input: the bias columns must be chained through the scale."""
    layout = _scale_layout(bias)
    x = _state(layout, (r, p, y))
    x[layout.nominal["gyro_scale"]] = k
    x[layout.nominal["wheel_scale"]] = s
    u = _input(world, gyro)
    _, F, _ = _predict(backend, layout, x, u, dt, np.zeros(layout.error_dim))
    F_num = transition_jacobian(layout, lambda st_: propagate_state(layout, st_, u, dt), x)
    np.testing.assert_allclose(F, F_num, atol=2e-7, rtol=1e-6)


def test_scales_correct_the_inputs_and_their_noise(backend):
    layout = _scale_layout()
    x = _state(layout, (0.0, 0.0, 0.0), bias=(0.0, 0.0, 0.1))
    x[layout.nominal["gyro_scale"]] = 0.5
    x[layout.nominal["wheel_scale"]] = 2.0
    u = _input(world=True, gyro=True)
    x1, _, Q = _predict(backend, layout, x, u, 1.0, np.zeros(layout.error_dim))
    np.testing.assert_allclose(x1[0:3], x[0:3] + 2.0 * np.array(u.linear), atol=1e-12)
    yaw_rate = 0.5 * (u.angular[2] - 0.1)
    q1 = rot.mul(tuple(x[3:7].tolist()), rot.exp(u.angular[0], u.angular[1], yaw_rate))
    np.testing.assert_allclose(rot.log(rot.mul(tuple(x1[3:7].tolist()), rot.conj(q1))), 0.0, atol=1e-12)
    # the wheel noise scales with the speed: world frame, dt = 1 -> Q = s^2 Sigma T
    np.testing.assert_allclose(Q[0:3, 0:3], 4.0 * u.linear_period * np.reshape(u.linear_cov, (3, 3)), atol=1e-15)


# -- the twist's pitch in the body ------------------------------------------------------------------------------

def _pitch_layout() -> StateLayout:
    from fusiond.estimator import TwistPitchBlock, WheelScaleBlock

    return StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), WheelScaleBlock(0.1, 1e-4),
                        TwistPitchBlock(0.1, 1e-5)])


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, dt=st.floats(0.001, 0.5), world=st.booleans(), gyro=st.booleans(),
       s=st.floats(0.7, 1.3), b=st.floats(-0.3, 0.3))
def test_twist_pitch_transition_jacobian_matches_central_differences(r, p, y, dt, world, gyro, s, b, backend):
    """Scale then pitch correct the same wheel input: the scale's columns are chained through the rotation."""
    layout = _pitch_layout()
    x = _state(layout, (r, p, y))
    x[layout.nominal["wheel_scale"]] = s
    x[layout.nominal["twist_pitch"]] = b
    u = _input(world, gyro)
    _, F, _ = _predict(backend, layout, x, u, dt, np.zeros(layout.error_dim))
    F_num = transition_jacobian(layout, lambda st_: propagate_state(layout, st_, u, dt), x)
    np.testing.assert_allclose(F, F_num, atol=2e-7, rtol=1e-6)


def test_a_twist_pitch_turns_the_wheels_forward_speed_into_the_body(backend):
    """Body pitched by b against the vehicle: the wheels' (v, 0, 0) is (cos b v, 0, sin b v) in the body,
    so along a level body x the base climbs by sin b per metre, and the pitched body sees level travel."""
    from fusiond.estimator import MotionInput

    layout = _pitch_layout()
    b = 0.07
    x = _state(layout, (0.0, b, 0.0))  # the body (the IMU's frame) pitched nose down by b
    x[layout.nominal["twist_pitch"]] = b
    u = MotionInput()
    u.linear = (10.0, 0.0, 0.0)
    x1, _, _ = _predict(backend, layout, x, u, 1.0, np.zeros(layout.error_dim))
    np.testing.assert_allclose(x1[0:3] - x[0:3], (10.0, 0.0, 0.0), atol=1e-12)  # level travel: the vehicle's


# -- Gauss-Markov GPS error state --------------------------------------------------------------------------------

def _gm_layout():
    from fusiond.estimator import GpsErrorBlock, WheelScaleBlock

    return StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), WheelScaleBlock(0.1, 1e-4),
                        GpsErrorBlock(30.0, (1.0, 1.5, 2.0))])


@settings(max_examples=40, deadline=None)
@given(r=tilts, p=tilts, y=angles, dt=st.floats(0.001, 5.0), world=st.booleans(), gyro=st.booleans(),
       b=st.tuples(*[st.floats(-3.0, 3.0)] * 3))
def test_gauss_markov_transition_jacobian_matches_central_differences(r, p, y, dt, world, gyro, b, backend):
    layout = _gm_layout()
    x = _state(layout, (r, p, y))
    x[layout.nominal["gps_error"]] = b
    u = _input(world, gyro)
    x1, F, _ = _predict(backend, layout, x, u, dt, np.zeros(layout.error_dim))
    F_num = transition_jacobian(layout, lambda s: propagate_state(layout, s, u, dt), x)
    np.testing.assert_allclose(F, F_num, atol=2e-7, rtol=1e-6)
    np.testing.assert_allclose(x1[layout.nominal["gps_error"]], np.array(b) * math.exp(-dt / 30.0), rtol=1e-12)


def test_gauss_markov_noise_keeps_the_stationary_variance_whatever_the_step(backend):
    layout = _gm_layout()
    es = layout.error["gps_error"]
    sig2 = np.array([1.0, 1.5, 2.0]) ** 2
    u = _input()
    for dt in (0.01, 0.5, 7.0):
        x = _state(layout, (0.0, 0.0, 0.0))
        _, F, Q = _predict(backend, layout, x, u, dt, np.zeros(layout.error_dim))
        a = math.exp(-dt / 30.0)
        np.testing.assert_allclose(np.diag(Q)[es], sig2 * (1.0 - math.exp(-2.0 * dt / 30.0)), rtol=1e-12)
        np.testing.assert_allclose(np.diag(F)[es], a, rtol=1e-15)
        # P_bb = sigma^2 (the stationary distribution) is a fixed point of F P F^T + Q
        P_bb = a * a * sig2 + np.diag(Q)[es]
        np.testing.assert_allclose(P_bb, sig2, rtol=1e-12)
    assert layout.dynamic_blocks and not _layout().dynamic_blocks


def test_position_with_gps_error_jacobian_matches_central_differences():
    from fusiond.estimator.numeric import measurement_jacobian

    layout = _gm_layout()
    x = _state(layout, (0.2, -0.3, 1.1))
    x[layout.nominal["gps_error"]] = (0.4, -0.7, 1.2)
    lever = (0.3, 0.1, 0.5)

    def h(s):
        return -obs.position(layout, s, (0.0, 0.0, 0.0), (1.0,) * 9, lever, "gps_error")[0]

    y, H, _ = obs.position(layout, x, (0.0, 0.0, 0.0), (1.0,) * 9, lever, "gps_error")
    np.testing.assert_allclose(H, measurement_jacobian(layout, h, x, angular=False), atol=1e-7)
    y0, H0, _ = obs.position(layout, x, (0.0, 0.0, 0.0), (1.0,) * 9, lever)
    np.testing.assert_allclose(y, y0 - np.array([0.4, -0.7, 1.2]), atol=1e-15)
    np.testing.assert_array_equal(H[:, layout.error["gps_error"]], np.eye(3))
    np.testing.assert_array_equal(H0[:, layout.error["gps_error"]], 0.0)


# -- the preallocated predict workspace ------------------------------------------------------------------------

_step_inputs = st.tuples(st.booleans(), st.booleans(), st.booleans(), st.booleans(), st.booleans(),
                         st.floats(0.0, 0.3))


@settings(max_examples=40, deadline=None)
@given(steps=st.lists(_step_inputs, min_size=2, max_size=8))
def test_a_reused_workspace_gives_what_a_fresh_one_gives(steps, backend):
    """predict rewrites only the entries of F and Q a step sets and puts back what an earlier step
    wrote and this one does not (an input block that stops applying when the gyro goes silent, a
    silent input's noise, world vs body twist, dt = 0). Whatever sequence of steps went before,
    F and Q must equal (exactly: the same float operations) those from a fresh workspace."""
    from fusiond.estimator import GpsErrorBlock, PredictWorkspace

    layout = StateLayout(_scale_layout().blocks + [GpsErrorBlock(30.0, (1.0, 1.5, 2.0))])
    ws = PredictWorkspace(layout)
    x = _state(layout, (0.1, -0.2, 0.7))
    density = np.linspace(1e-6, 1e-5, layout.error_dim)
    for world, gyro, planar, linear_on, angular_on, dt in steps:
        u = _input(world, gyro, planar)
        u.linear_period = 0.02 if linear_on else 0.0
        u.angular_period = 0.02 if angular_on else 0.0
        x1, F, Q = _predict(backend, layout, x, u, dt, density, ws)
        x2, F2, Q2 = _predict(backend, layout, x, u, dt, density)
        np.testing.assert_array_equal(x1, x2)
        np.testing.assert_array_equal(F, F2)
        np.testing.assert_array_equal(Q, Q2)
        x = x1


def test_orientation_noise_is_shared_read_only_and_follows_the_covariance(backend):
    """R is cached per (covariance, rows): a changed covariance must give its own R, and the shared
    array must refuse writes (a caller scaling it in place would change every later update)."""
    layout = _layout()
    x = _state(layout, (0.1, 0.2, 0.3))
    cov_a = (1e-4, 0.0, 0.0, 0.0, 2e-4, 0.0, 0.0, 0.0, 3e-4)
    cov_b = (5e-4, 1e-5, 0.0, 1e-5, 6e-4, 0.0, 0.0, 0.0, 7e-4)
    _, _, Ra = obs.orientation(layout, x, (0.0, 0.0, 0.0), cov_a, (0, 1), backend)
    _, _, Rb = obs.orientation(layout, x, (0.0, 0.0, 0.0), list(cov_b), (0, 1, 2), backend)
    np.testing.assert_array_equal(Ra, [[1e-4, 0.0], [0.0, 2e-4]])
    np.testing.assert_array_equal(Rb, np.reshape(cov_b, (3, 3)))
    with pytest.raises(ValueError):
        Ra *= 2.0
    _, _, Ra2 = obs.orientation(layout, x, (0.0, 0.0, 0.0), cov_a, (0, 1), backend)
    np.testing.assert_array_equal(Ra2, [[1e-4, 0.0], [0.0, 2e-4]])


@settings(max_examples=60, deadline=None)
@given(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-3.1, 3.1), st.floats(-3.1, 3.1), st.floats(1e-6, 3.0))
def test_turn_heading_turns_the_attitude_about_world_z_and_sets_the_yaw_variance(r, p, y, angle, ratio):
    """q' = Rz(angle) q: roll/pitch as seen in the world frame turn with it, the yaw moves by angle, the
    position stays. The attitude error turns (dtheta' = Rz dtheta); the yaw variance becomes exactly the
    one asked (here ratio x what it was): widened, only that entry grows (the attitude block's trace by
    the difference); narrowed, the yaw row and column scale, so every correlation coefficient with the yaw
    stays and the rest of P is untouched. P stays positive definite either way. (Narrowed by at most a
    million: a variance made 0, or subnormal, has no correlation coefficient left to compare.)"""
    rng = np.random.default_rng(1)
    layout = _layout()
    ekf = ErrorStateEKF(layout)
    ekf.set_attitude(rot.from_rpy(r, p, y))
    ekf.x[0:3] = (1.0, -2.0, 0.5)
    A = rng.normal(0, 0.1, (layout.error_dim, layout.error_dim))
    ekf.P = A @ A.T + 1e-6 * np.eye(layout.error_dim)
    q0, p0 = tuple(ekf.x[3:7].tolist()), ekf.x[0:3].copy()
    J = np.eye(layout.error_dim)
    c, s_ = math.cos(angle), math.sin(angle)
    J[3:5, 3:5] = ((c, -s_), (s_, c))
    turned = J @ ekf.P @ J.T  # the attitude error turned, the variance not yet set
    target = ratio * turned[5, 5]
    ekf.turn_heading(angle, target)
    q1 = tuple(ekf.x[3:7].tolist())
    assert abs(sum(c * c for c in q1) - 1.0) < 1e-12
    np.testing.assert_array_equal(ekf.x[0:3], p0)
    Rz = rot.matrix(rot.exp(0.0, 0.0, angle))
    np.testing.assert_allclose(rot.matrix(q1), Rz @ rot.matrix(q0), atol=1e-12)
    P = ekf.P
    assert P[5, 5] == pytest.approx(target, rel=1e-12, abs=1e-15)
    others = [i for i in range(layout.error_dim) if i != 5]
    np.testing.assert_allclose(P[np.ix_(others, others)], turned[np.ix_(others, others)], rtol=1e-12, atol=1e-15)
    if ratio >= 1.0:
        np.testing.assert_allclose(P[5, others], turned[5, others], rtol=1e-12, atol=1e-15)
    elif ratio > 0.0:
        d, d0 = np.sqrt(np.diag(P)), np.sqrt(np.diag(turned))
        np.testing.assert_allclose(P[5, others] / (d[5] * d[others]), turned[5, others] / (d0[5] * d0[others]),
                                   rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-15)
    # scaled towards 0 the yaw's variance takes the smallest eigenvalue with it, to rounding
    assert np.linalg.eigvalsh(P).min() > (0.0 if ratio > 0.01 else -1e-15)
