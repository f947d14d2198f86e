"""Zero motion from a stream of twists: the noise the stream shows, and a window's test of a zero mean.

The reference of the backends' ``difference_noise`` and ``zero_mean_window`` (``_kernels.c`` computes the
same doubles: the same operations in the same order, Python's ``d ** 2`` as libm's ``pow`` of ``|d|``). The
odometry's standstill test (``core/sensors/odom/rest.py``) is their one user and says why they are so; here
is the arithmetic, with the model's constants and its bounds as arguments.
"""

from __future__ import annotations

from collections.abc import Callable

Twist = tuple[float, float, float, float, float, float]


def difference_noise(track: tuple | None, values: Twist, stamp: float, period: float, gap_factor: float,
                     memory: float) -> tuple:
    """The running noise per component after ``values``: (values, the variance per component or None, weight,
    stamp). An exponentially weighted mean (over ~``memory`` messages) of the squared first differences,
    halved (a difference of two white readings has twice the variance); a message more than ``gap_factor``
    periods after the previous one starts the differences again. Immutable tuples: the state is snapshotted."""
    if track is None:
        return (values, None, 0.0, stamp)
    prev, var, weight = track[0], track[1], track[2]
    if period > 0.0 and stamp - track[3] > gap_factor * period:
        return (values, var, weight, stamp)
    weight = weight + 1.0 if weight < memory else memory
    a0, a1, a2, a3, a4, a5 = values
    b0, b1, b2, b3, b4, b5 = prev
    d = (0.5 * (a0 - b0) ** 2, 0.5 * (a1 - b1) ** 2, 0.5 * (a2 - b2) ** 2,
         0.5 * (a3 - b3) ** 2, 0.5 * (a4 - b4) ** 2, 0.5 * (a5 - b5) ** 2)
    if var is None:
        return (values, d, weight, stamp)
    g = 1.0 / weight
    v0, v1, v2, v3, v4, v5 = var
    return (values, (v0 + g * (d[0] - v0), v1 + g * (d[1] - v1), v2 + g * (d[2] - v2),
                     v3 + g * (d[3] - v3), v4 + g * (d[4] - v4), v5 + g * (d[5] - v5)), weight, stamp)


def zero_mean_window(window: tuple, values: Twist, measured: tuple[bool, ...], running: tuple | None,
                     stamp: float, span: float, z: float, min_window: int, floor: float,
                     bound: Callable[[int], float]) -> tuple[tuple, bool]:
    """The window after one message, and whether its ``measured`` components read a zero mean.

    A reading beyond ``z`` running-noise sigmas (``running``, floored at ``floor`` as a variance) of zero ends
    the window at once. Otherwise the window holds (stamp, values) of the last ``span`` seconds, at least
    ``min_window`` messages, and each measured component's mean m over its n readings passes when
    n m^2 <= bound(n) s^2, s^2 from its first differences (halved, floored)."""
    zz = z * z
    if running is not None:
        for v, var, used in zip(values, running, measured):
            if used and v * v > zz * (var if var > floor else floor):
                return (), False  # beyond any rest noise the stream has shown: moving
    drop = 0
    n = len(window) + 1
    while n - drop > min_window and stamp - window[drop][0] >= span:
        drop += 1
    window = window[drop:] + ((stamp, values),)
    n = len(window)
    if n < min_window:
        return window, False
    b = bound(n)
    for i in range(6):
        if not measured[i]:
            continue
        total = 0.0
        diff2 = 0.0
        previous = None
        for entry in window:
            v = entry[1][i]
            total += v
            if previous is not None:
                diff2 += (v - previous) ** 2
            previous = v
        var = diff2 / (2.0 * (n - 1))
        if total * total / n > b * (var if var > floor else floor):
            return window, False
    return window, True


__all__ = ["Twist", "difference_noise", "zero_mean_window"]
