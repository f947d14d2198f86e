"""The RTS smoother (fusiond.estimator.smoother) against what it must equal.

- Linear-Gaussian: a constant-velocity model in the additive blocks of the filter's own state (the
  attitude never excited), smoothed through ``ErrorStateEKF`` with the recorder attached, equals the
  information-form least-squares solve of the prior, every transition and every measurement at once
  (means and covariances), whether the anchors are every step or every few (composed maps).
- A rewound filter (a history copy restored, as the core does for late data) records the final
  timeline only.
- On the nonlinear motion model (heading-dependent position, GPS-like position fixes) the smoothed
  errors are consistent with the smoothed covariances over Monte Carlo runs (NEES).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fusiond.estimator import ErrorStateEKF, MotionInput, PoseBlock, SmoothingRecorder, StateBlock, StateLayout, predict


class _Velocity(StateBlock):
    """An additive 3-vector (the test's velocity): its error is plain addition."""

    name = "velocity"
    nominal_size = 3
    error_size = 3

    def initial_sigma(self) -> list[float]:
        return [1.0, 1.0, 1.0]


DT = 0.1
P_ROWS = [0, 1, 2]
V_ROWS = [6, 7, 8]
LIN = P_ROWS + V_ROWS  # the linear part; the attitude (rows 3..5) is never observed nor coupled


def _linear_problem(seed: int, steps: int = 40):
    rng = np.random.default_rng(seed)
    layout = StateLayout([PoseBlock(position_sigma=2.0, attitude_sigma=0.1), _Velocity()])
    n = layout.error_dim
    F = np.eye(n)
    F[np.ix_(P_ROWS, V_ROWS)] = DT * np.eye(3)
    q = np.diag([1e-4] * 3 + [1e-6] * 3 + [4e-3] * 3)
    H = np.zeros((3, n))
    H[:, P_ROWS] = np.eye(3)
    R = np.diag([0.3, 0.5, 0.4]) ** 2
    truth = np.zeros(6)
    truth[3:] = (1.0, -0.5, 0.2)
    zs = []
    for k in range(steps):
        truth = F[np.ix_(LIN, LIN)] @ truth + rng.multivariate_normal(np.zeros(6), q[np.ix_(LIN, LIN)])
        # some steps have no measurement: the smoother must carry through pure predictions
        zs.append(truth[:3] + rng.multivariate_normal(np.zeros(3), R) if k % 4 != 2 else None)
    return layout, F, q, H, R, zs


def _filter_and_smooth(layout, F, q, H, R, zs, every: int):
    rec = SmoothingRecorder(layout, covariance=True)
    ekf = ErrorStateEKF(layout)
    ekf.record(rec.open())
    ekf.anchor(0.0)
    stamps = [0.0]
    for k, z in enumerate(zs):
        x_new = ekf.x.copy()
        x_new[0:3] += DT * ekf.x[7:10]  # nominal: p += v dt (v at nominal indices 7..9)
        ekf.propagate(x_new, F, q)
        if z is not None:
            res = ekf.update(z - ekf.x[0:3], H, R)
            assert not res.rejected
        if (k + 1) % every == 0 or k == len(zs) - 1:
            ekf.anchor((k + 1) * DT)
            stamps.append((k + 1) * DT)
    return rec, ekf, stamps


def _batch(layout, F, q, H, R, zs):
    """The information-form solve over the linear states of all steps (prior, dynamics, fixes)."""
    m = 6
    K = len(zs) + 1
    Fl, Ql = F[np.ix_(LIN, LIN)], q[np.ix_(LIN, LIN)]
    Hl = H[:, LIN]
    P0 = layout.initial_covariance()[np.ix_(LIN, LIN)]
    Lam = np.zeros((K * m, K * m))
    eta = np.zeros(K * m)
    Lam[:m, :m] += np.linalg.inv(P0)  # prior mean 0 (the filter's initial state)
    Qi = np.linalg.inv(Ql)
    Ri = np.linalg.inv(R)
    for k in range(K - 1):
        a, b = slice(k * m, (k + 1) * m), slice((k + 1) * m, (k + 2) * m)
        # (x_{k+1} - F x_k)^T Q^-1 (...)
        Lam[a, a] += Fl.T @ Qi @ Fl
        Lam[a, b] -= Fl.T @ Qi
        Lam[b, a] -= Qi @ Fl
        Lam[b, b] += Qi
        z = zs[k]
        if z is not None:
            Lam[b, b] += Hl.T @ Ri @ Hl
            eta[b] += Hl.T @ Ri @ z
    cov = np.linalg.inv(Lam)
    mean = cov @ eta
    return mean.reshape(K, m), cov


@pytest.mark.parametrize("every", [1, 3])
def test_linear_gaussian_smoother_equals_batch_least_squares(every):
    layout, F, q, H, R, zs = _linear_problem(seed=7)
    rec, ekf, stamps = _filter_and_smooth(layout, F, q, H, R, zs, every)
    sm = rec.smooth()
    mean, cov = _batch(layout, F, q, H, R, zs)
    assert sm.t.tolist() == stamps
    nominal_lin = [0, 1, 2, 7, 8, 9]
    for i, t in enumerate(stamps):
        k = int(round(t / DT))
        np.testing.assert_allclose(sm.x[i, nominal_lin], mean[k], rtol=0, atol=1e-9)
        block = cov[k * 6:(k + 1) * 6, k * 6:(k + 1) * 6]
        np.testing.assert_allclose(sm.P[i][np.ix_(LIN, LIN)], block, rtol=0, atol=1e-9)
    # the attitude was never observed nor coupled: it stays exactly the identity
    assert np.array_equal(sm.x[:, 3:7], np.tile([0.0, 0.0, 0.0, 1.0], (len(stamps), 1)))
    # at the last stamp the smoothed estimate is the filtered one
    assert np.array_equal(sm.x[-1], ekf.x)
    assert np.array_equal(sm.P[-1], ekf.P)
    # and the smoother did move the earlier ones
    assert np.abs(sm.x[:-1, 0:3] - sm.filtered[:-1, 0:3]).max() > 1e-3


def test_a_rewound_filter_records_its_final_timeline_only():
    """The core's late-data rewind: a copy taken at some step is restored and the later steps run
    again (here with other fixes); the anchors equal a straight run on the final data."""
    layout, F, q, H, R, zs = _linear_problem(seed=11, steps=20)
    rec = SmoothingRecorder(layout, covariance=True)
    ekf = ErrorStateEKF(layout)
    ekf.record(rec.open())
    ekf.anchor(0.0)
    saved = None
    other = [None if z is None else z + 1.0 for z in zs]
    for k, z in enumerate(other):  # the first timeline, with wrong fixes after step 9
        if k == 10:
            saved = ekf.copy()
        x_new = ekf.x.copy()
        x_new[0:3] += DT * ekf.x[7:10]
        ekf.propagate(x_new, F, q)
        if z is not None:
            ekf.update((zs[k] if k < 10 else z) - ekf.x[0:3], H, R)
        ekf.anchor((k + 1) * DT)
    ekf = saved
    for k in range(10, len(zs)):  # the rewind: from the copy, the final data
        x_new = ekf.x.copy()
        x_new[0:3] += DT * ekf.x[7:10]
        ekf.propagate(x_new, F, q)
        if zs[k] is not None:
            ekf.update(zs[k] - ekf.x[0:3], H, R)
        ekf.anchor((k + 1) * DT)
    straight, _, _ = _filter_and_smooth(layout, F, q, H, R, zs, 1)
    a, b = rec.smooth(), straight.smooth()
    assert a.t.tolist() == b.t.tolist()
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.P, b.P, rtol=0, atol=1e-12)


