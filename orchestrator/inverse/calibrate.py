"""Surrogate calibration of a scenario against a measurement (DESIGN.md §5, as in seed 000).

Pipeline (every stage's runs go through :func:`orchestrator.sweeps.sweep.run_sweep`, so they
are resumable and run on local processes or a Dask cluster):

0. **Parameters** (:func:`~orchestrator.inverse.calibration_params.parse_params`) are mapped to the unit cube, ``u in [0, 1]^k``;
   stiffness scales on a log scale. Bounds and scales come from the cause catalogue
   (:data:`orchestrator.inputs.causes.CATALOGUE`) unless given. The objective is J of
   :mod:`orchestrator.inverse.objective` (weighted sum over sensor groups of the channels'
   nRMSE), with the time alignment fixed once from the nominal scenario.
1. **Latin hypercube** of ``n1`` runs over the whole cube (:class:`scipy.stats.qmc.LatinHypercube`).
2. **Response surface**: a polyharmonic spline (:class:`scipy.interpolate.RBFInterpolator`,
   thin-plate kernel, linear polynomial tail) of J and, jointly, of every channel's
   nRMSE (:func:`~orchestrator.inverse.surrogate.fit_surrogate`). The smoothing is chosen by k-fold cross-validation,
   and so is what is fitted of J: J, log J or J^2, whichever predicts the best runs best
   (:func:`~orchestrator.inverse.surrogate.fit_objective`). The CV error is the RMSE of the held-out predictions, also
   given relative to the standard deviation of the values (``cv_rel``: 0 perfect, 1 no
   better than the mean) and over the best runs only (``local_cv_rmse``).
3. **Sensitivity and narrowed bounds** (:func:`~orchestrator.inverse.surrogate.sensitivity`): at the surrogate's
   minimiser ``u*`` the surrogate is profiled along each axis; the sensitivity of a
   parameter is the range of its profile. The narrowed interval of a parameter is the
   part of its axis where the profile stays within ``tau`` of its minimum, with
   ``tau = NARROW_CV_FACTOR x`` the surrogate's *local* CV RMSE (over the runs with
   the lowest ``LOCAL_SHARE`` of J: the error where it matters, not at the far
   corners where J is large and the spline's error with it): a rise of the profile
   smaller than that is not resolved,
   widened to hold the ``NARROW_KEEP_BEST`` best runs, padded by ``NARROW_MARGIN`` on
   each side and at least ``NARROW_MIN_WIDTH`` wide (all in unit coordinates).
   A parameter the objective hardly sees keeps its whole range.
4. **Second Latin hypercube** of ``n2`` runs in the narrowed box plus its ``2^k``
   corners; the surrogates are refitted on every run of stages 1 and 4.
5. **Optimisation** of the surrogate in the narrowed box: bounded interior-point
   :func:`scipy.optimize.minimize` (``method="trust-constr"``), started from the best
   runs and from random points (:func:`~orchestrator.inverse.surrogate.minimise_surrogate`).
6. **Confirmation**: the optimum is simulated (with the nominal scenario, for the
   before/after comparison).
7. **Polish** (added to the seed's procedure; ``polish=0`` leaves it out): bounded
   least squares on real runs (:func:`orchestrator.inverse.fitting.fit_unit_cube`, ``trf`` over
   the *whole* unit cube, the finite-difference Jacobian's ``k`` runs in parallel) of
   the weighted residual vector whose sum of squares is J's least-squares counterpart
   (:meth:`orchestrator.inverse.objective.Target.weighted_residuals`), started from the better of
   the confirmed optimum and the best run of the design, and again from the nominal
   scenario. Why: with 8 parameters a 1256-run spline resolves J only to its CV error
   (~30 % of J's spread, measured), and near the optimum the void gaps move J by less
   than that; the surrogate finds the basin (and the sensitivities), the polish finds
   the point. Why the second start: a void gap larger than the sleeper's deflection
   there is a plateau (that end never touches, so the residuals do not change with
   it); a start on such a plateau stays there (measured: the surrogate's optimum had
   the far-end gap at 1.1 mm against 0.05 mm true, and the polish kept it at 1.4 mm),
   while the nominal scenario is in contact everywhere, where every gap has a gradient.
   Each iteration's runs are a small sweep (``OUT/polish/<start>/bNNN``) on one executor
   kept for the stage, so the stage resumes like the others: the iteration is
   deterministic, and a rerun replays the finished runs from disk.

The calibrated scenario is whichever of the confirmed optimum, the best run of the
design and the polished point has the least simulated J (``calibration.json`` says which).

Each run is one scenario whose ``name`` labels its stage and position
(``<name>-cal1-0007``); the calibrated parameters enter as scenario overrides
(``track.ballast.voids`` as a whole list, ``track.ballast.stiffness_scale``, ...).

Output folder (``OUT``)::

    OUT/base.yaml, OUT/sensors.yaml          snapshots of the nominal scenario and its sensor layout
                                             (what every run loads)
    OUT/stage1/, OUT/stage2/, OUT/confirm/   the sweeps (sweep.csv, runs/<id>/result.json)
    OUT/polish/<start>/bNNN/, OUT/final/     the polish's iterations; the calibrated point re-run with its signals
    OUT/stage2_plan.json                     the narrowed box (reused on resume)
    OUT/calibrated.yaml                      the calibrated scenario
    OUT/calibration.json                     everything measured (:meth:`CalibrationResult.to_json`)
    OUT/report.md                            a short report
    OUT/calibration_cv.png, calibration_sensitivity.png, calibration_signals.png

``--params`` syntax (:func:`~orchestrator.inverse.calibration_params.parse_params`), comma-separated items, each optionally
followed by ``=LO:HI[:log|:lin]`` (bounds in the scenario's SI units):

* ``h1`` ballast stiffness scale, ``h2`` rail-pad stiffness scale (global), ``angle``
  crossing impact angle [rad];
* ``gaps@K`` the 6 void gaps [m] of sleeper K, ``gapI@K`` one of them (I = 1..6);
  ``pad@K`` the pad stiffness scale of sleeper K. K is an index or ``T``, ``T+1``,
  ``T-2`` (relative to the crossing transition sleeper);
* any numeric scenario key path with bounds, e.g. ``track.ballast.stiffness_scale=0.3:3:log``
  or ``track.rail_pad.damping=1e4:4e4``.

Default: ``gaps@T,h1,h2`` (seed 000's 8 parameters).

The code follows the pipeline: :mod:`orchestrator.inverse.calibration_params` (the
parameters, ``--params``, their values in a scenario), :mod:`orchestrator.inverse.surrogate`
(response surface, CV, sensitivity, optimisation, designs),
:mod:`orchestrator.inverse.calibration_runs` (the run function, sweeps of points, the
polish), :mod:`orchestrator.inverse.calibration_stages` (the stages, in order) and
:mod:`orchestrator.inverse.calibration_report` (``calibration.json``'s content, the report,
the plots). This module is the entry point, :func:`calibrate` and its result; it also
gives the names of those modules that callers use (``cal.parse_params``, ...).
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from orchestrator.inverse.calibration_params import (
    DEFAULT_PARAMS,
    Parameter,
    apply_values,
    nominal_values,
    parse_params,
    values_at,
)
from orchestrator.inverse.calibration_report import plots, report, summarise
from orchestrator.inverse.calibration_runs import (
    BASE_FILE,
    POLISH_MAX_NFEV,
    RESIDUALS_FILE,
    SIGNALS_FILE,
    CalibrationIncomplete,
    Runs,
    objective_run,
    polish,
    snapshot,
)
from orchestrator.inverse.calibration_stages import Outcome, Setup, check_sizes, objective_of, prepare, run_stages
from orchestrator.inverse.jsonable import numpy_default
from orchestrator.inverse.surrogate import (
    CV_FOLDS,
    KERNEL,
    LOCAL_SHARE,
    TRANSFORMS,
    Surrogate,
    fit_objective,
    fit_surrogate,
    latin_hypercube,
    minimise_surrogate,
    sensitivity,
)

__all__ = [
    "Parameter",
    "Surrogate",
    "CalibrationResult",
    "CalibrationIncomplete",
    "parse_params",
    "fit_surrogate",
    "sensitivity",
    "minimise_surrogate",
    "objective_run",
    "calibrate",
    "DEFAULT_PARAMS",
]

CALIBRATION_FILE = "calibration.json"  # OUT/calibration.json: CalibrationResult.to_json
REPORT_FILE = "report.md"  # OUT/report.md

# Names that callers (tests, benchmarks) reach through this module, private ones included; so are the
# imports above that this module does not use itself (apply_values, RESIDUALS_FILE, CV_FOLDS, ...).
_lhs = latin_hypercube
_values = values_at
_snapshot = snapshot


@dataclass
class CalibrationResult:
    """What :func:`calibrate` found (everything is also in ``calibration.json``).

    Attributes
    ----------
    params : list of Parameter
    values : dict
        Parameter name -> calibrated value [its unit].
    u : ndarray, shape (k,)
        The calibrated point in unit coordinates.
    summary : dict
        The content of ``calibration.json`` (:meth:`to_json`).
    out_dir : Path
    scenario_file : Path
        ``calibrated.yaml``.
    stages : dict
        Stage -> the :class:`orchestrator.sweeps.sweep.SweepResult` of its runs (not in the JSON).
    """

    params: list
    values: dict
    u: np.ndarray
    summary: dict
    out_dir: Path
    scenario_file: Path
    stages: dict

    def to_json(self) -> str:
        """The text of ``calibration.json``: :attr:`summary` as JSON (indent 1; arrays as lists).

        Its keys (the file format): ``scenario``, ``measured`` (paths), ``parameters``
        (:meth:`Parameter.as_dict` each), ``runs`` (design sizes and counts), ``shift`` [s],
        ``seed``, ``kernel``, ``bounds`` (``stage1``, ``stage2`` [units], ``stage2_unit``),
        ``surrogate_stage1`` and ``surrogate`` (:meth:`Surrogate.summary`),
        ``channel_surrogates``, ``sensitivity``, ``optimum``, ``best_run``, ``polish``,
        ``calibrated`` (``source``, ``values``, ``file``), ``objective_before``,
        ``objective_after``, ``gain``, ``channels`` (nRMSE per channel), ``wall_time_s`` [s]
        and ``plots`` (:func:`orchestrator.inverse.calibration_report.summarise`).
        """
        return json.dumps(self.summary, indent=1, default=numpy_default)

    @classmethod
    def from_json(cls, text: str, out_dir: str | os.PathLike) -> CalibrationResult:
        """The result of a ``calibration.json`` text (:meth:`to_json`) found in ``out_dir``.

        ``params``, ``values`` and ``scenario_file`` are read from the summary; ``u`` is the
        calibrated point as stored (the polish's or the surrogate optimum's unit coordinates;
        for the design's best run, its values mapped back, exact to round-off); ``stages``
        is empty (the sweeps are on disk, not in the JSON).
        """
        summary = json.loads(text)
        params = [Parameter.from_dict(d) for d in summary["parameters"]]
        values = dict(summary["calibrated"]["values"])
        stored = {"polish": summary["polish"].get("u"), "surrogate optimum": summary["optimum"]["u"]}
        u = stored.get(summary["calibrated"]["source"])
        u = np.array([u[p.name] for p in params] if u is not None else [p.to_unit(values[p.name]) for p in params])
        out = Path(out_dir)
        return cls(params, values, u, summary, out, out / summary["calibrated"]["file"], {})

    @classmethod
    def read(cls, out_dir: str | os.PathLike) -> CalibrationResult:
        """The result stored in ``out_dir/calibration.json``."""
        return cls.from_json((Path(out_dir) / CALIBRATION_FILE).read_text(), out_dir)


def calibrate(base_path: str | os.PathLike, measured: str | os.PathLike | None, out_dir: str | os.PathLike, *,
              params: str | Sequence[Parameter] | None = None, n1: int = 500, n2: int = 500, seed: int = 0,
              workers: int | None = None, scheduler: str | None = None, progress: bool = True,
              run_fn: Callable | None = None, transforms: Sequence[str] = TRANSFORMS,
              polish: int = POLISH_MAX_NFEV, polish_fn: Callable | None = None) -> CalibrationResult:
    """Calibrate the parameters of a scenario against a measurement (module docstring).

    Parameters
    ----------
    base_path : path-like
        The nominal scenario YAML.
    measured : path-like or None
        The measurement file; may be ``None`` only with a custom ``run_fn``.
    out_dir : path-like
        ``OUT`` (created; a rerun with the same arguments resumes there).
    params : str or sequence of Parameter, optional
        ``--params`` text (:func:`parse_params`); default :data:`DEFAULT_PARAMS`.
    n1, n2 : int
        Runs of the first and the second Latin hypercube.
    seed : int
        Seed of the designs, the CV folds and the random starts.
    workers : int, optional
        Local worker processes (default: one per core; ignored with ``scheduler``).
    scheduler : str, optional
        Dask scheduler address.
    progress : bool
        Progress bars.
    run_fn : callable, optional
        ``run_fn(scenario, run_dir) -> {"objective": J, "nrmse.<id>": ...}``, top level
        (picklable); default :func:`objective_run` against ``measured``.
    transforms : sequence of str
        Candidate transforms of J for its surrogate (:func:`fit_surrogate`); the one with
        the least local CV error is used (:func:`~orchestrator.inverse.surrogate.fit_objective`).
    polish : int
        Least-squares iterations of the polish (stage 7); 0 leaves it out.
    polish_fn : callable, optional
        The polish's run function: as ``run_fn``, and it also writes the run's residual
        vector to ``run_dir / "residuals.npy"``. Default: :func:`objective_run` with
        ``save_residuals`` (with a custom ``run_fn`` and no ``polish_fn`` there is no polish).

    Returns
    -------
    CalibrationResult

    Raises
    ------
    UserInputError
        Bad scenario, measurement file, parameters or sizes.
    CalibrationIncomplete
        Runs of a stage failed or were lost; a rerun does only the missing ones.
    """
    t_start = time.perf_counter()
    base_path, out = Path(base_path), Path(out_dir)
    check_sizes(n1, n2, polish)
    scenario, raw, plist = prepare(base_path, out, params, n1)
    objective = objective_of(measured, scenario, base_path, run_fn, polish_fn)
    # one executor for every stage: a local pool's workers start (imports, numba's set-up, the kernel's
    # load) once instead of once per stage, five times (benchmarks/RESULTS.md, 2026-11-27)
    from orchestrator.sweeps.executors import make_executor

    executor = make_executor(workers, scheduler)
    try:
        setup = Setup(base_path, out, Runs(out / BASE_FILE, raw, plist, workers, scheduler, progress, executor),
                      objective, n1, n2, seed, tuple(transforms), polish)
        return _finish(setup, run_stages(setup), t_start)
    finally:
        executor.shutdown()


def _finish(setup: Setup, found: Outcome, t_start: float) -> CalibrationResult:
    """Plot, and write ``calibration.json`` and ``report.md``; returns the result (``t_start``: for the wall time)."""
    summary = summarise(setup, found)
    summary["plots"] = [p.name for p in plots(setup, found)]
    summary["wall_time_s"] = time.perf_counter() - t_start
    result = CalibrationResult(setup.params, dict(zip([p.name for p in setup.params], found.values)),
                               np.asarray(found.chosen.u), summary, setup.out, found.scenario_file,
                               {"stage1": found.first.results[0], "stage2": found.design.results[1],
                                "confirm": found.confirmation.sweep})
    (setup.out / CALIBRATION_FILE).write_text(result.to_json())
    (setup.out / REPORT_FILE).write_text(report(summary))
    return result


def _polish(snapshot_path: Path, raw: dict, params, starts: dict, out: Path, polish_fn, max_nfev: int, workers,
            scheduler, progress) -> dict:
    """Stage 7 by itself: :func:`~orchestrator.inverse.calibration_runs.polish` with its runs made from
    ``snapshot_path`` (``OUT/base.yaml``) and ``raw`` on ``workers`` or ``scheduler``."""
    return polish(Runs(snapshot_path, raw, list(params), workers, scheduler, progress), starts, out, polish_fn,
                  max_nfev)
