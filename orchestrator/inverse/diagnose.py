"""``turnout diagnose``: what the simulation gets wrong, the cause, the extended model, the gain.

The procedure (DESIGN.md §4.5; every threshold is a named constant below):

1. **Baseline.** The nominal scenario is simulated and compared with the measurement
   (:class:`orchestrator.inverse.objective.Target`: time alignment on the accelerometers,
   per-channel nRMSE, the objective J, the noise level of each channel estimated from
   the measurement itself, chi-square). *Where* it is wrong: per group, per sleeper
   carrying sensors, and the time window holding 80 % of each channel's residual.
2. **Screening.** Every candidate of the catalogue (:mod:`orchestrator.inputs.causes`: each
   cause at each sleeper carrying sensors, and the global ones) is run at the few
   magnitudes of its screening grid. Between grid points the *signals* are
   interpolated (monotone cubic in the magnitude, log scale for stiffness factors),
   so each candidate's best magnitude and objective come from a dense 1-D search
   without further runs (:func:`orchestrator.inverse.screening.dense_search`, on
   :data:`~orchestrator.inverse.screening.DENSE` points).
3. **Confirmation.** The :data:`CONFIRM` best candidates are re-run at their best
   magnitude.
4. **Fit.** Every confirmed candidate is fitted coarsely (a void as a wedge, see
   :func:`_stages`; the other causes have one parameter); the best of them, and up to
   :data:`FIT` - 1 runners-up whose chi-square is within a factor :data:`FIT_RATIO` of
   its own, then get all their parameters fitted
   (a void's six gaps; the other causes have one) by bounded least squares
   (:func:`scipy.optimize.least_squares`, ``trf``) on the weighted, normalised
   residuals, with the finite-difference Jacobian's runs done in parallel
   (:func:`orchestrator.inverse.fitting.fit_unit_cube`).
5. **Ranking and naming.** Each candidate's evidence: its objective, the reduction of
   the objective, chi-square and the Bayesian information criterion
   BIC = chi2 + k ln N (k fitted parameters, N samples). The named cause is the
   candidate with the lowest BIC, *if* it beats the nominal model by more than
   :data:`DELTA_BIC` (Kass & Raftery 1995: a BIC difference above 10 is "very strong"
   evidence); otherwise the residual is consistent with the noise and the cause is
   ``none``. Candidates within :data:`DELTA_BIC` of the named one cannot be told apart
   from it with this data: they are listed with it.
6. **Extended model and gain.** The named cause is added to the scenario
   (``extended.yaml``); gain = 1 - J_after / J_before, per channel and in total; for
   further measured passages at other speeds (``--validate FILE@SPEED``) the same
   before/after comparison without refitting.

The diagnosis sees only the scenario and the measurement files: the catalogue, the
grids and the thresholds are fixed here, the same for every measurement.

:func:`diagnose` runs these steps as a sequence of stages (one function each, from
:func:`_read_inputs` to :func:`_write_outputs`) and returns the typed result,
:class:`orchestrator.inverse.diagnosis.Diagnosis`, whose ``to_json()`` is
``diagnosis.json``; the runs and the screening search are in
:mod:`orchestrator.inverse.screening`, the report in :mod:`orchestrator.inverse.diagnose_report`.
"""
from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orchestrator.cosim.sensing import variant_for_speed
from orchestrator.inputs.causes import Candidate, candidates, kind_of
from orchestrator.inputs.errors import UserInputError
from orchestrator.inverse.diagnosis import Baseline, CauseFit, Diagnosis, Gain, Passage
from orchestrator.inverse.jsonable import numpy_default
from orchestrator.inverse.objective import Comparison, Target
from orchestrator.inverse.screening import Evaluated, Pool, comparison, dense_search, scalar_axis

DELTA_BIC = 10.0     # BIC difference for "very strong" evidence (Kass & Raftery 1995)
CONFIRM = 4          # candidates re-run at their screened optimum
FIT = 2              # candidates whose full parameter set is fitted, at most ...
FIT_RATIO = 2.0      # ... of those whose confirmed chi-square is within this factor of the best's
FIT_MAX_NFEV = 5     # least-squares iterations of a coarse fit (each: one run + a parallel Jacobian) ...
FINE_MAX_NFEV = 8    # ... and of the fine stages (six gaps)
SENSOR_REACH = 0     # local causes on the sleepers carrying sensors +- this many


