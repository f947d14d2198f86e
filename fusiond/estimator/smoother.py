"""A Rauch-Tung-Striebel smoother over the error-state filter's own steps, kept at the output rate.

A causal filter's estimate at t knows only what came before t; after the fact, what came later says
where the state was too. The smoother is the classical RTS backward pass on the manifold: errors are
composed through the same F the filter used, and the smoothed nominal state is the filtered one
corrected by boxplus.

Output rate, not message rate. The filter steps once per message (a transition F, then zero or more
corrections); the caller only wants the smoothed state at its output moments (``anchor``). The RTS
recursion from one filter step to the one before,

    d_j = G_j (d_(j+1) + c_(j+1)),   G_j = P_j F_j^T P_(j+1|j)^-1,
    Ps_j = P_j + G_j (Ps_(j+1) - P_(j+1|j)) G_j^T,

(d: the smoothed correction of step j's filtered nominal state, c: the corrections the filter applied
at step j + 1, taken as the nominal states' boxminus) is affine in (d, Ps) of the later step, and the
affine maps compose. Between two anchors the recorder keeps, as the filter steps, only their
composition: with A the product of the G since the anchor,

    d_i = b + A d_(i+1),  b = sum of A c over the corrections;
    Ps_i = B + A (Ps_(i+1) - P_(i+1)) A^T,  B = P_i + sum of A (P_after - P_before) A^T over them,

which is exactly the per-step RTS result at the anchors. A component held at a value (two-D mode's
z, roll, pitch) is a correction too: its nominal moved, its variance went. Any other change of the
covariance that is a linear change of variables (P' = J P J^T, e.g. turning the world frame) is a
transition with F = J and no noise; a change the smoother cannot see through (a covariance reset, a variance re-opened, caps,
a time gap, a re-initialisation) ends the segment: each segment is smoothed on its own, and its last
anchor keeps its filtered estimate.

Transitions in a row. Where no correction comes between two transitions, P_(j+1) = P_(j+1|j) and

    G_j G_(j+1) = P_j F_j^T P_(j+1|j)^-1 P_(j+1|j) F_(j+1)^T P_(j+2|j+1)^-1 = P_j (F_(j+1) F_j)^T P_(j+2|j+1)^-1,

exactly (on the components with variance: a component with none has a zero row in F_j P_j, so the
pseudo-inverse's projector leaves the product as it is). A 1 kHz IMU steps the filter ten times per 100 Hz
odometry anchor with no correction between, so the recorder keeps the covariance before such a run and
the product of its F, and folds their one gain into A where a correction or an anchor needs A: one solve
per run instead of one per step.

A heading found late. While a GPS searches for the heading, the caller publishes a position of its own
(``Anchor.shown``) and the state dead-reckons from the newest fix (``Anchor.origin``) along a placeholder
heading; each fit then turns the state about the antenna (``ErrorStateEKF.rotate_yaw``, recorded as
``heading_turn``) and ends the segment. After the fact the turns that came later are known: such an
anchor's position is its origin plus its dead-reckoned displacement turned by the sum of those turns
(the displacement along the heading found), and its attitude turned by as much (its placeholder heading was
off by that), or the shown position, its attitude as the filter had it, when no turn came after it.

Cost (n: error dimension, 9-16 here; m: nominal dimension). Per message while recording: one n x n
product for its transition (the run's F product); per run of transitions, one n x n solve and product
(G = P F^T P_pred^-1, A <- A G); one n-vector product per correction, and with ``covariance`` two n x n
products where a transition follows corrections.
Memory per anchor: x (m floats) and A (n x n) and b (n); with ``covariance`` also P and B (two n x n
more). For n = 15 that is 2.0 kB an anchor (5.6 kB with covariance): 100 Hz odometry anchors for an
hour hold 0.74 GB (2.0 GB), whatever the IMU's rate (measured: scripts/smoother_bench.py,
docs/SMOOTHER.md). The open segment's A, b (B) travel with every copy of the filter (the core's
late-data history copies it per message), so a rewound filter continues from the segment as it was at
its restore point; anchors and heading turns recorded after that point are dropped when the rewound
filter records its next one.

Pure maths: no clocks, no I/O. The filter calls the recorder (``ErrorStateEKF.record``); nothing else
writes its state.
"""

