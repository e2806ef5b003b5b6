"""The stages of :func:`orchestrator.inverse.calibrate.calibrate`, one function each.

The pipeline and its numbers are described in :mod:`orchestrator.inverse.calibrate`;
this module holds its steps, in order: :func:`check_sizes`, :func:`prepare`,
:func:`objective_of` (stage 0), :func:`first_design` (stage 1 and its surrogate),
:func:`narrow` (stage 3), :func:`second_design` (stage 4), :func:`fit_all`,
:func:`optimise` (stage 5), :func:`confirm` (stage 6), :func:`polish_stage` (stage 7) and
:func:`write_calibrated`. Each takes what the earlier ones returned (dataclasses here)
and returns what it found; :func:`run_stages` calls stages 1 to 7 in order and returns
their :class:`Outcome`.
"""
from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from orchestrator.inputs.errors import UserInputError
from orchestrator.inverse.calibration_params import (
    Parameter,
    apply_values,
    nominal_values,
    parse_params,
    values_at,
    variation,
)
from orchestrator.inverse.calibration_runs import (
    CalibrationIncomplete,
    Runs,
    digest,
    finite,
    objective_run,
    polish,
    snapshot,
)
from orchestrator.inverse.surrogate import (
    MAX_CORNER_DIM,
    NARROW_CV_FACTOR,
    OBJECTIVE,
    Surrogate,
    corners,
    fit_objective,
    fit_surrogate,
    latin_hypercube,
    minimise_surrogate,
    multistarts,
    sensitivity,
)

PLAN_FILE = "stage2_plan.json"  # OUT/stage2_plan.json: the narrowed box (reused on resume)
CALIBRATED_FILE = "calibrated.yaml"  # OUT/calibrated.yaml: the calibrated scenario


# ======================================================================================
# What the stages pass on
# ======================================================================================
@dataclass(frozen=True)
class Objective:
    """What the runs are compared with, and the run functions of the stages.

    Attributes
    ----------
    measured : path-like or None
        The measurement file (as given, possibly ``None``, with a custom run function).
    target : Target or None
        The measurement read against the snapshot's sensor layout (``None`` with a custom run function).
    shift : float or None
        The time alignment [s] fixed from the nominal scenario.
    run_fn, confirm_fn : callable
        Run functions of the designs and of the confirmation (the latter saves the signals).
    polish_fn : callable or None
        Run function of the polish (saves the residuals); ``None``: no polish.
    """

    measured: Any
    target: Any
    shift: float | None
    run_fn: Callable
    confirm_fn: Callable
    polish_fn: Callable | None


@dataclass(frozen=True)
class Setup:
    """The checked inputs of a calibration: how runs are made, against what, and the stages' sizes."""

    base_path: Path
    out: Path
    runs: Runs
    objective: Objective
    n1: int
    n2: int
    seed: int
    transforms: tuple
    polish: int

    @property
    def params(self) -> list[Parameter]:
        return self.runs.params

    @property
    def raw(self) -> dict:
        return self.runs.raw


@dataclass
class Design:
    """The runs of one or more designs.

    Attributes
    ----------
    U : ndarray, shape (n, k)
        Points in the unit cube.
    y : ndarray, shape (n,)
        J of each point (``nan``: the run gave none).
    channels : dict
        Sensor id -> nRMSE of each point, shape (n,).
    results : list of SweepResult
        The sweeps the points were run in, in order.
    sizes : list of int
        Points per sweep.
    """

    U: np.ndarray
    y: np.ndarray
    channels: dict
    results: list
    sizes: list

    @property
    def ok(self) -> np.ndarray:
        """The points with an objective, shape (n,) of bool."""
        return np.isfinite(self.y)

    def row(self, i: int) -> dict:
        """The result row of point ``i``."""
        for res, n in zip(self.results, self.sizes):
            if i < n:
                return next(r for r in res.rows if r["index"] == i)
            i -= n
        raise IndexError(i)

    def __add__(self, other: Design) -> Design:
        """Both designs' runs (the channels both have)."""
        return Design(np.vstack([self.U, other.U]), np.concatenate([self.y, other.y]),
                      {c: np.concatenate([self.channels[c], other.channels[c]])
                       for c in sorted(set(self.channels) & set(other.channels))}, self.results + other.results,
                      self.sizes + other.sizes)


@dataclass(frozen=True)
class Narrowing:
    """Stage 3: the stage-1 surrogate's minimiser ``u_star`` (k,) and ``f_star``, ``tau``,
    the :func:`~orchestrator.inverse.surrogate.sensitivity` dict ``sens``, and the box
    ``lower``, ``upper`` (k,) of stage 2 (unit coordinates)."""

    u_star: np.ndarray
    f_star: float
    tau: float
    sens: dict
    lower: np.ndarray
    upper: np.ndarray


