"""Everything that affects the estimate, in one object the history can snapshot.

Arrival-order independence rests on this: whatever a sample changes that later
samples depend on (held inputs, offsets, anchors, adaptive scales) lives here and
is copied after every event, so that rewinding to a snapshot and re-applying
reproduces the same numbers.
"""

from __future__ import annotations


class FilterState:
    """Everything that affects the estimate; copied into the history after each event."""

    __slots__ = (
        "t", "ekf", "last", "period",
        "linear", "linear_cov", "wheel_angular", "wheel_angular_cov", "wheel_yaw_measured",
        "gyro", "gyro_cov", "gyro_last",
        "still_since", "bias_window", "bias_rejects", "attitude_ready", "tilt_seen", "yaw_offset", "adaptive",
        "frame_ready", "enu", "heading_ready", "gps_anchor", "travel", "pose_anchor",
    )

    def copy(self, into: "FilterState | None" = None) -> "FilterState":
        """A snapshot; ``into`` (a snapshot the history no longer needs) is overwritten instead of
        allocating a new one, its x and P by np.copyto."""
        if into is None:
            c = FilterState.__new__(FilterState)
            c.ekf = self.ekf.copy()
        else:
            c = into
            c.ekf = self.ekf.copy(into=into.ekf)
        c.t = self.t
        c.last = list(self.last)
        c.period = list(self.period)
        # numpy inputs are replaced on update, never mutated, so sharing them is safe
        c.linear, c.linear_cov = self.linear, self.linear_cov
        c.wheel_angular, c.wheel_angular_cov = self.wheel_angular, self.wheel_angular_cov
        c.wheel_yaw_measured = self.wheel_yaw_measured
        c.gyro, c.gyro_cov, c.gyro_last = self.gyro, self.gyro_cov, self.gyro_last
        c.still_since = self.still_since
        c.bias_window, c.bias_rejects = self.bias_window, self.bias_rejects  # immutable tuples
        c.tilt_seen = self.tilt_seen
        c.attitude_ready = self.attitude_ready
        c.yaw_offset = dict(self.yaw_offset) if self.yaw_offset else {}
        c.adaptive = {k: list(v) for k, v in self.adaptive.items()} if self.adaptive else {}
        # world frame: flags and immutable values (tuples, EnuFrame) only, so sharing is safe
        c.frame_ready, c.enu, c.heading_ready = self.frame_ready, self.enu, self.heading_ready
        c.gps_anchor, c.travel = self.gps_anchor, self.travel
        c.pose_anchor = self.pose_anchor  # copy-on-write: replaced, never mutated
        return c
