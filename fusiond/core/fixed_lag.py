"""The fixed-lag smoothed pose: the pose of ``lag_s`` ago, smoothed over the window since.

A mapping node that can wait gets a better pose than the causal one: what the filter learnt in the last
``lag_s`` also says where the robot was then. The maths is the offline smoother's
(``fusiond.estimator.smoother``): the filter records an anchor at every publish moment with the composed
RTS maps between them; here the anchor at or just before ``newest - lag_s`` is smoothed over the anchors
since (``smoothed_at``: the same as the offline smoother over that window), and the anchors no window can
reach any more are forgotten, so memory stays bounded while the daemon runs.

What a window keeps: the anchors of the last ``lag_s + history_s`` (``history_s``: the late-data history,
so a rewind of the filter lands on anchors still held), each the nominal state, its filtered covariance,
and the link (A, b, B), and the link composed with its neighbours (``lag_window``: two stacks of maps).
Per publish moment: a few n x n products (the window's compositions kept as it slides, ``lag_window``)
and one boxplus, whatever the lag.

The stated covariance is the smoothed one of that moment (the RTS covariance over the window since, the
same as the offline smoother's over that window): what the later evidence says about where the robot
was, never larger than the filtered covariance of that moment. Where the published position was shown
instead of the state's (``smoother.Anchor.shown``: a GPS heading search), the filtered one, as the causal
pose stated it.
"""

from __future__ import annotations

import msgspec

from ..estimator import POSE_ERR, attitude_of, position_of
from ..estimator.lag_window import SlidingCorrection
from ..estimator.smoother import OpenSegment, SmoothingRecorder, smoothed_at
from ..estimator.state import StateLayout

__all__ = ["FixedLag", "LaggedPose"]


class LaggedPose(msgspec.Struct, gc=False):
    """A smoothed pose of the past: its stamp, position, orientation (x y z w) and its smoothed pose
    covariance (ROS row-major 6 x 6), as ``Estimate``'s pose fields."""

    stamp: float
    position: tuple[float, float, float]
    orientation: tuple[float, float, float, float]
    pose_covariance: list[float]


class FixedLag:
    """The recorder of a fixed-lag output and the window it keeps (module doc)."""

    def __init__(self, layout: StateLayout, lag_s: float, history_s: float) -> None:
        if not lag_s > 0.0:
            raise ValueError(f"the lag must be positive, got {lag_s}")
        self.layout = layout
        self.lag_s = lag_s
        self.keep_s = lag_s + history_s
        self.recorder = SmoothingRecorder(layout, covariance=True)
        self.window = SlidingCorrection(layout.error_dim, covariance=True)
        self._last = -1  # the timeline's index of the last anchor returned: each is returned once
        self._tail: list[LaggedPose] = []  # an ended timeline's last moments, returned by the next ``poses``

    def restart(self, segment: OpenSegment | None) -> None:
        """The filter starts over (a time jump back, set_pose, a resumed state): what came before is
        another timeline, whose stamps may be later than the new one's; the window starts empty. The old
        timeline's moments not returned yet (its last ``lag_s``) are smoothed over the anchors to its end, as
        the offline smoother ends a segment, and ``poses`` returns them first: a consumer of every moment
        loses none at a reset."""
        rec = self.recorder
        if segment is not None:
            rec.keep(segment.count, segment.turns)
            first = max(self._last + 1 - rec.base, 0)
            self._tail += [self._smoothed(j) for j in range(first, len(rec.anchors))]
            self._last = rec.base + len(rec.anchors) - 1
        rec.forget(len(rec.anchors))

    def pose(self, segment: OpenSegment | None) -> LaggedPose | None:
        """The newest of ``poses``: the pose at the newest anchor's stamp - ``lag_s`` (the anchor at or just
        before it), None when there is none not returned yet (the ones before it are returned no more)."""
        poses = self.poses(segment)
        return poses[-1] if poses else None

    def poses(self, segment: OpenSegment | None) -> list[LaggedPose]:
        """Every anchor's pose not returned yet up to the newest anchor's stamp - ``lag_s`` (the anchor at or
        just before it), in order, each smoothed over the anchors since: one a publish moment as the lag reaches
        it, several where the newest stamp leapt (a logging gap: the moments before it, all of them, not the
        last alone). Empty while no anchor is that old. ``segment``: the newest filter's view of the record
        (what an abandoned timeline recorded goes). After a ``restart``, the ended timeline's last moments
        come first."""
        tail, self._tail = self._tail, []
        return tail + self._reached(segment) if tail else self._reached(segment)

    def _reached(self, segment: OpenSegment | None) -> list[LaggedPose]:
        """``poses`` of the newest timeline."""
        rec = self.recorder
        if segment is None:
            return []
        rec.keep(segment.count, segment.turns)
        anchors = rec.anchors
        if not anchors:
            return []
        target = anchors[-1].stamp - self.lag_s
        k = _last_at_or_before(anchors, target)
        first = max(self._last + 1 - rec.base, 0)  # the first anchor not returned yet
        if k < first:
            return []
        # what no window can reach any more, even after a rewind within the history, goes (not one to return)
        drop = min(first, max(_last_at_or_before(anchors, anchors[-1].stamp - self.keep_s), 0))
        rec.forget(drop)
        k, first = k - drop, first - drop
        self._last = rec.base + k
        return [self._smoothed(j) for j in range(first, k + 1)]

    def _smoothed(self, k: int) -> LaggedPose:
        rec = self.recorder
        a = rec.anchors[k]
        window = self.window
        d = window.correction(rec.anchors, rec.base, k)
        x = smoothed_at(self.layout, rec.anchors, k, rec.relative_turns(), d)
        # a position shown instead of the state's (a GPS heading search) is not the state's estimate, and
        # the RTS covariance is not its own: it keeps what the causal pose stated then
        P = window.covariance_k if a.shown is None else a.P
        return LaggedPose(stamp=a.stamp, position=position_of(x), orientation=attitude_of(x),
                          pose_covariance=(0.5 * (P + P.T))[POSE_ERR, POSE_ERR].ravel().tolist())


def _last_at_or_before(anchors: list, stamp: float) -> int:
    """The index of the last anchor stamped at or before ``stamp`` (-1: none); stamps are in order."""
    lo, hi = 0, len(anchors)
    while lo < hi:
        mid = (lo + hi) // 2
        if anchors[mid].stamp <= stamp:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1