def test_a_cut_ends_the_segment_there():
    layout, F, q, H, R, zs = _linear_problem(seed=3, steps=12)
    rec = SmoothingRecorder(layout)
    ekf = ErrorStateEKF(layout)
    ekf.record(rec.open())
    for k, z in enumerate(zs):
        x_new = ekf.x.copy()
        x_new[0:3] += DT * ekf.x[7:10]
        ekf.propagate(x_new, F, q)
        if z is not None:
            ekf.update(z - ekf.x[0:3], H, R)
        if k == 5:
            ekf.reset_variance(8, 1.0)  # P changed in a way no transition describes
        ekf.anchor((k + 1) * DT)
    sm = rec.smooth()
    # the cut came before the sixth anchor: it starts a segment, the fifth ends one
    assert [a.link is None for a in rec.anchors] == [True] + [False] * 4 + [True] + [False] * 6
    assert np.array_equal(sm.x[4], sm.filtered[4])
    assert not np.array_equal(sm.x[3], sm.filtered[3])


def _nonlinear_run(rng, steps: int = 120):
    """A planar unicycle through the filter's own motion model (body twist, yaw rate), its truth
    disturbed by the very Q the model states, with position fixes every 5th step."""
    layout = StateLayout([PoseBlock(position_sigma=0.5, attitude_sigma=0.05)])
    density = layout.noise_density(np.array([0.02 ** 2] * 3 + [0.01 ** 2] * 3))
    u = MotionInput()
    u.linear, u.angular = (1.5, 0.0, 0.0), (0.0, 0.0, 0.25)
    u.linear_period = u.angular_period = DT
    H = np.zeros((3, 6))
    H[:, 0:3] = np.eye(3)
    R = np.diag([0.4, 0.4, 0.4]) ** 2
    ekf = ErrorStateEKF(layout)
    truth = layout.initial_state()
    truth = _perturb(layout, truth, layout.initial_covariance(), rng)
    rec = SmoothingRecorder(layout, covariance=True)
    ekf.record(rec.open())
    ekf.anchor(0.0)
    truths = [truth.copy()]
    for k in range(steps):
        xt, _, Qt = predict(layout, truth, u, DT, density)
        truth = _perturb(layout, xt.copy(), Qt.copy(), rng)
        x, F, Q = predict(layout, ekf.x, u, DT, density)
        ekf.propagate(x.copy(), F.copy(), Q.copy())
        if k % 5 == 4:
            z = truth[0:3] + rng.multivariate_normal(np.zeros(3), R)
            ekf.update(z - ekf.x[0:3], H, R)
        ekf.anchor((k + 1) * DT)
        truths.append(truth.copy())
    return layout, rec.smooth(), rec, truths


