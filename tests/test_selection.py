"""The fit of a void candidate (:class:`orchestrator.inverse.selection.CauseFitter`) on a closed-form response.

No simulation: the fitter's runs are replaced by a closed-form stand-in for a sleeper on a
gapped bed — each of the six gap points carries ``max(0, d - u_i)`` (the part of the
sleeper's deflection ``d`` that closes the gap ``u_i``, unit cube), so a sleeper whose
every gap exceeds ``d`` hangs and no signal depends on the gaps (the plateau of
``selection._wedge_starts``' docstring).
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from orchestrator.inputs.causes import Candidate, kind_of
from orchestrator.inverse.screening import Evaluated
from orchestrator.inverse.selection import FIT_MAX_NFEV, CauseFitter

DEFLECTION = 0.5                                          # d, unit cube (2 mm of the 0-4 mm gap range)
TRUTH = np.array([0.45, 0.45, 0.6, 0.6, 0.6, 0.6])        # rests near the low-y end, hangs over four points


def _signals(u: np.ndarray) -> np.ndarray:
    return np.maximum(0.0, DEFLECTION - np.asarray(u, float))


class _ClosedForm(CauseFitter):
    """A :class:`CauseFitter` whose runs are :func:`_signals` against the truth's (no pool, no target); its
    objective, by which a fit keeps its best point, is the residual's norm (monotone in its chi-square)."""

    truth = TRUTH

    def runs(self, us, ahead=()):   # no pool: nothing runs ahead (spare 0)
        for u in us:
            if u.tobytes() not in self.cache:
                r = _signals(u) - _signals(self.truth)
                self.cache[u.tobytes()] = SimpleNamespace(chi2=float(r @ r), objective=float(np.sqrt(r @ r)), r=r)
        return [self.cache[u.tobytes()] for u in us]

    def residuals(self, us, ahead=()):
        return [cm.r for cm in self.runs(us)]


def _start(u: np.ndarray, truth: np.ndarray = TRUTH) -> Evaluated:
    c = Candidate("ballast_void", 3)
    r = _signals(u) - _signals(truth)
    cmp = SimpleNamespace(chi2=float(r @ r), objective=float(np.sqrt(r @ r)), r=r)
    return Evaluated(c, kind_of(c).from_unit(u), cmp, 1, "confirmed")


def test_a_void_fit_leaves_a_hanging_uniform_start():
    """A uniform gap on the plateau fits better than both one-sided wedges to its peak, but no fit can
    leave it; the wedge fit must restart from the better wedge and end below the plateau's chi-square.

    Closed form: on the plateau (every gap 0.7 > d) the residual is minus the truth's signals,
    chi2 = 2 x 0.05^2 = 0.005; the wedge 0.45 -> 0.7 (within the two-parameter family) leaves
    only point 2 off (gap 0.5 vs 0.45: 0.05), chi2 = 0.0025. The old start rule (the best of the
    three starts) stayed on the plateau: chi2 0.005.
    """
    plateau = np.full(6, 0.7)
    start = _start(plateau)
    assert abs(start.cmp.chi2 - 2 * 0.05 ** 2) < 1e-12
    fitter = _ClosedForm(pool=None, target=None, raw={}, start=start, reference=None)
    wedges = fitter._wedge_starts(plateau, lambda p: np.linspace(p[0], p[1], 6))
    assert np.allclose(wedges[0], [0.7, 0.7])             # the plateau does fit best of the three starts
    fitted = fitter.fit(start, slice(0, 1), FIT_MAX_NFEV)
    assert fitted.cmp.chi2 < 0.8 * start.cmp.chi2         # left the plateau (0.0025 in reach; 0.8: well clear of it)
    assert fitted.values.max() > 0.0


def test_a_void_fit_that_no_start_improves_tries_half_the_screened_gap():
    """When no start of the wedge stage improves on the screened point (here the one-sided wedges' runs
    are taken as failed, so the plateau is the only start, and no fit can leave it), the fitter tries
    the uniform gap at half the screened peak, which touches the bed, and keeps the best point visited
    (the field-like case void_off_sensor 7202 stayed on its plateau this way: RESULTS, session 22).

    Closed form as above: the plateau at 0.7 has chi2 0.005; the start 0.35 (every point touching,
    chi2 0.11) has a gradient, and the wedge 0.45 -> 0.7 (chi2 0.0025) is in reach of a fit from it.
    """
    plateau = np.full(6, 0.7)
    start = _start(plateau)

    class _NoWedges(_ClosedForm):
        def _wedge_starts(self, u, to_u):
            return [u[[0, -1]]]

    fitter = _NoWedges(pool=None, target=None, raw={}, start=start, reference=None)
    fitted = fitter.fit(start, slice(0, 1), FIT_MAX_NFEV)
    assert any(np.allclose(np.frombuffer(b), 0.35) for b in fitter.cache)   # the half start ran
    assert fitted.cmp.chi2 < 0.8 * start.cmp.chi2          # left the plateau (0.8: as in the test above)


