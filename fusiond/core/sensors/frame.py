"""World-frame helpers shared by the absolute sensors (GPS, pose)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ...estimator import mat3
from ...estimator import attitude_of
from ...estimator import rotation as rot

if TYPE_CHECKING:
    from ..state import FilterState


def set_position(s: FilterState, z, cov9, offset, rows: tuple[int, ...] = (0, 1, 2)) -> None:
    """Put the base where the sensor says (p = z - R t), with the sensor's position covariance."""
    ekf = s.ekf
    a = lever(ekf.x, offset)
    ekf.set_position([z[i] - a[i] for i in range(3)], rows)
    ekf.reset_covariance(list(rows), np.array([[cov9[3 * i + j] for j in rows] for i in rows]))


def new_frame(s: FilterState) -> None:
    """The world frame was defined or turned under the state: what a sensor measured relative to
    the old one (a differential pose sensor's anchor) restarts from its next message."""
    s.frame_epoch += 1


def lever(x: np.ndarray, t: tuple[float, float, float]) -> tuple[float, float, float]:
    """R(q) t: the sensor's offset from base_link, in the world."""
    return mat3.apply(rot.matrix9(attitude_of(x)), t)
