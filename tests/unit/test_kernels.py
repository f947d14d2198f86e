"""The compiled backend (estimator/_kernels.c) computes what the Python reference computes.

Each test runs the same EKF step twice, once on a filter built with the compiled backend and once
with the reference (``ErrorStateEKF(..., backend=...)``, estimator/backend.py), and compares. The
tolerances are rounding, not modelling: the two differ only in the order of the products' sums
(OpenBLAS against plain loops), a few ulps of values of order one, so 1e-12 relative holds with
margin; a wrong index or a missed mask weight moves a result by its own size. On the Jackal bag the
two trajectories must agree to the pin's 1e-9 m / 1e-9 rad.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusiond.errors import EstimatorError
from fusiond.estimator import (ErrorStateEKF, GpsErrorBlock, GyroBiasBlock, GyroScaleBlock, MotionInput, PoseBlock,
                               PredictWorkspace, StateBlock, StateLayout, WheelScaleBlock)
from fusiond.estimator import motion as motion_module
from fusiond.estimator import observations
from fusiond.estimator.twist_pitch import TwistPitchBlock
from fusiond.estimator import backend as backend_module
from fusiond.estimator.backend import COMPILED, PYTHON, choose, from_environment

pytestmark = pytest.mark.skipif(COMPILED is None,
                                reason="fusiond.estimator._kernels not built (no C compiler at install)")
k = backend_module._kernels  # the compiled module itself, for its own checks

RTOL = 1e-12
BOTH = (COMPILED, PYTHON)


class _LoggedOffset(StateBlock):
    """A non-additive block (its boxplus is not plain addition): the kernel hands dx back to Python."""

    name = "logged_offset"
    nominal_size = error_size = 1
    additive = False

    def initial_sigma(self) -> list[float]:
        return [0.3]

    def boxplus(self, x, dx, n0, e0) -> None:
        x[n0] += 0.5 * dx[e0]


LAYOUTS = {
    "pose": StateLayout([PoseBlock(0.1, 0.1)]),
    "bias_scale": StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), WheelScaleBlock(0.05, 1e-4)]),
    "non_additive": StateLayout([PoseBlock(0.1, 0.1), _LoggedOffset()]),
}


def _random_filter(layout: StateLayout, rng: np.random.Generator, backend=PYTHON) -> ErrorStateEKF:
    n = layout.error_dim
    A = rng.normal(size=(n, n)) * rng.uniform(0.01, 1.0)
    x = layout.initial_state()
    q = rng.normal(size=4)
    x[3:7] = q / np.linalg.norm(q)
    x[0:3] = rng.normal(size=3) * 10.0
    return ErrorStateEKF(layout, x, A @ A.T + np.eye(n) * 1e-4, backend=backend)


def _both(layout: StateLayout, seed: int, step) -> tuple:
    """(result, x, P, resets) of ``step(ekf)`` on the same random filter, compiled then the reference."""
    out = []
    for b in BOTH:
        ekf = _random_filter(layout, np.random.default_rng(seed), b)
        res = step(ekf)
        out.append((res, ekf.x.copy(), ekf.P.copy(), ekf.resets))
    return out[0], out[1]


def _close(a: np.ndarray, b: np.ndarray) -> None:
    scale = max(float(np.max(np.abs(b))), 1.0)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=RTOL * scale)


@settings(max_examples=80, deadline=None)
@given(layout=st.sampled_from(sorted(LAYOUTS)), seed=st.integers(0, 100_000), m=st.integers(1, 6),
       masked=st.booleans(), hold=st.booleans(), gate=st.sampled_from([math.inf, 3.0, 0.5]))
def test_update_matches_the_numpy_path(layout, seed, m, masked, hold, gate):
    lay = LAYOUTS[layout]
    n = lay.error_dim
    rng = np.random.default_rng(seed + 1)
    H = np.zeros((m, n))
    for r in range(m):  # a few columns per row, as the measurement models make
        cols = rng.choice(n, size=min(n, 3), replace=False)
        H[r, cols] = rng.normal(size=cols.size)
    B = rng.normal(size=(m, m)) * 0.1
    R = B @ B.T + np.eye(m) * 1e-3
    y = rng.normal(size=m) * 0.5
    mask = rng.random(n) < 0.6 if masked else None

    def step(ekf):
        return ekf.update(y, H, R, gate, mask=mask, hold_heading=hold and lay is not LAYOUTS["non_additive"])

    (rc, xc, Pc, _), (rn, xn, Pn, _) = _both(lay, seed, step)
    assert (rc.rejected, rc.singular, rc.covariance_reset) == (rn.rejected, rn.singular, rn.covariance_reset)
    assert rc.nis == pytest.approx(rn.nis, rel=1e-11)
    np.testing.assert_allclose(rc.innovation_var, rn.innovation_var, rtol=1e-11)
    _close(Pc, Pn)
    _close(xc, xn)
    assert abs(np.linalg.norm(xc[3:7]) - 1.0) < 1e-12


@settings(max_examples=60, deadline=None)
@given(layout=st.sampled_from(sorted(LAYOUTS)), seed=st.integers(0, 100_000))
def test_propagate_matches_the_numpy_path(layout, seed):
    lay = LAYOUTS[layout]
    n = lay.error_dim
    rng = np.random.default_rng(seed + 2)
    F = np.eye(n)
    F[rng.random((n, n)) < 0.2] = rng.normal()  # identity plus a few blocks, as the motion model's
    Qh = rng.normal(size=(n, n)) * 0.01
    Q = Qh @ Qh.T
    x_new = lay.initial_state()
    (ok_c, _, Pc, _), (ok_n, _, Pn, _) = _both(lay, seed, lambda ekf: ekf.propagate(x_new.copy(), F, Q))
    assert ok_c is ok_n is True
    _close(Pc, Pn)


class _SlowGpsError(GpsErrorBlock):
    """A subclass that changes the decay without naming a kernel_decay of its own: Python decays it."""

    def transition(self, dt):
        a = math.exp(-0.5 * dt / self.tau)
        return [a, a, a]


class _HalfWheelScale(WheelScaleBlock):
    """A subclass that changes the maths without naming a kernel code of its own: Python predicts it."""

    def correct(self, xb, u):
        return (0.5 * xb[0] * u[0], 0.5 * xb[0] * u[1], 0.5 * xb[0] * u[2])

    def input_derivative(self, xb, u):
        s = 0.5 * xb[0]
        return (s, 0.0, 0.0, 0.0, s, 0.0, 0.0, 0.0, s)

    def chain(self, G, xb, u):
        return tuple(0.5 * c for c in super().chain(G, xb, u))


PREDICT_LAYOUTS = {
    "pose": StateLayout([PoseBlock(0.1, 0.1)]),
    "inputs": StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), GyroScaleBlock(0.05, 1e-5),
                           WheelScaleBlock(0.05, 1e-4)]),
    "gps_error": StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), GpsErrorBlock(30.0, (2.0, 2.0, 5.0))]),
    # every compiled kind, the twist corrected twice (scale then pitch: the chain through both), a dynamic block
    "all_kinds": StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), WheelScaleBlock(0.05, 1e-4),
                              GyroScaleBlock(0.05, 1e-5), TwistPitchBlock(0.05, 1e-5),
                              GpsErrorBlock(30.0, (2.0, 2.0, 5.0))]),
    "python_block": StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), _HalfWheelScale(0.05, 1e-4)]),
    # a Gauss-Markov block whose own class names no kernel_decay: compiled inputs, its decay in Python
    "python_decay": StateLayout([PoseBlock(0.1, 0.1), GyroBiasBlock(0.01, 1e-4), _SlowGpsError(30.0, (2.0, 2.0, 5.0))]),
}
COMPILED_PREDICT = {"pose", "inputs", "gps_error", "all_kinds", "python_decay"}
COMPILED_DECAY = {"gps_error", "all_kinds"}
finite = st.floats(-3.0, 3.0)
cov9 = st.one_of(  # a diagonal covariance (the usual), a full one, or the tuple of a silent input
    st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(0.0, 1.0)).map(
        lambda d: (d[0], 0.0, 0.0, 0.0, d[1], 0.0, 0.0, 0.0, d[2])),
    st.lists(st.floats(-0.1, 1.0), min_size=9, max_size=9).map(tuple))


@settings(max_examples=150, deadline=None)
@given(layout=st.sampled_from(sorted(PREDICT_LAYOUTS)), seed=st.integers(0, 10_000),
       v=st.tuples(finite, finite, finite), w=st.tuples(finite, finite, finite), lin_cov=cov9, ang_cov=cov9,
       periods=st.tuples(st.sampled_from([0.0, 0.01, 0.2]), st.sampled_from([0.0, 0.005, 0.1])),
       flags=st.tuples(st.booleans(), st.booleans(), st.booleans()), tau=st.sampled_from([0.0, 0.05]),
       dt=st.sampled_from([0.0, 0.001, 0.02, 0.7]))
def test_compiled_predict_gives_the_python_paths_floats(layout, seed, v, w, lin_cov, ang_cov, periods, flags, tau,
                                                        dt):
    """The motion model's x', F and Q from the compiled backend are the reference's, to the bit: the input
    blocks' corrections and chain, the rotation, the right Jacobian and the input noise are the same
    expressions in C, compiled without FMA contraction. A layout with a block that has no compiled
    form predicts in Python on both backends."""
    lay = PREDICT_LAYOUTS[layout]
    u = MotionInput()
    u.linear, u.angular, u.linear_cov, u.angular_cov = v, w, lin_cov, ang_cov
    u.linear_period, u.angular_period = periods
    u.from_gyro, u.world_frame, u.planar = flags
    u.twist_correlation = tau
    rng = np.random.default_rng(seed)
    ekf = _random_filter(lay, rng)
    # the blocks away from their priors: a bias, scales off 1, a pitch, a GPS error
    ekf.x[7:] += rng.uniform(-0.3, 0.3, lay.nominal_dim - 7)
    density = rng.uniform(0.0, 1e-3, lay.error_dim)
    out = []
    for b in BOTH:
        ws = PredictWorkspace(lay)
        assert (ws._kernel_blocks is not None) is (layout in COMPILED_PREDICT)
        assert (ws._kernel_decays is not None) is (layout in COMPILED_DECAY)
        b.predict(lay, ekf.x, u, 0.3, density * 2.0, ws)  # an earlier step: nothing of it may stay in F or Q
        x, F, Q = b.predict(lay, ekf.x, u, dt, density, ws)
        out.append((x.copy(), F.copy(), Q.copy()))
    (xc, Fc, Qc), (xn, Fn, Qn) = out
    np.testing.assert_array_equal(xc, xn)
    np.testing.assert_array_equal(Fc, Fn)
    np.testing.assert_array_equal(Qc, Qn)


def test_a_non_finite_propagation_resets_alike():
    lay = LAYOUTS["bias_scale"]
    F = np.eye(lay.error_dim)
    F[0, 4] = math.nan
    Q = np.zeros_like(F)
    (ok_c, _, Pc, rc), (ok_n, _, Pn, rn) = _both(lay, 7, lambda ekf: ekf.propagate(lay.initial_state(), F, Q))
    assert ok_c is ok_n is False
    assert rc == rn == 1
    np.testing.assert_array_equal(Pc, lay.initial_covariance())
    np.testing.assert_array_equal(Pn, lay.initial_covariance())


def test_a_negative_variance_takes_the_reference_checks():
    """P with a negative variance (not PSD) and an update that keeps S positive: the kernel reports
    the diagonal and the reference path's clipping (an eigendecomposition) makes the same P."""
    lay = LAYOUTS["pose"]
    n = lay.error_dim

    def step(ekf):
        ekf.P = np.eye(n) * 0.5
        ekf.P[0, 0] = -0.2
        H = np.zeros((1, n))
        H[0, 0] = 1.0
        return ekf.update(np.array([0.1]), H, np.array([[1.0]]))

    (rc, xc, Pc, _), (rn, xn, Pn, _) = _both(lay, 3, step)
    assert not rc.rejected and not rn.rejected
    assert np.diagonal(Pc).min() >= 0.0
    _close(Pc, Pn)
    _close(xc, xn)