def _parse_validate(texts) -> list[tuple[Path, float]]:
    """``--validate`` texts ``FILE@SPEED`` as (path, speed [m/s]); :class:`UserInputError` if malformed."""
    out = []
    for text in texts or ():
        path, sep, speed = str(text).rpartition("@")
        try:
            v = float(speed)
        except ValueError:
            v = float("nan")
        if not sep or not path or not (v > 0 and math.isfinite(v)):
            raise UserInputError(f"--validate {text!r}: give FILE@SPEED with the speed in m/s, e.g. pass2.csv@27.78")
        out.append((Path(path), v))
    return out


def _sensor_sleepers(sensors) -> list[int]:
    """Indices of the sleepers carrying sensors, sorted."""
    out = set()
    for s in sensors:
        if s.body.startswith("sleeper_"):
            out.add(int(s.body.split("_")[1]))
    return sorted(out)


def _where(cmp: Comparison, sensors) -> dict:
    """Where the simulation is wrong: groups, sleepers, time windows of the worst channels."""
    by_sleeper: dict[int, list[float]] = {}
    for s in sensors:
        if s.id in cmp.channels and s.body.startswith("sleeper_"):
            by_sleeper.setdefault(int(s.body.split("_")[1]), []).append(cmp.channels[s.id]["nrmse"])
    worst = sorted(cmp.channels, key=lambda k: -cmp.channels[k]["nrmse"])[:5]
    return {"groups": dict(sorted(cmp.groups.items(), key=lambda kv: -kv[1])),
            "sleepers": {str(k): float(np.mean(v)) for k, v in sorted(by_sleeper.items())},
            "worst_channels": [{"id": k, "nrmse": cmp.channels[k]["nrmse"], "t_peak": cmp.channels[k]["t_peak"],
                                "window": cmp.channels[k]["window"]} for k in worst]}


def _stages(kind) -> list:
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


def _fit(pool: Pool, target: Target, raw: dict, start: Evaluated, stages: slice = slice(None),
         max_nfev: int = FIT_MAX_NFEV) -> Evaluated:
    """A candidate's parameters by bounded least squares, through ``_stages(kind)[stages]`` (module doc, step 4)."""
    from orchestrator.inverse.fitting import fit_unit_cube

    c = start.candidate
    kind = kind_of(c)
    cache: dict[bytes, Comparison] = {}

    def runs(us: list[np.ndarray]) -> list[Comparison]:
        todo = list({u.tobytes(): u for u in us if u.tobytes() not in cache}.values())
        if todo:
            out = pool.map([kind.apply(raw, c.sleeper, kind.from_unit(u)) for u in todo])
            for u, run in zip(todo, out):
                cache[u.tobytes()] = comparison(target, run)
        return [cache[u.tobytes()] for u in us]

    u_best = np.clip(kind.to_unit(start.values), 0.0, 1.0)
    k = start.k
    for n, to_u in _stages(kind)[stages]:
        k = n

        def batch(ps, to_u=to_u):
            return [target.weighted_residuals(cm) for cm in runs([np.clip(to_u(p), 0.0, 1.0) for p in ps])]

        p0 = u_best[[0, -1]] if n == 2 else u_best   # the wedge starts from the current ends
        fit_unit_cube(batch, p0, max_nfev=max_nfev)
        u_best = np.frombuffer(min(cache, key=lambda b: cache[b].chi2), dtype=float).copy()
    best = cache[u_best.tobytes()]
    if best.chi2 > start.cmp.chi2:   # the fit never did better than its start
        return Evaluated(c, start.values, start.cmp, k, "fitted")
    return Evaluated(c, kind.from_unit(u_best), best, k, "fitted")


def _gain(after: float, before: float) -> float:
    """1 - after / before (an objective or an nRMSE), 0 when ``before`` is 0."""
    return 1.0 - after / before if before > 0 else 0.0


