"""The filter's backend: who runs the per-step numerics, chosen once when the filter is built.

Every message costs a prediction (the motion model's x', F, Q), a propagation P' = F P F^T + Q and
one or more Kalman updates (the IMU's orientation the most frequent). Two implementations run them:

- ``PythonBackend``, the reference: the maths as written in numpy and Python floats (the EKF steps
  here, the motion model in ``motion.predict``, the orientation observation in
  ``orientation_residual.rpy_residual``). It runs everywhere and is what the other is held to.
- ``CompiledBackend``: the same steps as one C call each (``_kernels.c``, built by ``pip install``
  where a compiler is; see its header for why C). What the kernels cannot take (an array that is not
  C-contiguous float64, a layout wider than their fixed scratch, an input block without a compiled
  form) runs the reference, inherited: the one fallback, in this class.

``ErrorStateEKF(layout, backend=...)`` takes one (default: ``DEFAULT``, compiled when built); the
motion and observation models get it from the filter. Tests run both and hold them to the same
estimates (tests/unit/test_kernels.py, the Jackal trajectory pin). A whole process picks one by name
(``choose``; ``from_environment`` reads FUSIOND_KERNELS for the command line): the estimator itself
reads no environment and keeps no process-wide switch.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from types import ModuleType
from typing import TYPE_CHECKING

import numpy as np

from ..errors import EstimatorError
from . import motion, zero_motion
from .orientation_residual import rpy_residual
from .cholesky import gain_rows
from .rts import rts_gain
from .line_fit import line_fit
from .planar import hold_planar
from .state import YAW_ROW, add_motion_noise

if TYPE_CHECKING:
    from .motion import MotionInput, PredictWorkspace
    from .state import StateLayout

try:
    from . import _kernels
except ImportError:  # built without a C compiler: the reference runs
    _kernels = None

__all__ = ["Backend", "PythonBackend", "CompiledBackend", "UpdateWorkspace", "PYTHON", "COMPILED", "DEFAULT",
           "CHOICES", "ENVIRONMENT", "APPLIED", "GATED", "SINGULAR", "NEEDS_CHECK", "choose", "from_environment"]

# An update's outcome (the compiled kernel's status codes, _kernels.c): applied with a checked
# diagonal, gated, S not positive definite (or a non-finite NIS), or applied with P left for the
# filter's checks (a negative or non-finite variance; the reference leaves every P to them).
APPLIED, GATED, SINGULAR, NEEDS_CHECK = 0, 1, 2, 3
# the compiled kernels' fixed sizes (_kernels.c MAX_N, MAX_M; pinned by tests/unit/test_kernels.py)
MAX_N, MAX_M = 48, 12
_MASKS_KEPT = 8  # distinct masks held by a workspace (the core uses at most three)


class Backend:
    """What the filter and its models ask of a backend. Methods take and fill arrays: the filter
    owns its state and buffers, a backend keeps none (one object serves every filter)."""

    name = "?"

    def for_layout(self, layout: "StateLayout") -> "Backend":
        """The backend that runs filters of ``layout``: this one, or the reference where it cannot."""
        return self

    def propagate(self, F: np.ndarray, P: np.ndarray, Q: np.ndarray, out: np.ndarray) -> np.ndarray | None:
        """F P F^T + Q, written into ``out`` or a new array (which is returned); None when not finite."""
        raise NotImplementedError

    def update(self, layout: "StateLayout", x: np.ndarray, P: np.ndarray, H: np.ndarray, R: np.ndarray,
               y: np.ndarray, threshold2: float, keep: np.ndarray | None, joseph: np.ndarray | None,
               hold_heading: bool, out: np.ndarray, ws: "UpdateWorkspace") -> tuple[int, float, list[float]]:
        """The gated Kalman update (``ErrorStateEKF.update`` documents it): (status, NIS, diag S).
        Applied (APPLIED, NEEDS_CHECK): x moved by K y in place, P - K S K^T written into ``out``."""
        raise NotImplementedError

    def copy_into(self, x: np.ndarray, P: np.ndarray, x_to: np.ndarray, P_to: np.ndarray) -> bool:
        """x_to[...] = x and P_to[...] = P; False, nothing written, when the shapes differ."""
        raise NotImplementedError

    def predict(self, layout: "StateLayout", x: np.ndarray, u: "MotionInput", dt: float,
                noise_density: np.ndarray, ws: "PredictWorkspace") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The motion model's (x', F, Q) over dt (``motion.predict``)."""
        raise NotImplementedError

    def orientation(self, layout: "StateLayout", x: np.ndarray, z_rpy: tuple[float, float, float],
                    rows: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
        """The orientation observation's (y, H) (``observations.orientation``)."""
        raise NotImplementedError

    def line_fit(self, pairs: tuple[tuple[float, float], ...]) -> tuple[float, float]:
        """(slope, rms misfit) of the least-squares line through (t, v) pairs (``line_fit.line_fit``)."""
        raise NotImplementedError

    def difference_noise(self, track: tuple | None, values: tuple, stamp: float, period: float, gap_factor: float,
                         memory: float) -> tuple:
        """A twist stream's running noise after ``values`` (``zero_motion.difference_noise``)."""
        raise NotImplementedError

    def zero_mean_window(self, window: tuple, values: tuple, measured: tuple, running: tuple | None, stamp: float,
                         span: float, z: float, min_window: int, floor: float,
                         bound: Callable[[int], float]) -> tuple[tuple, bool]:
        """A twist window's test of a zero mean after ``values`` (``zero_motion.zero_mean_window``)."""
        raise NotImplementedError

    def rts_fold(self, A: np.ndarray, P0: np.ndarray, F: np.ndarray, P1: np.ndarray) -> np.ndarray:
        """The smoother's fold of a run of transitions (``smoother.OpenSegment``): A P0 F^T P1^-1 on the
        components P1 gives any variance."""
        raise NotImplementedError

    def add_motion_noise(self, Q: np.ndarray, xx: float, xy: float, yy: float, yaw: float = 0.0) -> None:
        """Q += the horizontal position covariance [[xx, xy], [xy, yy]] and the heading variance yaw, in
        place (``state.add_motion_noise``)."""
        raise NotImplementedError

    def hold_planar(self, x: np.ndarray, P: np.ndarray, nominal_zero: tuple[int, ...], error_zero) -> None:
        """Two-D mode's hold of x and P, in place (``planar.hold_planar``)."""
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<{self.name} backend>"


class PythonBackend(Backend):
    """The reference: numpy for the n x n products, Python floats for the small factorisation.

    For the 9-15 dimensional states here every numpy call costs more in dispatch than in
    arithmetic, so each step is a fixed, short list of calls (products through ``ndarray.dot``,
    which skips np.dot's Python-level dispatch). The update forms H P once, takes W = L^-1 H P and
    K y in a single product with the small matrix [L^-1; (L^-T z)^T] (``cholesky.gain_rows``), and
    writes P - K S K^T = P - W^T W into the filter's spare buffer.
    """

    name = "numpy"

    def propagate(self, F, P, Q, out):
        """P' = F P F^T + Q."""
        # Two fresh products: measured faster than np.dot(..., out=) at these sizes (the out= path's
        # checks cost more than a 9x9 allocation), so ``out`` is left alone.
        P_new = F.dot(P).dot(F.T)
        P_new += Q
        # The diagonal is enough (as in ``ErrorStateEKF._store``): a NaN/inf in F's row i makes
        # (F P F^T)_ii non-finite (inf * 0 is NaN too), and Q's off-diagonal entries come from the
        # same rows as its diagonal. A Python sum of 9-15 floats costs less than a numpy reduction.
        if not math.isfinite(sum(P_new.diagonal().tolist())):
            return None
        return P_new

    def update(self, layout, x, P, H, R, y, threshold2, keep, joseph, hold_heading, out, ws):
        """With S = H P H^T + R = L L^T (Cholesky), z = L^-1 y and W = L^-1 H P:

            NIS = z.z                       (gated when NIS > threshold2)
            K y = P H^T S^-1 y = W^T z      x [+]= K y
            K S K^T = W^T W                 P' = P - W^T W

        and with a mask M (a Schmidt update: the gain rows of the others zeroed), K y -> M K y and
        W^T W -> (W^T W) .* J, J_ij = 1 - (1 - m_i)(1 - m_j): the Joseph form's closed form."""
        HP = H.dot(P)  # H P = (P H^T)^T: P is symmetric
        S = HP.dot(H.T)
        S += R
        S_rows = S.tolist()
        s_diag = [row[i] for i, row in enumerate(S_rows)]
        solved = gain_rows(S_rows, y.tolist())
        if solved is None:
            return SINGULAR, math.nan, s_diag
        z, rows = solved  # z = L^-1 y, the whitened innovation; rows = [L^-1; (L^-T z)^T]
        # fsum: the NIS gates and feeds the consistency tests; for one or two terms a float
        # addition is already the correctly rounded sum, so it is used there (the same bits).
        m = len(z)
        if m == 2:
            nis = z[0] * z[0] + z[1] * z[1]
        elif m == 1:
            nis = z[0] * z[0]
        else:
            nis = math.fsum([v * v for v in z])
        if not math.isfinite(nis):
            return SINGULAR, nis, s_diag
        if nis > threshold2:
            return GATED, nis, s_diag
        # One product gives both W = L^-1 H P and the correction K y = P H^T S^-1 y = (H P)^T L^-T z:
        # [W; (K y)^T] = [L^-1; (L^-T z)^T] H P, its m + 1 rows on the left written in place.
        g = ws.gain(m)
        g.rows_flat[:] = rows
        g.rows.dot(HP, g.product)  # into g.product: g.W and g.dx are views of its rows
        W, dx = g.W, g.dx
        C = W.T.dot(W)  # K S K^T = K H P for the optimal gain K = P H^T S^-1
        if keep is not None:
            # Gain rows zeroed by the mask (M K): Joseph's P - MKHP - PH^TK^TM + MKSK^TM
            # collapses to P - C * J with J_ij = 1 - (1 - m_i)(1 - m_j).
            dx *= keep
            C *= joseph
        np.subtract(P, C, out=out)
        layout.boxplus(x, dx, hold_heading)
        return NEEDS_CHECK, nis, s_diag

    def copy_into(self, x, P, x_to, P_to):
        if P_to.shape != P.shape or x_to.shape != x.shape:
            return False
        x_to[...] = x  # equal shapes: the bytes are copied
        P_to[...] = P
        return True

    def predict(self, layout, x, u, dt, noise_density, ws):
        return motion.predict(layout, x, u, dt, noise_density, ws)

    def orientation(self, layout, x, z_rpy, rows):
        return rpy_residual(layout, x, z_rpy, rows)

    def line_fit(self, pairs):
        return line_fit(pairs)

    def difference_noise(self, track, values, stamp, period, gap_factor, memory):
        return zero_motion.difference_noise(track, values, stamp, period, gap_factor, memory)

    def zero_mean_window(self, window, values, measured, running, stamp, span, z, min_window, floor, bound):
        return zero_motion.zero_mean_window(window, values, measured, running, stamp, span, z, min_window, floor,
                                            bound)

    def rts_fold(self, A, P0, F, P1):
        return A.dot(rts_gain(P0, F, P1))

    def add_motion_noise(self, Q, xx, xy, yy, yaw=0.0):
        add_motion_noise(Q, xx, xy, yy, yaw)

    def hold_planar(self, x, P, nominal_zero, error_zero):
        hold_planar(x, P, nominal_zero, error_zero)


class CompiledBackend(PythonBackend):
    """The steps as one call each of ``_kernels`` (the same maths; ``_kernels.c``). P is written into
    the filter's spare buffer, the update's boxplus done in the same call where every block after the
    pose is additive. Where the kernels cannot run a step, the reference method it inherits does."""

    name = "compiled"

    def __init__(self, kernels: ModuleType) -> None:
        self._k = kernels

    def for_layout(self, layout):
        return self if layout.error_dim <= MAX_N else PYTHON

    def propagate(self, F, P, Q, out):
        try:
            finite = self._k.propagate(F, P, Q, out)
        except BufferError:  # an array not C-contiguous float64
            return PythonBackend.propagate(self, F, P, Q, out)
        return out if finite else None

    def update(self, layout, x, P, H, R, y, threshold2, keep, joseph, hold_heading, out, ws):
        if len(y) > MAX_M:
            return PythonBackend.update(self, layout, x, P, H, R, y, threshold2, keep, joseph, hold_heading, out, ws)
        # boxplus: 1 (in the kernel) where every block after the pose is additive, 2 also holding the
        # heading, 0 (dx handed back, the layout's own boxplus) otherwise
        mode = 1 if layout._additive_tail else 0
        target = x if mode else ws.dx()
        if mode and hold_heading:
            mode = 2
        try:
            status, nis, s_diag = self._k.update(P, H, R, y, threshold2, keep, joseph, out, target, mode)
        except BufferError:  # an array not C-contiguous float64
            return PythonBackend.update(self, layout, x, P, H, R, y, threshold2, keep, joseph, hold_heading, out, ws)
        except ArithmeticError:
            raise EstimatorError("quaternion has zero or non-finite norm") from None
        if not mode and (status == APPLIED or status == NEEDS_CHECK):
            layout.boxplus(x, target, hold_heading)
        return status, nis, s_diag

    def copy_into(self, x, P, x_to, P_to):
        try:
            self._k.copy_into(x, P, x_to, P_to)
            return True
        except (BufferError, ValueError):  # another size or layout of array: the reference decides
            return PythonBackend.copy_into(self, x, P, x_to, P_to)

    def predict(self, layout, x, u, dt, noise_density, ws):
        if ws._kernel_blocks is not None:  # every input block has a compiled form
            try:
                return motion.predict_compiled(self._k, layout, x, u, dt, noise_density, ws)
            except BufferError:  # an array not C-contiguous float64
                pass
        return motion.predict(layout, x, u, dt, noise_density, ws)

    def orientation(self, layout, x, z_rpy, rows):
        y, H = np.empty(len(rows)), np.empty((len(rows), layout.error_dim))
        try:
            self._k.orientation(x, z_rpy, rows, y, H)
        except BufferError:  # x not C-contiguous float64
            return rpy_residual(layout, x, z_rpy, rows)
        return y, H

    def line_fit(self, pairs):
        fit = self._k.line_fit(pairs)
        return line_fit(pairs) if fit is None else fit  # None: not floats in tuples, or a degenerate fit

    def difference_noise(self, track, values, stamp, period, gap_factor, memory):
        noise = self._k.difference_noise(track, values, stamp, period, gap_factor, memory)
        if noise is None:  # not plain floats in tuples, or a square overflows: the reference decides
            return zero_motion.difference_noise(track, values, stamp, period, gap_factor, memory)
        return noise

    def zero_mean_window(self, window, values, measured, running, stamp, span, z, min_window, floor, bound):
        tested = self._k.zero_mean_window(window, values, measured, running, stamp, span, z, min_window, floor, bound)
        if tested is None:  # not plain floats, bools and tuples, or a square overflows: the reference decides
            return zero_motion.zero_mean_window(window, values, measured, running, stamp, span, z, min_window, floor,
                                                bound)
        return tested

    def rts_fold(self, A, P0, F, P1):
        out = np.empty_like(A)
        try:
            if self._k.rts_fold(A, P0, F, P1, out):
                return out
        except BufferError:  # an array not C-contiguous float64
            pass
        return PythonBackend.rts_fold(self, A, P0, F, P1)  # also where P1's Cholesky fails: least squares

    def add_motion_noise(self, Q, xx, xy, yy, yaw=0.0):
        try:
            self._k.add_motion_noise(Q, xx, xy, yy, YAW_ROW, yaw)
        except BufferError:  # Q not C-contiguous float64
            add_motion_noise(Q, xx, xy, yy, yaw)

    def hold_planar(self, x, P, nominal_zero, error_zero):
        if type(error_zero) is tuple:  # indices: one call; an array or a mask: the reference's writes
            try:
                self._k.hold_planar(x, P, nominal_zero, error_zero)
                return
            except BufferError:  # an array not C-contiguous float64
                pass
        hold_planar(x, P, nominal_zero, error_zero)


class UpdateWorkspace:
    """A filter's scratch for the update (shared with its copies, never holding state between
    calls): the reference's gain products per row count, the compiled update's dx, the masks' weights."""

    __slots__ = ("n", "_gains", "masks", "_dx")

    def __init__(self, n: int) -> None:
        self.n = n
        self._gains: dict[int, _GainRows] = {}
        self._dx: np.ndarray | None = None
        # id(mask) -> (mask, its floats, its Joseph weights); the mask itself is kept so that its id
        # cannot be reused by another array while the entry lives
        self.masks: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    def dx(self) -> np.ndarray:
        """The compiled update's correction, for layouts whose boxplus runs in Python."""
        if self._dx is None:
            self._dx = np.empty(self.n)
        return self._dx

    def gain(self, m: int) -> "_GainRows":
        g = self._gains.get(m)
        if g is None:
            g = self._gains[m] = _GainRows(m, self.n)
        return g

    def mask(self, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(mask, its floats, the Joseph weights J), made once per mask array: the core holds one array
        per kind of masked update (tilt, GPS position, pose delta), and updates of different kinds
        interleave, so all of them are kept."""
        masks = self.masks
        entry = masks.get(id(mask))
        if entry is None or entry[0] is not mask:
            if len(masks) >= _MASKS_KEPT:
                masks.clear()
            keep = mask.astype(float)
            entry = masks[id(mask)] = (mask, keep, 1.0 - np.outer(1.0 - keep, 1.0 - keep))
        return entry


class _GainRows:
    """The arrays of an m-row update: [L^-1; (L^-T z)^T] (written through a flat view) and its
    product with H P, whose first m rows are W and last row K y (views made once)."""

    __slots__ = ("rows", "rows_flat", "product", "W", "dx")

    def __init__(self, m: int, n: int) -> None:
        self.rows = np.empty((m + 1, m))
        self.rows_flat = self.rows.reshape(-1)
        self.product = np.empty((m + 1, n))
        self.W = self.product[:m]
        self.dx = self.product[m]


PYTHON = PythonBackend()
COMPILED: CompiledBackend | None = CompiledBackend(_kernels) if _kernels is not None else None
DEFAULT: Backend = COMPILED if COMPILED is not None else PYTHON

CHOICES = ("auto", "compiled", "numpy")
ENVIRONMENT = "FUSIOND_KERNELS"


def choose(name: str) -> Backend:
    """The backend called ``name``: "auto" (compiled when built), "compiled" (an EstimatorError when it
    was not built) or "numpy" (the reference)."""
    if name not in CHOICES:
        raise EstimatorError(f"the backend must be one of {', '.join(CHOICES)}, got {name!r}")
    if name == "compiled" and COMPILED is None:
        raise EstimatorError("the compiled kernels (fusiond.estimator._kernels) were not built: "
                             "no C compiler at install time")
    return PYTHON if name == "numpy" else DEFAULT


def from_environment(environ: Mapping[str, str]) -> Backend:
    """``choose`` the name that ``environ`` (the caller's os.environ) gives FUSIOND_KERNELS, "auto" when
    it gives none; an unknown name is an EstimatorError that says so."""
    name = environ.get(ENVIRONMENT) or "auto"
    try:
        return choose(name)
    except EstimatorError as e:
        raise EstimatorError(f"{ENVIRONMENT}={name}: {e}") from None
