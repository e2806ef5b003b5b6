"""``turnout diagnose``: what the simulation gets wrong, the cause, the extended model, the gain.

The procedure (DESIGN.md §4.5; every threshold is a named constant below):

1. **Baseline.** The nominal scenario is simulated and compared with the measurement
   (:class:`orchestrator.inverse.objective.Target`: time alignment on the accelerometers,
   per-channel nRMSE, the objective J, the noise level of each channel estimated from
   the measurement itself, chi-square). *Where* it is wrong: per group, per sleeper
   carrying sensors, and the time window holding 80 % of each channel's residual.
2. **Screening.** Every candidate of the catalogue (:mod:`orchestrator.inverse.causes`: each
   cause at each sleeper carrying sensors, and the global ones) is run at the few
   magnitudes of its screening grid. Between grid points the *signals* are
   interpolated (monotone cubic in the magnitude, log scale for stiffness factors),
   so each candidate's best magnitude and objective come from a dense 1-D search
   without further runs.
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
"""
from __future__ import annotations

import copy
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orchestrator.inverse.causes import Candidate, candidates, kind_of
from orchestrator.inputs.errors import UserInputError
from orchestrator.inverse.objective import Comparison, Target
from orchestrator.cosim.sensing import variant_for_speed

DELTA_BIC = 10.0     # BIC difference for "very strong" evidence (Kass & Raftery 1995)
CONFIRM = 4          # candidates re-run at their screened optimum
FIT = 2              # candidates whose full parameter set is fitted, at most ...
FIT_RATIO = 2.0      # ... of those whose confirmed chi-square is within this factor of the best's
DENSE = 121          # points of the 1-D search between screening runs
FIT_MAX_NFEV = 5     # least-squares iterations of a coarse fit (each: one run + a parallel Jacobian) ...
FINE_MAX_NFEV = 8    # ... and of the fine stages (six gaps)
SENSOR_REACH = 0     # local causes on the sleepers carrying sensors +- this many


@dataclass
class Evaluated:
    """One candidate at one parameter vector, with its comparison."""

    candidate: Candidate
    values: np.ndarray
    cmp: Comparison
    k: int
    stage: str

    def bic(self) -> float:
        return self.cmp.chi2 + self.k * math.log(self.cmp.n)


@dataclass
class _Pool:
    """Runs of scenario variants on an executor (local processes or Dask)."""

    executor: object
    base_dir: str
    layout_path: str | None
    runs: int = 0
    wall: float = 0.0
    bar: object = None

    def map(self, raws: list[dict]) -> list:
        from orchestrator.cosim.sensing import sensors_job

        t0 = time.perf_counter()
        futures = [self.executor.submit(sensors_job, raw, self.base_dir, self.layout_path) for raw in raws]
        out = []
        for f in futures:
            run = f.result()
            out.append(run)
            if self.bar is not None:
                self.bar.update(1)
        self.runs += len(raws)
        self.wall += time.perf_counter() - t0
        return out


def _parse_validate(texts) -> list[tuple[Path, float]]:
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


def _scalar_axis(kind, raw: dict, sleeper) -> tuple[np.ndarray, float]:
    """Screening magnitudes with the nominal one, sorted, and the nominal magnitude."""
    nominal = float(np.max(kind.nominal(raw, sleeper))) if kind.name == "ballast_void" else \
        float(kind.nominal(raw, sleeper)[0])
    grid = sorted(set([nominal] + [g for g in kind.grid if abs(g - nominal) > 1e-12]))
    return np.array(grid, float), nominal


def _dense_search(target: Target, kind, xs: np.ndarray, signals: list[dict]) -> tuple[float, Comparison]:
    """Best magnitude of a 1-D family of runs by interpolating their signals (module doc, step 2)."""
    from scipy.interpolate import PchipInterpolator

    u = np.log(xs) if kind.log else xs
    ids = list(signals[0])
    Y = np.stack([np.concatenate([sig[k] for k in ids]) for sig in signals])   # (nx, total)
    sizes = np.cumsum([0] + [signals[0][k].size for k in ids])
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):   # flat stretches of a signal
        interp = PchipInterpolator(u, Y, axis=0)
    best = None
    for ud in np.linspace(u[0], u[-1], DENSE):
        row = interp(ud)
        on = {k: row[sizes[i]:sizes[i + 1]] for i, k in enumerate(ids)}
        cmp = target.score(on)
        if best is None or cmp.chi2 < best[1].chi2:
            best = (float(np.exp(ud) if kind.log else ud), cmp)
    return best


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


