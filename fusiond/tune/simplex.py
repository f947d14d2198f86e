"""Nelder-Mead over bounded log-scales, step for step scipy's, with the next point replayed beside the
reflection.

Each iteration of Nelder-Mead replays the reflection of the worst vertex through the others' centroid,
and then, by where its value falls, one more point or none: the expansion beyond it (a new best), the
outside contraction (between the second-worst and the worst), the inside contraction (worse than the
worst), or nothing (in between: the reflection replaces the worst). A replay is the whole cost here, and
the machine has more than one core, so the second point is replayed beside the reflection instead of
after it: the one the previous iteration's outcome makes likely (``_guess``). When the guess was the
point needed, the iteration took one replay's time instead of two; otherwise the guess cost another
core's time and the iteration what it would have anyway. A guess is replayed on a one-CPU machine too
(after the reflection): tune's bound counts replays, and so where it binds the fit it ends at does not
depend on the machine.

The points asked for, and so the fit, are scipy's ``minimize(method="Nelder-Mead")`` with
``initial_simplex`` and ``bounds`` (scipy 1.17's ``_minimize_neldermead``, its arithmetic in numpy as
there): a guess's value is kept by the objective's cache and read back when the step asks for it.
``tests/doctor/test_simplex.py`` holds the two to the same points on test functions.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

__all__ = ["nelder_mead"]

EXPAND, CONTRACT_OUT, CONTRACT_IN, REFLECT = "expand", "contract_out", "contract_in", "reflect"


def nelder_mead(f: Callable[[np.ndarray], float], f_many: Callable[[Sequence[np.ndarray], int], list[float]],
                initial_simplex: Sequence[Sequence[float]], bounds: Sequence[tuple[float, float]],
                xatol: float, fatol: float, adaptive: bool) -> tuple[np.ndarray, float, list[str]]:
    """(the best vertex, its value, each iteration's step) of Nelder-Mead from ``initial_simplex`` (N + 1
    vertices of N log-scales) within ``bounds``, stopping when the simplex spans at most ``xatol`` in every
    coordinate around its best vertex and its values at most ``fatol`` (scipy's test). ``f``: one point's
    value; ``f_many(points, asked)``: several points' values, replayed side by side, of which the first
    ``asked`` are the step's (the reflection, with a guess beside it; a shrink's vertices, all asked). An
    exception from either ends the fit there (a budget: the caller keeps its best point)."""
    sim = np.atleast_2d(np.asarray(initial_simplex, dtype=float)).copy()
    n = sim.shape[1]
    if adaptive:
        rho, chi, psi, sigma = 1, 1 + 2 / n, 0.75 - 1 / (2 * n), 1 - 1 / n
    else:
        rho, chi, psi, sigma = 1, 2, 0.5, 0.5
    lower = np.array([b[0] for b in bounds], dtype=float)
    upper = np.array([b[1] for b in bounds], dtype=float)
    sim = np.clip(np.where(sim > upper, 2 * upper - sim, sim), lower, upper)
    fsim = np.full((n + 1,), np.inf, dtype=float)
    for k in range(n + 1):
        fsim[k] = f(sim[k])
    order = np.argsort(fsim)
    sim, fsim = np.take(sim, order, 0), np.take(fsim, order, 0)
    steps: list[str] = []
    while True:
        if np.max(np.ravel(np.abs(sim[1:] - sim[0]))) <= xatol and np.max(np.abs(fsim[0] - fsim[1:])) <= fatol:
            break
        xbar = np.add.reduce(sim[:-1], 0) / n
        xr = np.clip((1 + rho) * xbar - rho * sim[-1], lower, upper)
        candidates = {
            EXPAND: np.clip((1 + rho * chi) * xbar - rho * chi * sim[-1], lower, upper),
            CONTRACT_OUT: np.clip((1 + psi * rho) * xbar - psi * rho * sim[-1], lower, upper),
            CONTRACT_IN: np.clip((1 - psi) * xbar + psi * sim[-1], lower, upper),
        }
        guess = _guess(steps)
        fxr = f_many([xr, candidates[guess]], 1)[0]
        shrink = False
        if fxr < fsim[0]:
            xe = candidates[EXPAND]
            fxe = f(xe)
            if fxe < fxr:
                sim[-1], fsim[-1] = xe, fxe
            else:
                sim[-1], fsim[-1] = xr, fxr
            steps.append(EXPAND)
        elif fxr < fsim[-2]:
            sim[-1], fsim[-1] = xr, fxr
            steps.append(REFLECT)
        elif fxr < fsim[-1]:
            xc = candidates[CONTRACT_OUT]
            fxc = f(xc)
            if fxc <= fxr:
                sim[-1], fsim[-1] = xc, fxc
            else:
                shrink = True
            steps.append(CONTRACT_OUT)
        else:
            xcc = candidates[CONTRACT_IN]
            fxcc = f(xcc)
            if fxcc < fsim[-1]:
                sim[-1], fsim[-1] = xcc, fxcc
            else:
                shrink = True
            steps.append(CONTRACT_IN)
        if shrink:  # every vertex but the best towards it: independent points, replayed side by side
            for j in range(1, n + 1):
                sim[j] = np.clip(sim[0] + sigma * (sim[j] - sim[0]), lower, upper)
            fsim[1:] = f_many([sim[j] for j in range(1, n + 1)], n)
        order = np.argsort(fsim)
        sim, fsim = np.take(sim, order, 0), np.take(fsim, order, 0)
    return sim[0], float(np.min(fsim)), steps


def _guess(steps: list[str]) -> str:
    """The second point to replay beside the reflection: an expansion after an expansion (a slope being
    followed), else the inside contraction (near an optimum the reflection lands worse than the worst)."""
    if steps and steps[-1] == EXPAND:
        return EXPAND
    return CONTRACT_IN
