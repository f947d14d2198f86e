"""A twist component that is not a measurement: found at run time against the gyro.

A driver that lost (or never had) a rate fills it in: the F1/10's logger wrote its angular
columns as 0 with covariance 0, and by its covariance that is a perfect measurement of "not
turning". Taken at its word it is read as slip at every turn, teaches a wheel yaw scale of 0 and
turns the heading across logging gaps by nothing. ``twist_measured`` declares it; a new user
does not know to. So the odometry watches each angular component it takes as measured: one that
has read the same value, bit for bit, since the first message while the gyro turned on that axis
beyond its quiet bound (noise plus the bias's prior range, ``imu/gyro_bias.quiet_bound``), and away
from that value by as much, for LOST_AFTER consecutive odometry messages is not measured from then on (logged once as
``twist_component_lost``; the doctor names the ``twist_measured`` to declare).

The rule's false alarm is bounded by its parts: a real rate reads the same double at every
message only when nothing moves it (a drive reading a steady turn as one double from its first
message, which the gyro agrees with, is not refuted by it), and the quiet bound is three sigma of the gyro's noise and
the prior bias each, exceeded by chance with probability < 0.0027 per message, so LOST_AFTER = 5
in a row is < 1e-12 per message. Linear components have no such witness (the accelerometer's
integral drifts): a lost speed is the user's to declare.
"""

from __future__ import annotations

LOST_AFTER = 5  # consecutive odometry messages of a constant component while the gyro turns on its axis
TWIST = ("vx", "vy", "vz", "wx", "wy", "wz")  # twist_measured's order
ANGULAR = TWIST[3:]


def watch(watched: tuple | None, angular: tuple, measured: tuple, gyro: tuple | None,
          bounds: tuple | None) -> tuple:
    """(first values, per component: the run of turning messages, -1 when no longer a candidate, or -2 when
    lost; whether any is still a candidate; whether any is lost) after one message. ``gyro``: the
    bias-corrected gyro rates now (None: not fused or stale); ``bounds``: each axis's quiet bound."""
    if watched is None:
        runs = tuple(0 if measured[3 + i] else -1 for i in range(3))
        return (angular, runs, any(r >= 0 for r in runs), False)
    first, runs = watched[0], watched[1]
    out = list(runs)
    for i in range(3):
        r = runs[i]
        if r < 0:
            continue
        if angular[i] != first[i]:
            out[i] = -1  # it moved: a measurement
        elif gyro is not None and abs(gyro[i]) > bounds[i] and abs(gyro[i] - first[i]) > bounds[i]:
            out[i] = -2 if r + 1 >= LOST_AFTER else r + 1
        else:
            out[i] = 0
    return (first, tuple(out), any(r >= 0 for r in out), any(r == -2 for r in out))


def lost(watched: tuple | None) -> tuple[bool, bool, bool]:
    """Which angular components are found lost."""
    if watched is None:
        return (False, False, False)
    runs = watched[1]
    return (runs[0] == -2, runs[1] == -2, runs[2] == -2)


__all__ = ["ANGULAR", "LOST_AFTER", "TWIST", "lost", "watch"]