def test_a_void_fit_that_moves_from_its_first_start_is_not_restarted():
    """From a start with a gradient the fit moves and the other starts are never fitted: the fitter runs
    the two one-sided wedges (to choose the start) and exactly the points of one fit from the start
    (consistency check against :func:`fit_unit_cube` on the same closed form)."""
    from orchestrator.inverse.fitting import fit_unit_cube

    u0 = np.linspace(0.3, 0.6, 6)
    start = _start(u0)
    fitter = _ClosedForm(pool=None, target=None, raw={}, start=start, reference=None)
    fitted = fitter.fit(start, slice(0, 1), FIT_MAX_NFEV)
    assert fitted.cmp.chi2 < start.cmp.chi2

    def batch(ps):
        return [_signals(np.linspace(p[0], p[1], 6)) - _signals(TRUTH) for p in ps]

    alone = fit_unit_cube(batch, np.array([0.3, 0.6]), max_nfev=FIT_MAX_NFEV)
    assert alone.cost < alone.cost_start
    assert len(fitter.cache) == alone.evaluations + 2


def test_a_point_run_ahead_waits_until_asked_for(monkeypatch):
    """CauseFitter.runs with points ``ahead`` (fitting module doc, "Runs ahead"): they run in the same pool
    round but enter the fitter's cache (which :meth:`best` reads) and the dropped list only when a later
    call asks for them, then without a second run. A stand-in cause, pool and comparison (no simulation)."""
    from orchestrator.inverse import selection

    kind = SimpleNamespace(names=("scale",), from_unit=lambda u: np.asarray(u, float),
                           apply=lambda raw, sleeper, v: {"v": float(v[0])})
    monkeypatch.setattr(selection, "kind_of", lambda c: kind)
    # a run at v > 0.9 "diverges": checked_comparison gives no comparison and its reason
    monkeypatch.setattr(selection, "checked_comparison",
                        lambda target, run, ref: (None, "diverged") if run > 0.9 else (SimpleNamespace(objective=run), None))

    class Pool:
        spare, ahead_runs, ahead_used, dropped, rounds = 1, 0, 0, [], []

        def map(self, raws, then=None):
            self.rounds.append(len(raws))
            return [r["v"] if then is None else then(r["v"]) for r in raws]

        def drop(self, variant, stage, reason):
            self.dropped.append(reason)

        def count(self, **increments):
            for name, value in increments.items():
                setattr(self, name, getattr(self, name) + value)

    pool = Pool()
    start = Evaluated(SimpleNamespace(label="stand-in", sleeper=None), np.array([0.5]), SimpleNamespace(objective=0.5),
                      1, "confirmed")
    fitter = CauseFitter(pool=pool, target=None, raw={}, start=start, reference=None)
    u1, u2, u3 = np.array([0.3]), np.array([0.95]), np.array([0.2])
    assert fitter.runs([u1], ahead=[u2, u3])[0].objective == 0.3
    assert pool.rounds == [3] and pool.ahead_runs == 2
    assert list(fitter.cache) == [u1.tobytes()] and pool.dropped == []     # u3 (J 0.2) is not yet best
    assert np.array_equal(fitter.best(), u1)
    assert fitter.runs([u2, u1]) == [None, fitter.cache[u1.tobytes()]]
    assert pool.rounds == [3] and pool.ahead_used == 1 and pool.dropped == ["diverged"]   # no second run
    fitter.runs([u3])
    assert pool.rounds == [3] and pool.ahead_used == 2 and np.array_equal(fitter.best(), u3)


def test_fits_side_by_side_overlap_and_keep_their_order():
    """selection.side_by_side: with a spare worker the fits run at the same time (two calls that each
    wait for the other pass a two-party barrier, which one after another would time out on), the
    results come back in the calls' order; without a spare worker they run one after another, in order."""
    import threading

    from orchestrator.inverse.selection import side_by_side

    barrier = threading.Barrier(2, timeout=10)
    order = []

    def fit(name):
        order.append(name)
        return name, barrier.wait()

    got = side_by_side(SimpleNamespace(spare=1), {"b": lambda: fit("b"), "a": lambda: fit("a")})
    assert list(got) == ["b", "a"] and {got["a"][1], got["b"][1]} == {0, 1}
    order.clear()
    got = side_by_side(SimpleNamespace(spare=0),
                       {"b": lambda: order.append("b") or 2, "a": lambda: order.append("a") or 1})
    assert got == {"b": 2, "a": 1} and order == ["b", "a"]