from __future__ import annotations

import numpy as np

from . import rotation as rot
from .backend import DEFAULT, Backend
from .state import StateLayout

__all__ = ["Anchor", "Smoothed", "SmoothingRecorder", "OpenSegment", "smooth", "smoothed_at"]


class Anchor:
    """The filtered estimate at one output moment and the link that smooths the anchor before it.

    ``link``: (A, b, B) from the previous anchor to this one (``B`` None without covariance), or None
    when this anchor starts a segment. ``shown``: a position the caller published instead of the
    state's (a GPS heading search publishes the fix's neighbourhood): the state's was not an
    estimate there, so the output keeps the shown one."""

    __slots__ = ("stamp", "x", "P", "link", "shown", "origin")

    def __init__(self, stamp: float, x: np.ndarray, P: np.ndarray | None,
                 link: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None,
                 shown: tuple[float, float, float] | None = None, origin: tuple[float, float] | None = None) -> None:
        self.stamp = stamp
        self.x = x
        self.P = P
        self.link = link
        self.shown = shown
        self.origin = origin  # where the state's shown-over position is dead-reckoned from (module doc)


class Smoothed:
    """The smoothed trajectory at the anchors: stamps (N,), nominal states (N, m), covariances
    (N, n, n) or None, and the filtered states they came from."""

    __slots__ = ("t", "x", "P", "filtered")

    def __init__(self, t: np.ndarray, x: np.ndarray, P: np.ndarray | None, filtered: np.ndarray) -> None:
        self.t, self.x, self.P, self.filtered = t, x, P, filtered


class SmoothingRecorder:
    """The anchors of one run, in the order of the filter's final timeline.

    ``covariance``: also keep what the smoothed covariance needs (three times the memory).

    A fixed-lag output needs the last window only: ``forget`` drops the anchors before one, and
    ``base`` counts them, so the counts the filters carry (``OpenSegment.count``, ``turns``) stay the
    timeline's own: ``anchors[i]`` is the timeline's anchor ``base + i``."""

    def __init__(self, layout: StateLayout, covariance: bool = False) -> None:
        self.layout = layout
        self.covariance = covariance
        self.anchors: list[Anchor] = []
        self.turns: list[tuple[int, float]] = []  # (anchors recorded before it, angle) of each heading turn
        self.base = 0  # anchors forgotten before anchors[0]
        self.turns_base = 0  # heading turns forgotten before turns[0]

    def open(self, anchors: int = 0) -> "OpenSegment":
        """A filter's view of the recorder, starting after the first ``anchors`` anchors with no
        segment open (a new filter: nothing links it to what came before)."""
        return OpenSegment(self, anchors, len(self.turns))

    def keep(self, count: int, turns: int) -> None:
        """Drop the anchors after the first ``count`` and the heading turns after the first ``turns``: a
        rewound filter's timeline replaces them. A rewind to before the forgotten ones empties the record
        (the window restarts there)."""
        k = count - self.base
        if k < 0:
            self.anchors.clear()
            self.base = count
        elif len(self.anchors) > k:
            del self.anchors[k:]
        k = turns - self.turns_base
        if k < 0:
            self.turns.clear()
            self.turns_base = turns
        elif len(self.turns) > k:
            del self.turns[k:]

    def forget(self, index: int) -> None:
        """Drop ``anchors[:index]`` and the heading turns that only turned those (a fixed-lag window)."""
        if index <= 0:
            return
        del self.anchors[:index]
        self.base += index
        drop = 0
        for before, _ in self.turns:
            if before > self.base:
                break
            drop += 1
        if drop:
            del self.turns[:drop]
            self.turns_base += drop

    def relative_turns(self) -> list[tuple[int, float]]:
        """The heading turns with their counts relative to ``anchors[0]``."""
        base = self.base
        return [(before - base, angle) for before, angle in self.turns]

    def smooth(self) -> Smoothed:
        return smooth(self.layout, self.anchors, self.covariance, self.relative_turns())


