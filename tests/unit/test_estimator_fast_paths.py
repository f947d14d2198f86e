"""The estimator's fast paths compute exactly what the plain compositions they replace compute.

Each fused or specialised function exists only to save calls on the per-message path; these tests
hold them to the same floats (assert_array_equal / ==, not a tolerance) as the reference spelled out
in its docstring, so that a fast path can never drift the estimate.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond.estimator import GyroBiasBlock, MotionInput, PoseBlock, PredictWorkspace, StateLayout, predict
from fusiond.estimator import mat3
from fusiond.estimator import rotation as rot
from fusiond.estimator.cholesky import gain_rows, whiten

# rotation vectors from below the series threshold (1e-8) to a few radians, and unit quaternions
small_or_large = st.one_of(st.floats(-1e-8, 1e-8), st.floats(-3.0, 3.0))
rotvec = st.tuples(small_or_large, small_or_large, small_or_large)
unit_q = st.tuples(st.floats(-1.2, 1.2), st.floats(-1.2, 1.2), st.floats(-math.pi, math.pi)).map(
    lambda rpy: rot.from_rpy(*rpy))


@given(q=unit_q, v=rotvec)
def test_advance_is_q_times_exp_normalised(q, v):
    assert rot.advance(q, *v) == rot.normalize(rot.mul(q, rot.exp(*v)))


@given(q=unit_q, v=rotvec)
def test_turn_is_exp_times_q_normalised(q, v):
    assert rot.turn(*v, q) == rot.normalize(rot.mul(rot.exp(*v), q))


@given(A=st.lists(st.floats(-10.0, 10.0), min_size=9, max_size=9),
       d=st.lists(st.floats(0.0, 5.0), min_size=3, max_size=3), scale=st.floats(0.0, 100.0))
def test_sandwich_diag_is_sandwich_of_the_diagonal_matrix(A, d, scale):
    S = mat3.diag(*d)
    assert mat3.sandwich_diag(tuple(A), d[0], d[1], d[2], scale) == mat3.sandwich(tuple(A), S, scale)


@settings(max_examples=60, deadline=None)
@given(m=st.integers(1, 5), seed=st.integers(0, 10_000))
def test_gain_rows_are_whitening_and_back_substitution(m, seed):
    """[L^-1; (L^-T z)^T] with z = L^-1 y: the first m rows and z are ``whiten``'s (the same floats),
    the last row is S^-1 y (L^-T L^-1 = S^-1)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(m, m))
    S = A @ A.T + np.eye(m) * 1e-3
    y = rng.normal(size=m)
    z, rows = gain_rows(S.tolist(), y.tolist())
    Linv, z_ref = whiten(S.tolist(), y.tolist())
    assert z == z_ref
    rows = np.array(rows).reshape(m + 1, m)
    np.testing.assert_array_equal(rows[:m], np.array(Linv))
    np.testing.assert_allclose(rows[m], np.linalg.solve(S, y), rtol=1e-9, atol=1e-12)
    assert gain_rows((-S).tolist(), y.tolist()) is None


def _inputs(linear_cov, angular_cov) -> MotionInput:
    u = MotionInput()
    u.linear, u.angular = (0.8, 0.1, -0.05), (0.2, -0.3, 0.9)
    u.linear_cov, u.angular_cov = linear_cov, angular_cov
    u.linear_period = u.angular_period = 0.02
    u.from_gyro = True
    return u