def _entry(e: Evaluated, base: Evaluated, best_bic: float | None, twins: list[str]) -> CauseFit:
    """The typed result of one evaluated candidate, with its evidence against the nominal ``base``."""
    return CauseFit(
        e.candidate.cause, kind_of(e.candidate).parameters(e.values), e.cmp.objective,
        _gain(e.cmp.objective, base.cmp.objective),
        {"stage": e.stage, "objective_reduction": base.cmp.objective - e.cmp.objective,
         "chi2": e.cmp.chi2, "n_samples": e.cmp.n, "n_parameters": e.k, "bic": e.bic(),
         "delta_bic_vs_nominal": base.bic() - e.bic(),
         "delta_bic_vs_best": None if best_bic is None else e.bic() - best_bic,
         "indistinguishable_from": twins},
        sleeper=None if e.candidate.sleeper is None else int(e.candidate.sleeper))


# ------------------------------------------------------------------------------------ stages
@dataclass
class _Inputs:
    """What the stages of a diagnosis read: the nominal scenario, its sensors, the measurements, the candidates.

    Attributes
    ----------
    scenario_path, measured_path
        As given to :func:`diagnose`.
    out_dir : Path
    scenario : Scenario
        The nominal scenario (:attr:`raw` is its raw dict).
    layout : SensorLayout
    sensors : list
        The layout's sensors resolved on the nominal track model.
    target : Target
        The measured passage.
    validations : list of (Target, Path, float)
        Further passages: their target, file and speed [m/s].
    cands : list of Candidate
        The catalogue's candidates at the sensors.
    axes : dict
        Candidate -> (screening magnitudes with the nominal one, the nominal magnitude).
    """

    scenario_path: object
    measured_path: object
    out_dir: Path
    scenario: object
    layout: object
    sensors: list
    target: Target
    validations: list
    cands: list
    axes: dict

    @property
    def raw0(self) -> dict:
        """The nominal scenario's raw dict."""
        return self.scenario.raw


def _read_inputs(scenario_path, measured_path, out_dir, validate) -> _Inputs:
    """Read and check everything before any run.

    Input: :func:`diagnose`'s paths and ``--validate`` texts. Output: the :class:`_Inputs`
    (``out_dir`` is created). Raises :class:`UserInputError` on bad input.
    """
    from orchestrator.inputs.scenario import load_scenario
    from orchestrator.inputs.sensor_layout import layout_of, resolve
    from orchestrator.inputs.track_model import track_model

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    validations = _parse_validate(validate)
    scenario = load_scenario(scenario_path)
    raw0 = scenario.raw
    layout = layout_of(scenario)
    model = track_model(scenario.track)
    sensors = resolve(layout, model)
    target = Target.read(measured_path, layout)
    sim_rate = 1.0 / scenario.simulation.output_step
    if sim_rate < 2.0 * target.measured.rate * (1 - 1e-9):
        raise UserInputError(f"{measured_path}: sampled at {target.measured.rate:g} Hz; the simulation's output step "
                             f"({scenario.simulation.output_step:g} s) must be at most half the sampling interval "
                             f"(simulation.output_step <= {0.5 / target.measured.rate:.3g} s)")
    val_targets = [(Target.read(p, layout), p, v) for p, v in validations]
    cands = candidates(_sensor_sleepers(sensors), len(model.layout.sleepers), SENSOR_REACH)
    axes = {c: scalar_axis(kind_of(c), raw0, c.sleeper) for c in cands}
    return _Inputs(scenario_path, measured_path, out_dir, scenario, layout, sensors, target, val_targets, cands, axes)


def _baseline(pool: Pool, inp: _Inputs) -> tuple[Evaluated, Baseline]:
    """Step 1: the nominal run.

    Input: the pool, the inputs. Output: the nominal model's :class:`Evaluated` and its
    :class:`Baseline`, which is written to ``baseline.json`` at once (so a diagnosis that
    fails later keeps it). Aligns ``inp.target`` in time on the nominal run.
    """
    base_run = pool.map([inp.raw0])[0]
    if base_run.error:
        raise UserInputError(f"{inp.scenario_path}: the nominal run stopped early: {base_run.error}")
    inp.target.align_to(base_run.t, base_run.signals)
    base = Evaluated(Candidate("none"), np.zeros(0), comparison(inp.target, base_run), 0, "nominal")
    text = json.dumps({**base.cmp.summary(), "bic": base.bic(), "where": _where(base.cmp, inp.sensors),
                       "noise_sigma": inp.target.sigma}, indent=1, default=numpy_default)
    (inp.out_dir / "baseline.json").write_text(text)
    return base, Baseline.from_json(json.loads(text))


