"""What the daemon puts on the TF key with each published estimate, and when.

- When: only for an estimate whose stamp is newer than the last TF's. tf2 rejects a repeated
  stamp, and a late odometry sample is answered with a pose at a stamp already published.
- What: without a sensor that defines the world, the estimate itself, frame_id ->
  child_frame_id (`odom -> base_link`). With a GPS or an absolute pose the estimate is the
  world pose, which jumps with every correction; Nav2 wants `map -> odom -> base_link` with a
  continuous odom frame, so each message holds both, built by the core's pure maths
  (`core/tf_tree.py`): the dead-reckoned odometry frame and the world correction.
- After a backwards clock jump (a bag replayed again, a simulation restarted) the core resets onto the
  new time base; so does the TF at once (its stamp bound and odometry frame start again), or Nav2 would
  lose `odom -> base_link` until the new stamps passed the old ones.
"""

from __future__ import annotations

from ..codecs import encode_tf_cdr, encode_tf_tree_cdr
from ..config import Config
from ..core.fusion import Estimate
from ..core.tf_tree import OdomFrame, map_to_odom, tf_tree_active

__all__ = ["TfBroadcast"]


class TfBroadcast:
    """The TF messages of one daemon (the core held): ``message`` per published estimate."""

    __slots__ = ("map_frame", "frame_id", "child_frame_id", "odom_frame", "pose_frame", "stamp", "published",
                 "timeline", "_odom_timeout")

    def __init__(self, cfg: Config) -> None:
        out = cfg.output
        self.map_frame, self.frame_id, self.child_frame_id = out.map_frame, out.frame_id, out.child_frame_id
        # The tree needs the odometry frame, whose inputs the filter holds no longer than the
        # odometry's timeout; None: the one transform of the estimate.
        self.odom_frame: OdomFrame | None = None
        self._odom_timeout = 0.0
        if tf_tree_active(cfg):
            odom = next(s for s in cfg.sensors if type(s).__struct_config__.tag == "odom")
            self._odom_timeout = odom.timeout_s
            self.odom_frame = OdomFrame(odom.timeout_s)
        # The estimate's own frame, for the pose and odometry messages too: the world when it is the map.
        self.pose_frame = out.map_frame if self.odom_frame is not None else out.frame_id
        self.stamp = -float("inf")  # stamp of the last TF: TF stamps strictly increase
        self.published = 0
        self.timeline = 0  # the core's time-jump resets seen: a new one starts the TF's time base again

    def message(self, est: Estimate, timeline: int = 0) -> bytes | None:
        """The TFMessage for this estimate, or None when its stamp is not newer than the last one of its
        timeline (``timeline``: the core's count of backwards time-jump resets, ``FusionCore.resets``)."""
        if timeline != self.timeline:
            self.timeline = timeline
            self.stamp = -float("inf")
            if self.odom_frame is not None:
                self.odom_frame = OdomFrame(self._odom_timeout)
        if not est.stamp > self.stamp:
            return None
        if self.odom_frame is None:
            tf = encode_tf_cdr(est.stamp, self.frame_id, self.child_frame_id, est.position, est.orientation)
        else:
            odom_base = self.odom_frame.advance(est.stamp, est.position, est.orientation, est.linear, est.angular)
            map_odom = map_to_odom((est.position, est.orientation), odom_base)
            tf = encode_tf_tree_cdr(est.stamp, [(self.map_frame, self.frame_id, *map_odom),
                                                (self.frame_id, self.child_frame_id, *odom_base)])
        self.stamp = est.stamp
        self.published += 1
        return tf
