"""Odometry-driven motion model.

The wheel twist is a control input, not a measurement: position moves by
R(q) v dt (body-frame twist) or v dt (world-frame twist), attitude by the
body rate, which comes either from the wheels' yaw rate or from the gyro.
Input blocks of the state (gyro bias, wheel scale) correct the input first
and get their columns of F by the chain rule through ``G_lin``/``G_ang``.

With global attitude errors (R_true = Exp(dtheta) R):
    p' = p + R v dt        ->  dp' = dp - [R v dt]x dtheta + R dt dv
    R' = R Exp(w dt)       ->  dtheta' = dtheta + R' Jr(w dt) dt dw
so F = [[I, -[R v dt]x], [0, I]] plus the input blocks' columns. Blocks with their own
dynamics (``StateBlock.dynamic``, e.g. a Gauss-Markov GPS error) decay component-wise,
x' = a x, and add their discrete process noise to Q's diagonal; a layout without them
pays one empty-list test.

Input noise, per second of travel rather than per message. A gyro's sample noise is
white: held over its sample period T it integrates to a random walk of variance
sigma^2 * T * dt (Q = G (Sigma * T / dt) G^T). Odometry's is not: wheel slip, tyre
deformation and the ground make consecutive twist errors alike for a while, so a
faster odometry does not average its stated sigma away. Taking the odometry
covariance as a velocity error with correlation time tau (first-order Gauss-Markov)
gives, for travel much longer than tau, the random walk of spectral density
2 sigma^2 tau: Q = G (Sigma * max(T, 2 tau) / dt) G^T. The same motion then grows
the same position uncertainty at 10 Hz as at 83 Hz (per message it would shrink as
1/rate, and a GPS could no longer correct along the track). ``twist_correlation``
holds tau (the odometry sensor's ``twist_correlation_s``); 0 gives back the
per-message model. The filter's own ``process_noise`` is a density already.
Rates stay white per sample: a gyro's noise is, and the wheels' yaw rate drives
heading only without a gyro, where skid-steer wheels misreading the turn must keep
showing as inconsistent innovations of the absolute yaw (the doctor's cue), not be
hidden behind a widened prediction.

This runs once per message, through the filter's backend (``backend.py``): ``predict`` below is
the reference, where the 3x3 algebra is done on Python floats (several times cheaper than numpy
calls on 3-vectors) and numpy only sees the n x n blocks; the compiled backend runs the whole step
as one call of ``_kernels.predict`` (``predict_compiled``), the same expressions in C, for layouts
whose input blocks all name a ``kernel_code``, held to the reference's bits by
tests/unit/test_kernels.py.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from . import mat3
from . import rotation as rot
from ..errors import EstimatorError
from .state import StateLayout, Vec3

_POSITION = slice(0, 3)
_ATTITUDE = slice(3, 6)
_KERNEL_MAX_N = 48  # the compiled kernels' largest error dimension (_kernels.c MAX_N, pinned by test_kernels)


class MotionInput:
    """The inputs held between messages (zero-order hold), with their noise.

    Vectors are 3-tuples and covariances row-major 9-tuples of floats.
    """

    __slots__ = (
        "linear", "linear_cov", "linear_period",
        "angular", "angular_cov", "angular_period",
        "from_gyro", "world_frame", "twist_correlation", "planar",
    )

    def __init__(self) -> None:
        self.linear: Vec3 = (0.0, 0.0, 0.0)
        self.linear_cov: tuple[float, ...] = (0.0,) * 9
        self.linear_period = 0.0
        self.angular: Vec3 = (0.0, 0.0, 0.0)
        self.angular_cov: tuple[float, ...] = (0.0,) * 9
        self.angular_period = 0.0
        self.from_gyro = False
        self.world_frame = False
        self.twist_correlation = 0.0  # odometry twist error correlation time tau, s (see module doc)
        # roll/pitch rates not integrated (two-D mode, or no tilt reference): the corrected rate
        # is projected on body z, w' = P_z (w - b), and so are its Jacobian and noise
        self.planar = False


def _right_jacobian(x: float, y: float, z: float) -> tuple:
    """Jr(phi) = I - a [phi]x + b [phi]x^2, row-major 9-tuple."""
    t2 = x * x + y * y + z * z
    if t2 < 1e-10:
        a, b = 0.5, 1.0 / 6.0
    else:
        t = math.sqrt(t2)
        a = (1.0 - math.cos(t)) / t2
        b = (t - math.sin(t)) / (t2 * t)
    # [phi]x^2 = phi phi^T - t2 I
    return (
        1.0 + b * (x * x - t2), a * z + b * x * y, -a * y + b * x * z,
        -a * z + b * x * y, 1.0 + b * (y * y - t2), a * x + b * y * z,
        a * y + b * x * z, -a * x + b * y * z, 1.0 + b * (z * z - t2),
    )


class PredictWorkspace:
    """F and Q of one layout, preallocated and rewritten in place by each ``predict``.

    Building F from an identity copy and Q as a fresh dense matrix, block by block from
    nested tuples, cost more than the arithmetic (each numpy call on a 3x3 is ~1 us, and a
    scalar write ~0.1 us). Here F stays the identity and Q zero except for a fixed set of
    entries, fixed by the layout alone:

    - F: the off-diagonal of F[0:3, 3:6] (-[R v dt]x), each input block's columns in the
      rows of the input it corrects, each dynamic block's diagonal;
    - Q: the diagonal and the off-diagonals of the two 3x3 input-noise blocks (position and
      attitude).

    F and Q are the two halves of one buffer, so a step writes every one of those entries with
    a single fancy-index assignment from a flat list of floats (zeros where a block does not
    apply this step or an input is silent): no entry keeps a value from an earlier step, and
    there is nothing to put back. The arrays belong to the workspace: valid until its next use.
    """

    __slots__ = ("F", "Q", "_flat", "_index", "_pack", "_q_entries", "_zero_columns",
                 "_cov_seen", "_cov_diagonal", "_nominal_dim", "_kernel_blocks", "_decay_f", "_decay_x", "_kernel_decays")

    def __init__(self, layout: StateLayout) -> None:
        n = layout.error_dim
        buffer = np.zeros(2 * n * n)
        self.F = buffer[: n * n].reshape(n, n)  # C-contiguous views of the buffer's halves
        self.Q = buffer[n * n :].reshape(n, n)
        self.F[np.diag_indices(n)] = 1.0
        self._flat = buffer
        # F's written entries, in the order ``predict`` lists their values
        f = [r * n + c for r, c in _CROSS_ENTRIES]
        for blk, _, _, cols in layout.input_blocks:
            r0 = _POSITION.start if blk.corrects == "linear" else _ATTITUDE.start
            f += [(r0 + r) * n + c for r in range(3) for c in range(cols.start, cols.stop)]
        for blk, _, e0 in layout.dynamic_blocks:
            f += [(e0 + i) * (n + 1) for i in range(blk.error_size)]
        # then Q's: the diagonal, then each noise block's (k, k+1), (k, k+2), (k+1, k+2) and their mirrors
        q = [i * (n + 1) for i in range(n)]
        for k in (_POSITION.start, _ATTITUDE.start):
            for a, b in ((k, k + 1), (k, k + 2), (k + 1, k + 2)):
                q += [a * n + b, b * n + a]
        self._index = np.array(f + [n * n + i for i in q], dtype=np.intp)
        # the step's values as packed doubles: a fancy assignment from a list converts it element
        # by element (~2 us for ~40 floats); packing them with struct and viewing the bytes costs
        # a third of that, the same doubles
        self._pack = struct.Struct(f"{len(self._index)}d").pack
        self._q_entries = len(q)
        # an input block's columns while it does not apply (row-major, 3 x error_size)
        self._zero_columns = [[0.0] * (3 * blk.error_size) for blk, _, _, _ in layout.input_blocks]
        # the last covariance tuple of each input (linear, angular) and its diagonal (None: not diagonal)
        self._cov_seen: list[tuple | None] = [None, None]
        self._cov_diagonal: list[tuple[float, float, float] | None] = [None, None]
        self._nominal_dim = layout.nominal_dim
        self._kernel_blocks = _kernel_blocks(layout)
        # the dynamic blocks' entries that the compiled path leaves to Python: F's diagonal (flat) and x
        self._decay_f = np.array([(e0 + i) * (n + 1) for blk, _, e0 in layout.dynamic_blocks
                                  for i in range(blk.error_size)], dtype=np.intp)
        self._decay_x = np.array([n0 + i for blk, n0, _ in layout.dynamic_blocks for i in range(blk.error_size)],
                                 dtype=np.intp)
        self._kernel_decays = _kernel_decays(layout)


def _kernel_blocks(layout: StateLayout) -> tuple[tuple, tuple] | None:
    """The layout's input blocks as ``_kernels.predict`` takes them, for a step without and with the gyro
    (index: ``from_gyro``): (code, applies, corrects linear, nominal start, error start, error size) each.
    ``applies`` is asked of the block here, once per layout. None when a block has no compiled form: its
    own class must name one (a subclass that changes the maths inherits its parent's code otherwise)."""
    if layout.error_dim > _KERNEL_MAX_N:
        return None
    specs = []
    for blk, n0, _, cols in layout.input_blocks:
        code = type(blk).__dict__.get("kernel_code", 0)
        if not code:
            return None
        specs.append((code, blk.corrects == "linear", n0, cols.start, cols.stop - cols.start, blk))
    return tuple(tuple((c, int(b.applies(g)), int(lin), n0, c0, size) for c, lin, n0, c0, size, b in specs)
                 for g in (False, True))


def _kernel_decays(layout: StateLayout) -> tuple | None:
    """The dynamic blocks as ``_kernels.predict`` decays them itself: (n0, e0, tau, variances) each; None
    when one has no compiled form (its own class defines no ``kernel_decay``), or there are none: their
    decay and noise then stay in Python (``predict_compiled``)."""
    specs = []
    for blk, n0, e0 in layout.dynamic_blocks:
        if "kernel_decay" not in type(blk).__dict__ or blk.error_size != blk.nominal_size:
            return None
        tau, var = blk.kernel_decay()
        specs.append((n0, e0, float(tau), tuple(float(v) for v in var)))
    return tuple(specs) or None


# F[0:3, 3:6] = -[dp]x: its off-diagonal entries, row-major (the diagonal stays 0)
_CROSS_ENTRIES = ((0, 4), (0, 5), (1, 3), (1, 5), (2, 3), (2, 4))
_NO_CROSS = (0.0,) * 6
_NO_NOISE = (0.0,) * 6


def _input_noise(ws: PredictWorkspace, j: int, qd: list[float], G: mat3.Mat3, cov, scale: float) -> tuple:
    """G (cov * scale) G^T of input j (0: linear, into Q's position block; 1: angular, attitude).

    Its diagonal is added into ``qd`` (Q's diagonal so far) in place; returned are its
    off-diagonal entries in ``PredictWorkspace``'s order. A sensor's covariance is usually
    diagonal and the same tuple for every prediction until its next message: whether it is
    diagonal is decided once per tuple (by identity: tuples do not change), and a diagonal one
    takes ``mat3.sandwich_diag`` (the same floats as ``mat3.sandwich``).
    """
    if cov is not ws._cov_seen[j]:
        diagonal = None
        if cov[1] == 0.0 and cov[2] == 0.0 and cov[3] == 0.0 and cov[5] == 0.0 and cov[6] == 0.0 and cov[7] == 0.0:
            diagonal = (float(cov[0]), float(cov[4]), float(cov[8]))
        ws._cov_diagonal[j] = diagonal
        ws._cov_seen[j] = cov if type(cov) is tuple else None  # a list could change in place: not kept
    d = ws._cov_diagonal[j]
    if d is None:
        (c00, c01, c02), (_, c11, c12), (_, _, c22) = mat3.sandwich(G, cov, scale)
    else:
        (c00, c01, c02), (_, c11, c12), (_, _, c22) = mat3.sandwich_diag(G, d[0], d[1], d[2], scale)
    k = 3 * j
    qd[k] = c00 + qd[k]
    qd[k + 1] = c11 + qd[k + 1]
    qd[k + 2] = c22 + qd[k + 2]
    return (c01, c01, c02, c02, c12, c12)


def corrected_inputs(layout: StateLayout, x: np.ndarray, linear: Vec3, angular: Vec3,
                     from_gyro: bool) -> tuple[Vec3, Vec3]:
    """(linear, angular) as the motion model drives the pose with them: each input block (gyro bias,
    gyro and wheel scales) applied in layout order, as ``predict`` applies them (which also keeps
    the intermediate inputs, for the chain rule)."""
    if not layout.input_blocks:
        return linear, angular
    xl = x.tolist()
    for blk, n0, n1, _ in layout.input_blocks:
        if blk.applies(from_gyro):
            if blk.corrects == "linear":
                linear = blk.correct(xl[n0:n1], linear)
            else:
                angular = blk.correct(xl[n0:n1], angular)
    return linear, angular


def propagate_state(layout: StateLayout, x: np.ndarray, u: MotionInput, dt: float) -> np.ndarray:
    """f(x, u, dt): the exact function the filter runs (used by numeric Jacobian tests)."""
    return predict(layout, x, u, dt, np.zeros(layout.error_dim))[0]


def predict_compiled(k, layout: StateLayout, x: np.ndarray, u: MotionInput, dt: float,
                      noise_density: np.ndarray, ws: PredictWorkspace) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``predict`` as one call of ``k.predict`` (``_kernels``: the same expressions in C, _kernels.c): the
    input blocks' chain, x', F and Q. The dynamic blocks' decay and noise: in the same call when each
    has a ``kernel_decay`` (``_kernel_decays``), else here, the blocks' own ``transition``/``process_noise``:
    x' = a x and F's diagonal a are written after the call."""
    flags = (1 if u.world_frame else 0) | (2 if u.planar else 0)
    x_new = np.empty(ws._nominal_dim)
    decays = ws._kernel_decays
    if decays is not None:  # the Gauss-Markov blocks' decay and noise in the same call
        try:
            k.predict(x, x_new, ws.F, ws.Q, noise_density, dt, None, u.linear, u.angular, u.linear_cov,
                      u.angular_cov, u.linear_period, u.angular_period, u.twist_correlation, flags,
                      ws._kernel_blocks[u.from_gyro], decays)
        except ArithmeticError:
            raise EstimatorError("quaternion has zero or non-finite norm") from None
        return x_new, ws.F, ws.Q
    dynamic = layout.dynamic_blocks
    extra = None
    decay: list[float] | tuple = ()
    if dynamic:
        decay = []
        noise = [0.0] * len(noise_density)  # summed as a list: an item of an array is a numpy call each
        for blk, _, e0 in dynamic:
            decay += blk.transition(dt)
            if dt > 0.0:
                for i, q in enumerate(blk.process_noise(dt)):
                    noise[e0 + i] += q
        extra = np.array(noise)
    try:
        k.predict(x, x_new, ws.F, ws.Q, noise_density, dt, extra, u.linear, u.angular, u.linear_cov, u.angular_cov,
                  u.linear_period, u.angular_period, u.twist_correlation, flags, ws._kernel_blocks[u.from_gyro])
    except ArithmeticError:
        raise EstimatorError("quaternion has zero or non-finite norm") from None
    if decay:
        a = np.array(decay)
        x_new[ws._decay_x] *= a
        ws._flat[ws._decay_f] = a
    return x_new, ws.F, ws.Q


def predict(
    layout: StateLayout, x: np.ndarray, u: MotionInput, dt: float, noise_density: np.ndarray,
    ws: PredictWorkspace | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Propagate the nominal state over dt; return (x_new, F, Q) in error space (the reference).

    ``noise_density``: variance per second added to each error component (model
    error of the pose plus the blocks' random walks, see ``StateLayout.noise_density``).
    ``ws``: where F and Q are written (the filter's loop passes its own; without one a
    fresh workspace is made). F and Q are the workspace's arrays.
    """
    if ws is None:
        ws = PredictWorkspace(layout)
    xl = x.tolist()
    v = u.linear
    w = u.angular
    corrections = []
    columns = ws._zero_columns.copy()  # each input block's columns of F (row-major); zeros unless it applies
    for k, (blk, n0, n1, _) in enumerate(layout.input_blocks):
        if not blk.applies(u.from_gyro):
            continue
        xb = xl[n0:n1]
        if blk.corrects == "linear":
            corrections.append((k, True, blk, xb, v))
            v = blk.correct(xb, v)
        else:
            corrections.append((k, False, blk, xb, w))
            w = blk.correct(xb, w)

    px, py, pz, qx, qy, qz, qw = xl[0:7]
    vx, vy, vz = v
    R = rot.matrix9((qx, qy, qz, qw))
    if u.world_frame:
        G_lin = (dt, 0.0, 0.0, 0.0, dt, 0.0, 0.0, 0.0, dt)
        dpx, dpy, dpz = vx * dt, vy * dt, vz * dt
        cross = _NO_CROSS
    else:
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = R
        G_lin = (r0 * dt, r1 * dt, r2 * dt, r3 * dt, r4 * dt, r5 * dt, r6 * dt, r7 * dt, r8 * dt)
        dpx = (r0 * vx + r1 * vy + r2 * vz) * dt
        dpy = (r3 * vx + r4 * vy + r5 * vz) * dt
        dpz = (r6 * vx + r7 * vy + r8 * vz) * dt
        cross = (dpz, -dpy, -dpz, dpx, dpy, -dpx)  # F[0:3, 3:6] = -[dp]x at _CROSS_ENTRIES
    if u.planar:
        w = (0.0, 0.0, w[2])
    ax, ay, az = w[0] * dt, w[1] * dt, w[2] * dt
    q1 = rot.advance((qx, qy, qz, qw), ax, ay, az)  # q Exp(w dt)
    xl[0:7] = (px + dpx, py + dpy, pz + dpz, *q1)
    f_values = [*cross]
    dynamic = layout.dynamic_blocks
    decay: list[float] = []
    if dynamic:  # blocks with their own dynamics (Gauss-Markov errors): x' = a x, F diagonal a
        for blk, n0, _ in dynamic:
            for i, a in enumerate(blk.transition(dt)):
                xl[n0 + i] *= a
                decay.append(a)
    x_new = np.array(xl)
    # d theta' / d w = R' Jr(w dt) dt = R Exp(w dt) Jr(w dt) dt = R Jl(w dt) dt, Jl(phi) = Jr(-phi)
    G_ang = mat3.mul(R, _right_jacobian(-ax, -ay, -az), dt)
    if u.planar:  # d w' / d w = P_z: the x/y columns go
        G_ang = (0.0, 0.0, G_ang[2], 0.0, 0.0, G_ang[5], 0.0, 0.0, G_ang[8])

    # Blocks correct an input in turn (u1 = g1(u0), u2 = g2(u1), ...): walking them
    # backwards, each block's columns are G d u_last / d u_its_output times its own
    # input Jacobian, and G is carried through the block's d u_out / d u_in.
    for k, linear, blk, xb, u_in in reversed(corrections):
        if linear:
            columns[k] = blk.chain(G_lin, xb, u_in)
            if blk.scales_input:
                G_lin = mat3.mul(G_lin, blk.input_derivative(xb, u_in))
        else:
            columns[k] = blk.chain(G_ang, xb, u_in)
            if blk.scales_input:
                G_ang = mat3.mul(G_ang, blk.input_derivative(xb, u_in))
    for c in columns:
        f_values += c
    if decay:
        f_values += decay

    # G_lin/G_ang now map the measured inputs, whose noise the covariances describe. Q's
    # diagonal is assembled in floats (input noise + density * dt + the blocks' own noise,
    # summed in that order), then the input blocks' off-diagonals; all written at once.
    if dt > 0.0:
        qd = [d * dt for d in noise_density.tolist()]
        if dynamic:
            for blk, n0, e0 in dynamic:
                for i, q in enumerate(blk.process_noise(dt)):
                    qd[e0 + i] += q
        if u.linear_period > 0.0:  # odometry: a velocity error that lasts ~tau (module doc)
            period = max(u.linear_period, 2.0 * u.twist_correlation)
            qd += _input_noise(ws, 0, qd, G_lin, u.linear_cov, period / dt)
        else:
            qd += _NO_NOISE
        if u.angular_period > 0.0:
            qd += _input_noise(ws, 1, qd, G_ang, u.angular_cov, u.angular_period / dt)
        else:
            qd += _NO_NOISE
    else:
        qd = [0.0] * ws._q_entries
    f_values += qd
    ws._flat[ws._index] = np.frombuffer(ws._pack(*f_values))  # F's entries, then Q's
    return x_new, ws.F, ws.Q
