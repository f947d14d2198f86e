"""The plain EKF's maths (scripts/plain_ekf.py, the benchmark's textbook filter): its quaternion helpers,
and its analytic error-state Jacobians against central differences of exactly the functions it runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tests.support.scripts import load_script


def _plain():
    return load_script("plain_ekf")


pe = _plain()
RNG = np.random.default_rng(7)


def _random_quat(rng) -> np.ndarray:
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def _random_state(rng):
    return pe.State(rng.normal(size=3) * 5.0, _random_quat(rng), rng.normal(size=3) * 0.02)


def test_quaternion_product_is_the_rotation_product_and_exp_log_invert():
    for _ in range(20):
        a, b = _random_quat(RNG), _random_quat(RNG)
        np.testing.assert_allclose(pe.quat_matrix(pe.quat_mul(a, b)), pe.quat_matrix(a) @ pe.quat_matrix(b),
                                   atol=1e-12)
        np.testing.assert_allclose(pe.quat_matrix(pe.quat_conj(a)), pe.quat_matrix(a).T, atol=1e-12)
        axis = RNG.normal(size=3)
        phi = axis / np.linalg.norm(axis) * RNG.uniform(1e-9, 3.0)  # an angle below pi: the log's range
        np.testing.assert_allclose(pe.quat_log(pe.quat_exp(phi)), phi, atol=1e-10)
        # q and -q are one rotation: the log takes the shorter way
        np.testing.assert_allclose(pe.quat_log(-pe.quat_exp(phi)), phi, atol=1e-10)
        # Exp(phi) is the rotation matrix of Rodrigues' formula
        k = pe.skew(phi)
        a_ = np.linalg.norm(phi)
        rodrigues = np.eye(3) + math.sin(a_) / a_ * k + (1 - math.cos(a_)) / a_**2 * k @ k
        np.testing.assert_allclose(pe.quat_matrix(pe.quat_exp(phi)), rodrigues, atol=1e-9)


def test_roll_pitch_yaw_round_trip_in_fixed_axes():
    for _ in range(20):
        r, p, y = RNG.uniform(-3.0, 3.0), RNG.uniform(-1.4, 1.4), RNG.uniform(-3.0, 3.0)
        np.testing.assert_allclose(pe.quat_rpy(pe.quat_from_rpy(r, p, y)), (r, p, y), atol=1e-10)
    # fixed axes (URDF, tf2): a yaw of pi/2 turns body x onto world y
    np.testing.assert_allclose(pe.quat_matrix(pe.quat_from_rpy(0.0, 0.0, math.pi / 2)) @ [1, 0, 0], [0, 1, 0],
                               atol=1e-12)


def test_right_jacobian_against_central_differences():
    for scale in (1e-8, 0.3, 2.5):
        phi = RNG.normal(size=3) * scale
        num = np.zeros((3, 3))
        h = 1e-6
        for i in range(3):
            d = np.zeros(3)
            d[i] = h
            plus = pe.quat_log(pe.quat_mul(pe.quat_conj(pe.quat_exp(phi)), pe.quat_exp(phi + d)))
            minus = pe.quat_log(pe.quat_mul(pe.quat_conj(pe.quat_exp(phi)), pe.quat_exp(phi - d)))
            num[:, i] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(pe.right_jacobian(phi), num, atol=1e-8)


@pytest.mark.parametrize("gyro", [True, False])
@pytest.mark.parametrize("world_twist", [False, True])
def test_error_state_transition_against_central_differences(gyro, world_twist):
    """F = d(error after a step) / d(error before): perturb the state by dx, run the step the filter
    runs (propagate), and difference against the nominal step."""
    h = 1e-6
    for _ in range(5):
        s = _random_state(RNG)
        v, w, dt = RNG.normal(size=3) * 3.0, RNG.normal(size=3) * 0.8, RNG.uniform(0.005, 0.5)
        nominal = pe.propagate(s, v, w, dt, world_twist, gyro)
        num = np.zeros((9, 9))
        for i in range(9):
            d = np.zeros(9)
            d[i] = h
            plus = pe.boxminus(pe.propagate(pe.boxplus(s, d), v, w, dt, world_twist, gyro), nominal)
            minus = pe.boxminus(pe.propagate(pe.boxplus(s, -d), v, w, dt, world_twist, gyro), nominal)
            num[:, i] = (plus - minus) / (2 * h)
        np.testing.assert_allclose(pe.transition(s, v, w, dt, world_twist, gyro), num, atol=1e-7)


def test_roll_pitch_rows_against_central_differences():
    h = 1e-6
    for _ in range(10):
        q = pe.quat_from_rpy(RNG.uniform(-1.0, 1.0), RNG.uniform(-1.0, 1.0), RNG.uniform(-3.0, 3.0))
        roll, pitch, _ = pe.quat_rpy(q)
        num = np.zeros((2, 3))
        for i in range(3):
            d = np.zeros(3)
            d[i] = h
            plus = pe.quat_rpy(pe.quat_mul(q, pe.quat_exp(d)))[:2]
            minus = pe.quat_rpy(pe.quat_mul(q, pe.quat_exp(-d)))[:2]
            num[:, i] = (np.array(plus) - np.array(minus)) / (2 * h)
        np.testing.assert_allclose(pe.euler_rate_rows(roll, pitch), num, atol=1e-8)


def test_an_update_moves_the_state_by_the_gain_and_keeps_the_covariance_symmetric():
    f = pe.PlainEkf(gps=True, absolute_yaw=False, gyro=True, world_twist=False)
    f.predict(0.0)
    f.v = np.array([1.0, 0.0, 0.0])
    f.predict(1.0)
    before = np.diag(f.P).copy()
    f.update_position(np.array([1.0, 0.5, 0.0]), np.eye(3))
    assert np.all(np.isfinite(f.P)) and np.allclose(f.P, f.P.T)
    assert np.all(np.diag(f.P)[:3] < before[:3])
    assert np.linalg.eigvalsh(f.P).min() > 0.0
