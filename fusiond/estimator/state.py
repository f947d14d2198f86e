"""The filter state as a list of blocks.

The nominal state lives on a manifold (a unit quaternion is not a vector), the
covariance on its tangent space: each block says how big it is in both and how a
tangent-space correction is injected (``boxplus``). Adding a state such as a wheel
scale factor means writing one block here (and, if it corrects a motion input,
its input Jacobian); the EKF and the motion model never change.

Attitude errors are global (world frame): R_true = Exp(dtheta) R. With that choice a
rotation about world z is exactly the third error component, so roll/pitch
observations have an exactly zero yaw column and cannot leak into heading.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import rotation as rot


class StateBlock:
    """A piece of the state: sizes, initial value and uncertainty, boxplus.

    Blocks work on Python lists of floats (the nominal state's ``tolist()``):
    per-message numpy calls on 3-vectors cost more than the arithmetic.
    """

    name: str = ""
    nominal_size: int = 0
    error_size: int = 0

    def initial(self) -> list[float]:
        return [0.0] * self.nominal_size

    def initial_sigma(self) -> list[float]:
        return [0.0] * self.error_size

    def random_walk(self) -> list[float]:
        """Process noise density (std per sqrt(s)) of each error component."""
        return [0.0] * self.error_size

    # Blocks with their own dynamics (e.g. a Gauss-Markov error) set ``dynamic = True`` and
    # override ``transition`` and ``process_noise``; the motion model applies them generically.
    # Such a block must be additive (nominal_size == error_size) and decay component-wise.
    dynamic = False

    def transition(self, dt: float) -> list[float]:
        """Per-component decay a over dt: x' = a x (so the error also maps as a dx); F's diagonal."""
        return [1.0] * self.error_size

    def process_noise(self, dt: float) -> list[float]:
        """Discrete variance added to each error component over dt (beyond ``random_walk``)."""
        return [0.0] * self.error_size

    # True when boxplus is plain addition, x[n0 + i] += dx[e0 + i] (nominal_size == error_size):
    # the layout then adds such blocks in one loop instead of a call per block. A block whose
    # boxplus does anything else must set it False.
    additive = True

    def boxplus(self, x: list[float], dx: list[float], n0: int, e0: int) -> None:
        """Inject the correction dx[e0:e0+error_size] into x[n0:n0+nominal_size], in place."""
        for i in range(self.nominal_size):
            x[n0 + i] += dx[e0 + i]


# Where the pose sits in every layout (its first block: ``StateLayout`` refuses any other order). Outside
# the estimator the pose is read through these names (and ``ErrorStateEKF.position`` / ``attitude`` /
# ``yaw_variance``), never by bare indices: the nominal position x[POSITION], the attitude quaternion
# x[ATTITUDE] (x y z w), and in the error state the position's rows POSITION_ROWS (POSITION_ERR), the
# pose's (POSE_ERR: position, then attitude) and the heading's row YAW_ROW (the global attitude error's z).
POSITION = slice(0, 3)
ATTITUDE = slice(3, 7)
POSE = slice(0, 7)
POSITION_ROWS = (0, 1, 2)
POSITION_ERR = slice(0, 3)
POSE_ERR = slice(0, 6)
YAW_ROW = 5


def position_of(x) -> tuple[float, float, float]:
    """The position of a nominal state vector, as floats."""
    return (float(x[0]), float(x[1]), float(x[2]))


def attitude_of(x) -> tuple[float, float, float, float]:
    """The attitude quaternion (x y z w) of a nominal state vector, as floats."""
    return (float(x[3]), float(x[4]), float(x[5]), float(x[6]))


def add_motion_noise(Q: np.ndarray, xx: float = 0.0, xy: float = 0.0, yy: float = 0.0, yaw: float = 0.0) -> None:
    """Add to a prediction's error covariance Q, in place, a horizontal position covariance
    [[xx, xy], [xy, yy]] (m^2) and a heading variance (rad^2): motion the model's inputs did not describe."""
    Q[0, 0] += xx
    Q[0, 1] += xy
    Q[1, 0] += xy
    Q[1, 1] += yy
    Q[YAW_ROW, YAW_ROW] += yaw


class PoseBlock(StateBlock):
    """Position (3) and unit quaternion (4, x y z w); error: dp (3), global dtheta (3)."""

    name = "pose"
    nominal_size = 7
    error_size = 6
    additive = False

    def __init__(self, position_sigma: float = 0.0, attitude_sigma: float = 0.1) -> None:
        self.position_sigma = position_sigma
        self.attitude_sigma = attitude_sigma

    def initial(self) -> list[float]:
        return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]

    def initial_sigma(self) -> list[float]:
        return [self.position_sigma] * 3 + [self.attitude_sigma] * 3

    def boxplus(self, x: list[float], dx: list[float], n0: int, e0: int) -> None:
        # p += dp; q = Exp(dtheta) q (global attitude error)
        x[n0] += dx[e0]
        x[n0 + 1] += dx[e0 + 1]
        x[n0 + 2] += dx[e0 + 2]
        x[n0 + 3 : n0 + 7] = rot.turn(dx[e0 + 3], dx[e0 + 4], dx[e0 + 5], x[n0 + 3 : n0 + 7])


