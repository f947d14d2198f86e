"""Faults applied to simulated sample streams after the fact (the doctor's tests).

Each takes the samples a simulator produced (in arrival order) and returns them as a driver or a
recorder would have delivered them: a logging gap, a driver's stated gyro covariance, a yaw rate
marked "not measured", a sensor stamping with another clock. The physics is untouched, so what
the doctor must find is exactly the fault applied.
"""

from __future__ import annotations

import msgspec

from fusiond.core.sensors import ImuSample, OdomSample


def drop_span(samples: list, t0: float, t1: float) -> list:
    """A logging gap: every topic silent for stamps in [t0, t1) (absolute stamps); the robot moves on."""
    return [s for s in samples if not t0 <= s.stamp < t1]


def state_gyro_variance(samples: list, variance: float) -> list:
    """The IMU's messages state this gyro variance on each axis (razor_imu_9dof states 0.02 rad^2/s^2)."""
    cov = (variance, 0.0, 0.0, 0.0, variance, 0.0, 0.0, 0.0, variance)
    return [msgspec.structs.replace(s, angular_velocity_covariance=cov) if isinstance(s, ImuSample) else s
            for s in samples]


def mark_yaw_rate_unmeasured(samples: list, variance: float = 1e6, value: float = 0.0) -> list:
    """The odometry driver has no yaw rate: it sends ``value`` with variance 1e6 ("not measured")."""
    out = []
    for s in samples:
        if isinstance(s, OdomSample):
            cov = list(s.twist_covariance)
            cov[35] = variance
            s = msgspec.structs.replace(s, angular=(s.angular[0], s.angular[1], value), twist_covariance=tuple(cov))
        out.append(s)
    return out


def shift_stamps(samples: list, sensor: str, offset: float) -> list:
    """One sensor stamps with another clock (GPS time is 18 s ahead of UTC): its stamps move by offset,
    its messages still arrive when they did (the list order is the arrival order)."""
    return [msgspec.structs.replace(s, stamp=s.stamp + offset) if s.sensor == sensor else s for s in samples]