class OpenSegment:
    """The composed RTS maps since the last anchor, carried by a filter and copied with it."""

    __slots__ = ("recorder", "count", "turns", "A", "b", "B", "dP", "pending", "open", "gain_P", "gain_F", "backend")

    def __init__(self, recorder: SmoothingRecorder, count: int, turns: int = 0, backend: Backend = DEFAULT) -> None:
        self.recorder = recorder
        self.backend = backend  # who folds (``Backend.rts_fold``): the filter's own (``ErrorStateEKF.record``)
        self.count = count  # anchors of this filter's timeline
        self.turns = turns  # heading turns of this filter's timeline
        self.A: np.ndarray | None = None
        self.b: np.ndarray | None = None
        self.B: np.ndarray | None = None
        self.dP: np.ndarray | None = None  # corrections' covariance change since the last transition
        self.pending = False
        self.open = False  # False: the next anchor starts a segment
        # Transitions not yet folded into A (module doc, "transitions in a row"): the covariance before
        # the first of them and the product of their F.
        self.gain_P: np.ndarray | None = None
        self.gain_F: np.ndarray | None = None

    def copy(self) -> "OpenSegment":
        c = OpenSegment(self.recorder, self.count, self.turns, self.backend)
        c.open, c.pending = self.open, self.pending
        if self.open:  # the arrays are replaced, never written in place: copies share them
            c.A, c.b, c.B, c.dP, c.gain_P, c.gain_F = self.A, self.b, self.B, self.dP, self.gain_P, self.gain_F
        return c

    # -- what the filter reports -----------------------------------------------------------------
    def transition(self, P_before: np.ndarray, F: np.ndarray, P_after: np.ndarray) -> None:
        """P_after = F P_before F^T + Q: A <- A G with G = P_before F^T P_after^-1, folded in when a
        correction or an anchor needs A (module doc, "transitions in a row")."""
        if not self.open:
            return
        if self.gain_P is None:
            self._flush()
            self.gain_P, self.gain_F = P_before.copy(), F.copy()  # the filter reuses both buffers
        else:
            self.gain_F = F.dot(self.gain_F)

    def _fold(self, P: np.ndarray) -> None:
        """A <- A G for the transitions since the last fold, P the covariance they ended at."""
        if self.gain_P is not None:
            self.A = self.backend.rts_fold(self.A, self.gain_P, self.gain_F, P)
            self.gain_P = self.gain_F = None

    def correction(self, layout: StateLayout, x_before: np.ndarray, x_after: np.ndarray,
                   P_before: np.ndarray, P_after: np.ndarray) -> None:
        """The nominal state and covariance changed at one moment (an update, a held component)."""
        if not self.open:
            return
        self._fold(P_before)
        c = layout.boxminus(x_after, x_before)
        self.b = self.b + self.A.dot(c)
        if self.B is not None:
            d = P_after - P_before
            if self.pending:
                self.dP = self.dP + d
            else:
                self.dP = d
            self.pending = True

    def heading_turn(self, angle: float) -> None:
        """The heading was found off by ``angle`` and the state turned (module doc: a heading found late)."""
        rec = self.recorder
        rec.keep(self.count, self.turns)
        rec.turns.append((self.count, angle))
        self.turns += 1

    def cut(self) -> None:
        """A change the smoother cannot see through: the segment ends at the last anchor."""
        self.open = False
        self.pending = False
        self.A = self.b = self.B = self.dP = self.gain_P = self.gain_F = None

    def anchor(self, stamp: float, x: np.ndarray, P: np.ndarray, shown: tuple[float, float, float] | None = None,
               origin: tuple[float, float] | None = None) -> None:
        """An output moment: the filter's estimate at it, linked to the previous anchor if the segment
        holds; a new segment opens here. ``shown``, ``origin``: see ``Anchor``."""
        rec = self.recorder
        link = None
        if self.open:
            self._fold(P)
            self._flush()
            link = (self.A, self.b, self.B)
        rec.keep(self.count, self.turns)
        rec.anchors.append(Anchor(stamp, x.copy(), P.copy() if rec.covariance else None, link, shown, origin))
        self.count += 1
        n = P.shape[0]
        self.A = np.eye(n)
        self.b = np.zeros(n)
        self.B = P.copy() if rec.covariance else None
        self.dP = None
        self.pending = False
        self.open = True
        self.gain_P = self.gain_F = None

    def _flush(self) -> None:
        if self.pending:
            A = self.A
            self.B = self.B + A.dot(self.dP).dot(A.T)
            self.pending = False