@dataclass(frozen=True)
class Fit:
    """The surrogates on all runs: J's and, when the runs report channels, the channels' (or ``None``)."""

    surrogate: Surrogate
    channels: Surrogate | None


@dataclass(frozen=True)
class Optimum:
    """Stage 5: the surrogate's minimiser ``u`` (k,), its predicted J ``value`` and the per-start ``runs``."""

    u: np.ndarray
    value: float
    runs: list


@dataclass(frozen=True)
class Choice:
    """A candidate calibrated point.

    Attributes
    ----------
    source : str
        ``surrogate optimum``, ``best run`` or ``polish``.
    u : ndarray, shape (k,)
        The point in unit coordinates.
    objective : float
        Its simulated J.
    row : dict
        Its run's result row.
    signals_at : tuple or None
        (runs folder, run id) where its signals are saved, if they are.
    """

    source: str
    u: np.ndarray
    objective: float
    row: dict
    signals_at: tuple | None


@dataclass(frozen=True)
class Confirmation:
    """Stage 6: the result rows of the ``nominal`` scenario and of the surrogate ``optimum``,
    the better of that optimum and the design's best run (``chosen``), and the ``sweep`` (SweepResult)."""

    nominal: dict
    optimum: dict
    chosen: Choice
    sweep: Any

    @property
    def objective_before(self) -> float:
        return finite(self.nominal.get(OBJECTIVE))

    @property
    def objective_confirmed(self) -> float:
        return finite(self.optimum.get(OBJECTIVE))


# ======================================================================================
# Stage 0: inputs, snapshot, objective
# ======================================================================================
def check_sizes(n1, n2, polish_nfev) -> None:
    """A user error unless ``n1``, ``n2`` >= 1 and ``polish`` >= 0 are integers."""
    for name, n, least in (("n1", n1, 1), ("n2", n2, 1), ("polish", polish_nfev, 0)):
        if isinstance(n, bool) or not isinstance(n, int) or n < least:
            raise UserInputError(f"{name} must be an integer >= {least}, got {n!r}")


def prepare(base_path: Path, out: Path, params: str | Sequence[Parameter] | None, n1: int):
    """Load the scenario, parse the parameters, check ``n1``, and write the snapshot into ``out``.

    Returns
    -------
    (scenario, raw, params)
        The snapshot's scenario (what every run loads), the loaded scenario's raw mapping
        (what the parameters' values are set on: ``calibrated.yaml`` keeps the user's
        sensor layout) and the list of Parameter.
    """
    from orchestrator.inputs.scenario import load_scenario

    scenario = load_scenario(base_path)
    plist = parse_params(params, scenario) if params is None or isinstance(params, str) else list(params)
    k = len(plist)
    if n1 < k + 2:
        raise UserInputError(f"n1 = {n1} is too small for {k} parameters: give at least {k + 2} "
                             f"(a few hundred for a useful surrogate)")
    out.mkdir(parents=True, exist_ok=True)
    # Every run loads this snapshot (scenario and sensor layout), not the user's files: a calibration takes
    # long, and an edit of a file meanwhile must not mix two models in one design (a changed file on
    # resume changes the snapshot, hence the run ids, and the runs are redone).
    return snapshot(scenario, out), scenario.raw, plist


def objective_of(measured, scenario, base_path: Path, run_fn: Callable | None,
                 polish_fn: Callable | None) -> Objective:
    """The run functions: given ones, or :func:`objective_run` against ``measured`` aligned on the nominal run."""
    if run_fn is not None:
        return Objective(measured, None, None, run_fn, run_fn, polish_fn)
    if measured is None:
        raise UserInputError("calibrate needs --measured FILE")
    measured = Path(measured)
    if not measured.is_file():
        raise UserInputError(f"--measured {measured}: no such file")
    from orchestrator.cosim.sensing import simulate_sensors
    from orchestrator.inputs.sensor_layout import layout_of
    from orchestrator.inverse.objective import Target

    target = Target.read(measured, layout_of(scenario))  # a constant channel: objective.channel_scales
    nominal = simulate_sensors(scenario, target.layout, reconstruct=False)
    if nominal.error:
        raise UserInputError(f"{base_path}: the nominal scenario does not run to the end ({nominal.error})")
    shift = float(target.align_to(nominal.t, nominal.signals))
    run_fn = functools.partial(objective_run, measured=str(measured.resolve()), shift=shift)
    return Objective(measured, target, shift, run_fn, functools.partial(run_fn, save_signals=True),
                     polish_fn or functools.partial(run_fn, save_residuals=True))