def test_a_singular_innovation_covariance_is_refused_alike():
    lay = LAYOUTS["pose"]
    H = np.zeros((2, lay.error_dim))  # observes nothing, with no noise: S = 0

    def step(ekf):
        return ekf.update(np.array([0.1, 0.2]), H, np.zeros((2, 2)))

    (rc, xc, Pc, _), (rn, xn, Pn, _) = _both(lay, 4, step)
    assert rc.singular and rn.singular and rc.rejected and rn.rejected
    assert math.isnan(rc.nis) and math.isnan(rn.nis)
    np.testing.assert_array_equal(xc, xn)
    np.testing.assert_array_equal(Pc, Pn)


def test_arrays_the_kernel_cannot_read_take_the_numpy_path():
    """An int or Fortran-ordered array is not refused: the update falls back to numpy and agrees."""
    lay = LAYOUTS["pose"]
    n = lay.error_dim
    H = np.zeros((3, n))
    H[0, 0] = H[1, 1] = H[2, 5] = 1.0

    def step(ekf):
        ekf.P = np.asfortranarray(ekf.P)
        return ekf.update(np.array([1, 2, 0]), np.asfortranarray(H), np.eye(3, dtype=int))

    (rc, xc, Pc, _), (rn, xn, Pn, _) = _both(lay, 5, step)
    assert rc.nis == rn.nis
    np.testing.assert_array_equal(xc, xn)
    np.testing.assert_array_equal(Pc, Pn)


