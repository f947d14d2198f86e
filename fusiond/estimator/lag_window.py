"""The smoothed correction (and covariance) at the oldest anchor of a sliding window, in constant time per anchor.

The fixed-lag pose (``fusiond/core/fixed_lag.py``) needs, at every publish moment, anchor k's correction
d_k = M_(k+1)(M_(k+2)(... M_(N-1)(0))), with M_j(d) = b_j + A_j d the link into anchor j
(``smoother``: a segment's end, no link, is M_j = 0). Carried back anchor by anchor that is one n-vector
product per anchor of the window per message; the maps are affine, so they compose, and a window that
slides (anchors join at the new end, leave at the old one) keeps the composition with two stacks:

- back: the compositions M_(f1) o ... o M_j of the anchors since the last flip, one per anchor (a new
  anchor: one n x n product); a rewind that replaced anchors from p drops the entries from p (O(1));
- front: the suffix compositions M_i o ... o M_(f1 - 1) of the anchors before, built at once when the
  window's start passes f1 (the flip: one n x n product per anchor, once per window).

d_k is front's entry at k + 1 applied to back's last: two products per anchor in all, whatever the window's
length. The same maps as the anchor-by-anchor pass, associated otherwise: equal to rounding.

The smoothed covariance goes the same way. The smoother's recursion Ps_(j-1) = B_j + A_j (Ps_j - P_j) A_j^T
(P_j: anchor j's filtered covariance) is the map S -> C_j + A_j S A_j^T with C_j = B_j - A_j P_j A_j^T,
and where anchor j starts a segment, S -> P_(j-1) (the segment's last anchor keeps its filtered
covariance). Such maps compose too: (C1, A1) o (C2, A2) = (C1 + A1 C2 A1^T, A1 A2); the window's result is
the composition applied to the newest anchor's filtered P. Two more n x n products per composition.

Pure maths: no clocks, no I/O.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SlidingCorrection"]

# one map: (A, b, C); C None without covariance
Map = tuple[np.ndarray, np.ndarray, "np.ndarray | None"]


class SlidingCorrection:
    """Anchor k's correction (and with ``covariance`` its smoothed covariance) over the window anchors[k:],
    kept across calls (module doc).

    ``correction(anchors, base, k)``: ``anchors[i]`` is the timeline's anchor ``base + i`` (a recorder
    that forgets its oldest, ``SmoothingRecorder.base``); anchors are matched by identity, so a rewound
    timeline's replaced anchors are seen as such. With ``covariance`` the anchors' links hold B and the
    anchors their filtered P (``SmoothingRecorder(covariance=True)``), and ``covariance_k`` is the smoothed
    covariance of the anchor the last call corrected."""

    def __init__(self, n: int, covariance: bool = False) -> None:
        self.n = n
        self.covariance = covariance
        self.covariance_k: np.ndarray | None = None
        self._zero_A, self._zero_b = np.zeros((n, n)), np.zeros(n)
        self._reset(0)

    def _reset(self, start: int) -> None:
        self.f0 = self.f1 = start  # front covers [f0, f1), back [f1, f1 + len(back))
        self.front: list[Map] = []
        self.back: list[Map] = []
        self.objs: list[object] = []  # the anchors of [f0, f1 + len(back))
        self.maps: list[Map] = []  # each one's own map (``_link``), made once as it joins

    def _link(self, anchor, before) -> Map:
        """The map into ``anchor`` from the anchor ``before`` it (None: not held, never in a window)."""
        link = anchor.link
        if link is None:  # a segment starts here: the one before keeps its filtered estimate
            if not self.covariance:
                return self._zero_A, self._zero_b, None
            # the record's first anchor: no window starts before it, so its map is never applied
            return self._zero_A, self._zero_b, before.P if before is not None else self._zero_A
        A, b, B = link
        if not self.covariance:
            return A, b, None
        return A, b, B - A.dot(anchor.P).dot(A.T)

    def _compose(self, outer: Map, inner: Map) -> Map:
        A1, b1, C1 = outer
        A2, b2, C2 = inner
        C = None
        if self.covariance:
            C = C1 + A1.dot(C2).dot(A1.T)
        return A1.dot(A2), b1 + A1.dot(b2), C

    def correction(self, anchors: list, base: int, k: int) -> np.ndarray:
        N = base + len(anchors)
        K1 = base + k + 1  # the window's first link
        # what is still the timeline's: a rewind replaces a tail, so anchors match up to a point
        lo = max(self.f0, base)
        seen = min(self.f0 + len(self.objs), N)
        while seen > lo and anchors[seen - 1 - base] is not self.objs[seen - 1 - self.f0]:
            seen -= 1
        if seen < self.f1 or K1 < self.f0 or seen < base:
            self._reset(K1)  # the front's compositions hold replaced anchors: rebuilt from the window
            seen = K1
        else:
            del self.back[seen - self.f1:]
            del self.objs[seen - self.f0:]
            del self.maps[seen - self.f0:]
        for j in range(seen, N):  # new anchors join the back
            a = anchors[j - base]
            m = self._link(a, anchors[j - base - 1] if j > base else None)
            self.back.append(self._compose(self.back[-1], m) if self.back else m)
            self.objs.append(a)
            self.maps.append(m)
        if K1 >= self.f1:  # the window starts in the back: flip it into suffix compositions from K1
            self._flip(K1, N)
        elif K1 > self.f0:  # what left the window goes
            del self.front[:K1 - self.f0]
            del self.objs[:K1 - self.f0]
            del self.maps[:K1 - self.f0]
            self.f0 = K1
        last_P = anchors[-1].P if self.covariance else None
        if K1 >= N:
            self.covariance_k = last_P
            return np.zeros(self.n)
        whole = self.front[K1 - self.f0]
        if self.back:
            whole = self._compose(whole, self.back[-1])
        A, b, C = whole
        if self.covariance:
            self.covariance_k = C + A.dot(last_P).dot(A.T)
        return b if self.back else b.copy()

    def _flip(self, K1: int, N: int) -> None:
        maps = self.maps[K1 - self.f0:]
        front: list[Map] = [None] * (N - K1)  # type: ignore[list-item]
        S = None
        for j in range(N - 1, K1 - 1, -1):
            m = maps[j - K1]
            S = m if S is None else self._compose(m, S)
            front[j - K1] = S
        self.front, self.back, self.objs, self.maps = front, [], self.objs[K1 - self.f0:], maps
        self.f0, self.f1 = K1, N
