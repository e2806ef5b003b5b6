"""The calibration's simulation runs: the run function, the snapshot, sweeps of points, the polish.

Part of :mod:`orchestrator.inverse.calibrate` (its module docstring describes the
pipeline and the output folder). Every run of the calibration goes through
:meth:`Runs.sweep` (:func:`orchestrator.sweeps.sweep.run_sweep`: resumable, local
processes or Dask, the scenario and the measurement sent by value); :func:`objective_run` is what a run computes (J and each channel's
nRMSE); :func:`polish` is stage 7, least squares on real runs.
"""
from __future__ import annotations

import copy
import functools
import hashlib
import itertools
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from orchestrator.inputs.errors import one_line
from orchestrator.inverse.calibration_params import Parameter, values_at, variation
from orchestrator.inverse.surrogate import OBJECTIVE

__all__ = ["CalibrationIncomplete", "Runs", "objective_run", "measured_by_value", "snapshot", "polish", "finite"]

CHANNEL_PREFIX = "nrmse."  # run-function scalars "nrmse.<sensor id>": channel surrogates
SIGNALS_FILE = "signals.npz"  # the confirmation runs' sensor signals
RESIDUALS_FILE = "residuals.npy"  # a polish run's weighted residual vector (Target.weighted_residuals)
POLISH_MAX_NFEV = 15  # least-squares iterations of the polish (measured: the 8-parameter benchmark converges in ~10)
FAILED_RUN_PENALTY = 10.0  # a polish run that stops early counts as this x the start's residual vector
BASE_FILE = "base.yaml"  # OUT/base.yaml: the snapshot of the nominal scenario every run loads
LAYOUT_FILE = "sensors.yaml"  # OUT/sensors.yaml: the snapshot of its sensor layout


class CalibrationIncomplete(RuntimeError):
    """Runs of a stage did not finish (failed, or a worker died); finished ones are kept: rerun to resume."""


# ======================================================================================
# The run function (executed in the sweep's workers)
# ======================================================================================
_TARGETS: dict[tuple, Any] = {}  # per worker process: (measured file, layout file) -> Target


def _target(measured, scenario):
    """The worker's :class:`~orchestrator.inverse.objective.Target` of a measurement and the scenario's layout.

    ``measured`` is a :class:`~orchestrator.cosim.portable.FileValue` (recreated in the
    worker's temporary space, once per content) or a path the worker can read.
    """
    from orchestrator.cosim.portable import FileValue
    from orchestrator.inputs.sensor_layout import layout_of
    from orchestrator.inverse.objective import Target

    path = measured.local_path() if isinstance(measured, FileValue) else measured
    key = (str(path), scenario.sensors)
    if key not in _TARGETS:
        _TARGETS[key] = Target.read(path, layout_of(scenario))
    return _TARGETS[key]


def measured_by_value(run_fn: Callable) -> Callable:
    """``run_fn`` with the measurement sent by value when it is :func:`objective_run` given a path.

    The calibration's run functions are partials of :func:`objective_run` with
    ``measured=`` a path on the client; a worker on another machine cannot read it, so
    the file's content goes with the function instead
    (:class:`~orchestrator.cosim.portable.FileValue`). Any other run function is returned as is.
    """
    from orchestrator.cosim.portable import FileValue

    if isinstance(run_fn, functools.partial) and run_fn.func is objective_run and \
            isinstance(run_fn.keywords.get("measured"), (str, Path)):
        return functools.partial(run_fn, measured=FileValue.read(run_fn.keywords["measured"]))
    return run_fn


def objective_run(scenario, run_dir: Path, *, measured, shift: float, save_signals: bool = False,
                  save_residuals: bool = False) -> dict:
    """Simulate ``scenario`` and compare it with a measurement: J and each channel's nRMSE.

    A top-level function: :func:`functools.partial` of it with the keywords pickles,
    so it is the ``run_fn`` of the calibration's sweeps.

    Parameters
    ----------
    scenario : Scenario
    run_dir : Path
        The run's folder (``signals.npz`` goes there with ``save_signals``).
    measured : str or FileValue
        The measurement file (CSV, HDF5 or MAT; :func:`orchestrator.inputs.measured.read_measured`):
        its path, or its content (:func:`measured_by_value`: what the calibration sends).
    shift : float
        Time alignment [s] fixed once for all runs (:meth:`orchestrator.inverse.objective.Target.align_to`).
    save_signals : bool
        Write the simulated sensor signals (``t`` [s] and one array per sensor id, shape (nt,)).
    save_residuals : bool
        Write the weighted residual vector (``residuals.npy``; the polish's least squares).

    Returns
    -------
    dict
        ``objective`` (J [-]) and ``nrmse.<id>`` [-] per measured channel; a run
        that stopped early gives ``objective = nan`` and its ``error``.
    """
    from orchestrator.cosim.sensing import simulate_sensors

    target = _target(measured, scenario)
    target.shift = float(shift)
    run = simulate_sensors(scenario, target.layout, reconstruct=False)
    if save_signals:
        np.savez(Path(run_dir) / SIGNALS_FILE, t=run.t, **run.signals)
    if run.error:
        return {OBJECTIVE: float("nan"), "error": one_line(run.error)}
    cmp = target.compare(run.t, run.signals)
    if save_residuals:
        np.save(Path(run_dir) / RESIDUALS_FILE, target.weighted_residuals(cmp))
    out = {OBJECTIVE: float(cmp.objective)}
    out.update({f"{CHANNEL_PREFIX}{k}": float(v["nrmse"]) for k, v in cmp.channels.items()})
    return out