def _fit(pool: _Pool, target: Target, raw: dict, start: Evaluated, stages: slice = slice(None),
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
                cache[u.tobytes()] = _comparison(target, run)
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


def _comparison(target: Target, run) -> Comparison:
    if run.error:
        raise RuntimeError(f"a diagnosis run stopped early: {run.error}")
    return target.compare(run.t, run.signals)


def _entry(e: Evaluated, base: Evaluated, best_bic: float | None, twins: list[str]) -> dict:
    kind = kind_of(e.candidate)
    out = {"cause": e.candidate.cause}
    if e.candidate.sleeper is not None:
        out["sleeper"] = int(e.candidate.sleeper)
    out.update({
        "parameters": kind.parameters(e.values), "objective": e.cmp.objective,
        "gain": 1.0 - e.cmp.objective / base.cmp.objective if base.cmp.objective > 0 else 0.0,
        "evidence": {"stage": e.stage, "objective_reduction": base.cmp.objective - e.cmp.objective,
                     "chi2": e.cmp.chi2, "n_samples": e.cmp.n, "n_parameters": e.k, "bic": e.bic(),
                     "delta_bic_vs_nominal": base.bic() - e.bic(),
                     "delta_bic_vs_best": None if best_bic is None else e.bic() - best_bic,
                     "indistinguishable_from": twins},
    })
    return out


def diagnose(scenario_path, measured_path, out_dir, validate=(), workers: int = 2, scheduler: str | None = None,
             progress: bool = True) -> dict:
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
    workers : int
        Local worker processes.
    scheduler : str, optional
        Dask scheduler address.
    progress : bool

    Returns
    -------
    dict
        The content of diagnosis.json.
    """
    from tqdm import tqdm

    from track.model import build_track

    from orchestrator.inputs.scenario import dump_scenario, load_scenario, scenario_from_dict
    from orchestrator.inputs.sensor_layout import layout_of
    from orchestrator.inputs.sensor_layout import resolve
    from orchestrator.sweeps.sweep import make_executor

    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    validations = _parse_validate(validate)
    scenario = load_scenario(scenario_path)
    raw0 = scenario.raw
    layout = layout_of(scenario)
    model = build_track(scenario.track)
    sensors = resolve(layout, model)
    target = Target.read(measured_path, layout)
    sim_rate = 1.0 / scenario.simulation.output_step
    if sim_rate < 2.0 * target.measured.rate * (1 - 1e-9):
        raise UserInputError(f"{measured_path}: sampled at {target.measured.rate:g} Hz; the simulation's output step "
                             f"({scenario.simulation.output_step:g} s) must be at most half the sampling interval "
                             f"(simulation.output_step <= {0.5 / target.measured.rate:.3g} s)")
    val_targets = [(Target.read(p, layout), p, v) for p, v in validations]
    cands = candidates(_sensor_sleepers(sensors), len(model.layout.sleepers), SENSOR_REACH)
    axes = {c: _scalar_axis(kind_of(c), raw0, c.sleeper) for c in cands}
    n_screen = sum(len(xs) - 1 for xs, _ in axes.values())

    executor = make_executor(workers, scheduler)
    bar = tqdm(total=1 + n_screen, desc="diagnose", unit="run", disable=not progress)
    pool = _Pool(executor, str(Path(scenario_path).resolve().parent), scenario.sensors, bar=bar)
    try:
        # 1. baseline
        base_run = pool.map([raw0])[0]
        if base_run.error:
            raise UserInputError(f"{scenario_path}: the nominal run stopped early: {base_run.error}")
        target.align_to(base_run.t, base_run.signals)
        base = Evaluated(Candidate("none"), np.zeros(0), _comparison(target, base_run), 0, "nominal")
        # what the simulation gets wrong is on disk before the long part starts
        (out_dir / "baseline.json").write_text(json.dumps(
            {**base.cmp.summary(), "bic": base.bic(), "where": _where(base.cmp, sensors),
             "noise_sigma": target.sigma}, indent=1, default=_json_default))

        # 2. screening: all candidates x grid in one batch
        jobs = [(c, x) for c in cands for x in axes[c][0] if abs(x - axes[c][1]) > 1e-12]
        runs = pool.map([kind_of(c).apply_scalar(raw0, c.sleeper, x) for c, x in jobs])
        screened: dict[Candidate, dict[float, dict]] = {c: {axes[c][1]: base.cmp.simulated} for c in cands}
        for (c, x), run in zip(jobs, runs):
            screened[c][x] = _comparison(target, run).simulated
        dense = {}
        for c in cands:
            xs = np.array(sorted(screened[c]))
            x_best, cmp = _dense_search(target, kind_of(c), xs, [screened[c][x] for x in xs])
            dense[c] = Evaluated(c, kind_of(c).scalar_to_vector(x_best), cmp, 1, "screened")
        order = sorted(cands, key=lambda c: dense[c].bic())

        # 3. confirmation
        top = order[:CONFIRM]
        bar.total += len(top)
        runs = pool.map([kind_of(c).apply(raw0, c.sleeper, dense[c].values) for c in top])
        confirmed = {c: Evaluated(c, dense[c].values, _comparison(target, r), 1, "confirmed") for c, r in zip(top, runs)}

        # 4. fit: the first (coarse) stage for every confirmed candidate, the finer ones for the
        #    best and the runners-up close to it
        for c in top:
            bar.total += FIT_MAX_NFEV * (_stages(kind_of(c))[0][0] + 1)
        coarse = {c: _fit(pool, target, raw0, confirmed[c], slice(0, 1)) for c in top}
        by_fit = sorted(coarse, key=lambda c: coarse[c].bic())
        lead = coarse[by_fit[0]].cmp.chi2
        fitted = dict(coarse)
        for c in [c for c in by_fit if coarse[c].cmp.chi2 <= FIT_RATIO * lead][:FIT]:
            if len(_stages(kind_of(c))) > 1:
                bar.total += FINE_MAX_NFEV * sum(n + 1 for n, _ in _stages(kind_of(c))[1:])
                fitted[c] = _fit(pool, target, raw0, coarse[c], slice(1, None), FINE_MAX_NFEV)

        # 5. ranking
        final = {c: fitted.get(c) or confirmed.get(c) or dense[c] for c in cands}
        ranked = sorted(final.values(), key=lambda e: (e.stage not in ("fitted", "confirmed"), e.bic()))
        best = min((e for e in ranked if e.stage in ("fitted", "confirmed")), key=lambda e: e.bic())
        significant = base.bic() - best.bic() > DELTA_BIC
        real = [e for e in ranked if e.stage in ("fitted", "confirmed")]
        twins = {e.candidate: [o.candidate.label for o in real if o is not e and abs(o.bic() - e.bic()) < DELTA_BIC]
                 for e in real}
        causes = [_entry(e, base, best.bic(), twins.get(e.candidate, [])) for e in ranked]
        named_eval = best if significant else None

        # 6. extended model, gain, validation
        ext_raw = kind_of(best.candidate).apply(raw0, best.candidate.sleeper, best.values) if significant \
            else copy.deepcopy(raw0)
        ext_scenario = scenario_from_dict(ext_raw, source=str(scenario_path), base_dir=Path(scenario_path).parent)
        ext_path = dump_scenario(ext_scenario, out_dir / "extended.yaml")
        after = named_eval.cmp if significant else base.cmp
        validation = []
        for vt, vpath, speed in val_targets:
            bar.total += 2
            r_before, r_after = pool.map([variant_for_speed(raw0, speed), variant_for_speed(ext_raw, speed)])
            vt.align_to(r_before.t, r_before.signals)
            cb, ca = _comparison(vt, r_before), _comparison(vt, r_after)
            validation.append({"file": str(vpath), "speed": speed, "objective_before": cb.objective,
                               "objective_after": ca.objective,
                               "gain": 1.0 - ca.objective / cb.objective if cb.objective > 0 else 0.0,
                               "channels": {k: {"nrmse_before": cb.channels[k]["nrmse"],
                                                "nrmse_after": ca.channels[k]["nrmse"]} for k in cb.channels}})
    finally:
        bar.close()
        executor.shutdown(wait=True, cancel_futures=True)

    if significant:
        named = _entry(named_eval, base, best.bic(), twins.get(best.candidate, []))
        sleepers = sorted(({named.get("sleeper")} | {e.candidate.sleeper for e in real
                                                     if e.candidate.label in twins.get(best.candidate, [])
                                                     and e.candidate.cause == best.candidate.cause}) - {None})
        named["ambiguity"] = {"candidates": [best.candidate.label] + twins.get(best.candidate, []),
                              "sleepers": sleepers}
    else:
        named = {"cause": "none", "parameters": {}, "objective": base.cmp.objective, "gain": 0.0,
                 "evidence": {"best_candidate": best.candidate.label,
                              "delta_bic_vs_nominal": base.bic() - best.bic(),
                              "threshold": DELTA_BIC,
                              "reason": "no candidate explains the residual better than the noise does"}}
    result = {
        "scenario": str(scenario_path), "measured": str(measured_path),
        "baseline": json.loads((out_dir / "baseline.json").read_text()),
        "causes": causes,
        "named_cause": named,
        "extended_scenario": ext_path.name,
        "gain": {"total": 1.0 - after.objective / base.cmp.objective if base.cmp.objective > 0 else 0.0,
                 "channels": {k: 1.0 - after.channels[k]["nrmse"] / v["nrmse"] if v["nrmse"] > 0 else 0.0
                              for k, v in base.cmp.channels.items()}},
        "validation": validation,
        "runs": pool.runs, "wall_seconds": time.perf_counter() - t_start,
        "settings": {"delta_bic": DELTA_BIC, "confirm": CONFIRM, "fit": FIT, "sensor_reach": SENSOR_REACH,
                     "candidates": [c.label for c in cands]},
    }
    (out_dir / "diagnosis.json").write_text(json.dumps(result, indent=1, default=_json_default))
    from orchestrator.inverse.diagnose_report import write_report

    write_report(out_dir, result, target, base.cmp, after, layout)
    return result


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o).__name__)


__all__ = ["diagnose", "DELTA_BIC"]
