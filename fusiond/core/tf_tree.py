"""The TF tree Nav2 expects beside a GPS or an absolute pose: map -> odom -> base_link (REP-105).

fusiond runs one filter. Without an absolute sensor its estimate is the odometry frame and the
daemon publishes it as ``odom -> base_link``. With a GPS or an absolute pose the estimate is
the world (``map``) pose, and it jumps: a fix corrects it, a GPS heading found late turns it.
REP-105 wants ``odom -> base_link`` continuous, so Nav2's local planner and costmaps never see
the robot leap; robot_localization gets that from a second, local EKF and lets navsat's global
EKF publish the jumps as ``map -> odom``.

Here the continuous frame is dead-reckoned from the filter's own motion instead of a second
filter: ``OdomFrame`` integrates the published twist (already corrected for the learned gyro
bias and wheel scale) between consecutive poses, and takes roll and pitch from the estimate
(they are gravity-referenced in both frames, as REP-105's z-up odom frame is). Both frames then
share the vertical, so ``map -> odom`` is a translation and a turn about z, and it alone carries
the corrections. ``map_to_odom`` is that world correction, pure SE(3) algebra:
``map->odom = map->base_link * inverse(odom->base_link)``.
"""

from __future__ import annotations

import math

from ..config_tables import Config
from ..errors import CoreError
from ..estimator import rotation as rot
from .layout import absolute_sensor

__all__ = ["Transform", "compose", "inverse", "map_to_odom", "OdomFrame", "tf_tree_active"]

Vec3 = tuple[float, float, float]
Transform = tuple[Vec3, rot.Quat]  # (translation, unit quaternion x y z w): parent -> child


def tf_tree_active(cfg: Config) -> bool:
    """Does this config publish map -> odom -> base_link? With TF on, a sensor defining the world
    (a GPS, an absolute pose) and a map frame distinct from the odometry frame; otherwise the one
    transform frame_id -> child_frame_id of the estimate, as without a world sensor."""
    out = cfg.output
    return (out.publish_tf and out.map_frame not in ("", out.frame_id)
            and any(absolute_sensor(s) for s in cfg.sensors))


def _rotate(q: rot.Quat, v: Vec3) -> Vec3:
    """R(q) v, by the quaternion sandwich written out (no matrix, no numpy: runs per pose)."""
    qx, qy, qz, qw = q
    vx, vy, vz = v
    # t = 2 q_vec x v; v' = v + w t + q_vec x t
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (vx + qw * tx + (qy * tz - qz * ty),
            vy + qw * ty + (qz * tx - qx * tz),
            vz + qw * tz + (qx * ty - qy * tx))


def compose(a: Transform, b: Transform) -> Transform:
    """a * b: the child of ``b`` seen from the parent of ``a`` (tf2's multiplication)."""
    (pa, qa), (pb, qb) = a, b
    r = _rotate(qa, pb)
    return (pa[0] + r[0], pa[1] + r[1], pa[2] + r[2]), rot.normalize(rot.mul(qa, qb))


def inverse(a: Transform) -> Transform:
    """The transform back: inverse(a) * a is the identity."""
    p, q = a
    qi = rot.conj(q)
    r = _rotate(qi, p)
    return (-r[0], -r[1], -r[2]), qi


def map_to_odom(map_base: Transform, odom_base: Transform) -> Transform:
    """The world correction: map->odom = map->base_link * inverse(odom->base_link), so that
    composing it with odom->base_link gives map->base_link again (what tf2 does for Nav2)."""
    return compose(map_base, inverse(odom_base))


class OdomFrame:
    """The continuous odometry frame's pose of base_link, dead-reckoned from the filter's twist.

    ``advance`` is fed every published estimate (stamp, world pose, body twist) and moves the
    odometry pose by the twist held since the previous one (zero-order hold, as the filter's
    own prediction holds its inputs), at most ``max_step_s`` of it: across a logging gap the
    filter stops holding its inputs too, and what the world pose did meanwhile is a correction.
    Heading and position integrate; roll and pitch are the estimate's. A stamp that does not
    advance (a late sample answered at a stamp already published, a clock reset) leaves the
    frame where it is. The first estimate defines the frame: odom and map coincide there.
    """

    __slots__ = ("max_step_s", "stamp", "position", "orientation", "_linear", "_angular")

    def __init__(self, max_step_s: float) -> None:
        if not max_step_s > 0.0:
            raise CoreError(f"max_step_s must be positive, got {max_step_s}")
        self.max_step_s = max_step_s
        self.stamp: float | None = None
        self.position: Vec3 = (0.0, 0.0, 0.0)
        self.orientation: rot.Quat = rot.IDENTITY
        self._linear: Vec3 = (0.0, 0.0, 0.0)
        self._angular: Vec3 = (0.0, 0.0, 0.0)

    def advance(self, stamp: float, position: Vec3, orientation: rot.Quat, linear: Vec3,
                angular: Vec3) -> Transform:
        """odom->base_link at ``stamp``, given the estimate there (world pose and body twist)."""
        if self.stamp is None:
            self.position, self.orientation = tuple(position), rot.normalize(tuple(orientation))
        elif stamp > self.stamp:
            dt = min(stamp - self.stamp, self.max_step_s)
            wx, wy, wz = self._angular
            q = self.orientation
            mid = rot.advance(q, 0.5 * wx * dt, 0.5 * wy * dt, 0.5 * wz * dt)
            vx, vy, vz = self._linear
            d = _rotate(mid, (vx * dt, vy * dt, vz * dt))
            p = self.position
            self.position = (p[0] + d[0], p[1] + d[1], p[2] + d[2])
            heading = rot.yaw(rot.advance(q, wx * dt, wy * dt, wz * dt))
            self.orientation = _with_heading(rot.normalize(tuple(orientation)), heading)
        else:
            return self.position, self.orientation
        self.stamp = stamp
        self._linear, self._angular = tuple(linear), tuple(angular)
        return self.position, self.orientation


def _with_heading(q: rot.Quat, heading: float) -> rot.Quat:
    """``q``'s roll and pitch under the yaw ``heading``: Rz(heading - yaw(q)) q."""
    turn = rot.wrap(heading - rot.yaw(q))
    return rot.normalize(rot.mul((0.0, 0.0, math.sin(0.5 * turn), math.cos(0.5 * turn)), q))