# ======================================================================================
# Sweeps of points
# ======================================================================================
def snapshot(scenario, out: Path):
    """Write ``OUT/base.yaml`` and ``OUT/sensors.yaml`` (its sensor layout); returns the snapshot's scenario."""
    from orchestrator.inputs.scenario import dump_scenario, scenario_from_dict
    from orchestrator.inputs.sensor_layout import default_layout_path

    raw = copy.deepcopy(scenario.raw)
    layout = Path(raw["sensors"]) if raw.get("sensors") else default_layout_path()
    text = layout.read_text(encoding="utf-8")
    target = out / LAYOUT_FILE
    if not target.is_file() or target.read_text(encoding="utf-8") != text:
        target.write_text(text, encoding="utf-8")
    raw["sensors"] = str(target.resolve())
    snap = scenario_from_dict(raw, source=str(out / BASE_FILE), base_dir=out)
    dump_scenario(snap, out / BASE_FILE)
    return snap


def finite(v) -> float:
    """A result value as a float; ``nan`` for what is not a number (missing, an error text, a bool)."""
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else float("nan")


def channels_of(row: dict) -> dict[str, float]:
    """The ``nrmse.<id>`` values of a result row, as ``{id: nRMSE}``."""
    return {c[len(CHANNEL_PREFIX):]: finite(v) for c, v in row.items() if c.startswith(CHANNEL_PREFIX)}


