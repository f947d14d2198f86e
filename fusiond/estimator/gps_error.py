"""GPS error as a first-order Gauss-Markov state (ENU, metres).

Real GPS error is not white: multipath and atmosphere make it wander over tens
of seconds, and receivers sometimes repeat a fix for seconds. Modelled as
db/dt = -b / tau + w, it is exactly discretised as

    b(t + dt) = exp(-dt / tau) b,    Q = sigma^2 (1 - exp(-2 dt / tau)),

with sigma the steady-state standard deviation per axis (east, north, up). The
state is nominal additive; the GPS observation becomes h = p + R t + b. With
odometry tying consecutive positions together, the filter can then average the
slow error over ~tau instead of following it fix by fix.
"""

from __future__ import annotations

import math

from ..errors import EstimatorError

from .state import StateBlock


class GpsErrorBlock(StateBlock):
    """b (3, ENU): Gauss-Markov with time constant ``tau`` and steady-state std devs ``sigma``."""

    name = "gps_error"
    nominal_size = 3
    error_size = 3
    dynamic = True

    def __init__(self, tau: float, sigma: tuple[float, float, float]) -> None:
        if not tau > 0.0:
            raise EstimatorError("gps error time constant must be positive")
        self.tau = float(tau)
        self.sigma = tuple(float(s) for s in sigma)
        self._var = tuple(s * s for s in self.sigma)

    def initial_sigma(self) -> list[float]:
        return list(self.sigma)  # the stationary distribution

    def transition(self, dt: float) -> list[float]:
        a = math.exp(-dt / self.tau)
        return [a, a, a]

    def process_noise(self, dt: float) -> list[float]:
        k = -math.expm1(-2.0 * dt / self.tau)  # 1 - exp(-2 dt / tau), accurate for small dt
        v0, v1, v2 = self._var
        return [v0 * k, v1 * k, v2 * k]

    def kernel_decay(self) -> tuple[float, tuple[float, ...]]:
        """(tau, per-axis variance): what ``_kernels.predict`` needs to run ``transition`` and
        ``process_noise`` itself, with the same expressions (a subclass that changes them does not
        inherit this, so it keeps the Python path)."""
        return self.tau, self._var

    def boxplus(self, x: list[float], dx: list[float], n0: int, e0: int) -> None:
        x[n0] += dx[e0]
        x[n0 + 1] += dx[e0 + 1]
        x[n0 + 2] += dx[e0 + 2]