def _screen(pool: Pool, inp: _Inputs, base: Evaluated) -> dict[Candidate, dict[float, dict]]:
    """Step 2, runs: every candidate at the magnitudes of its screening grid, in one batch.

    Input: the pool, the inputs, the nominal evaluation. Output: candidate -> magnitude
    -> simulated signals on the measured time base (the nominal magnitude's are the
    nominal run's).
    """
    jobs = [(c, x) for c in inp.cands for x in inp.axes[c][0] if abs(x - inp.axes[c][1]) > 1e-12]
    runs = pool.map([kind_of(c).apply_scalar(inp.raw0, c.sleeper, x) for c, x in jobs])
    screened: dict[Candidate, dict[float, dict]] = {c: {inp.axes[c][1]: base.cmp.simulated} for c in inp.cands}
    for (c, x), run in zip(jobs, runs):
        screened[c][x] = comparison(inp.target, run).simulated
    return screened


def _search(inp: _Inputs, screened: dict[Candidate, dict[float, dict]]) -> dict[Candidate, Evaluated]:
    """Step 2, no runs: each candidate's best magnitude by the dense 1-D search between its screening runs.

    Input: the inputs, :func:`_screen`'s signals. Output: candidate -> its ``screened``
    evaluation (one parameter).
    """
    dense = {}
    for c in inp.cands:
        xs = np.array(sorted(screened[c]))
        x_best, cmp = dense_search(inp.target, kind_of(c), xs, [screened[c][x] for x in xs])
        dense[c] = Evaluated(c, kind_of(c).scalar_to_vector(x_best), cmp, 1, "screened")
    return dense


def _confirm(pool: Pool, inp: _Inputs, dense: dict[Candidate, Evaluated]) -> dict[Candidate, Evaluated]:
    """Step 3: the :data:`CONFIRM` best screened candidates (by BIC) re-run at their best magnitude.

    Input: the pool, the inputs, :func:`_search`'s evaluations. Output: candidate -> its
    ``confirmed`` evaluation, best screened first.
    """
    top = sorted(inp.cands, key=lambda c: dense[c].bic())[:CONFIRM]
    pool.expect(len(top))
    runs = pool.map([kind_of(c).apply(inp.raw0, c.sleeper, dense[c].values) for c in top])
    return {c: Evaluated(c, dense[c].values, comparison(inp.target, r), 1, "confirmed") for c, r in zip(top, runs)}


def _coarse_fits(pool: Pool, inp: _Inputs, confirmed: dict[Candidate, Evaluated]) -> dict[Candidate, Evaluated]:
    """Step 4, first stage: every confirmed candidate fitted coarsely (:func:`_stages`, a void as a wedge).

    Input: the pool, the inputs, :func:`_confirm`'s evaluations. Output: candidate -> its
    ``fitted`` evaluation, in the same order.
    """
    for c in confirmed:
        pool.expect(FIT_MAX_NFEV * (_stages(kind_of(c))[0][0] + 1))
    return {c: _fit(pool, inp.target, inp.raw0, confirmed[c], slice(0, 1)) for c in confirmed}


def _fine_fits(pool: Pool, inp: _Inputs, coarse: dict[Candidate, Evaluated]) -> dict[Candidate, Evaluated]:
    """Step 4, finer stages: all parameters of the best coarse fit and of up to :data:`FIT` - 1 runners-up
    whose chi-square is within :data:`FIT_RATIO` of its own.

    Input: the pool, the inputs, :func:`_coarse_fits`' evaluations. Output: the same
    mapping with the finely fitted candidates replaced.
    """
    by_fit = sorted(coarse, key=lambda c: coarse[c].bic())
    lead = coarse[by_fit[0]].cmp.chi2
    fitted = dict(coarse)
    for c in [c for c in by_fit if coarse[c].cmp.chi2 <= FIT_RATIO * lead][:FIT]:
        stages = _stages(kind_of(c))
        if len(stages) > 1:
            pool.expect(FINE_MAX_NFEV * sum(n + 1 for n, _ in stages[1:]))
            fitted[c] = _fit(pool, inp.target, inp.raw0, coarse[c], slice(1, None), FINE_MAX_NFEV)
    return fitted