def test_input_noise_follows_a_covariance_that_changes():
    """The workspace decides once per covariance tuple whether it is diagonal. A new tuple (the next
    message) must be looked at again, and a list, which can change in place, every time: Q from a
    reused workspace equals Q from a fresh one through diagonal -> full -> diagonal changes."""
    layout = StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4)])
    ws = PredictWorkspace(layout)
    x = layout.initial_state()
    density = np.full(layout.error_dim, 1e-6)
    diag = (1e-3, 0.0, 0.0, 0.0, 2e-3, 0.0, 0.0, 0.0, 3e-3)
    full = (1e-3, 1e-4, 0.0, 1e-4, 2e-3, 0.0, 0.0, 0.0, 3e-3)
    changing = list(diag)
    for lin, ang in ((diag, diag), (full, diag), (diag, full), (changing, diag)):
        u = _inputs(lin, ang)
        _, _, Q = predict(layout, x, u, 0.01, density, ws)
        _, _, Q_ref = predict(layout, x, u, 0.01, density)
        np.testing.assert_array_equal(Q, Q_ref)
    changing[1] = changing[3] = 5e-4  # the same list object, now not diagonal
    _, _, Q = predict(layout, x, _inputs(changing, diag), 0.01, density, ws)
    _, _, Q_ref = predict(layout, x, _inputs(changing, diag), 0.01, density)
    np.testing.assert_array_equal(Q, Q_ref)
    assert Q[0, 1] != 0.0  # the off-diagonal input noise is there


def test_interleaved_masks_each_get_their_own_weights():
    """Masked updates of two kinds (tilt, position) alternate in the core; the weights kept per mask
    must be the ones of the mask at hand: the same floats as a filter that sees that mask first."""
    from fusiond.estimator import ErrorStateEKF
    from fusiond.estimator import observations as obs

    layout = StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4)])
    rng = np.random.default_rng(3)
    A = rng.normal(size=(9, 9))
    ekf = ErrorStateEKF(layout, P=A @ A.T * 1e-2 + np.eye(9) * 1e-3)
    tilt = np.ones(9, dtype=bool)
    tilt[[0, 1, 2, 5, 8]] = False
    position = np.zeros(9, dtype=bool)
    position[0:3] = True
    cov3 = (1e-3, 0.0, 0.0, 0.0, 2e-3, 0.0, 0.0, 0.0, 3e-3)
    for k in range(6):
        mask = tilt if k % 2 == 0 else position
        if mask is tilt:
            y, H, R = obs.orientation(layout, ekf.x, (0.02, -0.01, 0.0), cov3, (0, 1))
        else:
            y, H, R = obs.position(layout, ekf.x, (0.1, -0.2, 0.05), cov3)
        fresh = ErrorStateEKF(layout, x=ekf.x, P=ekf.P)  # has seen no mask yet
        fresh.update(y, H, R, mask=mask)
        ekf.update(y, H, R, mask=mask)
        np.testing.assert_array_equal(ekf.P, fresh.P)
        np.testing.assert_array_equal(ekf.x, fresh.x)
    assert len(ekf._ws.masks) == 2


def test_hold_planar_by_tuple_by_mask_and_by_index_hold_alike():
    """Two-D mode's held error components as the core hands them (a tuple: one compiled call), as an index
    array or as a mask (one numpy write): the same x and P."""
    import numpy as np

    from fusiond.estimator import ErrorStateEKF, GyroBiasBlock, PoseBlock, StateLayout, planar_mask

    layout = StateLayout([PoseBlock(0.0, 0.1), GyroBiasBlock(0.01, 2e-5)])
    rng = np.random.default_rng(1)
    a = ErrorStateEKF(layout)
    A = rng.normal(size=(layout.error_dim, layout.error_dim))
    a.P[:] = A @ A.T
    a.x[3:7] = (0.1, -0.2, 0.3, 0.9)
    a.x[3:7] /= np.linalg.norm(a.x[3:7])
    b, c = a.copy(), a.copy()
    nb, eb = layout.nominal["gyro_bias"].start, layout.error["gyro_bias"].start
    nominal_zero, error_zero = (2, nb, nb + 1), [2, 3, 4, eb, eb + 1]
    a.hold_planar(nominal_zero, np.array(error_zero))
    b.hold_planar(nominal_zero, planar_mask(error_zero, layout.error_dim))
    c.hold_planar(nominal_zero, tuple(error_zero))
    assert np.array_equal(a.P, b.P) and np.array_equal(a.x, b.x)
    assert np.array_equal(a.P, c.P) and np.array_equal(a.x, c.x)
    assert not a.P[error_zero].any() and not a.P[:, error_zero].any()