def test_kernel_refuses_wrong_shapes_with_a_clear_error():
    P = np.eye(4)
    with pytest.raises(ValueError, match="F has 9 values, expected 16"):
        k.propagate(np.eye(3), P, np.zeros((4, 4)), np.empty((4, 4)))
    with pytest.raises(BufferError, match="C-contiguous float64"):
        k.propagate(np.eye(4, dtype=np.float32), P, np.zeros((4, 4)), np.empty((4, 4)))
    with pytest.raises(ValueError, match="square with 1 to 48 rows"):
        k.propagate(np.eye(49), np.eye(49), np.eye(49), np.empty((49, 49)))
    y, H, R, out, x = np.zeros(2), np.zeros((2, 4)), np.eye(2), np.empty((4, 4)), np.zeros(5)
    with pytest.raises(ValueError, match="H has 6 values, expected 8"):
        k.update(P, np.zeros((2, 3)), R, y, 1.0, None, None, out, x, 1)
    with pytest.raises(ValueError, match="y must have 1 to 12 rows"):
        k.update(P, H, R, np.zeros(0), 1.0, None, None, out, x, 1)
    with pytest.raises(ValueError, match="x has 5 values, expected 4"):
        k.update(P, H, R, y, 1.0, None, None, out, x, 0)  # mode 0 writes dx: n values
    frozen = np.empty((4, 4))
    frozen.flags.writeable = False
    with pytest.raises(BufferError, match="out must be a C-contiguous writable"):
        k.update(P, H, R, y, 1.0, None, None, frozen, x, 1)