# ======================================================================================
# Stages 1-5: designs, surrogates, narrowing, optimisation
# ======================================================================================
def first_design(setup: Setup) -> tuple[Design, Surrogate]:
    """Stage 1: a Latin hypercube of ``n1`` runs over the whole cube, and J's surrogate on it."""
    k = len(setup.params)
    U1 = latin_hypercube(k, setup.n1, setup.seed)
    y1, ch1, res1 = setup.runs.stage(U1, "cal1", setup.out / "stage1", setup.objective.run_fn)
    d1 = Design(U1, y1, ch1, [res1], [len(U1)])
    ok = d1.ok
    if ok.sum() < k + 2:
        raise CalibrationIncomplete(f"calibration stage 1: only {int(ok.sum())} of {setup.n1} runs gave an objective")
    return d1, fit_objective(U1[ok], y1[ok], setup.transforms, setup.seed)


def narrow(setup: Setup, d1: Design, s1: Surrogate, rng: np.random.Generator) -> Narrowing:
    """Stage 3: the stage-1 surrogate's minimiser, its profiles and the narrowed box.

    The box is kept in ``OUT/stage2_plan.json`` and reused while stage 1's runs, ``n2``
    and ``seed`` are the same (so a resume runs the same stage 2). ``rng`` draws the
    random multistarts (and is passed on to stage 5).
    """
    k = len(setup.params)
    ok = d1.ok
    plan_file = setup.out / PLAN_FILE
    res1 = d1.results[0]
    stage1_id = digest([res1.rows[i]["run_id"] for i in range(len(res1.rows))] + [d1.y.tolist()])
    plan = json.loads(plan_file.read_text()) if plan_file.is_file() else None
    starts = multistarts(d1.U[ok], d1.y[ok], np.zeros(k), np.ones(k), rng)
    u_star, f_star, _ = minimise_surrogate(s1, np.zeros(k), np.ones(k), starts)
    tau = NARROW_CV_FACTOR * float(s1.local_cv_rmse()[0])
    sens = sensitivity(s1, u_star, d1.U[ok], d1.y[ok], tau)
    if plan is None or plan.get("stage1") != stage1_id or plan.get("n2") != setup.n2 or plan.get("seed") != setup.seed:
        plan = {"stage1": stage1_id, "n2": setup.n2, "seed": setup.seed, "lower": sens["lower"].tolist(),
                "upper": sens["upper"].tolist()}
        plan_file.write_text(json.dumps(plan, indent=1))
    return Narrowing(u_star, f_star, tau, sens, np.array(plan["lower"]), np.array(plan["upper"]))


def second_design(setup: Setup, box: Narrowing) -> tuple[Design, int]:
    """Stage 4: ``n2`` Latin-hypercube runs in the narrowed box plus its ``2^k`` corners; returns them and the corner count."""
    k = len(setup.params)
    lo, hi = box.lower, box.upper
    U2 = lo + latin_hypercube(k, setup.n2, setup.seed + 1) * (hi - lo)
    cs = corners(lo, hi) if k <= MAX_CORNER_DIM else np.empty((0, k))
    U2 = np.vstack([U2, cs])
    y2, ch2, res2 = setup.runs.stage(U2, "cal2", setup.out / "stage2", setup.objective.run_fn)
    return Design(U2, y2, ch2, [res2], [len(U2)]), len(cs)


def fit_all(setup: Setup, design: Design) -> Fit:
    """J's surrogate on every run of stages 1 and 4 and, jointly, the channels' nRMSE surrogate."""
    ok = design.ok
    surrogate = fit_objective(design.U[ok], design.y[ok], setup.transforms, setup.seed)
    names = sorted(design.channels)
    if not names:
        return Fit(surrogate, None)
    C = np.column_stack([design.channels[c] for c in names])
    okc = ok & np.all(np.isfinite(C), axis=1)
    return Fit(surrogate, fit_surrogate(design.U[okc], C[okc], names, seed=setup.seed))


def optimise(fit: Fit, design: Design, box: Narrowing, rng: np.random.Generator) -> Optimum:
    """Stage 5: the surrogate's minimum in the narrowed box, from the best runs and random starts."""
    starts = multistarts(design.U, design.y, box.lower, box.upper, rng)
    return Optimum(*minimise_surrogate(fit.surrogate, box.lower, box.upper, starts))