InputName = Literal["linear", "angular"]
Vec3 = tuple[float, float, float]


class InputBlock(StateBlock):
    """A block that corrects one motion input (u' = g(u, x_block)).

    The motion model chains its own input Jacobian G with the block's to get
    this block's columns of F, so the block never touches the motion model.
    """

    corrects: InputName = "angular"
    scales_input = False  # True when d u'/d u is not the identity (see input_derivative)
    # Which of the compiled motion model's block kinds this is (_kernels.c, BLOCK_*): its correct,
    # chain and input_derivative written there too, held equal to these by tests/unit/test_kernels.py.
    # 0: none, and a layout with such a block predicts on the Python path.
    kernel_code = 0

    def applies(self, from_gyro: bool) -> bool:
        return True

    def correct(self, xb: list[float], u: Vec3) -> Vec3:
        raise NotImplementedError

    def input_jacobian(self, xb: list[float], u: Vec3) -> np.ndarray:
        """d u' / d (block error), shape (3, error_size)."""
        raise NotImplementedError

    def input_derivative(self, xb: list[float], u: Vec3) -> tuple[float, ...] | None:
        """d u' / d u as a row-major 9-tuple; None for the identity (an additive correction).

        When several blocks correct the same input in turn, the motion model chains the
        earlier blocks' columns through the later blocks' input derivatives.
        """
        return None

    def chain(self, G: tuple[float, ...], xb: list[float], u: Vec3) -> tuple[float, ...] | list[float]:
        """This block's columns of F: G (d state / d input, row-major 3x3) times the input Jacobian,
        as 3 x error_size floats, row-major (the motion model writes them into F at once).

        Blocks may override it with a cheaper closed form.
        """
        return np.dot(np.array(G).reshape(3, 3), self.input_jacobian(xb, u)).ravel().tolist()


class ScalarInputBlock(InputBlock):
    """An input block with one state: its nominal value starts at ``start`` (the input as measured),
    with a prior ``sigma`` around it and a random walk ``walk`` per sqrt(s)."""

    nominal_size = 1
    error_size = 1
    scales_input = True
    start = 0.0

    def __init__(self, sigma: float, walk: float) -> None:
        self.sigma = sigma
        self.walk = walk

    def initial(self) -> list[float]:
        return [self.start]

    def initial_sigma(self) -> list[float]:
        return [self.sigma]

    def random_walk(self) -> list[float]:
        return [self.walk]

    def boxplus(self, x: list[float], dx: list[float], n0: int, e0: int) -> None:
        x[n0] += dx[e0]


