"""What the daemon publishes: the estimate (pose, odometry, NavSatFix, TF), the JSON diagnostics records
(batched) and the ROS diagnostics, on publishers declared once.

Apart from the daemon's threading (``daemon.py``) so that what goes out, in which encoding and on which
key, reads in one place. The thread holding the daemon's core calls ``publish_estimate``, ``collect``
and ``flush_diagnostics`` (one at a time); the health thread calls ``put_ros_diagnostics``. Nothing here reads a sensor or
writes the filter: it is handed the core and asks it for the estimate.

- Pose (PoseWithCovarianceStamped CDR) and odometry (nav_msgs/Odometry CDR) on every estimate the core
  says to publish, with the world frame when a GPS or absolute pose defines it (``tf_broadcast.py``).
  They are batched, not ``express`` unless asked: on a loaded 2-core machine express messages lost a few
  poses to Zenoh's drop-on-congestion where batching lost none, at the same latency.
- With ``[output] smoothed_key``: beside each pose, the pose of ``smooth_lag_s`` ago smoothed over the window
  since (``core/fixed_lag.py``), in the pose's encoding and frame, once per publish moment it reaches (in
  stamp order along a timeline; a reset starts it again); off, no publisher is declared.
- Diagnostics (``[output] diagnostics_batch_s``): the records are collected and put as ONE JSON array,
  encoded in one msgspec call, when the worker's timer says so or MAX_BATCH are waiting; 0 puts one record
  per put. Readers accept both forms (``fusiond.monitor.decode_diagnostics``).
- Keys are the bridge's plain keys, or in rmw_zenoh mode the node's publishers (``rmw_zenoh.py``); the
  JSON diagnostics key stays plain.
"""

from __future__ import annotations

from typing import Any

import msgspec
import zenoh

from ..codecs import (
    DIAGNOSTIC_ARRAY, NAVSATFIX, ODOMETRY, POSE_COV_STAMPED, TF_MESSAGE, encode_diagnostic_array_cdr, encode_navsat_cdr,
    encode_odometry_cdr, encode_pose_cdr,
)
from ..config import Config
from ..logs import get_logger
from .rmw_zenoh import QUEUE_DEPTH, TF_DEPTH, RmwNode, topic_name
from .tf_broadcast import TfBroadcast

log = get_logger("fusiond.daemon")

# Records in one diagnostics put at most. A backlog (a bag played at full speed) flushes early, so a put
# stays within one Zenoh batch (65,535 bytes by default; a record is ~290 bytes of JSON): a larger put is
# fragmented, and under the publisher's default DROP congestion control one dropped fragment loses the
# whole put. Measured with the burst of tests/e2e/test_diagnostics_batches.py: at 1024 records a put was lost
# in 2 of 13 runs, at 200 in none of 25.
MAX_BATCH = 200

_diag_encoder = msgspec.json.Encoder()