def _perturb(layout, x, P, rng):
    dx = rng.multivariate_normal(np.zeros(P.shape[0]), 0.5 * (P + P.T))
    layout.boxplus(x, dx)
    return x


def test_nonlinear_smoother_is_consistent_over_monte_carlo_runs():
    rng = np.random.default_rng(2024)
    runs, dof = 40, 6
    nees_s, nees_f, err_s, err_f = [], [], [], []
    for _ in range(runs):
        layout, sm, rec, truths = _nonlinear_run(rng)
        rows_s, rows_f = [], []
        for i, truth in enumerate(truths):
            es = layout.boxminus(truth, sm.x[i])
            ef = layout.boxminus(truth, rec.anchors[i].x)
            rows_s.append(es @ np.linalg.solve(sm.P[i], es))
            rows_f.append(ef @ np.linalg.solve(rec.anchors[i].P, ef))
            err_s.append(es[0] ** 2 + es[1] ** 2)
            err_f.append(ef[0] ** 2 + ef[1] ** 2)
        nees_s.append(rows_s)
        nees_f.append(rows_f)
    # the mean NEES over the runs at each stamp is chi2(runs * dof) / runs for a consistent estimator
    lo, hi = chi2.ppf([0.005, 0.995], runs * dof) / runs
    mean_s = np.mean(nees_s, axis=0)
    inside = np.mean((mean_s > lo) & (mean_s < hi))
    assert inside > 0.9, (inside, lo, hi, mean_s.min(), mean_s.max())
    assert abs(np.mean(mean_s) / dof - 1.0) < 0.1
    # the filter's own NEES on the same runs passes the same test (the check can tell them apart:
    # the smoothed errors are smaller, and judged against smaller covariances)
    assert np.mean((np.mean(nees_f, axis=0) > lo) & (np.mean(nees_f, axis=0) < hi)) > 0.9
    assert np.sqrt(np.mean(err_s)) < 0.8 * np.sqrt(np.mean(err_f))


