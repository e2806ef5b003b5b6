"""Parameter sweeps: many runs of one scenario, resumable, locally or on a Dask cluster.

A sweep is a base scenario plus a list of variations (:mod:`orchestrator.sweeps.plan`:
:func:`grid_from_vary`, :func:`list_from_file`, validated by :func:`plan_sweep`), run
through a :mod:`concurrent.futures` executor (:mod:`orchestrator.sweeps.executors`:
local spawned processes or a Dask cluster) into a resumable store under ``OUT``
(:mod:`orchestrator.sweeps.store`: ``OUT/runs/<run_id>/``, ``OUT/sweep.csv``).
This module holds :func:`run_sweep`, which ties them together, its result
(:class:`SweepResult`, :class:`SweepIncomplete`) and the plots ``OUT/sweep_<scalar>.png``
(:func:`plot_sweep`).

:func:`run_sweep` in stages: plan and check everything (nothing runs on a bad key,
value or option), read the runs already finished, run the missing ones (the table is
rewritten every :data:`TABLE_EVERY` seconds as they come), then write the table and the
plots and sort out what did not finish. The runs travel to the workers by value and come
back by value
(:mod:`orchestrator.sweeps.store`): a Dask cluster on other machines needs no shared
file system, and only this process writes ``OUT``.
"""
from __future__ import annotations

import concurrent.futures as cf
import math
import numbers
import os
import pickle
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from orchestrator.inputs.errors import UserInputError

# DASK_CONNECT_TIMEOUT is read here at each call, so that it can be set on this module (the tests shorten it).
from orchestrator.sweeps.executors import (
    DASK_CONNECT_TIMEOUT,
    check_workers,
    default_workers,
    lost_worker,
    make_executor,
)

# Re-exported: the sweep's public face (the CLI and the tests read them here).
from orchestrator.sweeps.plan import Run, SweepPlan, expand_grid, grid_from_vary, list_from_file, plan_sweep
from orchestrator.sweeps.store import (
    ID_COLUMN,
    INDEX_COLUMN,
    RESULT_FILE,
    RUNS_DIR,
    TABLE_FILE,
    RunJob,
    SweepStore,
    cell_text,
    execute_run,
    write_table,
)

__all__ = [
    "Run",
    "SweepPlan",
    "SweepResult",
    "SweepIncomplete",
    "grid_from_vary",
    "expand_grid",
    "list_from_file",
    "plan_sweep",
    "run_sweep",
    "make_executor",
    "write_table",
    "plot_sweep",
    "RUNS_DIR",
    "RESULT_FILE",
    "TABLE_FILE",
]

PLOT_PREFIX = "sweep_"  # OUT/sweep_<scalar>.png
MAX_IDS_IN_MESSAGE = 8  # run ids listed in an error message before "..."
TABLE_EVERY = 2.0  # s: sweep.csv is rewritten at most this often while runs come in (and at the end). Rewriting
#                    it after every run made the client's work grow with the square of the runs: in a 1256-run
#                    calibration on 2 workers half the client's samples (py-spy), taken from the workers' cores