class Outputs:
    """The daemon's publishers on an open session (and, in rmw_zenoh mode, its node)."""

    def __init__(self, cfg: Config, session: zenoh.Session, node: RmwNode | None, express: bool = False) -> None:
        out = cfg.output
        self.cfg = cfg
        self._session = session
        self._node = node
        self._express = express
        self.tf = TfBroadcast(cfg)  # what goes on the TF key, and when
        self.pose = self._ros_publisher(out.pose_key, POSE_COV_STAMPED)
        self.odometry = self._ros_publisher(out.odometry_key, ODOMETRY)
        self.diagnostics = session.declare_publisher(out.diagnostics_key, encoding=zenoh.Encoding.APPLICATION_JSON)
        self.navsat = self._ros_publisher(out.navsat_key, NAVSATFIX) if out.navsat_key else None
        self.smoothed = self._ros_publisher(out.smoothed_key, POSE_COV_STAMPED) if out.smoothed_key else None
        self.smoothed_published = 0
        self.tf_pub = self._ros_publisher(out.tf_key, TF_MESSAGE, depth=TF_DEPTH) if out.publish_tf else None
        self.ros_diagnostics = (self._ros_publisher(out.ros_diagnostics_key, DIAGNOSTIC_ARRAY)
                                if out.ros_diagnostics_key else None)
        self._batch_s = out.diagnostics_batch_s
        self._batch: list[Any] = []  # records not yet published (the core held)
        self.published = 0  # estimates published
        self.diagnostics_puts = 0  # puts on the diagnostics key (one per batch, or per record with batch 0)

    def _ros_publisher(self, key: str, msgtype: str, depth: int = QUEUE_DEPTH) -> Any:
        """A publisher of a ROS topic: the bridge's plain key, or rmw_zenoh's key with attachments and token."""
        if self._node is not None:
            return self._node.publisher(topic_name(key), msgtype, depth=depth, express=self._express)
        return self._session.declare_publisher(key, encoding=zenoh.Encoding.APPLICATION_CDR, express=self._express)

    @property
    def declared(self) -> list[Any]:
        """Every publisher, in the order declared (undeclared in reverse by the daemon)."""
        return [p for p in (self.pose, self.odometry, self.diagnostics, self.navsat, self.tf_pub,
                            self.ros_diagnostics, self.smoothed) if p is not None]

    @property
    def tf_published(self) -> int:
        return self.tf.published

    # -- the core held -------------------------------------------------------------------------
    def publish_estimate(self, core: Any) -> None:
        """The core's newest estimate as pose, odometry, (with a datum) NavSatFix and (when its stamp
        advanced) TF."""
        out = self.cfg.output
        est = core.estimate()
        frame = self.tf.pose_frame
        self.pose.put(encode_pose_cdr(est.stamp, frame, est.position, est.orientation, est.pose_covariance))
        self.odometry.put(encode_odometry_cdr(est.stamp, frame, out.child_frame_id, est.position, est.orientation,
                                              est.pose_covariance, est.linear, est.angular, est.twist_covariance))
        if self.navsat is not None:
            fix = core.geodetic()
            if fix is not None:
                self.navsat.put(encode_navsat_cdr(est.stamp, out.child_frame_id, *fix))
        if self.tf_pub is not None:
            tf = self.tf.message(est, core.resets)
            if tf is not None:
                self.tf_pub.put(tf)
        self.published += 1
        if self.smoothed is not None:
            self._publish_smoothed(core, frame)

    def _publish_smoothed(self, core: Any, frame: str) -> None:
        """The fixed-lag smoothed poses of the publish moments the lag has reached and not put yet, each once, in
        order (several after a logging gap: the core returns them all)."""
        for lagged in core.lagged_poses():
            self.smoothed.put(encode_pose_cdr(lagged.stamp, frame, lagged.position, lagged.orientation,
                                              lagged.pose_covariance))
            self.smoothed_published += 1

    @property
    def pending(self) -> bool:
        """Records collected and not yet put."""
        return bool(self._batch)

    def collect(self, records: list[Any]) -> None:
        """Diagnostics records of one sample: into the batch (put on the worker's timer, or now when it is
        full), or one put per record when batching is off."""
        if self._batch_s > 0.0:
            self._batch += records
            if len(self._batch) >= MAX_BATCH:
                self.flush_diagnostics()
        else:  # diagnostics_batch_s = 0: one record per put
            put, enc = self.diagnostics.put, _diag_encoder.encode
            for r in records:
                put(enc(r))
            self.diagnostics_puts += len(records)

    def flush_diagnostics(self) -> None:
        """Publish the collected records as one JSON array: one encode, one put."""
        batch = self._batch
        self._batch = []
        try:
            self.diagnostics.put(_diag_encoder.encode(batch))
        except zenoh.ZError as err:  # the publisher is gone (stop timed out): say what is lost
            log.warning("diagnostics_lost", count=len(batch), error=str(err))
            return
        self.diagnostics_puts += 1

    # -- health thread ----------------------------------------------------------------------------
    def put_ros_diagnostics(self, stamp: float, statuses: list[Any]) -> None:
        """The health as ``diagnostic_msgs/msg/DiagnosticArray`` (only with ``ros_diagnostics_key``)."""
        if self.ros_diagnostics is not None:
            self.ros_diagnostics.put(encode_diagnostic_array_cdr(stamp, statuses))


__all__ = ["MAX_BATCH", "Outputs"]