def test_a_zero_quaternion_is_an_estimator_error_and_leaves_x():
    lay = LAYOUTS["pose"]
    for b in BOTH:
        ekf = ErrorStateEKF(lay, backend=b)
        ekf.x[3:7] = 0.0
        before = ekf.x.copy()
        H = np.zeros((1, lay.error_dim))
        H[0, 3] = 1.0
        with pytest.raises(EstimatorError, match="quaternion"):
            ekf.update(np.array([0.1]), H, np.array([[0.01]]))
        np.testing.assert_array_equal(ekf.x, before)


def test_layouts_beyond_the_kernel_size_run_the_reference():
    """The kernels have fixed-size scratch: a layout with more error states than MAX_N runs the reference."""

    class Wide(StateBlock):
        name = "wide"
        nominal_size = error_size = 50

    ekf = ErrorStateEKF(StateLayout([PoseBlock(0.1, 0.1), Wide()]), backend=COMPILED)
    assert ekf.backend is PYTHON
    F, Q = np.eye(56), np.eye(56) * 1e-3
    assert ekf.propagate(ekf.x.copy(), F, Q)
    np.testing.assert_allclose(np.diagonal(ekf.P)[:6], 0.01 + 1e-3)


def test_compiled_predict_refuses_a_zero_quaternion_as_python_does():
    lay = PREDICT_LAYOUTS["inputs"]
    u = MotionInput()
    u.angular, u.from_gyro = (0.1, 0.2, 0.3), True
    x = lay.initial_state()
    x[3:7] = 0.0
    for b in BOTH:
        with pytest.raises(EstimatorError, match="quaternion"):
            b.predict(lay, x, u, 0.01, np.zeros(lay.error_dim), PredictWorkspace(lay))


def test_compiled_predict_refuses_blocks_outside_the_state():
    x, n = np.zeros(10), 9
    args = (x, np.empty(10), np.eye(n), np.zeros((n, n)), np.zeros(n), 0.01, None, (0.0,) * 3, (0.0,) * 3,
            (0.0,) * 9, (0.0,) * 9, 0.0, 0.0, 0.0, 0)
    with pytest.raises(ValueError, match="outside the state, or of an unknown kind"):
        k.predict(*args, ((1, 1, 0, 8, 6, 3),))  # a 3-vector bias from nominal 8 runs past x
    with pytest.raises(ValueError, match="outside the state, or of an unknown kind"):
        k.predict(*args, ((9, 1, 0, 7, 6, 3),))
    with pytest.raises(BufferError):
        k.predict(x.astype(np.float32), *args[1:], ())


def test_compiled_predict_refuses_decays_outside_the_state():
    x, n = np.zeros(10), 9
    args = (x, np.empty(10), np.eye(n), np.zeros((n, n)), np.zeros(n), 0.01, None, (0.0,) * 3, (0.0,) * 3,
            (0.0,) * 9, (0.0,) * 9, 0.0, 0.0, 0.0, 0, ())
    with pytest.raises(ValueError, match="a decaying block outside the state"):
        k.predict(*args, ((8, 6, 30.0, (1.0, 1.0, 1.0)),))  # three errors from nominal 8 run past x
    with pytest.raises(ValueError, match="a decaying block outside the state"):
        k.predict(*args, ((7, 3, 30.0, (1.0, 1.0, 1.0)),))  # into the pose's errors
    with pytest.raises(TypeError):
        k.predict(*args, ((7, 6, 30.0, [1.0, 1.0, 1.0]),))


def test_the_constants_mirror_the_c_module():
    assert motion_module._KERNEL_MAX_N == k.MAX_N
    codes = {GyroBiasBlock: k.BLOCK_GYRO_BIAS, WheelScaleBlock: k.BLOCK_WHEEL_SCALE,
             GyroScaleBlock: k.BLOCK_GYRO_SCALE, TwistPitchBlock: k.BLOCK_TWIST_PITCH}
    assert {cls: cls.__dict__["kernel_code"] for cls in codes} == codes
    assert (backend_module.MAX_N, backend_module.MAX_M) == (k.MAX_N, k.MAX_M)
    assert ((backend_module.APPLIED, backend_module.GATED, backend_module.SINGULAR, backend_module.NEEDS_CHECK)
            == (k.APPLIED, k.GATED, k.SINGULAR, k.NEEDS_CHECK))


def test_choose_names_the_choices():
    assert choose("numpy") is PYTHON and choose("auto") is COMPILED and choose("compiled") is COMPILED
    assert ErrorStateEKF(LAYOUTS["pose"]).backend is COMPILED  # the default where it was built
    with pytest.raises(EstimatorError, match="auto, compiled, numpy"):
        choose("fast")


