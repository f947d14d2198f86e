"""SlidingCorrection (fusiond/estimator/lag_window.py) against the anchor-by-anchor pass it replaces.

A random timeline of links (some ending a segment) grows, is rewound (a tail replaced by new anchors, as a
late message makes the recorder do), forgets its oldest anchors and slides its window; at every step the
kept compositions give the same correction as carrying it back through the window one link at a time.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest


def _reference(anchors: list, k: int, n: int) -> np.ndarray:
    d = np.zeros(n)
    for j in range(len(anchors) - 1, k, -1):
        link = anchors[j].link
        d = np.zeros(n) if link is None else link[1] + link[0].dot(d)
    return d


def _reference_covariance(anchors: list, k: int) -> np.ndarray:
    """The smoother's recursion (``smoother.smooth``): Ps_i = B + A (Ps_(i+1) - P_(i+1)) A^T, a segment's
    last anchor keeping its filtered P."""
    S = anchors[-1].P
    for j in range(len(anchors) - 1, k, -1):
        link = anchors[j].link
        if link is None:
            S = anchors[j - 1].P
        else:
            A, _, B = link
            S = B + A.dot(S - anchors[j].P).dot(A.T)
    return S


@pytest.mark.parametrize("covariance", [False, True])
def test_kept_compositions_equal_the_anchor_by_anchor_pass_through_rewinds_and_forgetting(covariance):
    from fusiond.estimator.lag_window import SlidingCorrection

    rng = np.random.default_rng(3)
    n, W = 5, 12
    anchors: list = []
    base = 0
    window = SlidingCorrection(n, covariance)

    def spd():
        M = rng.standard_normal((n, n))
        return M @ M.T + np.eye(n)

    def new_anchor():
        P = spd() if covariance else None
        if rng.random() < 0.05:
            return SimpleNamespace(link=None, P=P)
        return SimpleNamespace(link=(np.eye(n) * 0.9 + 0.05 * rng.standard_normal((n, n)),
                                     rng.standard_normal(n), spd() if covariance else None), P=P)

    checked = 0
    for step in range(3000):
        r = rng.random()
        if r < 0.01 and base > 5:  # a rewind to before the forgotten ones: the record restarts there
            base -= int(rng.integers(1, 5))
            anchors = [new_anchor() for _ in range(int(rng.integers(1, 20)))]
        elif r < 0.15 and len(anchors) > 3:  # a rewind: the last few replaced
            cut = int(rng.integers(1, min(len(anchors), 30)))
            del anchors[-cut:]
            anchors += [new_anchor() for _ in range(int(rng.integers(0, cut + 2)))]
        else:
            anchors.append(new_anchor())
        if not anchors:
            continue
        k = max(0, len(anchors) - 1 - W + int(rng.integers(-2, 3)))
        k = min(k, len(anchors) - 1)
        if rng.random() < 0.3 and k > 0:  # forget what no window reaches
            drop = int(rng.integers(0, k + 1))
            del anchors[:drop]
            base += drop
            k -= drop
        got = window.correction(anchors, base, k)
        want = _reference(anchors, k, n)
        assert np.max(np.abs(got - want)) < 1e-9 * (1 + np.max(np.abs(want))), step
        if covariance:
            want_S = _reference_covariance(anchors, k)
            assert np.max(np.abs(window.covariance_k - want_S)) < 1e-9 * (1 + np.max(np.abs(want_S))), step
        else:
            assert window.covariance_k is None
        checked += 1
    assert checked > 2900