# --------------------------------------------------------------------------------------
# Plots
# --------------------------------------------------------------------------------------
def _number(value: Any) -> float | None:
    """``value`` as a finite float, or ``None`` for booleans, non-numbers, NaN and infinities."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return None
    return float(value) if math.isfinite(float(value)) else None


def plot_sweep(rows: Sequence[Mapping[str, Any]], varied_keys: Sequence[str],
               out_dir: str | os.PathLike) -> list[Path]:
    """One PNG per returned scalar: the scalar against the first varied key (matplotlib, Agg).

    Parameters
    ----------
    rows : sequence of mapping
        The sweep table (``SweepResult.rows``).
    varied_keys : sequence of str
        The varied keys; the first is the abscissa, every combination of the
        others is one line.
    out_dir : path-like
        Where ``sweep_<scalar>.png`` go.

    Returns
    -------
    list of Path
        The files written; none when the first varied key is not numeric.
        Scalars that are not numbers (strings, booleans) get no plot.
    """
    from orchestrator.results.plots import _plt, save  # the package's plotting setup (Agg backend) and writer

    if not rows or not varied_keys:
        return []
    x_key, others = varied_keys[0], list(varied_keys[1:])
    if any(_number(r.get(x_key)) is None for r in rows):
        return []
    fixed = {INDEX_COLUMN, ID_COLUMN, *varied_keys}
    names = list(dict.fromkeys(k for r in rows for k in r if k not in fixed))
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    plt = _plt()
    written = []
    for name in names:
        if not any(_number(r.get(name)) is not None for r in rows) or \
                any(isinstance(r.get(name), (bool, str)) for r in rows):
            continue
        lines: dict[tuple, list[tuple[float, float]]] = {}
        for r in rows:
            y = _number(r.get(name))
            if y is not None:
                lines.setdefault(tuple(cell_text(r.get(k)) for k in others), []).append((_number(r[x_key]), y))
        fig, ax = plt.subplots(figsize=(6.0, 4.0))
        for combo, points in lines.items():
            xs, ys = zip(*sorted(points))
            label = ", ".join(f"{k} = {v}" for k, v in zip(others, combo)) or None
            ax.plot(xs, ys, "o-", label=label)
        ax.set_xlabel(x_key)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
        if others:
            ax.legend(fontsize="small")
        fig.tight_layout()
        path = out_dir / f"{PLOT_PREFIX}{re.sub(r'[^A-Za-z0-9._-]+', '_', name)}.png"
        save(fig, path)
        written.append(path)
    return written


# --------------------------------------------------------------------------------------
# Result
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SweepResult:
    """What a sweep did.

    Attributes
    ----------
    rows : list of dict
        The table: one row per finished run (this call's and earlier ones), grid order.
    varied_keys : tuple of str
    out_dir, table, runs_dir : Path
        ``OUT``, ``OUT/sweep.csv``, ``OUT/runs``.
    plots : tuple of Path
    done : int
        Runs finished by this call.
    skipped : int
        Runs found finished on disk and not redone.
    failed : int
        Runs whose run function raised (see ``errors``); a rerun retries them.
    errors : dict
        run id -> one-line error message of the failed runs.
    unfinished : tuple of str
        Ids of the runs that did not finish (failed or lost with a dead worker).
    """

    rows: list
    varied_keys: tuple
    out_dir: Path
    table: Path
    runs_dir: Path
    plots: tuple
    done: int
    skipped: int
    failed: int
    errors: dict
    unfinished: tuple

    def summary(self) -> str:
        """One line: runs done, skipped, failed and where the table is."""
        total = len(self.rows) + len(self.unfinished)
        line = (f"{total} runs: {self.done} done, {self.skipped} already finished, {self.failed} failed; "
                f"table {self.table}")
        if self.errors:
            run_id, message = next(iter(self.errors.items()))
            line += f"; {_ids(list(self.errors))} failed (first: {run_id}: {message}); rerun the same command to retry"
        return line


class SweepIncomplete(RuntimeError):
    """Workers died before every run finished; finished runs are on disk, a rerun does the rest.

    Attributes
    ----------
    result : SweepResult
        What was finished (its table and plots are written).
    """

    def __init__(self, message: str, result: SweepResult):
        super().__init__(message)
        self.result = result


def _ids(ids: Sequence[str]) -> str:
    """``ids`` comma-separated, the first ``MAX_IDS_IN_MESSAGE`` of them and how many in all."""
    shown = ", ".join(ids[:MAX_IDS_IN_MESSAGE])
    return shown + (f", ... ({len(ids)} in all)" if len(ids) > MAX_IDS_IN_MESSAGE else "")


def _one_line_error(exc: BaseException) -> str:
    """``Type: message`` of ``exc`` on one line."""
    text = re.sub(r"\s*[\r\n]+\s*", " ", str(exc)).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


# --------------------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Options:
    """How :func:`run_sweep` runs: its arguments ``run_fn`` .. ``executor``."""

    run_fn: Callable | None
    workers: int | None
    scheduler: str | None
    progress: bool
    executor: cf.Executor | None


@dataclass
class _Outcome:
    """The runs' outcome so far: records of finished runs, errors of failed runs, ids of lost runs."""

    records: dict[str, dict]
    errors: dict[str, str] = field(default_factory=dict)
    lost: list[str] = field(default_factory=list)


def run_sweep(base_path: str | os.PathLike, variations: Sequence[Mapping[str, Any]], out_dir: str | os.PathLike,
              run_fn: Callable | None = None, workers: int | None = None, scheduler: str | None = None,
              progress: bool = True, executor: cf.Executor | None = None) -> SweepResult:
    """Run (or resume) a sweep; write ``OUT/runs/*``, ``OUT/sweep.csv`` and the plots.

    Parameters
    ----------
    base_path : path-like
        The base scenario YAML.
    variations : sequence of mapping
        One ``{key.path: value}`` per run (:func:`grid_from_vary`, :func:`list_from_file`).
    out_dir : path-like
        ``OUT``; created if needed. Runs finished there before are not redone.
    run_fn : callable, optional
        ``run_fn(scenario, run_dir) -> dict[str, float]``, a top-level (picklable)
        function; default :func:`orchestrator.sweeps.study.run_case`. Non-scalar
        values it returns are left out of the table (write arrays to ``run_dir``:
        a fresh folder in the worker's temporary space, whose files are sent back and
        written to ``OUT/runs/<run_id>/`` by this process).
    workers : int, optional
        Local worker processes (default: one per core,
        :func:`orchestrator.sweeps.workers.default_workers`).
    scheduler : str, optional
        A Dask scheduler address; the runs go to that cluster instead.
    progress : bool
        Show a progress bar.
    executor : concurrent.futures.Executor, optional
        An executor to run on instead of a new one (``workers`` and ``scheduler`` are then
        not used); it is left running. For callers that run many small sweeps in a row
        (a fit's iterations), so that the workers and what they cache are kept.

    Returns
    -------
    SweepResult
        A run whose function raised is counted in ``failed`` and left unfinished.

    Raises
    ------
    ScenarioError, UserInputError
        A bad key or value in any run (before anything runs); a bad ``workers``
        or an unreachable ``scheduler``.
    SweepIncomplete
        A worker died (killed, out of memory); the message names the runs that
        did not finish. Finished runs are on disk: the same call resumes.
    """
    plan = plan_sweep(base_path, variations)
    options = _Options(run_fn, workers, scheduler, progress, executor)
    _check_options(options)
    store = SweepStore.open(out_dir)
    outcome = _Outcome(records=store.finished(plan.runs))
    todo = [run for run in plan.runs if run.run_id not in outcome.records]
    skipped = len(plan.runs) - len(todo)
    store.write_table(plan, outcome.records)
    if todo:
        _run_missing(plan, todo, store, outcome, options)
    return _finish(plan, store, outcome, skipped)


def _check_options(options: _Options) -> None:
    """Raise :class:`UserInputError` for a bad ``workers`` or a ``run_fn`` that cannot be pickled."""
    if options.scheduler is None and options.executor is None and options.workers is not None:
        check_workers(options.workers)
    if options.run_fn is not None:
        try:
            pickle.dumps(options.run_fn)
        except Exception:  # noqa: BLE001 - any pickling failure means the same to the user
            raise UserInputError(f"run_fn {options.run_fn!r} cannot be sent to a worker: "
                                 f"give a top-level function") from None


def _run_missing(plan: SweepPlan, todo: Sequence[Run], store: SweepStore, outcome: _Outcome,
                 options: _Options) -> None:
    """Run ``todo`` on the executor into ``store``; fills ``outcome``, rewrites the table as runs come in
    (:func:`_collect`).

    An executor made here is shut down at the end; one passed in is left running (the
    runs it still has are cancelled when this is interrupted).
    """
    from tqdm import tqdm

    executor, own = options.executor, options.executor is None
    if own:
        # No more local processes than runs: each spawned worker pays the imports.
        workers = options.workers if options.scheduler else min(options.workers or default_workers(), len(todo))
        executor = make_executor(workers, options.scheduler, connect_timeout=DASK_CONNECT_TIMEOUT)
    bar = tqdm(total=len(todo), desc="sweep", unit="run", disable=not options.progress)
    futures: dict[cf.Future, Run] = {}
    clean = False
    try:
        submitted = _submit(executor, plan.base_path, todo, options.run_fn, futures)
        if submitted < len(todo):  # a worker died while the runs were being handed out
            outcome.lost.extend(r.run_id for r in todo[submitted:])
            bar.update(len(todo) - submitted)
        _collect(futures, plan, store, outcome, bar)
        clean = True
    finally:
        bar.close()
        if own:
            executor.shutdown(wait=clean, cancel_futures=not clean)
        elif not clean:
            for future in futures:
                future.cancel()


def _submit(executor: cf.Executor, base_path: Path, todo: Sequence[Run], run_fn: Callable | None,
            futures: dict[cf.Future, Run]) -> int:
    """Hand ``todo`` to ``executor`` by value (:class:`~orchestrator.sweeps.store.RunJob`), adding each
    future to ``futures``; returns how many were handed out.

    Fewer than ``len(todo)`` when the executor broke (a worker died) on the way.
    """
    for k, run in enumerate(todo):
        try:
            futures[executor.submit(execute_run, RunJob.of(run, str(base_path)), run_fn)] = run
        except cf.BrokenExecutor:
            return k
    return len(todo)


def _collect(futures: Mapping[cf.Future, Run], plan: SweepPlan, store: SweepStore, outcome: _Outcome,
             bar) -> None:
    """Wait for ``futures`` as they complete; each finished run is saved in ``store`` (by this process:
    workers write nothing there) and goes into ``outcome``; the table is rewritten every
    :data:`TABLE_EVERY` seconds, and here once more when collecting is cut short (an interrupt, a
    failure of this process); after a normal end :func:`_finish` writes it. A run is finished when
    its ``result.json`` is written, so a table a few seconds behind loses nothing."""
    written = time.monotonic()
    try:
        for future in cf.as_completed(futures):
            run = futures[future]
            try:
                output = future.result()
            except Exception as exc:  # noqa: BLE001 - a run's failure must not stop the others
                if lost_worker(exc):
                    outcome.lost.append(run.run_id)
                else:
                    outcome.errors[run.run_id] = _one_line_error(exc)
            else:
                outcome.records[run.run_id] = store.save(output)
            if time.monotonic() - written >= TABLE_EVERY:
                store.write_table(plan, outcome.records)
                written = time.monotonic()
            bar.update(1)
    except BaseException:   # cut short: the table as far as it got (after a normal end _finish writes it)
        store.write_table(plan, outcome.records)
        raise


def _finish(plan: SweepPlan, store: SweepStore, outcome: _Outcome, skipped: int) -> SweepResult:
    """Write the final table and the plots; the :class:`SweepResult`, or :class:`SweepIncomplete` if runs were lost."""
    rows = store.write_table(plan, outcome.records)
    plots = tuple(plot_sweep(rows, plan.varied_keys, store.out_dir))
    order = {run.run_id: run.index for run in plan.runs}
    errors = {run_id: outcome.errors[run_id] for run_id in sorted(outcome.errors, key=order.__getitem__)}  # grid order
    lost = sorted(outcome.lost, key=order.__getitem__)
    unfinished = tuple(sorted([*errors, *lost], key=order.__getitem__))
    result = SweepResult(rows=rows, varied_keys=plan.varied_keys, out_dir=store.out_dir, table=store.table,
                         runs_dir=store.runs_dir, plots=plots, done=len(outcome.records) - skipped,
                         skipped=skipped, failed=len(errors), errors=errors, unfinished=unfinished)
    if lost:
        raise SweepIncomplete(
            f"a worker process died (killed or out of memory): {len(lost)} of {len(plan.runs)} runs did not "
            f"finish ({_ids(lost)}); the {len(rows)} finished runs are saved in {store.runs_dir} and {store.table}: "
            f"run the same command again to do only the missing runs", result)
    return result