def test_the_environment_selects_the_backend():
    assert from_environment({"FUSIOND_KERNELS": "numpy"}) is PYTHON
    assert from_environment({}) is COMPILED
    with pytest.raises(EstimatorError, match="FUSIOND_KERNELS=fast: the backend must be one of"):
        from_environment({"FUSIOND_KERNELS": "fast"})


@pytest.mark.e2e
def test_fusiond_replay_gives_the_same_tum_on_both_paths(jackal_bag, tmp_path):
    """The command line's FUSIOND_KERNELS: the numpy path and the compiled one write the same TUM
    (9 decimals), and an unknown name is refused before anything runs."""
    import os
    import subprocess
    import sys

    out = {}
    for name in ("numpy", "compiled", "bogus"):
        tum = tmp_path / f"{name}.tum"
        proc = subprocess.run([sys.executable, "-m", "fusiond", "replay", str(jackal_bag), "--config",
                               "examples/jackal.toml", "--tum", str(tum), "--quiet"],
                              env={**os.environ, "FUSIOND_KERNELS": name}, capture_output=True, text=True,
                              timeout=120, cwd=Path(__file__).resolve().parents[2])
        out[name] = (proc.returncode, tum.read_text() if tum.exists() else "", proc.stderr)
    assert out["numpy"][0] == out["compiled"][0] == 0
    assert out["numpy"][1] == out["compiled"][1] and out["numpy"][1].count("\n") > 3000
    assert out["bogus"][0] == 2 and "FUSIOND_KERNELS=bogus" in out["bogus"][2] and not out["bogus"][1]


@pytest.mark.e2e
def test_fusiond_kernels_reaches_every_core_the_replay_builds(jackal_bag, tmp_path, monkeypatch, capsys):
    """FUSIOND_KERNELS=numpy: the replay and the doctor's advice proofs (jackal_rl.toml has a paste line)
    never ask the compiled backend; without it they do (what shows the check can see them)."""
    from fusiond.cli import main
    from fusiond.estimator.backend import CompiledBackend, PythonBackend

    asked: list[str] = []
    for name in ("predict", "propagate", "update", "orientation", "copy_into"):
        def counted(self, *args, _name=name):
            asked.append(_name)
            return getattr(PythonBackend, _name)(self, *args)
        monkeypatch.setattr(CompiledBackend, name, counted)
    config = str(Path(__file__).resolve().parents[2] / "examples" / "jackal_rl.toml")
    argv = ["replay", str(jackal_bag), "--config", config, "--tum", str(tmp_path / "a.tum")]
    monkeypatch.setenv("FUSIOND_KERNELS", "numpy")
    assert main(argv) == 0
    assert "(replayed: likelihood" in capsys.readouterr().out and asked == []  # the advice was proven
    monkeypatch.delenv("FUSIOND_KERNELS")
    assert main(argv) == 0
    assert {"predict", "propagate", "update", "orientation", "copy_into"} <= set(asked)


@pytest.mark.e2e
@pytest.mark.parametrize("config", ["examples/jackal_rl.toml", "examples/jackal.toml"])
def test_jackal_trajectory_is_the_same_on_both_paths(jackal_bag, config):
    from tests.support.jackal_pin import trajectory

    ref = trajectory(jackal_bag, config, PYTHON)
    now = trajectory(jackal_bag, config, COMPILED)
    assert now["counters"] == ref["counters"]
    assert now["published"] == ref["published"]
    worst = max(abs(a - b) for pa, pb in zip(now["poses"], ref["poses"]) for a, b in zip(pa, pb))
    assert worst <= 1e-9


unit = st.floats(-1.0, 1.0)


@settings(max_examples=300, deadline=None)
@given(q=st.one_of(st.tuples(unit, unit, unit, unit),
                   # near pitch +-90 degrees, where cos(pitch) and the yaw row's denominator meet their floors
                   st.tuples(st.floats(-1e-3, 1e-3), st.sampled_from([0.7071067811865476, -0.7071067811865476]),
                             st.floats(-1e-3, 1e-3), st.sampled_from([0.7071067811865476, 0.7071067811865475]))),
       z=st.tuples(st.floats(-4.0, 4.0), st.floats(-4.0, 4.0), st.floats(-4.0, 4.0)),
       rows=st.sampled_from([(0, 1), (0, 1, 2), (2,), (1,), (2, 0)]),
       layout=st.sampled_from(["pose", "bias_scale"]))
def test_compiled_orientation_gives_the_python_paths_floats(q, z, rows, layout):
    """observations.orientation's y and H from the compiled backend are the reference's to the bit
    (rpy_jacobian and rot.wrap as the same expressions in C); R is the same shared array."""
    lay = LAYOUTS[layout]
    norm = math.sqrt(sum(c * c for c in q))
    if norm < 1e-6:
        q = (0.0, 0.0, 0.0, 1.0)
    x = lay.initial_state()
    x[3:7] = q if norm < 1e-6 else tuple(c / norm for c in q)
    cov = (0.01, 0.0, 0.0, 0.0, 0.02, 0.0, 0.0, 0.0, 0.03)
    out = []
    for b in BOTH:
        out.append(observations.orientation(lay, x, z, cov, rows, b))
    (yc, Hc, Rc), (yn, Hn, Rn) = out
    np.testing.assert_array_equal(yc, yn)
    np.testing.assert_array_equal(Hc, Hn)
    assert Rc is Rn


