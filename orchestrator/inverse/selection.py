"""One round of cause selection of a diagnosis: screen, search, confirm, fit, rank (steps 2-5).

A round works on a *reference* model — the nominal scenario (with its nuisance
estimates) for the first cause, the model extended by the causes named so far for the
next (forward selection, :mod:`orchestrator.inverse.diagnose`) — and a list of candidates:

1. :func:`_screen`: every candidate at the magnitudes of its screening grid (one batch),
   a void also as the two one-sided wedges (its :meth:`~orchestrator.inputs.causes.CauseKind.screen_proxies`);
2. :func:`_search_one`: each candidate's best magnitude by the dense 1-D search between its
   screening runs (:func:`orchestrator.inverse.screening.dense_search`, no runs), of its
   best-fitting proxy — done as soon as the candidate's last screening run is in, while the
   batch goes on;
3. :func:`_confirm`: the :data:`CONFIRM` best re-run at their best magnitude;
4. :func:`_fits`: bounded least squares (:class:`CauseFitter`;
   a void first as a wedge, :func:`cause_stages`, started from its screened profile (uniform gap or wedge)
   or a one-sided wedge, whichever fits better, and from the next of them when the fit cannot leave
   that start: a hanging sleeper has no gradient; when no start improves on the screened point, once
   more from the uniform gap at half its peak, which touches the bed; the six gaps once more with
   those that never touch the bed closed, when that fits better), all parameters of the best and of
   up to :data:`FIT` - 1 runners-up whose J is within a factor :data:`FIT_RATIO` of the best's; the candidates' fits of a stage run side by side (:func:`side_by_side`, same results as one
   after another);
5. :func:`_rank`: the fitted and confirmed candidates by their BIC on the effective
   sample size (:func:`orchestrator.inverse.significance.bic_eff`, N_eff of the best
   one's residual for all of them, so they compare like with like), and who cannot be
   told apart from whom (within :data:`~orchestrator.inverse.significance.DELTA_BIC`).

**One criterion.** Every choice of a round — the dense search's point and the screening proxy, which
candidates are confirmed, which are fitted fully, the point a fit keeps, round 2's superposed ranking —
is made by the objective J, the measure the gain is reported in (and the one a fit's least squares
minimise, squared); only the ranking of the fitted candidates and the naming use the BIC on the
effective sample size (:mod:`orchestrator.inverse.significance`). Until 2026-11-27 those choices were
by chi-square, whose optimum can sit elsewhere when a model-form mismatch leaves a residual the noise
level does not describe: a global pad beside a vehicle mismatch (field matrix pad_global+mismatch 7101)
was fitted towards J's optimum and then kept at its start, the point of least chi-square, 30 % gain
against the truth's 57 %; by J 51 %. Changing only some links moved borderline cases at the others
(RESULTS, session 20); the whole chain by J, on the field matrix: the gains of 25 of 51 diagnoses
changed, by -8 to +21 points (median +0.1 of those; worn_nose+mismatch 7202 +9.6), none of the
answers (RESULTS, session 21).

Variants whose run cannot be compared (stopped early, non-finite signals, outside the
record) are left out with their reason (:attr:`orchestrator.inverse.screening.Pool.dropped`);
inside a fit such a point gets a residual :data:`PENALTY` times the reference's, so the
trust region steps away from it.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial
from typing import Sequence

import numpy as np

from orchestrator.inputs.causes import kind_of
from orchestrator.inverse.objective import Comparison, Target
from orchestrator.inverse.screening import Evaluated, Pool, checked_comparison, dense_search, scalar_axis
from orchestrator.inverse.significance import DELTA_BIC, bic_eff, channel_neff

CONFIRM = 4          # candidates re-run at their screened optimum
FIT = 2              # candidates whose full parameter set is fitted, at most ...
FIT_RATIO = 2 ** 0.5  # ... of those whose coarse fit's J is within this factor of the best's (chi-square's factor 2)
FIT_MAX_NFEV = 5     # least-squares iterations of a coarse fit (each: one run + a parallel Jacobian) ...
FINE_MAX_NFEV = 8    # ... and of the fine stages (six gaps)
PENALTY = 10.0       # residual of a point whose run failed, times the reference's (inside a fit)


def cause_stages(kind) -> list:
    """Coarse-to-fine parameterisations of a fit: (number of parameters, map to the unit cube).

    A void is first fitted as a wedge (the gaps linear between the sleeper's ends: 2
    parameters, well conditioned, covering a uniform gap) and then point by point from
    there; six free gaps straight from a uniform start stall in the non-smooth contact
    response. The other causes have one parameter.
    """
    n = len(kind.names)
    if n == 1:
        return [(1, lambda p: np.asarray(p, float))]
    return [(2, lambda p: np.linspace(p[0], p[1], n)), (n, lambda p: np.asarray(p, float))]


@dataclass
class CauseFitter:
    """Runs of one candidate on a reference scenario, cached by the unit-cube point.

    Attributes
    ----------
    pool : Pool
    target : Target
    raw : dict
        The reference scenario the candidate is applied to.
    start : Evaluated
        The candidate's evaluation the fit starts from.
    reference : Comparison
        The reference model's comparison (what a failed point's residual is scaled from).
    cache : dict
        Unit-cube point (bytes) -> Comparison, or None for a failed run.
    ahead : dict
        Points run ahead of being asked for (:func:`orchestrator.inverse.fitting.fit_unit_cube`,
        "Runs ahead"): bytes -> (Comparison or None, why). A point moves to :attr:`cache`
        when :meth:`runs` is asked for it, so :meth:`best` sees only the points the fit visited.
    """

    pool: Pool
    target: Target
    raw: dict
    start: Evaluated
    reference: Comparison
    cache: dict = field(default_factory=dict)
    ahead: dict = field(default_factory=dict)

    def runs(self, us: list[np.ndarray], ahead: Sequence[np.ndarray] = ()) -> list[Comparison | None]:
        """The comparisons of the points ``us`` (full parameter vectors in the unit cube); the points
        ``ahead`` run in the same round and wait in :attr:`ahead` until asked for."""
        c, kind = self.start.candidate, kind_of(self.start.candidate)
        asked = {u.tobytes(): u for u in us if u.tobytes() not in self.cache}
        fresh = [u for b, u in asked.items() if b not in self.ahead]
        extra = {u.tobytes(): u for u in ahead
                 if u.tobytes() not in self.cache and u.tobytes() not in self.ahead and u.tobytes() not in asked}
        todo = fresh + list(extra.values())
        got = {}
        if todo:
            out = self.pool.map([kind.apply(self.raw, c.sleeper, kind.from_unit(u)) for u in todo],
                                then=lambda run: checked_comparison(self.target, run, self.reference))
            self.pool.count(ahead_runs=len(extra))
            got = {u.tobytes(): cw for u, cw in zip(todo, out)}
        for b, u in asked.items():   # in the order asked, whether run now or ahead
            if b in self.ahead:
                self.pool.count(ahead_used=1)
            self._keep(u, *(self.ahead.pop(b) if b in self.ahead else got[b]))
        for b in extra:
            self.ahead[b] = got[b]
        return [self.cache[u.tobytes()] for u in us]

    def known(self, values, cmp: Comparison) -> None:
        """Enter the comparison of the cause at ``values`` when the caller already has it (a refit that starts
        from the extended model itself): the fit's first point then needs no run."""
        self.cache[np.clip(kind_of(self.start.candidate).to_unit(values), 0.0, 1.0).tobytes()] = cmp

    def _keep(self, u: np.ndarray, cmp: Comparison | None, why: str | None) -> None:
        """Enter an evaluated point in :attr:`cache` (a failed run: dropped with its reason)."""
        if cmp is None:
            kind = kind_of(self.start.candidate)
            self.pool.drop(f"{self.start.candidate.label} at {np.round(kind.from_unit(u), 6).tolist()}", "fit", why)
        self.cache[u.tobytes()] = cmp

    def residuals(self, us: list[np.ndarray], ahead: Sequence[np.ndarray] = ()) -> list[np.ndarray]:
        """Weighted residuals of the points (a failed point: :data:`PENALTY` x the reference's); ``ahead``
        as in :meth:`runs`."""
        return [self.target.weighted_residuals(cm) if cm is not None
                else PENALTY * self.target.weighted_residuals(self.reference) for cm in self.runs(us, ahead)]

    def best(self) -> np.ndarray:
        """The cached point of least objective J (module doc, "One criterion")."""
        ok = {b: cm for b, cm in self.cache.items() if cm is not None}
        return np.frombuffer(min(ok, key=lambda b: ok[b].objective), dtype=float).copy()

    def best_objective(self) -> float:
        """J of :meth:`best` (inf before any point ran)."""
        return min((cm.objective for cm in self.cache.values() if cm is not None), default=np.inf)

    def fit(self, start: Evaluated, stages: slice, max_nfev: int) -> Evaluated:
        """Bounded least squares through ``cause_stages(kind)[stages]`` from ``start``.

        The wedge stage starts as :meth:`_wedge_starts` orders; when none of its fits improves on
        ``start`` (a screened uniform gap that lifts the whole sleeper, where J is flat, and wedges
        to that peak that fit worse), one more fit starts from the uniform gap at half the peak, in
        contact with the bed. Measured (field-like case void_off_sensor 7202, a bump-shaped void
        peaking at 1.19 mm two sleepers beyond the sensors, screened at a uniform 1.78 mm): J along
        the uniform gap (diagnose.hypothesis_gains, its nuisance refit included) is not monotone
        (1.78 and 1.4 mm: 0.0205, the plateau; 1.2 mm 0.0224, 0.8 mm 0.0183), the wedges to 1.78 mm
        0.0256 and 0.0329; the named void stayed on the plateau (gain 70.9 % against the truth's
        81.5 %) and, with this start, reached 80.4 %. The six-gap stage ends the same way for single
        points: :meth:`_closed_hanging`.
        """
        from orchestrator.inverse.fitting import fit_unit_cube

        kind = kind_of(start.candidate)
        u_best, k = np.clip(kind.to_unit(start.values), 0.0, 1.0), start.k
        for n, to_u in cause_stages(kind)[stages]:
            k = n

            def batch(ps, ahead=(), to_u=to_u):
                return self.residuals([np.clip(to_u(p), 0.0, 1.0) for p in ps],
                                      [np.clip(to_u(q), 0.0, 1.0) for q in ahead])

            spare = self.pool.spare if self.pool is not None else 0
            for p0 in (self._wedge_starts(u_best, to_u) if n == 2 else [u_best]):
                fit = fit_unit_cube(batch, p0, max_nfev=max_nfev, spare=spare)
                if fit.cost < fit.cost_start:   # the fit left its start: no restart
                    break
            if n == 2 and self.best_objective() >= start.cmp.objective:
                # no start improved on the screened point: a hanging sleeper's plateau (flat J)
                fit_unit_cube(batch, np.full(2, 0.5 * u_best.max()), max_nfev=max_nfev, spare=spare)
            if any(cm is not None for cm in self.cache.values()):
                closed = self._closed_hanging(self.best()) if n > 2 else None   # a hanging point's plateau
                if closed is not None:
                    fit_unit_cube(batch, closed, max_nfev=max_nfev, spare=spare)
                u_best = self.best()
        best = self.cache.get(u_best.tobytes())
        if best is None or best.objective > start.cmp.objective:   # the fit never did better than its start
            return Evaluated(start.candidate, start.values, start.cmp, k, "fitted")
        return Evaluated(start.candidate, kind.from_unit(u_best), best, k, "fitted")

    def _closed_hanging(self, u: np.ndarray) -> np.ndarray | None:
        """``u`` with its hanging gaps closed, when that fits better than ``u``; else None.

        A gap point that never touches the bed during the passage does not enter the run: J does
        not change with its gap (the forward difference of :func:`~orchestrator.inverse.fitting.forward_jacobian`
        is exactly zero), so no fit can move it, and any gap above the sleeper's deflection there
        gives the same J. Closing it (gap 0: the point bears) is the one change that can tell; a
        fit of the six gaps starts from there when it lowers J. Measured (field-like case
        void_off_sensor 7303, a void at 24 whose last two of six points bear, J along hand-given
        profiles with diagnose.hypothesis_gains): the fit stopped at 1.67 and 2.01 mm there, J
        0.042 (gain 59.1 % against the truth's 80.1 %); those two closed, 0.026; the truth 0.021;
        along the straight line from the fit to the truth J stays at 0.043-0.044 until the two gaps
        come below ~0.4 mm. Costs the Jacobian's runs at ``u`` not yet made (none when the fit ended
        on an accepted step) and one run.
        """
        from orchestrator.inverse.fitting import jacobian_points

        here = self.cache.get(u.tobytes())
        if here is None:
            return None
        steps = [q for q, _ in jacobian_points(u)]
        self.runs([q for q in steps if q.tobytes() not in self.cache])
        flat = [i for i, q in enumerate(steps) if u[i] > 0.0 and self.cache.get(q.tobytes()) is not None
                and self.cache[q.tobytes()].objective == here.objective]
        if not flat:
            return None
        closed = u.copy()
        closed[flat] = 0.0
        got = self.runs([closed])[0]
        return closed if got is not None and got.objective < here.objective else None

    def _wedge_starts(self, u: np.ndarray, to_u) -> list[np.ndarray]:
        """The wedge's starts, best first: the current ends and the two one-sided wedges to the same peak.

        A uniform screened gap that lifts the whole sleeper off the bed has no gradient
        (no point touches the ballast, a small change of any gap changes nothing), so a
        fit started there stays there; the two one-sided wedges (peak at one end, 0 at the
        other) touch the bed at one end. Such a hanging start may still fit better than
        both wedges (measured: a void of 1.1-1.75 mm over four of six points next to a
        soft pad, field-like case two_void_pad 7101: the hanging sleeper J 0.49, the
        wedges to its peak 3.0 and 4.2), so it is tried first and the next start is fitted
        only when the fit makes no progress at all from it (:meth:`fit`): from the better
        wedge the same case reached J 0.35. Two runs (the ends' run is the start's).
        """
        ends = [u[[0, -1]], np.array([u.max(), 0.0]), np.array([0.0, u.max()])]
        comps = self.runs([np.clip(to_u(p), 0.0, 1.0) for p in ends])
        j = [cm.objective if cm is not None else np.inf for cm in comps]
        order = [i for i in np.argsort(j, kind="stable") if np.isfinite(j[i])]
        return [ends[i] for i in order] or [ends[0]]

    def jacobian(self, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Jacobian of the weighted residuals in the unit cube, the residuals) at ``values``."""
        from orchestrator.inverse.fitting import forward_jacobian

        u = np.clip(kind_of(self.start.candidate).to_unit(values), 0.0, 1.0)
        jac = forward_jacobian(self.residuals, u)
        return jac, self.residuals([u])[0]


# ------------------------------------------------------------------------------------ a round
@dataclass
class Round:
    """What one round of selection found (module doc).

    Attributes
    ----------
    reference : Evaluated
        The model the candidates were added to.
    k_ref : int
        Parameters already fitted in it.
    ranked : list of Evaluated
        Every candidate's last evaluation: the fitted and confirmed ones by BIC on N_eff,
        then the screened ones by J.
    real : list of Evaluated
        The fitted and confirmed candidates of ``ranked``.
    bic : dict
        Candidate of ``real`` -> its BIC on N_eff (k counts the reference's parameters too).
    twins : dict
        Candidate of ``real`` -> labels of the others within DELTA_BIC of it.
    fitters : dict
        Candidate -> its :class:`CauseFitter` (its runs, for the intervals).
    screened : dict
        Candidate -> magnitude -> signals on the measured base (:func:`_screen`; of the
        candidate's best-fitting screening proxy).
    proxies : dict
        Candidate -> (its screening proxies as :func:`_axes` gives them, each proxy's magnitude ->
        signals): every screening run, for judging the round again on another target
        (:func:`rejudged`).
    """

    reference: Evaluated
    k_ref: int
    ranked: list
    real: list
    bic: dict
    twins: dict
    fitters: dict
    screened: dict = field(default_factory=dict)
    proxies: dict = field(default_factory=dict)


def _axes(kind, raw: dict, sleeper) -> list[tuple[np.ndarray | None, np.ndarray, float]]:
    """The screening proxies of a candidate: (profile, or None for the uniform one; magnitudes; nominal)."""
    return [(None if i == 0 else prof, *scalar_axis(kind, raw, sleeper, grid))
            for i, (prof, grid) in enumerate(kind.screen_proxies())]


def _screen(pool: Pool, target: Target, raw: dict, ref: Evaluated, cands: list, axes: dict) -> tuple[dict, dict]:
    """Step 2: the screening runs, and each candidate's dense search (:func:`_search_one`) as soon as its
    last run is in, while the later candidates' runs go on (the searches took ~2.5 s of an idle pool
    after the 96 runs of the default diagnosis). Failed variants are left out.

    Returns (candidate -> its screened evaluation, candidate -> the best proxy's magnitude -> signals),
    as :func:`_search_one` gives them (candidates with < 2 magnitudes left out), and candidate -> (its
    axes, every proxy's magnitude -> signals) (:attr:`Round.proxies`)."""
    jobs = [(c, i, x) for c in cands for i, (_, xs, x0) in enumerate(axes[c]) for x in xs if abs(x - x0) > 1e-12]
    left = {c: sum(1 for j in jobs if j[0] == c) for c in cands}
    screened = {c: [{x0: ref.cmp.simulated} for _, _, x0 in axes[c]] for c in cands}
    dense, grids = {}, {}

    def arrived(job, run) -> None:
        c, i, x = job
        cmp, why = checked_comparison(target, run, ref.cmp)
        if cmp is None:
            pool.drop(f"{c.label} at {x:.6g}" + ("" if i == 0 else f" (screening shape {i})"), "screening", why)
        else:
            screened[c][i][x] = cmp.simulated
        left[c] -= 1
        if left[c] == 0:
            _search_one(target, c, axes[c], screened[c], dense, grids)

    it = iter(jobs)   # pool.map hands the runs over in the order of the jobs
    pool.map([kind_of(c).apply_scalar(raw, c.sleeper, x, axes[c][i][0]) for c, i, x in jobs],
             then=lambda run: arrived(next(it), run))
    return ({c: dense[c] for c in cands if c in dense}, {c: grids[c] for c in cands if c in grids},
            {c: (axes[c], screened[c]) for c in cands})


def _search_one(target: Target, c, axes_c: list, screened_c: list, dense: dict, grids: dict) -> None:
    """Step 2, no runs: into ``dense[c]`` candidate ``c``'s evaluation at the best magnitude of its
    best-fitting proxy, into ``grids[c]`` that proxy's magnitude -> signals (nothing with < 2 magnitudes)."""
    for (profile, _, _), grid in zip(axes_c, screened_c):
        xs = np.array(sorted(grid))
        if xs.size < 2:
            continue
        x_best, cmp = dense_search(target, kind_of(c), xs, [grid[x] for x in xs])
        if c not in dense or cmp.objective < dense[c].cmp.objective:
            dense[c] = Evaluated(c, kind_of(c).scalar_to_vector(x_best, profile), cmp, 1, "screened")
            grids[c] = grid


def _confirm(pool: Pool, target: Target, raw: dict, ref: Evaluated, dense: dict, confirm: int) -> dict:
    """Step 3: the ``confirm`` best screened candidates re-run at their best magnitude."""
    top = sorted(dense, key=lambda c: dense[c].cmp.objective)[:confirm]
    pool.expect(len(top))
    got = pool.map([kind_of(c).apply(raw, c.sleeper, dense[c].values) for c in top],
                   then=lambda run: checked_comparison(target, run, ref.cmp))
    out = {}
    for c, (cmp, why) in zip(top, got):
        if cmp is None:
            pool.drop(f"{c.label} at {np.round(dense[c].values, 6).tolist()}", "confirmation", why)
        else:
            out[c] = Evaluated(c, dense[c].values, cmp, 1, "confirmed")
    return out


def _fits(pool: Pool, target: Target, raw: dict, ref: Evaluated, confirmed: dict) -> tuple[dict, dict]:
    """Step 4: every confirmed candidate fitted coarsely, then all parameters of the best (and close runners-up).

    Returns (candidate -> ``fitted`` evaluation, candidate -> its :class:`CauseFitter`).
    """
    fitters = {c: CauseFitter(pool, target, raw, e, ref.cmp) for c, e in confirmed.items()}
    for c in confirmed:
        pool.expect(FIT_MAX_NFEV * (cause_stages(kind_of(c))[0][0] + 1))
    fitted = side_by_side(pool, {c: partial(fitters[c].fit, confirmed[c], slice(0, 1), FIT_MAX_NFEV)
                                 for c in confirmed})
    if not fitted:
        return fitted, fitters
    by_fit = sorted(fitted, key=lambda c: fitted[c].cmp.objective)
    lead = fitted[by_fit[0]].cmp.objective
    fine = {}
    for c in [c for c in by_fit if fitted[c].cmp.objective <= FIT_RATIO * lead][:FIT]:
        stages = cause_stages(kind_of(c))
        if len(stages) > 1:
            pool.expect(FINE_MAX_NFEV * sum(n + 1 for n, _ in stages[1:]))
            fine[c] = partial(fitters[c].fit, fitted[c], slice(1, None), FINE_MAX_NFEV)
    fitted.update(side_by_side(pool, fine))
    return fitted, fitters


def side_by_side(pool: Pool, calls: dict) -> dict:
    """``{key: call()}`` of independent fits, each in its own thread when the pool has more than one
    worker, so that one fit's runs fill the workers another's leaves idle: a least-squares iteration
    is a trial point and then its Jacobian, a batch of one run and one of n, and a batch of one run
    leaves the second of two workers idle (30 such batches, most of them in the fits, took 17 s of the
    default diagnosis's 90 s). Each fit asks for the same points whatever the others do (its own
    :class:`CauseFitter` and cache), so the results are those of the fits one after another; only
    their runs' order on the workers changes (and the order in which their failed points enter
    ``pool.dropped``). In ``calls``' order."""
    if pool.spare < 1 or len(calls) < 2:
        return {k: call() for k, call in calls.items()}
    from concurrent.futures import ThreadPoolExecutor

    threads = ThreadPoolExecutor(len(calls), thread_name_prefix="fit")
    futures = {k: threads.submit(call) for k, call in calls.items()}
    try:
        return {k: f.result() for k, f in futures.items()}
    finally:   # not waited for on an error or ^C: the caller shuts the pool down, the fits end at their next run
        threads.shutdown(wait=False)


def _rank(target: Target, ref: Evaluated, k_ref: int, final: dict, fitters: dict) -> Round:
    """Step 5: the fitted and confirmed candidates by BIC on N_eff, then the screened ones; who are twins.

    ``final``: candidate -> its last evaluation (:func:`_explore`)."""
    real = [e for e in final.values() if e.stage in ("fitted", "confirmed")]
    rest = sorted((e for e in final.values() if e.stage == "screened"), key=lambda e: e.cmp.objective)
    if not real:
        return Round(ref, k_ref, rest, [], {}, {}, fitters)
    neff = channel_neff(min(real, key=lambda e: e.cmp.chi2).cmp)
    bic = {e.candidate: bic_eff(e.cmp, target.sigma, neff, k_ref + e.k) for e in real}
    real.sort(key=lambda e: bic[e.candidate])
    twins = {e.candidate: [o.candidate.label for o in real if o is not e and abs(bic[o.candidate] - bic[e.candidate])
                           < DELTA_BIC] for e in real}
    return Round(ref, k_ref, real + rest, real, bic, twins, fitters)


def select(pool: Pool, target: Target, raw: dict, ref: Evaluated, k_ref: int, cands: list,
           confirm: int = CONFIRM) -> Round:
    """One round (module doc): ``cands`` added one at a time to the reference ``raw`` / ``ref``.

    ``confirm``: how many of the screened candidates are re-run and fitted (the later
    rounds of forward selection confirm fewer: they screen only a few).
    """
    final, grids, fitters, proxies = _explore(pool, target, raw, ref, cands, confirm)
    rd = _rank(target, ref, k_ref, final, fitters)
    rd.screened, rd.proxies = grids, proxies
    return rd


def rejudged(pool: Pool, target: Target, raw: dict, ref: Evaluated, rd: Round, confirm: int = CONFIRM) -> Round:
    """Round ``rd`` judged again on another ``target`` (the same measurement compared otherwise: a channel
    gain released) with ``ref``, the reference's comparison on it: each candidate's dense search over
    ``rd``'s screening runs (no runs), then confirmed, fitted and ranked as :func:`select` does."""
    dense, grids = {}, {}
    for c, (axes_c, screened_c) in rd.proxies.items():
        _search_one(target, c, axes_c, screened_c, dense, grids)
    final, fitters = _settle(pool, target, raw, ref, dense, confirm)
    out = _rank(target, ref, rd.k_ref, final, fitters)
    out.screened, out.proxies = grids, rd.proxies
    return out


def _explore(pool: Pool, target: Target, raw: dict, ref: Evaluated, cands: list, confirm: int) -> tuple:
    """Steps 1-4 of a round for ``cands``: (candidate -> its last evaluation, fitted else confirmed else
    screened; candidate -> its screening grid's signals; candidate -> its :class:`CauseFitter`)."""
    axes = {c: _axes(kind_of(c), raw, c.sleeper) for c in cands}
    pool.expect(sum(len(xs) - 1 for c in cands for _, xs, _ in axes[c]))
    dense, grids, proxies = _screen(pool, target, raw, ref, cands, axes)
    final, fitters = _settle(pool, target, raw, ref, dense, confirm)
    return final, grids, fitters, proxies


def _settle(pool: Pool, target: Target, raw: dict, ref: Evaluated, dense: dict, confirm: int) -> tuple[dict, dict]:
    """Steps 3-4 from the screened candidates ``dense``: (candidate -> its last evaluation, fitted else
    confirmed else screened; candidate -> its :class:`CauseFitter`)."""
    confirmed = _confirm(pool, target, raw, ref, dense, confirm)
    fitted, fitters = _fits(pool, target, raw, ref, confirmed)
    return {c: fitted.get(c) or confirmed.get(c) or dense[c] for c in dense}, fitters


def widen(pool: Pool, target: Target, raw: dict, rd: Round, more: list, confirm: int = CONFIRM) -> Round:
    """Round ``rd`` (of :func:`select`, on ``raw``) with the candidates ``more`` added: they are screened,
    confirmed (their ``confirm`` best) and fitted as :func:`select` does, and ranked with ``rd``'s, on the
    same reference, as one round (:func:`_rank`; ``rd``'s runs are not repeated)."""
    final, grids, fitters, proxies = _explore(pool, target, raw, rd.reference, more, confirm)
    out = _rank(target, rd.reference, rd.k_ref, {**{e.candidate: e for e in rd.ranked}, **final},
                {**rd.fitters, **fitters})
    out.screened, out.proxies = {**rd.screened, **grids}, {**rd.proxies, **proxies}
    return out


def superposed_ranking(target: Target, first: Round, extended: Evaluated, cands: list) -> list:
    """Candidates ranked by their screened effect *added* to an extended model, without runs.

    Forward selection's choice of whom to screen again (:mod:`orchestrator.inverse.diagnose`):
    each candidate's screening signals of round 1 enter as a change on top of the extended
    model's, ``s_ext + (s_c(x) - s_ref)`` (superposition: a second effect changes the
    signals about as it did on the nominal model, to first order), and the dense 1-D
    search ranks them by J. The best few are then screened and fitted for real.
    """
    ref = first.reference.cmp.simulated
    out = []
    for c in cands:
        grid = first.screened.get(c, {})
        xs = np.array(sorted(grid))
        if xs.size < 2:
            continue
        sig = [{k: extended.cmp.simulated[k] + (grid[x][k] - ref[k]) for k in ref} for x in xs]
        out.append((dense_search(target, kind_of(c), xs, sig)[1].objective, c))
    return [c for _, c in sorted(out, key=lambda t: t[0])]


__all__ = ["select", "widen", "rejudged", "superposed_ranking", "Round", "CauseFitter", "cause_stages", "CONFIRM", "FIT", "FIT_RATIO",
           "FIT_MAX_NFEV", "FINE_MAX_NFEV", "PENALTY"]
