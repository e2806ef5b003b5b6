"""Bounded least squares with batched finite-difference Jacobians (orchestrator.inverse.fitting)."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.inverse.fitting import fit_unit_cube

T = np.linspace(0.0, 1.0, 40)


def _model(p: np.ndarray) -> np.ndarray:
    """A decaying oscillation whose amplitude, rate and frequency are p in [0, 1]^3 (nonlinear in two)."""
    a, k, f = 0.5 + p[0], 1.0 + 4.0 * p[1], 1.0 + 2.0 * p[2]
    return a * np.exp(-k * T) * np.cos(2 * np.pi * f * T)


def test_recovers_an_exact_nonlinear_model_with_the_jacobian_in_one_batch():
    truth = np.array([0.3, 0.6, 0.45])
    data = _model(truth)
    sizes = []

    def batch(ps):
        sizes.append(len(ps))
        return [_model(p) - data for p in ps]

    fit = fit_unit_cube(batch, [0.5, 0.5, 0.5], max_nfev=30)
    # noise-free data: the forward-difference Jacobian (step 0.02) only slows the convergence, the fixed point
    # is exact; 1e-5 in the unit cube is far below anything a simulation fit needs and above round-off
    assert np.allclose(fit.p, truth, atol=1e-5), fit.p
    assert fit.cost < 1e-10 < fit.cost_start
    assert fit.evaluations == sum(sizes) and fit.batches == len(sizes)
    assert 3 in sizes  # the Jacobian's three perturbed points went out together
    assert min(fit.history) == fit.cost


def test_bounds_hold_and_a_minimum_on_a_face_is_found():
    # the unconstrained minimum is at p0 = 1.4: the fit must stop on the face p0 = 1, and never ask outside
    seen = []

    def batch(ps):
        seen.extend(ps)
        return [np.array([p[0] - 1.4, 3.0 * (p[1] - 0.2)]) for p in ps]

    fit = fit_unit_cube(batch, [0.1, 0.9], max_nfev=20)
    assert np.all((np.array(seen) >= 0.0) & (np.array(seen) <= 1.0))
    assert fit.p == pytest.approx([1.0, 0.2], abs=1e-6)


def test_points_are_never_evaluated_twice():
    calls = {}

    def batch(ps):
        for p in ps:
            calls[p.tobytes()] = calls.get(p.tobytes(), 0) + 1
        return [np.array([np.sin(3 * p[0]) - 0.5, p[1] - 0.7]) for p in ps]

    fit = fit_unit_cube(batch, [0.0, 0.0], max_nfev=15)
    assert set(calls.values()) == {1} and len(calls) == fit.evaluations
    assert fit.p == pytest.approx([np.arcsin(0.5) / 3, 0.7], abs=1e-5)


def test_runs_ahead_change_nothing_but_the_rounds():
    """Consistency check (two paths of ours): a one-parameter fit with a spare worker runs each trial
    point's Jacobian point beside it (fitting module doc, "Runs ahead"); it must visit the same points
    in the same order and return the same numbers as without, in fewer rounds, never running a point
    twice. Exact equality: the same residual function at the same points (no tolerance needed)."""
    def residual(p):   # from 0.9, trf rejects its second trial (0.226): a Jacobian point run for nothing
        return np.array([np.tanh(10.0 * (p[0] - 0.63)), 0.3 * (p[0] - 0.6) ** 2, 0.05])

    def fitted(spare):
        rounds, ran, kept = [], [], {}

        def batch(ps, ahead=()):       # as CauseFitter: a point run ahead is served without a new run
            fresh = [p for p in ps if p.tobytes() not in kept] + list(ahead)
            rounds.append(len(fresh))
            for p in fresh:
                ran.append(p.tobytes())
                kept[p.tobytes()] = residual(p)
            return [kept[p.tobytes()] for p in ps]

        fit = fit_unit_cube(batch, [0.9], max_nfev=12, spare=spare)
        return fit, [r for r in rounds if r], ran

    plain, rounds0, ran0 = fitted(0)
    ahead, rounds1, ran1 = fitted(1)
    assert ahead.p.tobytes() == plain.p.tobytes() and ahead.cost == plain.cost
    assert ahead.history == plain.history and ahead.evaluations == plain.evaluations
    assert len(set(ran1)) == len(ran1)                       # never run twice
    assert set(ran0) < set(ran1)                             # every point the fit asked for ran, and more
    assert 2 in rounds1                                       # trial and its Jacobian point went out together
    assert len(rounds1) < len(rounds0)                        # in fewer rounds
    assert abs(ahead.p[0] - 0.63) < 1e-3                      # and the fit still converges (tanh zero at 0.63)