def test_compiled_orientation_refuses_bad_rows_and_shapes():
    x = np.zeros(7)
    x[6] = 1.0
    with pytest.raises(ValueError, match="rows must be among 0, 1, 2"):
        k.orientation(x, (0.0,) * 3, (0, 3), np.empty(2), np.empty((2, 6)))
    with pytest.raises(ValueError, match="rows must have 1 to 3 entries"):
        k.orientation(x, (0.0,) * 3, (), np.empty(0), np.empty((0, 6)))
    with pytest.raises(ValueError, match="H must have len\\(rows\\) rows"):
        k.orientation(x, (0.0,) * 3, (0, 1), np.empty(2), np.empty((2, 5)))
    with pytest.raises(BufferError):
        k.orientation(x[::-1], (0.0,) * 3, (0, 1), np.empty(2), np.empty((2, 6)))


def test_a_copy_into_a_recycled_filter_is_the_filter_in_its_own_arrays(backend):
    lay = LAYOUTS["bias_scale"]
    src = _random_filter(lay, np.random.default_rng(3), backend)
    old = _random_filter(lay, np.random.default_rng(4), backend)
    x_buf, P_buf = old.x, old.P
    c = src.copy(into=old)
    assert c is old and c.x is x_buf and c.P is P_buf  # the recycled arrays, overwritten
    np.testing.assert_array_equal(c.x, src.x)
    np.testing.assert_array_equal(c.P, src.P)
    assert not np.shares_memory(c.P, src.P) and not np.shares_memory(c.x, src.x)
    other = _random_filter(LAYOUTS["pose"], np.random.default_rng(5), backend)  # another size: a new object
    d = src.copy(into=other)
    assert d is not other
    np.testing.assert_array_equal(d.P, src.P)
    np.testing.assert_array_equal(other.P, _random_filter(LAYOUTS["pose"], np.random.default_rng(5)).P)


def test_copy_into_checks_every_size_before_writing():
    x, P = np.ones(4), np.ones((2, 2))
    x_to, P_to = np.zeros(4), np.zeros((3, 3))
    with pytest.raises(ValueError, match="P_to has 9 values, expected 4"):
        k.copy_into(x, P, x_to, P_to)
    assert not x_to.any()


def _bits(values) -> list[str]:
    return [float(v).hex() for v in values]


@settings(max_examples=200, deadline=None)
@given(t0=st.floats(0.0, 2e9), rate=st.floats(5.0, 1000.0), n=st.integers(3, 600),
       speeds=st.lists(st.floats(-60.0, 60.0), min_size=1, max_size=40), jitter=st.floats(0.0, 0.4))
def test_the_compiled_line_fit_gives_the_references_bits(t0, rate, n, speeds, jitter):
    """The odometry's forward acceleration: the same sums in the same order, squares by the same pow."""
    from fusiond.estimator.line_fit import line_fit

    pairs = tuple((t0 + (i + jitter * math.sin(7.0 * i)) / rate, speeds[i % len(speeds)] + 1e-3 * i)
                  for i in range(n))
    assert _bits(COMPILED.line_fit(pairs)) == _bits(line_fit(pairs)) == _bits(PYTHON.line_fit(pairs))


def test_a_line_fit_the_kernel_cannot_read_is_the_references():
    """Ints among the values, a list of pairs, all stamps alike: the reference answers (or raises)."""
    from fusiond.estimator.line_fit import line_fit

    assert k.line_fit(((1, 2.0), (2.0, 3.0), (3.0, 3.5))) is None
    assert COMPILED.line_fit(((1, 2.0), (2.0, 3.0), (3.0, 3.5))) == line_fit(((1, 2.0), (2.0, 3.0), (3.0, 3.5)))
    assert k.line_fit([(1.0, 2.0), (2.0, 3.0), (3.0, 3.5)]) is None
    assert k.line_fit(((1.0, 2.0), (1.0, 3.0), (1.0, 3.5))) is None
    with pytest.raises(ZeroDivisionError):
        COMPILED.line_fit(((1.0, 2.0), (1.0, 3.0), (1.0, 3.5)))


@given(seed=st.integers(0, 2**32 - 1), xx=st.floats(0.0, 1e3), xy=st.floats(-1e3, 1e3), yy=st.floats(0.0, 1e3),
       yaw=st.floats(0.0, 10.0))