class GyroBiasBlock(InputBlock):
    """Additive gyro bias: omega = omega_measured - b. Only applies to gyro-driven rates."""

    name = "gyro_bias"
    nominal_size = 3
    error_size = 3
    corrects = "angular"
    kernel_code = 1  # _kernels.c BLOCK_GYRO_BIAS
    _MINUS_I = -np.eye(3)

    def __init__(self, sigma: float = 0.01, walk: float = 2e-5) -> None:
        self.sigma = sigma
        self.walk = walk

    def initial_sigma(self) -> list[float]:
        return [self.sigma] * 3

    def random_walk(self) -> list[float]:
        return [self.walk] * 3

    def applies(self, from_gyro: bool) -> bool:
        return from_gyro

    def boxplus(self, x: list[float], dx: list[float], n0: int, e0: int) -> None:
        x[n0] += dx[e0]
        x[n0 + 1] += dx[e0 + 1]
        x[n0 + 2] += dx[e0 + 2]

    def correct(self, xb: list[float], u: Vec3) -> Vec3:
        return (u[0] - xb[0], u[1] - xb[1], u[2] - xb[2])

    def input_jacobian(self, xb: list[float], u: Vec3) -> np.ndarray:
        return self._MINUS_I

    def chain(self, G: tuple[float, ...], xb: list[float], u: Vec3):
        g0, g1, g2, g3, g4, g5, g6, g7, g8 = G  # G (-I) = -G
        return (-g0, -g1, -g2, -g3, -g4, -g5, -g6, -g7, -g8)


class YawOffsetBlock(StateBlock):
    """The offset o of an absolute-yaw sensor's heading reference: it reads yaw + o.

    A magnetometer's yaw carries declination, mounting offsets and disturbances near motors
    and steel that last seconds to minutes; a constant plus a slow random walk. It is
    observable only beside an absolute position or pose (GPS track, pose sensor), which pin
    the heading itself; the gyro then carries the heading between, and the yaw reading mostly
    moves o (when the walk is large against the gyro's) instead of the heading.
    """

    name = "yaw_offset"
    nominal_size = 1
    error_size = 1

    def __init__(self, sigma: float, walk: float) -> None:
        self.sigma = sigma
        self.walk = walk

    def initial_sigma(self) -> list[float]:
        return [self.sigma]

    def random_walk(self) -> list[float]:
        return [self.walk]


def hold_heading_of(q: rot.Quat, heading: float) -> rot.Quat:
    """q turned about world z back to ``heading``, its roll and pitch unchanged.

    A roll/pitch-only update corrects the attitude about world x/y; with the body tilted that
    still turns its Euler yaw a little (second order). The update holds heading by
    construction (its gain's yaw row is masked), so this puts the yaw back exactly.
    """
    return rot.mul(rot.exp(0.0, 0.0, rot.wrap(heading - rot.yaw(q))), q)


