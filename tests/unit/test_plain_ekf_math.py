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
    f = pe.PlainEkf(placed_by=True, absolute_yaw=False, gyro=True, world_twist=False)
    f.predict(0.0)
    f.v = np.array([1.0, 0.0, 0.0])
    f.predict(1.0)
    before = np.diag(f.P).copy()
    f.update_position(np.array([1.0, 0.5, 0.0]), np.eye(3))
    assert np.all(np.isfinite(f.P)) and np.allclose(f.P, f.P.T)
    assert np.all(np.diag(f.P)[:3] < before[:3])
    assert np.linalg.eigvalsh(f.P).min() > 0.0


class _Spy(pe.PlainEkf):
    """A plain EKF whose update hands back what it was given (residual, H, R) instead of applying it."""

    def update(self, residual, h, r):
        self.seen = (residual, h, r)


def _pose_residual(f, s, p_meas, q_meas, lever):
    f.x = s
    f.update_pose(p_meas, q_meas, np.eye(6) * 1e-4, lever)
    return f.seen


def test_pose_jacobian_with_a_lever_arm_against_central_differences():
    """h(x) = (p + R(q) t, q): the residual's slope in each error direction is -H (a sensor ahead of the base
    sees the heading through its lever arm). The attitude rows are the identity of the first-order error
    state: exact where the measured attitude is the state's (here within 1e-5 rad)."""
    f = _Spy(placed_by=True, absolute_yaw=False, gyro=True, world_twist=False)
    for _ in range(10):
        s = _random_state(RNG)
        lever = RNG.normal(size=3)
        p_meas, q_meas = s.p + RNG.normal(size=3) * 0.1, pe.quat_mul(s.q, pe.quat_exp(RNG.normal(size=3) * 1e-5))
        _, H, _ = _pose_residual(f, s, p_meas, q_meas, lever)
        num = np.zeros((6, 9))
        h = 1e-6
        for i in range(9):
            d = np.zeros(9)
            d[i] = h
            plus = _pose_residual(f, pe.boxplus(s, d), p_meas, q_meas, lever)[0]
            minus = _pose_residual(f, pe.boxplus(s, -d), p_meas, q_meas, lever)[0]
            num[:, i] = -(plus - minus) / (2 * h)
        np.testing.assert_allclose(H[:3], num[:3], atol=1e-6)  # the lever arm's rows
        np.testing.assert_allclose(H[3:], num[3:], atol=5e-5)  # off by about the residual's 1e-5 rad


def _odometry(x: float, y: float, yaw: float, sigma: float = 0.01):
    """A nav_msgs/Odometry-like message whose pose is (x, y, yaw) with ``sigma`` on each axis."""
    from types import SimpleNamespace as N

    q = pe.quat_exp(np.array([0.0, 0.0, yaw]))
    pose = N(position=N(x=x, y=y, z=0.0), orientation=N(x=q[0], y=q[1], z=q[2], w=q[3]))
    return N(pose=N(pose=pose, covariance=list((np.eye(6) * sigma**2).ravel())))


@pytest.mark.parametrize("mount_yaw", [0.0, 0.5 * math.pi])
def test_a_differential_pose_moves_the_filter_by_its_deltas_in_base_link(mount_yaw):
    """Visual odometry whose origin is 10 m and 1 rad away from the filter's (a drifting origin) and whose camera
    is turned by mount_yaw (stated): the filter, its wheels reading nothing, goes 1 m along its own x per message,
    as the deltas say once turned into base_link, and not to the camera's origin."""
    f = pe.PlainEkf(placed_by=False, absolute_yaw=False, gyro=False, world_twist=False)
    sensor = {"q_ext": pe.quat_exp(np.array([0.0, 0.0, mount_yaw])), "t_ext": np.zeros(3), "differential": True,
              "last": None}
    origin_yaw = 1.0
    camera_yaw = origin_yaw + mount_yaw  # the camera's frame: base_link's turned by the mount
    for k in range(5):
        f.predict(float(k))
        along = np.array([math.cos(origin_yaw), math.sin(origin_yaw)]) * k
        pe._fuse_pose(f, _odometry(10.0 + along[0], -3.0 + along[1], camera_yaw), sensor)
    np.testing.assert_allclose(f.x.p, [4.0, 0.0, 0.0], atol=0.05)
    assert abs(pe.quat_rpy(f.x.q)[2]) < 0.01


def test_an_absolute_pose_places_the_base_behind_its_sensor():
    """A marker system reading its marker 0.5 m ahead of the base (stated): the base is put 0.5 m behind it."""
    f = pe.PlainEkf(placed_by=True, absolute_yaw=False, gyro=False, world_twist=False)
    sensor = {"q_ext": np.array([0.0, 0.0, 0.0, 1.0]), "t_ext": np.array([0.5, 0.0, 0.0]), "differential": False,
              "last": None}
    f.predict(0.0)
    for k in range(3):
        f.predict(0.1 * (k + 1))
        pe._fuse_pose(f, _odometry(3.0, 2.0, 0.0, sigma=0.001), sensor)
    np.testing.assert_allclose(f.x.p, [2.5, 2.0, 0.0], atol=0.01)