@settings(max_examples=60, deadline=None)
def test_compiled_motion_noise_adds_the_references_doubles(seed, xx, xy, yy, yaw):
    from fusiond.estimator.state import add_motion_noise

    Q = np.random.default_rng(seed).normal(size=(9, 9))
    reference, compiled = Q.copy(), Q.copy()
    add_motion_noise(reference, xx, xy, yy, yaw)
    COMPILED.add_motion_noise(compiled, xx, xy, yy, yaw)
    assert compiled.tobytes() == reference.tobytes()


def test_compiled_motion_noise_refuses_a_row_outside_q_and_reads_any_array_through_the_reference():
    Q = np.zeros((6, 6))
    with pytest.raises(ValueError, match="yaw_row outside Q"):
        k.add_motion_noise(Q, 1.0, 0.0, 1.0, 6, 1.0)
    assert not Q.any()  # refused before anything was written
    strided = np.zeros((6, 12))[:, ::2]  # not C-contiguous: the reference writes it
    COMPILED.add_motion_noise(strided, 1.0, 0.5, 2.0, 0.25)
    assert strided[0, 0] == 1.0 and strided[0, 1] == strided[1, 0] == 0.5 and strided[1, 1] == 2.0
    assert strided[5, 5] == 0.25


@given(q=st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(lambda q: sum(c * c for c in q) > 1e-3),
       tilted=st.booleans(), seed=st.integers(0, 2**32 - 1))
@settings(max_examples=80, deadline=None)
def test_compiled_planar_hold_writes_the_references_doubles(q, tilted, seed):
    from fusiond.estimator.planar import hold_planar, planar_mask

    rng = np.random.default_rng(seed)
    norm = math.sqrt(sum(c * c for c in q))
    qx, qy, qz, qw = (c / norm for c in q)
    if not tilted:  # already a rotation about z: left as it is
        qx = qy = 0.0
    x = rng.normal(size=13)
    x[3:7] = qx, qy, qz, qw
    P = rng.normal(size=(12, 12))
    nominal, error = (2, 9, 10), (2, 3, 4, 9, 10)
    by_index, by_mask, compiled = (x.copy(), P.copy()), (x.copy(), P.copy()), (x.copy(), P.copy())
    hold_planar(*by_index, nominal, np.array(error))
    hold_planar(*by_mask, nominal, planar_mask(list(error), 12))
    COMPILED.hold_planar(*compiled, nominal, error)
    for got in (by_mask, compiled):
        assert got[0].tobytes() == by_index[0].tobytes() and got[1].tobytes() == by_index[1].tobytes()
    assert compiled[0][3] == compiled[0][4] == 0.0 and not compiled[1][list(error)].any()


def test_compiled_planar_hold_checks_every_index_before_writing():
    x, P = np.arange(13.0), np.ones((12, 12))
    x[3:7] = 0.1, 0.2, 0.3, 0.9
    before = x.copy()
    for nominal, error, said in (((13,), (2,), "nominal_zero outside x"), ((2,), (12,), "error_zero outside P"),
                                 ((-1,), (2,), "nominal_zero outside x")):
        with pytest.raises(ValueError, match=said):
            k.hold_planar(x, P, nominal, error)
        assert x.tobytes() == before.tobytes() and (P == 1.0).all()
    with pytest.raises(TypeError, match="tuples of ints"):
        k.hold_planar(x, P, [2], (2,))


def test_a_fix_measuring_two_axes_reaches_the_compiled_update():
    """A GPS whose altitude is not measured (its variance above max_sigma^2: the highway car's receiver) is
    fused as its two horizontal rows. The rows picked from its 3x3 noise must stay an array the kernel reads
    (C order): a column pick leaves Fortran order, and every such update took the Python reference
    (``CompiledBackend.update``'s BufferError fallback), a quarter of a fix's cost. Counted: none falls back.
    The pose's row pick (``observations._select_rows``) likewise."""
    import msgspec

    from fusiond.core.fusion import FusionCore
    from fusiond.core.sensors import GpsSample
    from fusiond.estimator.backend import PythonBackend
    from tests.support.configs import robot_config
    from tests.support.sim_gps import World, simulate

    fell_back: list[int] = []
    real = PythonBackend.update

    def counted(self, *args):
        fell_back.append(len(args[5]))
        return real(self, *args)

    assert COMPILED is not None
    core = FusionCore(robot_config(gps=""), backend=COMPILED)
    samples = [msgspec.structs.replace(s, position_covariance=(0.09, 0.0, 0.0, 0.0, 0.09, 0.0, 0.0, 0.0, 1.0e7))
               if isinstance(s, GpsSample) else s for s in simulate(World(duration=30.0, speed=5.0, gps_rate=10.0))]
    PythonBackend.update = counted
    try:
        fixes = [r for s in samples for r in core.ingest(s).records if r.sensor == "gps" and r.dof == 2]
    finally:
        PythonBackend.update = real
    assert len(fixes) > 200 and fell_back == []
    y, H, R = observations._select_rows(np.zeros(6), np.ones((6, 15)), tuple(np.eye(6).ravel()), (0, 1, 5))
    assert all(a.flags["C_CONTIGUOUS"] for a in (y, H, R))