# ======================================================================================
# Stages 6-7: confirmation, polish; the calibrated scenario
# ======================================================================================
def confirm(setup: Setup, optimum: Optimum, design: Design) -> Confirmation:
    """Stage 6: simulate the nominal scenario and the surrogate optimum; choose it or the design's best run."""
    raw = setup.raw
    conf_vars = [{"name": f"{raw['name']}-nominal"},
                 variation(raw, setup.params, values_at(setup.params, optimum.u), f"{raw['name']}-calibrated")]
    conf = setup.runs.sweep(conf_vars, setup.out / "confirm", "confirmation", setup.objective.confirm_fn,
                            progress=False)
    rows = {r["index"]: r for r in conf.rows}
    j_confirmed = finite(rows[1].get(OBJECTIVE))
    y = design.y
    i_best = int(np.nanargmin(y))
    if np.isfinite(y[i_best]) and not (j_confirmed <= y[i_best]):
        chosen = Choice("best run", design.U[i_best], float(y[i_best]), design.row(i_best), None)
    else:
        chosen = Choice("surrogate optimum", optimum.u, j_confirmed, rows[1],
                        (setup.out / "confirm" / "runs", rows[1]["run_id"]))
    return Confirmation(rows[0], rows[1], chosen, conf)


def polish_stage(setup: Setup, chosen: Choice) -> tuple[dict | None, Choice]:
    """Stage 7: the polish from the chosen point and from the nominal scenario.

    Returns what :func:`~orchestrator.inverse.calibration_runs.polish` found (``None`` when
    there is no polish) and the calibrated point: the polished one, re-run with its
    signals into ``OUT/final``, if its J is less than ``chosen``'s, else ``chosen``.
    """
    if not setup.polish or setup.objective.polish_fn is None:
        return None, chosen
    params = setup.params
    starts = {chosen.source: chosen.u,
              "nominal": np.array([p.to_unit(v) for p, v in zip(params, nominal_values(setup.raw, params))])}
    polished = polish(setup.runs, starts, setup.out / "polish", setup.objective.polish_fn, setup.polish)
    if not polished["objective"] < chosen.objective:
        return polished, chosen
    u = np.asarray(polished["u"])
    fin = setup.runs.stage(u[None], "final", setup.out / "final", setup.objective.confirm_fn, progress=False)[2]
    return polished, Choice("polish", u, polished["objective"], polished["row"],
                            (setup.out / "final" / "runs", fin.rows[0]["run_id"]))


def write_calibrated(setup: Setup, values: list[float]) -> Path:
    """Write ``OUT/calibrated.yaml``: the scenario with the calibrated ``values`` [units]; returns its path."""
    from orchestrator.inputs.scenario import dump_scenario, scenario_from_dict

    raw = setup.raw
    cal_raw = apply_values(raw, setup.params, values)
    cal_raw["name"] = f"{raw['name']}-calibrated"
    cal_scn = scenario_from_dict(cal_raw, source="<calibrated>", base_dir=setup.base_path.parent)
    return dump_scenario(cal_scn, setup.out / CALIBRATED_FILE)


# ======================================================================================
# The sequence
# ======================================================================================
@dataclass(frozen=True)
class Outcome:
    """What the stages found (what ``calibration.json``, the report and the plots show).

    Attributes
    ----------
    first : Design
        Stage 1's runs; ``s1`` their surrogate of J.
    box : Narrowing
        Stage 3.
    design : Design
        The runs of stages 1 and 4 (``corners`` of them the box's corners).
    fit : Fit
        The surrogates on ``design``.
    optimum : Optimum
        Stage 5.
    confirmation : Confirmation
        Stage 6.
    polished : dict or None
        Stage 7 (:func:`~orchestrator.inverse.calibration_runs.polish`); ``None``: no polish.
    chosen : Choice
        The calibrated point; ``values`` [units] its parameters' values.
    scenario_file : Path
        ``OUT/calibrated.yaml``.
    """

    first: Design
    s1: Surrogate
    box: Narrowing
    design: Design
    corners: int
    fit: Fit
    optimum: Optimum
    confirmation: Confirmation
    polished: dict | None
    chosen: Choice
    values: list
    scenario_file: Path


def run_stages(setup: Setup) -> Outcome:
    """Stages 1 to 7 and the calibrated scenario, in order (:mod:`orchestrator.inverse.calibrate`)."""
    rng = np.random.default_rng([setup.seed, 1])  # the multistarts of stages 3 and 5, in that order
    d1, s1 = first_design(setup)
    box = narrow(setup, d1, s1, rng)
    d2, n_corners = second_design(setup, box)
    design = d1 + d2
    fit = fit_all(setup, design)
    optimum = optimise(fit, design, box, rng)
    confirmation = confirm(setup, optimum, design)
    polished, chosen = polish_stage(setup, confirmation.chosen)
    values = values_at(setup.params, chosen.u)
    scenario_file = write_calibrated(setup, values)
    return Outcome(d1, s1, box, design, n_corners, fit, optimum, confirmation, polished, chosen, values,
                   scenario_file)


__all__ = ["Objective", "Setup", "Design", "Narrowing", "Fit", "Optimum", "Choice", "Confirmation", "Outcome",
           "check_sizes", "prepare", "objective_of", "first_design", "narrow", "second_design", "fit_all", "optimise",
           "confirm", "polish_stage", "write_calibrated", "run_stages"]
