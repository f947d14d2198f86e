"""Everything that affects the estimate, in one object the history can snapshot.

Arrival-order independence rests on this: whatever a sample changes that later
samples depend on (held inputs, offsets, anchors, adaptive scales) lives here and
is copied after every event, so that rewinding to a snapshot and re-applying
reproduces the same numbers.
"""

from __future__ import annotations

import math

_ZERO3 = (0.0, 0.0, 0.0)
# a sensor's longest recent interval before it has one (``inputs.recent_longest``: that interval, the current
# half-window's, when that half ends)
NO_RECENT = (0.0, 0.0, -math.inf)


class FilterState:
    """Everything that affects the estimate; copied into the history after each event.

    Shared by every sensor kind: filter time and the EKF, per-sensor stamps and periods, the held
    motion inputs (odometry twist, gyro rate) and the facts several kinds read (standstill since,
    attitude initialised, newest tilt information, the world frame). What only one sensor needs
    between its messages is its own immutable slice, ``own[index]`` (``core/sensors/``).
    """

    __slots__ = (
        "t", "ekf", "last", "period", "longest",
        "linear", "linear_cov", "linear_world", "wheel_angular", "wheel_angular_cov", "wheel_yaw_measured",
        "gyro", "gyro_cov", "gyro_last",
        "still_since", "attitude_ready", "tilt_seen", "turn_unseen", "wheel_turn",
        "frame_ready", "frame_epoch", "enu", "heading_ready",
        "own",
    )

    @classmethod
    def initial(cls, ekf, sensors: int, linear_cov: tuple[float, ...], angular_cov: tuple[float, ...]) -> "FilterState":
        """A fresh state with no time yet (the first sample in stamp order sets it): nothing held,
        no frame, every sensor's slice None until its model's ``on_start`` puts one in place.
        ``linear_cov``/``angular_cov``: the variances of a twist nobody measures."""
        s = cls.__new__(cls)
        s.t = None
        s.ekf = ekf
        s.last = [None] * sensors
        s.period = [0.0] * sensors
        s.longest = [NO_RECENT] * sensors  # per sensor ``inputs.recent_longest``
        s.linear, s.linear_cov = _ZERO3, linear_cov
        s.wheel_angular, s.wheel_angular_cov = _ZERO3, angular_cov
        s.linear_world = False  # the held linear twist is in the world frame (twist_frame = "world", no pose)
        s.wheel_yaw_measured = False
        s.gyro = s.gyro_cov = s.gyro_last = None
        s.still_since = None  # the odometry has read zero since this stamp
        s.attitude_ready = False  # roll/pitch (and yaw) taken from a first orientation
        s.tilt_seen = None  # stamp of the newest roll/pitch information fused (set at the first stamp)
        s.turn_unseen = None  # end of the newest prediction across a gap that no yaw-rate input covered
        s.wheel_turn = 0.0  # rad the predictions have turned by the odometry's yaw rate (no gyro), all told
        s.frame_ready = False  # the world frame: defined by the first absolute sample
        s.frame_epoch = 0  # counts the frame being defined or turned (differential sensors restart)
        s.enu, s.heading_ready = None, False
        s.own = [None] * sensors
        return s

    def copy(self, into: "FilterState | None" = None) -> "FilterState":
        """A snapshot; ``into`` (a snapshot the history no longer needs) is overwritten instead of
        allocating a new one, its x and P by in-place writes."""
        if into is None:
            c = FilterState.__new__(FilterState)
            c.ekf = self.ekf.copy()
        else:
            c = into
            c.ekf = self.ekf.copy(into=into.ekf)
        c.t = self.t
        c.last = list(self.last)
        c.period = list(self.period)
        c.longest = list(self.longest)
        # numpy inputs are replaced on update, never mutated, so sharing them is safe
        c.linear, c.linear_cov = self.linear, self.linear_cov
        c.wheel_angular, c.wheel_angular_cov = self.wheel_angular, self.wheel_angular_cov
        c.wheel_yaw_measured = self.wheel_yaw_measured
        c.linear_world = self.linear_world
        c.gyro, c.gyro_cov, c.gyro_last = self.gyro, self.gyro_cov, self.gyro_last
        c.still_since = self.still_since
        c.tilt_seen = self.tilt_seen
        c.turn_unseen, c.wheel_turn = self.turn_unseen, self.wheel_turn
        c.attitude_ready = self.attitude_ready
        # world frame: flags and immutable values (EnuFrame) only, so sharing is safe
        c.frame_ready, c.frame_epoch, c.enu, c.heading_ready = (self.frame_ready, self.frame_epoch, self.enu,
                                                               self.heading_ready)
        c.own = self.own.copy()  # each sensor's slice is immutable: replaced, never mutated
        return c