def _twist(draw_floats: list[float], k0: int) -> tuple[float, ...]:
    return tuple(draw_floats[(k0 + i) % len(draw_floats)] for i in range(6))


@settings(max_examples=200, deadline=None)
@given(readings=st.lists(st.floats(-3.0, 3.0), min_size=6, max_size=40), scale=st.sampled_from([0.0, 1e-3, 0.02, 1.0]),
       steps=st.integers(1, 60), period=st.sampled_from([0.0, 0.02, 0.1]), gaps=st.integers(0, 9),
       measured=st.tuples(*[st.booleans()] * 6), span=st.sampled_from([0.05, 0.3, 1.0]),
       z=st.floats(0.5, 5.0), min_window=st.integers(2, 8))
def test_the_compiled_zero_motion_tests_give_the_references_bits(readings, scale, steps, period, gaps, measured,
                                                                 span, z, min_window):
    """The odometry's standstill test: the running noise and the window's test, message after message, the
    same tuples of the same doubles through either backend (a stream at rest, creeping, with gaps)."""
    from fusiond.estimator import zero_motion

    bounds = []

    def bound(n: int) -> float:
        bounds.append(n)
        return 1.0 + 4.0 / n

    tracks = {b: None for b in (COMPILED, PYTHON, "reference")}
    windows = {b: () for b in tracks}
    stamp = 100.0
    for step in range(steps):
        stamp += 0.02 * (10 if gaps and step % (gaps + 1) == gaps else 1)
        values = tuple(scale * v for v in _twist(readings, step))
        out = []
        for b in tracks:
            noise = (zero_motion.difference_noise if b == "reference" else b.difference_noise)(
                tracks[b], values, stamp, period, 3.0, 64.0)
            window, at_rest = (zero_motion.zero_mean_window if b == "reference" else b.zero_mean_window)(
                windows[b], values, measured, noise[1], stamp, span, z, min_window, 1e-6, bound)
            tracks[b], windows[b] = noise, window
            out.append(repr((noise, window, at_rest)))
        assert out[0] == out[1] == out[2]
    assert len(bounds) % 3 == 0  # asked alike by each


def test_zero_motion_the_kernel_cannot_read_is_the_references():
    """Ints among the readings, lists for tuples, a bound that raises: the reference answers (or raises)."""
    from fusiond.estimator import zero_motion

    ints = (1, 0.0, 0.0, 0.0, 0.0, 0.0)
    assert k.difference_noise(None, ints, 1.0, 0.02, 3.0, 64.0) is None
    assert COMPILED.difference_noise(None, ints, 1.0, 0.02, 3.0, 64.0) == (ints, None, 0.0, 1.0)
    assert k.zero_mean_window((), [0.0] * 6, (True,) * 6, None, 1.0, 0.3, 2.0, 5, 1e-6, float) is None
    track = zero_motion.difference_noise(None, (0.1,) * 6, 1.0, 0.02, 3.0, 64.0)
    assert k.difference_noise(track, (1e300,) * 6, 1.02, 0.02, 3.0, 64.0) is None  # Python's ** overflows
    with pytest.raises(OverflowError):
        COMPILED.difference_noise(track, (1e300,) * 6, 1.02, 0.02, 3.0, 64.0)
    window = tuple((1.0 + 0.02 * i, (0.0,) * 6) for i in range(5))

    def refused(n: int) -> float:
        raise ValueError(f"no bound for {n}")

    with pytest.raises(ValueError, match="no bound for 6"):
        COMPILED.zero_mean_window(window, (0.0,) * 6, (True,) * 6, None, 1.1, 1.0, 2.0, 5, 1e-6, refused)
    moving = COMPILED.zero_mean_window(window, (1.0,) * 6, (True,) * 6, (1e-4,) * 6, 1.1, 1.0, 2.0, 5, 1e-6, refused)
    assert moving == ((), False)  # the early exit asks no bound
    with pytest.raises(ZeroDivisionError):  # a window of one reading has no difference to take a noise from
        COMPILED.zero_mean_window((), (0.0,) * 6, (True,) * 6, None, 1.0, 1.0, 2.0, 1, 1e-6, float)


@pytest.mark.parametrize("name, low, high", [
    ("predict", 16, 17), ("orientation", 5, 5), ("add_motion_noise", 6, 6), ("hold_planar", 4, 4), ("copy_into", 4, 4),
    ("propagate", 4, 4), ("update", 10, 10), ("rts_fold", 5, 5), ("line_fit", 1, 1), ("difference_noise", 6, 6),
    ("zero_mean_window", 10, 10)])
def test_a_kernel_called_with_another_count_of_arguments_says_which_it_takes(name, low, high):
    """A wrong count is refused before any argument is read, as Python refuses it for a function."""
    taken = f"{low} or {high} arguments" if high > low else f"{low} argument{'s' if low > 1 else ''}"
    for given in (0, high + 1):
        with pytest.raises(TypeError, match=rf"^{name}\b.* takes {taken} \({given} given\)$"):
            getattr(k, name)(*([None] * given))
