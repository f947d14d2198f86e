"""Standstill from evidence: the wheels' twist consistent with zero within its own noise.

A drive that reads exactly zero at rest is the easy case. Many do not: a car's wheel-speed
sensors read a few cm/s of noise while it stands, a skid-steer's encoders jitter. Waiting for
an exact zero, such a robot never stands still for the filter and never teaches it the gyro's
bias. So rest is a test on the odometry's window of the last ``standstill_s`` (at least
MIN_WINDOW messages), in the manner of the zero-velocity detectors of inertial navigation
(Skog et al., "Zero-velocity detection: an algorithm evaluation", IEEE TBME 2010).

Model. Under H0 "at rest" each measured twist component reads white noise about zero; the
alternative is a steady motion (a creep, a slow turn in place) under the same noise. The noise
is the one the window itself shows, not the stated one: drivers state it badly both ways (a
Jackal states 0.17 rad/s for a yaw rate that jitters by 0.002, so by its statement a turn in place
at 0.009 rad/s would be rest; a car states 0.01 m/s for a speed that jitters by 0.03 at rest). The
test per component i is then Student's: with N readings of mean m_i and noise s_i (from first
differences, which a steady motion does not move),

    t_i^2 = N m_i^2 / s_i^2   against   t(1 - alpha / (2 k); nu)^2

over the k measured components (Bonferroni: a true standstill's window is refused with
probability at most ``standstill_alpha``), nu = 2 (N - 1) / 3, the effective degrees of freedom of
a variance from overlapping differences. s_i is floored at RESOLUTION: a stream of exact zeros
has no noise to measure, and the old rule ("below 1 mm/s is zero") is the resolution it implied.

What the test can tell is physics: a creep c shows once N c^2 / s^2 passes the bound, so under
0.03 m/s of noise at 50 Hz over 0.3 s (N = 15) a creep of 0.04 m/s is found and 0.02 m/s is not.
A missed creep costs little: the gyro's bias is learned only where the gyro is quiet too
(``imu/gyro_bias.py``), and a robot creeping straight has a true turn rate of zero anyway.

Cost. While the robot moves the window is emptied by one comparison per component: a reading
beyond ``z(1 - alpha / (2 k))`` of the stream's running noise (``running_noise``, which motion only
raises) is not rest noise, and no window holding it could pass.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache, partial
from statistics import NormalDist
from typing import TYPE_CHECKING

from ....estimator import zero_motion
from ...diagnostics import t_quantile

if TYPE_CHECKING:
    from ....estimator.backend import Backend

MIN_WINDOW = 5  # messages a rest decision needs at least (a 10 Hz drive's 0.3 s holds only 3)
RESOLUTION = 1e-3  # m/s, rad/s: the smallest noise a rest window is judged with (module doc)
NOISE_MEMORY = 64.0  # messages: the running noise's exponential memory (a second or more of odometry)
GAP_FACTOR = 3.0  # a message more than this many periods after the previous one restarts the differences


@lru_cache(maxsize=64)
def normal_bound(alpha: float, k: int) -> float:
    """The two-sided normal quantile of size alpha shared over k components."""
    return NormalDist().inv_cdf(1.0 - alpha / (2.0 * k))


@lru_cache(maxsize=1024)
def t2_bound(alpha: float, k: int, n: int) -> float:
    """The squared Student bound of one component's t over a window of n readings (module doc)."""
    return t_quantile(normal_bound(alpha, k), 2.0 * (n - 1) / 3.0) ** 2


def running_noise(track: tuple | None, values: tuple, stamp: float, period: float,
                  backend: Backend | None = None) -> tuple:
    """The twist's running noise per component after ``values``: (values, the variance per component or None,
    weight, stamp). An exponentially weighted mean of the squared first differences over ~NOISE_MEMORY
    messages, halved (a difference of two white readings has twice the variance); motion only raises it, so
    it bounds the rest noise from above. A message after a gap (GAP_FACTOR periods) starts the differences
    again (a gap's jump is not noise). ``zero_motion.difference_noise``, run by ``backend`` (default: the
    reference)."""
    noise = zero_motion.difference_noise if backend is None else backend.difference_noise
    return noise(track, values, stamp, period, GAP_FACTOR, NOISE_MEMORY)


def rest_window(window: tuple, values: tuple, measured: tuple, running: tuple | None, stamp: float, span: float,
                alpha: float, backend: Backend | None = None) -> tuple[tuple, bool]:
    """The rest window after one message, and whether the wheels are at rest now (module doc).

    ``window`` holds the six twist components (unmeasured ones 0) and stamps of the last ``span``
    seconds, at least MIN_WINDOW messages; ``running`` is ``running_noise``'s variance per component.
    ``zero_motion.zero_mean_window`` with this test's bounds, run by ``backend`` (default: the reference)."""
    k = sum(measured)
    if k == 0:
        return (), False
    z, bound = _bounds(alpha, k)
    test = zero_motion.zero_mean_window if backend is None else backend.zero_mean_window
    return test(window, values, measured, running, stamp, span, z, MIN_WINDOW, RESOLUTION * RESOLUTION, bound)


@lru_cache(maxsize=64)
def _bounds(alpha: float, k: int) -> tuple[float, Callable[[int], float]]:
    """The early exit's normal bound over a window's first MIN_WINDOW messages and the Student bound by the
    window's length, for k measured components (module doc)."""
    return normal_bound(0.5 * alpha / MIN_WINDOW, k), partial(t2_bound, 0.5 * alpha, k)


__all__ = ["MIN_WINDOW", "RESOLUTION", "normal_bound", "rest_window", "running_noise", "t2_bound"]
