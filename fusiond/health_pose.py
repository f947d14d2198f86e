"""The latest pose in the health answer: where the filter thinks the robot is, and how sure it is.

An operator (or `fusiond set-pose`, or a fleet monitor) asks the health queryable "is it fine?" and
"where is it?" in one query; without the pose they had to subscribe to the CDR pose topic and decode
it. Built by the thread that feeds the core (with the rest of the core's counters), from the same
estimate the daemon publishes, so it is the published pose of that moment, in the published frame.

- ``sigma_xy``: the horizontal position's standard deviation along its worst direction (the square
  root of the larger eigenvalue of the x/y covariance block), so a long, thin uncertainty (a GPS
  with good across-track and poor along-track) is not averaged away.
- ``sigma_yaw``: the heading's standard deviation; large while the heading is unknown (a GPS that
  has not yet seen the robot travel), which ``filter.heading_known`` says in words.
- ``null`` before the first published pose (nothing fused yet, or the world frame not yet defined).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import msgspec

from .core.tf_tree import tf_tree_active
from .estimator import rotation as rot

if TYPE_CHECKING:
    from .core.fusion import Estimate

__all__ = ["PoseHealth", "pose_health", "sigma_worst_xy"]


class PoseHealth(msgspec.Struct, kw_only=True):
    """The newest published pose: stamp (message time), frame, position (m), yaw/roll/pitch (rad), sigmas."""

    stamp: float
    frame_id: str
    position: tuple[float, float, float]
    yaw: float
    sigma_xy: float
    sigma_yaw: float
    roll: float = 0.0
    pitch: float = 0.0
    sigma_z: float = 0.0


def sigma_worst_xy(cov: list[float]) -> float:
    """sqrt of the larger eigenvalue of the x/y block of a row-major 6x6 pose covariance."""
    a, b, d = cov[0], 0.5 * (cov[1] + cov[6]), cov[7]
    half = 0.5 * (a + d)
    return math.sqrt(max(half + math.hypot(0.5 * (a - d), b), 0.0))


def pose_health(core: Any, est: Estimate | None = None) -> PoseHealth | None:
    """The core's newest estimate as the health answer's ``pose`` (module doc), or None before there is one
    to publish; in the frame the daemon publishes it in (``map_frame`` in a map -> odom tree, else frame_id).
    ``est``: that estimate when the caller has built it already (``core_counters``, for its finiteness)."""
    if not core.ready or not core.initialised:
        return None
    out = core.cfg.output
    frame_id = out.map_frame if tf_tree_active(core.cfg) else out.frame_id
    if est is None:
        est = core.estimate()
    cov = est.pose_covariance
    roll, pitch, yaw = rot.to_rpy(tuple(est.orientation))
    return PoseHealth(stamp=est.stamp, frame_id=frame_id, position=tuple(est.position), yaw=yaw,
                      sigma_xy=sigma_worst_xy(cov), sigma_yaw=math.sqrt(max(cov[35], 0.0)), roll=roll, pitch=pitch,
                      sigma_z=math.sqrt(max(cov[14], 0.0)))
