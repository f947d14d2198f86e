"""The smoothed correction at the oldest anchor of a sliding window, in constant time per anchor.

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

Pure maths: no clocks, no I/O.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SlidingCorrection"]


class SlidingCorrection:
    """Anchor k's correction over the window anchors[k:], kept across calls (module doc).

    ``correction(anchors, base, k)``: ``anchors[i]`` is the timeline's anchor ``base + i`` (a recorder
    that forgets its oldest, ``SmoothingRecorder.base``); anchors are matched by identity, so a rewound
    timeline's replaced anchors are seen as such."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.zero = (np.zeros((n, n)), np.zeros(n))
        self._reset(0)

    def _reset(self, start: int) -> None:
        self.f0 = self.f1 = start  # front covers [f0, f1), back [f1, f1 + len(back))
        self.front: list[tuple[np.ndarray, np.ndarray]] = []
        self.back: list[tuple[np.ndarray, np.ndarray]] = []
        self.objs: list[object] = []  # the anchors of [f0, f1 + len(back))

    def _link(self, anchor) -> tuple[np.ndarray, np.ndarray]:
        link = anchor.link
        return self.zero if link is None else (link[0], link[1])

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
        for j in range(seen, N):  # new anchors join the back
            a = anchors[j - base]
            A, b = self._link(a)
            if self.back:
                Ab, bb = self.back[-1]
                self.back.append((Ab.dot(A), bb + Ab.dot(b)))
            else:
                self.back.append((A, b))
            self.objs.append(a)
        if K1 >= self.f1:  # the window starts in the back: flip it into suffix compositions from K1
            self._flip(K1, N)
        elif K1 > self.f0:  # what left the window goes
            del self.front[:K1 - self.f0]
            del self.objs[:K1 - self.f0]
            self.f0 = K1
        if K1 >= N:
            return np.zeros(self.n)
        A, b = self.front[K1 - self.f0]
        if self.back:
            return b + A.dot(self.back[-1][1])
        return b.copy()

    def _flip(self, K1: int, N: int) -> None:
        objs = self.objs[K1 - self.f0:]
        front: list[tuple[np.ndarray, np.ndarray]] = [self.zero] * (N - K1)
        S = None
        for j in range(N - 1, K1 - 1, -1):
            A, b = self._link(objs[j - K1])
            S = (A, b) if S is None else (A.dot(S[0]), b + A.dot(S[1]))
            front[j - K1] = S
        self.front, self.back, self.objs = front, [], objs
        self.f0, self.f1 = K1, N