def digest(obj) -> str:
    """A short SHA-1 of ``obj`` as sorted JSON (what identifies stage 1 in ``stage2_plan.json``)."""
    return hashlib.sha1(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Runs:
    """How the calibration's runs are made.

    Attributes
    ----------
    snapshot : Path
        ``OUT/base.yaml``, the scenario every run loads.
    raw : dict
        Its validated raw scenario (the parameters' values are set on it).
    params : list of Parameter
    workers : int
        Local worker processes (ignored with ``scheduler``).
    scheduler : str or None
        Dask scheduler address.
    progress : bool
        Progress bars of the design stages.
    executor : concurrent.futures.Executor or None
        One executor for every stage's runs (:func:`orchestrator.inverse.calibrate.calibrate` makes it
        and shuts it down: the workers start once, not once per stage); None: each stage makes its own.
    """

    snapshot: Path
    raw: dict
    params: list[Parameter]
    workers: int | None
    scheduler: str | None
    progress: bool
    executor: Any = None

    def sweep(self, variations: list[dict], out: Path, what: str, run_fn: Callable, *, progress: bool,
              executor=None):
        """:func:`orchestrator.sweeps.sweep.run_sweep` of ``variations`` into ``out``; returns its SweepResult.

        The runs and the measurement go to the workers by value (:func:`measured_by_value`).
        Unfinished or failed runs raise :class:`CalibrationIncomplete` (``what`` names the stage).
        """
        from orchestrator.sweeps.sweep import SweepIncomplete, run_sweep

        try:
            res = run_sweep(self.snapshot, variations, out, run_fn=measured_by_value(run_fn), workers=self.workers,
                            scheduler=self.scheduler, progress=progress,
                            executor=self.executor if executor is None else executor)
        except SweepIncomplete as exc:
            raise CalibrationIncomplete(f"calibration {what}: {exc}") from None
        if res.failed:
            raise CalibrationIncomplete(f"calibration {what}: {res.summary()}")
        return res

    def stage(self, points: np.ndarray, label: str, out: Path, run_fn: Callable, *, progress: bool | None = None,
              executor=None) -> tuple[np.ndarray, dict, Any]:
        """Run the points ``(n, k)`` of the unit cube; run ``i`` is named ``<name>-<label>-<i:04d>``.

        Returns
        -------
        y : ndarray, shape (n,)
            J of each point (``nan`` where the run gave none).
        channels : dict
            Sensor id -> nRMSE of each point, shape (n,).
        result : SweepResult
        """
        name = self.raw["name"]
        variations = [variation(self.raw, self.params, values_at(self.params, u), f"{name}-{label}-{i:04d}")
                      for i, u in enumerate(points)]
        res = self.sweep(variations, out, f"stage {label}", run_fn,
                         progress=self.progress if progress is None else progress, executor=executor)
        by_index = {row["index"]: row for row in res.rows}
        y = np.array([finite(by_index[i].get(OBJECTIVE)) for i in range(len(points))])
        names = sorted({c for row in res.rows for c in row if c.startswith(CHANNEL_PREFIX)})
        ch = {c[len(CHANNEL_PREFIX):]: np.array([finite(by_index[i].get(c)) for i in range(len(points))])
              for c in names}
        return y, ch, res


# ======================================================================================
# Stage 7: the polish
# ======================================================================================
def polish(runs: Runs, starts: dict, out: Path, polish_fn: Callable, max_nfev: int) -> dict:
    """Stage 7 (:mod:`orchestrator.inverse.calibrate`): least squares on real runs from each start.

    Parameters
    ----------
    runs : Runs
    starts : dict
        Label -> start in unit coordinates; each gets its own folder ``out/<label>``
        (a start equal to an earlier one is not run again).
    out : Path
    polish_fn : callable
        The run function; it writes the run's residual vector to ``residuals.npy``.
    max_nfev : int
        Least-squares iterations per start.

    Returns
    -------
    dict
        ``u`` (the point with the least sum of squares over all starts), its ``start``,
        ``objective`` J and result ``row``, ``cost_start`` (at that start) and ``cost``
        (sums of squared residuals), ``runs``, ``iterations`` (sweeps of parallel runs),
        ``wall_time_s`` and ``starts`` (per start: where it began and ended, J, runs).
    """
    from tqdm import tqdm

    from orchestrator.inverse.fitting import fit_unit_cube
    from orchestrator.sweeps.executors import make_executor

    t0 = time.perf_counter()
    found: dict[bytes, tuple[float, dict]] = {}  # point -> (J, result row) of every polish run
    bar = tqdm(desc="polish", unit="run", disable=not runs.progress)
    own = runs.executor is None
    executor = make_executor(runs.workers, runs.scheduler) if own else runs.executor
    fits, per_start = {}, {}
    names = [p.name for p in runs.params]
    try:
        items = list(starts.items())
        for n, (label, u0) in enumerate(items):
            if any(np.allclose(u0, v) for _, v in items[:n]):
                continue
            batch = _polish_batch(runs, out / label.replace(" ", "_"), polish_fn, executor, bar, found)
            fit = fits[label] = fit_unit_cube(batch, u0, max_nfev=max_nfev)
            per_start[label] = {"u0": dict(zip(names, map(float, np.clip(u0, 0, 1)))),
                                "u": dict(zip(names, map(float, fit.p))), "cost_start": fit.cost_start,
                                "cost": fit.cost, "objective": found[fit.p.tobytes()][0], "runs": fit.evaluations,
                                "iterations": fit.batches}
    finally:
        bar.close()
        if own:
            executor.shutdown()
    label = min(fits, key=lambda k: fits[k].cost)
    fit = fits[label]
    j, row = found[fit.p.tobytes()]
    return {"u": fit.p, "start": label, "objective": j, "row": row, "cost_start": fit.cost_start, "cost": fit.cost,
            "runs": sum(f.evaluations for f in fits.values()), "iterations": sum(f.batches for f in fits.values()),
            "wall_time_s": time.perf_counter() - t0, "starts": per_start}


def _polish_batch(runs: Runs, folder: Path, polish_fn: Callable, executor, bar, found: dict) -> Callable:
    """The batch function of one start's least squares: points -> their residual vectors.

    Call ``b`` runs its points as the sweep ``folder/bNNN``; the iteration is deterministic,
    so call ``b`` of a rerun is call ``b`` before and finds its runs on disk. Every run's
    (J, row) is recorded in ``found`` (keyed by the point's bytes).
    """
    calls = itertools.count()
    first: list[np.ndarray] = []  # the start's residuals

    def batch(ps: list[np.ndarray]) -> list[np.ndarray]:
        b = next(calls)
        res = runs.stage(np.asarray(ps), f"pol-{folder.name}-{b:03d}", folder / f"b{b:03d}", polish_fn,
                         progress=False, executor=executor)[2]
        bar.update(len(ps))
        by_index = {row["index"]: row for row in res.rows}
        rs = []
        for i, p in enumerate(ps):
            row = by_index[i]
            r = _residuals(res.runs_dir / row["run_id"] / RESIDUALS_FILE, row, first, folder.name)
            if not first:
                first.append(r)
            found[p.tobytes()] = (finite(row.get(OBJECTIVE)), row)
            rs.append(r)
        return rs

    return batch


def _residuals(path: Path, row: dict, first: list[np.ndarray], start: str) -> np.ndarray:
    """A polish run's residual vector; for a run that stopped early, the penalty times the start's."""
    if path.is_file() and np.isfinite(finite(row.get(OBJECTIVE))):
        return np.load(path)
    if first:  # the run stopped early: a residual far worse than the start's
        return FAILED_RUN_PENALTY * first[0]
    raise CalibrationIncomplete(f"calibration polish: the start point ({start}) gives no "
                                f"residuals ({row.get('error', 'no ' + RESIDUALS_FILE)})")
