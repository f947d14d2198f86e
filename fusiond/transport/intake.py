"""The input side's policies that need no daemon: which kind a sensor is, how a callback runs on
Zenoh's receive thread, and which accepted samples health counts as zero-covariance floored.

Kept apart from the daemon's threading and life cycle (`daemon.py`) because the bag player
and the latency bench use them too.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import zenoh

from ..core.sensors.registry import kind_of
from .thread_state import with_kept_thread_state

__all__ = ["direct", "sensor_kind", "zero_covariance_check"]


def sensor_kind(sensor: Any) -> str:
    """The config's `kind` tag (its descriptor's name)."""
    return kind_of(sensor).name


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
    the config overrides the message covariances (they are not read) or the kind has no such check
    (``SensorKind.zero_covariance``)."""
    return kind_of(sensor).zero_covariance(sensor)