class StateLayout:
    """Offsets of each block in the nominal vector and in the error vector."""

    def __init__(self, blocks: list[StateBlock]) -> None:
        if not blocks or not isinstance(blocks[0], PoseBlock):
            raise ValueError("the first block must be the pose")
        self.blocks = blocks
        self.nominal: dict[str, slice] = {}
        self.error: dict[str, slice] = {}
        n = e = 0
        for b in blocks:
            if b.name in self.nominal:
                raise ValueError(f"duplicate state block {b.name!r}")
            self.nominal[b.name] = slice(n, n + b.nominal_size)
            self.error[b.name] = slice(e, e + b.error_size)
            n += b.nominal_size
            e += b.error_size
        self.nominal_dim = n
        self.error_dim = e
        self.input_blocks = [
            (b, self.nominal[b.name].start, self.nominal[b.name].stop, self.error[b.name])
            for b in blocks
            if isinstance(b, InputBlock)
        ]
        self._offsets = [(b, self.nominal[b.name].start, self.error[b.name].start) for b in blocks]
        for b in blocks:
            if (b.dynamic or b.additive) and b.nominal_size != b.error_size:
                raise ValueError(f"state block {b.name!r} is declared additive but its sizes differ")
        # Everything after the pose is additive (the usual case): boxplus adds it in one loop,
        # nominal component i taking error component i - 1 (the quaternion's extra slot).
        self._additive_tail = all(b.additive for b in blocks[1:])
        self._position_rows: dict[str | None, np.ndarray] = {}
        # Blocks with their own dynamics; empty for odometry/IMU-only layouts (predict skips them).
        self.dynamic_blocks = [(b, n0, e0) for b, n0, e0 in self._offsets if b.dynamic]
        walk = np.concatenate([np.asarray(b.random_walk(), float) for b in blocks])
        self.random_walk_var = walk**2

    def position_rows(self, error: str | None = None) -> np.ndarray:
        """The Jacobian of a position observation (``observations.position``) before its lever's columns: the
        identity on the position's error (and on the additive 3-block ``error``). Made once per block; the
        caller copies it (every GPS fix's two blocks built it from zeros)."""
        rows = self._position_rows.get(error)
        if rows is None:
            rows = np.zeros((3, self.error_dim))
            rows[0, 0] = rows[1, 1] = rows[2, 2] = 1.0
            if error is not None:
                rows[0:3, self.error[error]] = np.eye(3)
            rows.flags.writeable = False
            self._position_rows[error] = rows
        return rows

    def noise_density(self, pose_noise_var: np.ndarray) -> np.ndarray:
        """Per-second variance of every error component: pose model error + random walks."""
        d = self.random_walk_var.copy()
        d[0:6] += pose_noise_var
        return d

    def has(self, name: str) -> bool:
        return name in self.nominal

    def index(self, name: str, component: int = 0, error: bool = False) -> int:
        """Where a block's component sits in x (or, ``error``, in the error state); -1 without the block."""
        if name not in self.nominal:
            return -1
        return (self.error if error else self.nominal)[name].start + component

    def initial_state(self) -> np.ndarray:
        return np.concatenate([np.asarray(b.initial(), float) for b in self.blocks])

    def initial_covariance(self) -> np.ndarray:
        sig = np.concatenate([np.asarray(b.initial_sigma(), float) for b in self.blocks])
        return np.diag(sig**2)

    def boxplus(self, x: np.ndarray, dx: np.ndarray, hold_heading: bool = False) -> None:
        """x [+]= dx, in place.

        ``hold_heading``: the attitude keeps its yaw exactly (see ``hold_heading``).
        """
        xl = x.tolist()
        dl = dx.tolist()
        if hold_heading:
            heading = rot.yaw(tuple(xl[3:7]))
        if self._additive_tail:
            # PoseBlock.boxplus at offset 0 (p += dp, q = Exp(dtheta) q), then the additive blocks
            # after the quaternion's extra slot: x_i += dx_(i-1)
            xl[0] += dl[0]
            xl[1] += dl[1]
            xl[2] += dl[2]
            xl[3:7] = rot.turn(dl[3], dl[4], dl[5], xl[3:7])
            for i in range(7, len(xl)):
                xl[i] += dl[i - 1]
        else:
            for b, n0, e0 in self._offsets:
                b.boxplus(xl, dl, n0, e0)
        if hold_heading:
            xl[3:7] = hold_heading_of(tuple(xl[3:7]), heading)
        x[:] = xl

    def boxminus(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """a [-] b in the error space (inverse of boxplus); used by numeric Jacobians."""
        out = np.empty(self.error_dim)
        for blk in self.blocks:
            ns, es = self.nominal[blk.name], self.error[blk.name]
            if isinstance(blk, PoseBlock):
                out[es.start : es.start + 3] = a[ns][0:3] - b[ns][0:3]
                qa = tuple(a[ns][3:7].tolist())
                qb = tuple(b[ns][3:7].tolist())
                out[es.start + 3 : es.stop] = rot.log(rot.mul(qa, rot.conj(qb)))
            else:
                out[es] = a[ns] - b[ns]
        return out
