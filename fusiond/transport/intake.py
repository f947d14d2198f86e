"""The input side's policies that need no daemon: which kind a sensor is, how a callback runs on
Zenoh's receive thread, and which accepted samples health counts as zero-covariance floored.

Kept apart from the daemon's threading and life cycle (`daemon.py`) because the bag player
and the latency bench use them too.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from typing import Any

import zenoh

from .thread_state import with_kept_thread_state

__all__ = ["direct", "sensor_kind", "zero_covariance_check"]


def sensor_kind(sensor: Any) -> str:
    """The config's `kind` tag (msgspec keeps it on the class)."""
    return str(type(sensor).__struct_config__.tag)


def direct(callback: Callable[[Any], None]) -> Any:
    """Run a non-blocking callback on Zenoh's receive thread (unstable zenoh-python option; else as is),
    keeping that thread's Python thread state between calls (`thread_state.py`)."""
    try:
        return zenoh.handlers.Callback(with_kept_thread_state(callback), indirect=False)
    except (AttributeError, TypeError):
        return callback


def zero_covariance_check(sensor: Any) -> Callable[[Any], bool] | None:
    """For health's `zero_covariance_floored`: does an accepted sample carry a zero variance that
    the sensor's floor replaces? Real drivers send all-zero covariances (robot_pose_ekf's "zero
    covariance" case); they are accepted with floors, and counted so an operator sees it. None when
    the config overrides the message covariances (they are not read) or the kind has no such check."""
    kind = sensor_kind(sensor)
    if kind == "odom":
        if sensor.twist_noise is not None:
            return None
        variances = operator.itemgetter(0, 7, 14, 21, 28, 35)  # the diagonal of the 6x6
        return lambda s: 0.0 in variances(s.twist_covariance)
    if kind == "imu":
        use_orientation = sensor.orientation != "off" and sensor.orientation_noise is None
        use_gyro = sensor.angular_velocity and sensor.gyro_noise is None
        if not (use_orientation or use_gyro):
            return None

        def check(s: Any) -> bool:
            oc, gc = s.orientation_covariance, s.angular_velocity_covariance
            if use_orientation and oc[0] != -1.0 and (oc[0] == 0.0 or oc[4] == 0.0 or oc[8] == 0.0):
                return True
            return use_gyro and gc[0] != -1.0 and (gc[0] == 0.0 or gc[4] == 0.0 or gc[8] == 0.0)

        return check
    return None