def test_pool_gives_a_freed_worker_to_the_shortest_queue_and_close_cancels_the_waiting():
    """screening.Pool with ``slots``: runs wait in the pool; a freed slot goes to the thread with the fewest
    runs waiting (a Gauss-Newton chain's single run before the rest of a Jacobian batch beside it), the
    oldest first among equals; a run's result reaches its caller; close() cancels what still waits and
    starts nothing more. A stand-in executor that finishes a run only when told (no simulation)."""
    import threading
    from concurrent.futures import CancelledError, Future

    from orchestrator.inverse.screening import Pool

    class Executor:
        def __init__(self):
            self.started = []    # (job, future) in the order the pool handed them over

        def submit(self, fn, job):
            f = Future()
            self.started.append((job, f))
            return f

    ex = Executor()
    pool = Pool(ex, slots=2)
    batch = pool._enqueue(["J1", "J2", "J3", "J4"])            # a Jacobian batch, from this thread
    assert [j for j, _ in ex.started] == ["J1", "J2"]          # two slots
    chain = []
    t = threading.Thread(target=lambda: chain.append(pool._enqueue(["G1"])))
    t.start()
    t.join()
    assert [j for j, _ in ex.started] == ["J1", "J2"]          # no free slot yet
    ex.started[0][1].set_result("r1")                          # J1 ends: G1's queue (1) is shorter than J's (2)
    assert [j for j, _ in ex.started] == ["J1", "J2", "G1"] and batch[0].result(timeout=1) == "r1"
    ex.started[1][1].set_result("r2")                          # J2 ends: only J's queue waits
    assert [j for j, _ in ex.started][-1] == "J3"
    pool.close()
    assert batch[3].cancelled() and not batch[2].done()
    ex.started[2][1].set_exception(RuntimeError("worker lost"))   # a run's error reaches its caller
    try:
        chain[0][0].result(timeout=1)
        raise AssertionError("the run's error was not passed on")
    except RuntimeError as exc:
        assert "worker lost" in str(exc)
    assert len(ex.started) == 4                                # nothing started after close()
    try:
        batch[3].result(timeout=1)
        raise AssertionError("a cancelled run gave a result")
    except CancelledError:
        pass


def test_a_gap_that_never_touches_the_bed_is_tried_closed():
    """A six-gap fit cannot move a gap whose point never touches the bed (its derivative is exactly 0: on
    the plateau above the sleeper's deflection, every gap gives the same J); the fitter then tries those
    gaps closed and fits again from there when that is better (field-like case void_off_sensor 7303:
    RESULTS, session 23).

    Closed form as above, truth (0.3, 0.3, 0.3, 0.3, 0, 0): the last two points bear (signal d = 0.5
    each). From (0.3, 0.3, 0.3, 0.3, 0.7, 0.7) they hang: residual -0.5 at each, chi2 0.5, and a zero
    column in the Jacobian. Closed, chi2 0 (the start's first four points are the truth's already).
    A gap that bears (a non-zero column) is never closed: from (0.2, 0.3, 0.3, 0.3, 0.7, 0.7) the first
    point is fitted (to 0.3) and not set to 0."""
    from orchestrator.inverse import selection

    class _Ends(_ClosedForm):
        truth = np.array([0.3, 0.3, 0.3, 0.3, 0.0, 0.0])

    def fit_from(u0):
        start = _start(u0, _Ends.truth)
        fitter = _Ends(pool=None, target=None, raw={}, start=start, reference=None)
        return start, fitter, fitter.fit(start, slice(1, 2), selection.FINE_MAX_NFEV)

    start, _, fitted = fit_from(np.array([0.3, 0.3, 0.3, 0.3, 0.7, 0.7]))
    assert abs(start.cmp.chi2 - 0.5) < 1e-12                       # hand value: two residuals of -0.5
    assert fitted.cmp.chi2 < 1e-6, fitted.cmp.chi2                 # the closed point itself ran: chi2 0 to round-off
    _, fitter, fitted = fit_from(np.array([0.2, 0.3, 0.3, 0.3, 0.7, 0.7]))
    assert not any(np.frombuffer(b)[0] == 0.0 for b in fitter.cache)   # the bearing first gap was never closed
    u = kind_of(fitted.candidate).to_unit(fitted.values)
    # 0.02: the forward-difference step (fitting.STEP), the resolution of a fit on this kinked response
    assert abs(u[0] - 0.3) < 0.02 and fitted.cmp.chi2 < 1e-4, (u, fitted.cmp.chi2)
