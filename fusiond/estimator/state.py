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
    """A piece of the state: sizes, initial value and uncertainty, boxplus."""

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

    def boxplus(self, xb: np.ndarray, dxb: np.ndarray) -> None:
        """Inject a tangent-space correction into the nominal block, in place."""
        xb += dxb


class PoseBlock(StateBlock):
    """Position (3) and unit quaternion (4, x y z w); error: dp (3), global dtheta (3)."""

    name = "pose"
    nominal_size = 7
    error_size = 6

    def __init__(self, position_sigma: float = 0.0, attitude_sigma: float = 0.1) -> None:
        self.position_sigma = position_sigma
        self.attitude_sigma = attitude_sigma

    def initial(self) -> list[float]:
        return [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]

    def initial_sigma(self) -> list[float]:
        return [self.position_sigma] * 3 + [self.attitude_sigma] * 3

    def boxplus(self, xb: np.ndarray, dxb: np.ndarray) -> None:
        xb[0:3] += dxb[0:3]
        q = rot.mul(rot.exp(float(dxb[3]), float(dxb[4]), float(dxb[5])), tuple(xb[3:7].tolist()))
        xb[3:7] = rot.normalize(q)


InputName = Literal["linear", "angular"]


class InputBlock(StateBlock):
    """A block that corrects one motion input (u' = g(u, x_block)).

    The motion model chains its own input Jacobian with ``input_jacobian`` to get
    this block's columns of F, so the block never touches the motion model.
    """

    corrects: InputName = "angular"

    def applies(self, from_gyro: bool) -> bool:
        return True

    def correct(self, xb: np.ndarray, u: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def input_jacobian(self, xb: np.ndarray, u: np.ndarray) -> np.ndarray:
        """d u' / d (block error), shape (3, error_size)."""
        raise NotImplementedError


class GyroBiasBlock(InputBlock):
    """Additive gyro bias: omega = omega_measured - b. Only applies to gyro-driven rates."""

    name = "gyro_bias"
    nominal_size = 3
    error_size = 3
    corrects = "angular"
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

    def correct(self, xb: np.ndarray, u: np.ndarray) -> np.ndarray:
        return u - xb

    def input_jacobian(self, xb: np.ndarray, u: np.ndarray) -> np.ndarray:
        return self._MINUS_I


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
        self.input_blocks = [b for b in blocks if isinstance(b, InputBlock)]
        walk = np.concatenate([np.asarray(b.random_walk(), float) for b in blocks])
        self.random_walk_var = walk**2

    def has(self, name: str) -> bool:
        return name in self.nominal

    def initial_state(self) -> np.ndarray:
        return np.concatenate([np.asarray(b.initial(), float) for b in self.blocks])

    def initial_covariance(self) -> np.ndarray:
        sig = np.concatenate([np.asarray(b.initial_sigma(), float) for b in self.blocks])
        return np.diag(sig**2)

    def boxplus(self, x: np.ndarray, dx: np.ndarray) -> None:
        for b in self.blocks:
            b.boxplus(x[self.nominal[b.name]], dx[self.error[b.name]])

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