def smooth(layout: StateLayout, anchors: list[Anchor], covariance: bool = False,
           turns: list[tuple[int, float]] | None = None) -> Smoothed:
    """The backward pass over the recorded anchors: each segment from its last anchor (smoothed =
    filtered there) back to its first; where a position was shown instead of the state's, the state's
    displacement from its origin turned by the heading turns that came later, else the shown one."""
    N = len(anchors)
    m, n = layout.nominal_dim, layout.error_dim
    t = np.array([a.stamp for a in anchors], dtype=float)
    xs = np.empty((N, m))
    filtered = np.empty((N, m))
    Ps = np.empty((N, n, n)) if covariance else None
    d_next = np.zeros(n)
    P_next = None
    for i in range(N - 1, -1, -1):
        a = anchors[i]
        filtered[i] = a.x
        later = anchors[i + 1].link if i + 1 < N else None
        if later is None:  # the last anchor of its segment
            d = np.zeros(n)
            P_s = a.P.copy() if covariance else None
        else:
            A, b, B = later
            d = b + A.dot(d_next)
            if covariance:
                P_s = B + A.dot(P_next - anchors[i + 1].P).dot(A.T)
        x = a.x.copy()
        layout.boxplus(x, d)
        xs[i] = x
        if covariance:
            Ps[i] = 0.5 * (P_s + P_s.T)
            P_next = Ps[i]
        d_next = d
    befores = np.array([b for b, _ in turns or ()], dtype=float)
    angles = np.array([a for _, a in turns or ()], dtype=float)
    for i, a in enumerate(anchors):
        if a.shown is None:
            continue
        later = befores > i
        _shown_turned(xs[i], a, float(angles[later].sum()) if later.any() else None)
    return Smoothed(t, xs, Ps, filtered)


def _shown_turned(x: np.ndarray, a: Anchor, turn: float | None) -> None:
    """``x`` (the anchor's nominal state, in place) where its published position was ``shown`` (module doc: a
    heading found late): its position the origin plus its dead-reckoned displacement turned by ``turn`` (the
    later heading turns' sum), and its attitude turned about the world's z by as much (the placeholder heading it
    dead-reckoned along was off by that); or the shown position, the attitude as it is, when no turn came after
    it (``turn`` None) or it has no origin."""
    if a.origin is None or turn is None:
        x[0:3] = a.shown
        return
    c, s = np.cos(turn), np.sin(turn)
    ox, oy = a.origin
    dx, dy = float(a.x[0]) - ox, float(a.x[1]) - oy
    x[0:3] = (ox + c * dx - s * dy, oy + s * dx + c * dy, a.shown[2])
    x[3:7] = rot.turn(0.0, 0.0, turn, tuple(float(v) for v in x[3:7]))



def smoothed_at(layout: StateLayout, anchors: list[Anchor], k: int,
                turns: list[tuple[int, float]] | None = None, d: np.ndarray | None = None) -> np.ndarray:
    """Anchor ``k``'s nominal state smoothed over ``anchors[k:]`` (a fixed lag: the window since it), the
    same as ``smooth(layout, anchors[k:], turns shifted by k).x[0]`` without smoothing the rest: only the
    correction d is carried back, from the last anchor of k's segment (d = 0 there) through the links
    in between, one n-vector product each, and one boxplus at k. ``d``: that correction when the caller
    keeps it otherwise (``lag_window.SlidingCorrection``). ``turns``: as ``smooth``'s, counted from
    ``anchors[0]``."""
    a = anchors[k]
    x = a.x.copy()
    if d is None:
        N = len(anchors)
        end = k + 1  # the first anchor after k's segment (or N)
        while end < N and anchors[end].link is not None:
            end += 1
        if end > k + 1:
            d = anchors[end - 1].link[1]
            for j in range(end - 2, k, -1):
                A, b, _ = anchors[j].link
                d = b + A.dot(d)
    if d is not None:
        layout.boxplus(x, d)
    if a.shown is not None:
        later = [angle for before, angle in turns or () if before > k]
        _shown_turned(x, a, float(np.array(later).sum()) if later else None)
    return x