@dataclass
class _Ranking:
    """The candidates ranked (module doc, step 5).

    Attributes
    ----------
    ranked : list of Evaluated
        Every candidate's last evaluation: the fitted and confirmed ones by BIC, then the
        screened ones by BIC.
    best : Evaluated
        The fitted or confirmed candidate of lowest BIC.
    significant : bool
        ``best`` beats the nominal model by more than :data:`DELTA_BIC`.
    real : list of Evaluated
        The fitted and confirmed candidates of ``ranked``.
    twins : dict
        Candidate of ``real`` -> labels of the others within :data:`DELTA_BIC` of it.
    """

    ranked: list
    best: Evaluated
    significant: bool
    real: list
    twins: dict


def _rank(base: Evaluated, inp: _Inputs, dense: dict, confirmed: dict, fitted: dict) -> _Ranking:
    """Step 5, ranking: every candidate's last evaluation by BIC, the best, and who cannot be told apart.

    Input: the nominal evaluation, the inputs, the evaluations of steps 2-4. Output: the
    :class:`_Ranking`.
    """
    final = {c: fitted.get(c) or confirmed.get(c) or dense[c] for c in inp.cands}
    ranked = sorted(final.values(), key=lambda e: (e.stage not in ("fitted", "confirmed"), e.bic()))
    best = min((e for e in ranked if e.stage in ("fitted", "confirmed")), key=lambda e: e.bic())
    significant = base.bic() - best.bic() > DELTA_BIC
    real = [e for e in ranked if e.stage in ("fitted", "confirmed")]
    twins = {e.candidate: [o.candidate.label for o in real if o is not e and abs(o.bic() - e.bic()) < DELTA_BIC]
             for e in real}
    return _Ranking(ranked, best, significant, real, twins)


def _named(base: Evaluated, rk: _Ranking) -> CauseFit:
    """Step 5, naming: the best candidate with its ambiguity set if it is significant, else ``none``.

    Input: the nominal evaluation, the ranking. Output: the named cause.
    """
    best = rk.best
    twins = rk.twins.get(best.candidate, [])
    if not rk.significant:
        return CauseFit("none", {}, base.cmp.objective, 0.0,
                        {"best_candidate": best.candidate.label, "delta_bic_vs_nominal": base.bic() - best.bic(),
                         "threshold": DELTA_BIC,
                         "reason": "no candidate explains the residual better than the noise does"})
    named = _entry(best, base, best.bic(), twins)
    sleepers = sorted(({named.sleeper} | {e.candidate.sleeper for e in rk.real
                                          if e.candidate.label in twins and e.candidate.cause == best.candidate.cause})
                      - {None})
    named.ambiguity = {"candidates": [best.candidate.label] + twins, "sleepers": sleepers}
    return named


def _extend(inp: _Inputs, rk: _Ranking) -> tuple[dict, Path]:
    """Step 6: the extended model, the named cause added to the nominal scenario (a copy of it for ``none``).

    Input: the inputs, the ranking. Output: the extended raw scenario and the path of
    ``extended.yaml``, written into the output folder.
    """
    from orchestrator.inputs.scenario import dump_scenario, scenario_from_dict

    best = rk.best
    ext_raw = kind_of(best.candidate).apply(inp.raw0, best.candidate.sleeper, best.values) if rk.significant \
        else copy.deepcopy(inp.raw0)
    ext_scenario = scenario_from_dict(ext_raw, source=str(inp.scenario_path), base_dir=Path(inp.scenario_path).parent)
    return ext_raw, dump_scenario(ext_scenario, inp.out_dir / "extended.yaml")


def _validate(pool: Pool, inp: _Inputs, ext_raw: dict) -> list[Passage]:
    """Step 6, further passages: nominal and extended model at each passage's speed, compared without refitting.

    Input: the pool, the inputs, the extended raw scenario. Output: one :class:`Passage`
    per ``--validate`` file.
    """
    validation = []
    for vt, vpath, speed in inp.validations:
        pool.expect(2)
        r_before, r_after = pool.map([variant_for_speed(inp.raw0, speed), variant_for_speed(ext_raw, speed)])
        vt.align_to(r_before.t, r_before.signals)
        cb, ca = comparison(vt, r_before), comparison(vt, r_after)
        validation.append(Passage(str(vpath), speed, cb.objective, ca.objective, _gain(ca.objective, cb.objective),
                                  {k: {"nrmse_before": cb.channels[k]["nrmse"], "nrmse_after": ca.channels[k]["nrmse"]}
                                   for k in cb.channels}))
    return validation


