"""Bounded least squares on simulation runs, the Jacobian's runs in one parallel batch.

Used where a fit's residuals come from whole simulations (a run takes seconds):
:class:`CauseFitter` (a diagnosis cause's parameters) and the polish stage of
:func:`orchestrator.inverse.calibrate.calibrate`. :func:`scipy.optimize.least_squares` (``trf``,
bounds ``[0, 1]^n``) drives the iteration; its Jacobian is a forward difference whose
``n`` perturbed runs are handed over together, so that they run on all workers at once
(:func:`forward_jacobian`, also what the parameter intervals of
:mod:`orchestrator.inverse.uncertainty` use at the fitted point).

Runs ahead. An iteration of ``trf`` evaluates one trial point and, when it accepts it,
the Jacobian there: two rounds of runs. With ``n`` parameters and ``spare >= n`` idle
workers (a 1-parameter cause on two workers) the trial point's Jacobian points go out
*with* the trial point (``batch(ps, ahead)``), so an accepted step costs one round
instead of two; a rejected one wastes runs on workers that would have idled. The
points and their order are :func:`forward_jacobian`'s (:func:`jacobian_points`), and a
point run ahead counts as evaluated only when the iteration asks for it, so the fit
visits the same points and returns the same numbers as without (tests/test_fitting.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

STEP = 0.02  # forward-difference step in the unit cube: 2 % of a parameter's range (0.08 mm of a 0-4 mm gap,
#              6.6 % of a 0.2-5 stiffness scale on a log axis) -- above the kinks of the contact response's
#              noise-free but non-smooth dependence on the gaps, below the scale of its curvature
START_MARGIN = 1e-3  # the start is moved this far inside the cube: from a point on a face (a gap of 0, a corner)
#                      scipy's trf makes it "strictly feasible" by 1e-10 and then stalls there (measured:
#                      0 progress from the corner of a 2-D problem, converged from 1e-3 inside)


@dataclass
class LeastSquaresFit:
    """What :func:`fit_unit_cube` found.

    Attributes
    ----------
    p : ndarray, shape (n,)
        The evaluated point with the least sum of squares (not necessarily the last one).
    cost : float
        Its sum of squared residuals.
    cost_start : float
        The sum of squares at the start.
    evaluations : int
        Distinct points evaluated (simulation runs).
    batches : int
        Calls of the batch function.
    history : list of float
        The sum of squares of every distinct point, in the order evaluated.
    """

    p: np.ndarray
    cost: float
    cost_start: float
    evaluations: int
    batches: int
    history: list


def fit_unit_cube(batch: Callable[..., Sequence[np.ndarray]], p0, *, max_nfev: int,
                  step: float = STEP, spare: int = 0) -> LeastSquaresFit:
    """Minimise ``|r(p)|^2`` over ``p in [0, 1]^n`` with residuals from ``batch``.

    Parameters
    ----------
    batch : callable
        ``batch([p_1, ..., p_m]) -> [r(p_1), ..., r(p_m)]``: residual vectors of a list of
        points (one simulation each; they may run in parallel). Called with points not
        evaluated before only. With ``spare``, also ``batch(ps, ahead)``: the points
        ``ahead`` run in the same round, kept by ``batch`` and not counted as evaluated
        until a later call asks for them (module doc, "Runs ahead").
    p0 : array_like, shape (n,)
        Start (clipped to ``[START_MARGIN, 1 - START_MARGIN]``).
    max_nfev : int
        Iterations of :func:`scipy.optimize.least_squares` (each: one trial point, and a
        Jacobian of ``n`` more runs when the trial is accepted).
    step : float
        Forward-difference step (away from the cube's faces: backwards at the upper one).
    spare : int
        Runs a batch of one point can add at no extra wall time (idle workers): when
        ``n <= spare`` each trial point's Jacobian points run ahead with it.

    Returns
    -------
    LeastSquaresFit
    """
    from scipy.optimize import least_squares

    cache: dict[bytes, np.ndarray] = {}
    order: list[bytes] = []
    calls = [0]

    def runs(ps: list[np.ndarray], ahead: Sequence[np.ndarray] = ()) -> list[np.ndarray]:
        ps = [np.clip(np.asarray(p, float), 0.0, 1.0) for p in ps]
        todo = list({p.tobytes(): p for p in ps if p.tobytes() not in cache}.values())
        if todo:
            calls[0] += 1
            ahead = [q for q in (np.clip(q, 0.0, 1.0) for q in ahead) if q.tobytes() not in cache]
            for p, r in zip(todo, batch(todo, ahead) if ahead else batch(todo)):
                cache[p.tobytes()] = np.asarray(r, float)
                order.append(p.tobytes())
        return [cache[p.tobytes()] for p in ps]

    def fun(p):
        ahead = [q for q, _ in jacobian_points(p, step)] if 0 < np.size(p) <= spare else ()
        return runs([p], ahead)[0]

    def jac(p):
        return forward_jacobian(runs, p, step)

    p0 = np.clip(np.asarray(p0, float), START_MARGIN, 1.0 - START_MARGIN)
    r_start = fun(p0)
    least_squares(fun, p0, jac=jac, bounds=(0.0, 1.0), method="trf", max_nfev=max_nfev)
    cost = {b: float(cache[b] @ cache[b]) for b in order}
    best = min(order, key=cost.__getitem__)
    return LeastSquaresFit(np.frombuffer(best, dtype=float).copy(), cost[best], float(r_start @ r_start),
                           len(order), calls[0], [cost[b] for b in order])


def forward_jacobian(runs: Callable[[list[np.ndarray]], Sequence[np.ndarray]], p, step: float = STEP) -> np.ndarray:
    """Forward-difference Jacobian of ``runs`` at ``p`` in ``[0, 1]^n`` (backwards at the upper face).

    ``runs([p_1, ...]) -> [r(p_1), ...]`` gets the ``n + 1`` points in one call.
    """
    p = np.asarray(p, float)
    steps = jacobian_points(p, step)
    r0, *rs = runs([p] + [q for q, _ in steps])
    return np.column_stack([(r - r0) / d for r, (_, d) in zip(rs, steps)])


def jacobian_points(p, step: float = STEP) -> list[tuple[np.ndarray, float]]:
    """The perturbed points of :func:`forward_jacobian` at ``p`` and their signed steps, in its order."""
    p = np.asarray(p, float)
    steps = []
    for i in range(p.size):
        dp = np.zeros_like(p)
        dp[i] = step if p[i] + step <= 1.0 else -step
        steps.append((p + dp, dp[i]))
    return steps


__all__ = ["fit_unit_cube", "forward_jacobian", "jacobian_points", "LeastSquaresFit", "STEP", "START_MARGIN"]
