"""Tune's Nelder-Mead (``fusiond.tune.simplex``) asks for scipy's points, one by one, and finds its optimum.

The reflection and a guessed next point are handed over together (``f_many``); a guess is only a point
computed early: the sequence of points the iterations use must be scipy's ``minimize(method=
"Nelder-Mead")`` with the same initial simplex, bounds and tolerances, bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize

from fusiond.tune.simplex import nelder_mead


def _rosenbrock(x) -> float:
    return float(sum(100.0 * (x[i + 1] - x[i] ** 2) ** 2 + (1.0 - x[i]) ** 2 for i in range(len(x) - 1)))


def _bowl(x) -> float:  # a likelihood-like bowl with a step (a gate switching) in it
    return float(sum((xi - 0.3 * (i + 1)) ** 2 for i, xi in enumerate(x)) + (0.05 if x[0] > 0.7 else 0.0))


CASES = [
    (_rosenbrock, 2, False, (-3.0, 3.0)),
    (_rosenbrock, 3, False, (-3.0, 3.0)),
    (_rosenbrock, 4, True, (-3.0, 3.0)),
    (_bowl, 2, False, (-1.0, 0.5)),  # the optimum's first coordinate beyond its upper bound: clipped steps
    (_bowl, 5, True, (-6.9, 6.9)),
]


def _simplex(n: int, step: float = math.log(2.0)) -> list[list[float]]:
    out = [[0.0] * n]
    for k in range(n):
        v = [0.0] * n
        v[k] = step
        out.append(v)
    return out


@pytest.mark.parametrize("fn, n, adaptive, bound", CASES)
def test_the_points_asked_for_are_scipys(fn, n, adaptive, bound):
    xatol, fatol = 0.03, 0.5e-3
    bounds = [bound] * n
    asked_scipy: list[tuple[float, ...]] = []

    def f_scipy(x):
        asked_scipy.append(tuple(np.asarray(x, dtype=float).tolist()))
        return fn(x)

    res = minimize(f_scipy, [0.0] * n, method="Nelder-Mead", bounds=bounds,
                   options={"initial_simplex": _simplex(n), "xatol": xatol, "fatol": fatol, "maxfev": 10**9,
                            "adaptive": adaptive})
    assert res.success

    values: dict[tuple[float, ...], float] = {}  # every point computed, asked or guessed
    asked: list[tuple[float, ...]] = []
    guessed = 0

    def f(x):
        key = tuple(np.asarray(x, dtype=float).tolist())
        asked.append(key)
        if key not in values:
            values[key] = fn(x)
        return values[key]

    def f_many(points, n_asked):
        nonlocal guessed
        out = []
        for x in points:
            key = tuple(np.asarray(x, dtype=float).tolist())
            if key not in values:
                values[key] = fn(x)
            out.append(values[key])
        asked.extend(tuple(np.asarray(x, dtype=float).tolist()) for x in points[:n_asked])
        guessed += len(points) - n_asked
        return out

    x, fx, steps = nelder_mead(f, f_many, _simplex(n), bounds, xatol, fatol, adaptive)
    assert np.asarray(x).tobytes() == np.asarray(res.x).tobytes() and fx == res.fun
    assert asked == asked_scipy
    assert guessed == len(steps) > 0  # one guess beside each reflection


def test_a_guess_that_was_right_is_not_asked_for_again():
    """The guessed point's value is what the step reads when it needs that point: counted once."""
    calls = []

    def fn(x):
        calls.append(tuple(x))
        return _rosenbrock(x)

    cache: dict[tuple[float, ...], float] = {}

    def f(x):
        key = tuple(np.asarray(x, dtype=float).tolist())
        if key not in cache:
            cache[key] = fn(key)
        return cache[key]

    x, _, steps = nelder_mead(f, lambda pts, asked: [f(p) for p in pts], _simplex(3), [(-3.0, 3.0)] * 3, 0.03, 1e-3, False)
    assert len(calls) == len(set(calls))
    assert len(set(steps) - {"expand", "reflect", "contract_in", "contract_out"}) == 0