def _total_gain(before: Comparison, after: Comparison) -> Gain:
    """Step 6, gain: of the extended model (``after``) over the nominal one (``before``), total and per channel."""
    return Gain(_gain(after.objective, before.objective),
                {k: _gain(after.channels[k]["nrmse"], v["nrmse"]) for k, v in before.channels.items()})


def _settings(cands: list[Candidate]) -> dict:
    """The thresholds of this module and the candidates' labels (``diagnosis.json`` ``settings``)."""
    return {"delta_bic": DELTA_BIC, "confirm": CONFIRM, "fit": FIT, "sensor_reach": SENSOR_REACH,
            "candidates": [c.label for c in cands]}


def _write_outputs(result: Diagnosis, inp: _Inputs, before: Comparison, after: Comparison) -> None:
    """Write ``diagnosis.json`` and the report (``report.md`` and its plots) into the output folder.

    Input: the diagnosis, the inputs, the nominal and the extended model's comparisons.
    """
    from orchestrator.inverse.diagnose_report import write_report

    (inp.out_dir / "diagnosis.json").write_text(json.dumps(result.to_json(), indent=1, default=numpy_default))
    write_report(inp.out_dir, result, inp.target, before, after, inp.layout)


def diagnose(scenario_path, measured_path, out_dir, validate=(), workers: int | None = None, scheduler: str | None = None,
             progress: bool = True) -> Diagnosis:
    """Run the diagnosis (module docstring); write diagnosis.json, extended.yaml, report.md, plots.

    ``baseline.json`` (the nominal model's residuals: step 1) is written as soon as it is
    known, so a diagnosis that fails later keeps it.

    Parameters
    ----------
    scenario_path : path-like
        The nominal scenario.
    measured_path : path-like
        The measured passage (CSV, HDF5, MAT; :mod:`orchestrator.inputs.measured`).
    out_dir : path-like
    validate : sequence of str
        Further passages as ``FILE@SPEED`` (speed in m/s): compared before/after, not fitted.
    workers : int, optional
        Local worker processes (default: one per core).
    scheduler : str, optional
        Dask scheduler address.
    progress : bool

    Returns
    -------
    Diagnosis
        The answer; its :meth:`~orchestrator.inverse.diagnosis.Diagnosis.to_json` is diagnosis.json.
    """
    from tqdm import tqdm

    from orchestrator.sweeps.executors import make_executor

    t_start = time.perf_counter()
    inp = _read_inputs(scenario_path, measured_path, out_dir, validate)
    executor = make_executor(workers, scheduler)
    bar = tqdm(total=1 + sum(len(xs) - 1 for xs, _ in inp.axes.values()), desc="diagnose", unit="run",
               disable=not progress)
    pool = Pool(executor, str(scenario_path), bar=bar)
    try:
        base, baseline = _baseline(pool, inp)
        dense = _search(inp, _screen(pool, inp, base))
        confirmed = _confirm(pool, inp, dense)
        fitted = _fine_fits(pool, inp, _coarse_fits(pool, inp, confirmed))
        ranking = _rank(base, inp, dense, confirmed, fitted)
        ext_raw, ext_path = _extend(inp, ranking)
        validation = _validate(pool, inp, ext_raw)
    finally:
        bar.close()
        executor.shutdown(wait=True, cancel_futures=True)

    after = ranking.best.cmp if ranking.significant else base.cmp
    causes = [_entry(e, base, ranking.best.bic(), ranking.twins.get(e.candidate, [])) for e in ranking.ranked]
    result = Diagnosis(str(scenario_path), str(measured_path), baseline, causes, _named(base, ranking),
                       ext_path.name, _total_gain(base.cmp, after), validation, pool.runs,
                       time.perf_counter() - t_start, _settings(inp.cands))
    _write_outputs(result, inp, base.cmp, after)
    return result


__all__ = ["diagnose", "DELTA_BIC", "Diagnosis", "CauseFit"]