@pytest.mark.parametrize("held", [False, True])
def test_transitions_in_a_row_fold_into_the_per_step_gains(held):
    """The recorder folds a run of transitions into one gain (smoother module doc): the product of the per-
    step RTS gains, also where a component is held at zero variance through the run."""
    from fusiond.estimator.rts import rts_gain

    rng = np.random.default_rng(3)
    layout = StateLayout([PoseBlock(position_sigma=2.0, attitude_sigma=0.1), _Velocity()])
    n = layout.error_dim
    M = rng.normal(size=(n, n))
    P = M @ M.T + np.eye(n)
    if held:
        P[2, :] = P[:, 2] = 0.0
    rec = SmoothingRecorder(layout)
    seg = rec.open()
    seg.anchor(0.0, layout.initial_state(), P)
    want = np.eye(n)
    for _ in range(4):
        F = np.eye(n) + 0.1 * rng.normal(size=(n, n))
        G = rng.normal(size=(n, n))
        Q = 0.01 * G @ G.T
        if held:
            F[2, :] = 0.0
            F[2, 2] = 1.0
            Q[2, :] = Q[:, 2] = 0.0
        P_next = F @ P @ F.T + Q
        want = want @ rts_gain(P, F, P_next)
        seg.transition(P, F, P_next)
        P = P_next
    seg.anchor(1.0, layout.initial_state(), P)
    A = rec.anchors[1].link[0]
    np.testing.assert_allclose(A, want, rtol=0, atol=1e-9 * np.abs(want).max())
    if held:
        assert not A[:, 2].any()


def test_compiled_fold_equals_the_python_reference():
    """The compiled backend's fold (``_kernels.rts_fold``, C) against the reference's ``A rts_gain(...)`` (numpy):
    random covariances, with and without held components; a P_after that is not positive definite is
    left to the reference's least squares."""
    from fusiond.estimator import backend
    from fusiond.estimator.rts import rts_gain

    if backend.COMPILED is None:
        pytest.skip("fusiond.estimator._kernels was not built (no C compiler at install time)")
    compiled, python = backend.COMPILED, backend.PYTHON
    fold = compiled._k.rts_fold
    rng = np.random.default_rng(11)
    for n in (3, 9, 13, 16):
        for held in ((), (2,), (1, 4)):
            M = rng.normal(size=(n, n))
            P0 = M @ M.T + 0.1 * np.eye(n)
            F = np.eye(n) + 0.2 * rng.normal(size=(n, n))
            G = rng.normal(size=(n, n))
            P1 = F @ P0 @ F.T + 0.01 * G @ G.T
            for h in held:
                if h < n:
                    P1[h, :] = P1[:, h] = 0.0
            A = rng.normal(size=(n, n))
            out = np.empty((n, n))
            assert fold(A, P0, F, P1, out)
            want = python.rts_fold(A, P0, F, P1)
            np.testing.assert_allclose(out, want, rtol=0, atol=1e-10 * np.abs(want).max())
            assert np.array_equal(compiled.rts_fold(A, P0, F, P1), out)
    # an indefinite P_after (its diagonal positive): nothing from C, the reference's least squares instead
    P1 = np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 2.0]])
    out = np.full((3, 3), 7.0)
    assert not fold(np.eye(3), np.eye(3), np.eye(3), P1, out)
    assert (out == 7.0).all()
    np.testing.assert_allclose(compiled.rts_fold(np.eye(3), np.eye(3), np.eye(3), P1),
                               rts_gain(np.eye(3), np.eye(3), P1))
    with pytest.raises(ValueError):
        fold(np.eye(3), np.eye(2), np.eye(3), np.eye(3), out)


@pytest.mark.parametrize("name", ["numpy", "compiled"])
def test_the_recorder_folds_with_its_filters_backend(name):
    """A filter records with its own backend: its segment, and the copies the history takes of it, fold
    with the backend the filter was built with."""
    from fusiond.estimator import backend

    if name == "compiled" and backend.COMPILED is None:
        pytest.skip("the compiled backend was not built")
    layout, F, q, H, R, zs = _linear_problem(seed=5)
    rec = SmoothingRecorder(layout, covariance=True)
    ekf = ErrorStateEKF(layout, backend=backend.choose(name))
    seg = rec.open()
    ekf.record(seg)
    assert seg.backend is ekf.backend and seg.copy().backend is ekf.backend
