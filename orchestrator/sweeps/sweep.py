"""Parameter sweeps: many runs of one scenario, resumable, locally or on a Dask cluster.

A sweep is a base scenario plus a list of variations, each a mapping
``{key.path: value}`` applied as scenario overrides (one run each). The list
comes from a grid (``--vary key=v1,v2,...``, repeatable: the Cartesian product,
:func:`grid_from_vary`) or from a YAML file (``--list FILE.yaml``,
:func:`list_from_file`). Every run's scenario is validated before anything
runs (:func:`plan_sweep`), so a bad key or value stops the sweep at once.

Store (everything under ``OUT``)::

    OUT/runs/<run_id>/result.json   the run is finished iff this file exists
    OUT/runs/<run_id>/...           whatever the run function writes (arrays, ...)
    OUT/sweep.csv                   one row per finished run, in grid order
    OUT/sweep_<scalar>.png          each returned scalar against the first varied key

A run id is a digest of the run's validated scenario (base + overrides), so it
does not depend on the run's position: re-running the same command, reordering
``--vary`` options or adding values reuses every run already finished. On
(re)start finished runs are skipped; any other run is done from scratch (its
folder is emptied first, so no file of a killed attempt survives).
``result.json`` and ``sweep.csv`` are written atomically (temporary file in the
same folder, then ``os.replace``), so a killed worker or a killed sweep never
leaves half a file behind.

Runs go through a :mod:`concurrent.futures` executor (:func:`make_executor`):
local processes (spawned, safe with numpy's BLAS threads) or a Dask cluster.
Workers receive only strings (base path, override texts, run folder) and load
the scenario themselves, so the local and the Dask path run identical code.
"""
from __future__ import annotations

import concurrent.futures as cf
import hashlib
import itertools
import json
import math
import multiprocessing
import numbers
import os
import pickle
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from orchestrator.inputs import keypath
from orchestrator.inputs.errors import ScenarioError, UserInputError
from orchestrator.inputs.scenario import parse_override, read_yaml, scenario_from_dict

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
]

RUNS_DIR = "runs"  # OUT/runs/<run_id>/: one folder per run
RESULT_FILE = "result.json"  # its presence marks a finished run
TABLE_FILE = "sweep.csv"
PLOT_PREFIX = "sweep_"  # OUT/sweep_<scalar>.png
RUN_ID_CHARS = 12  # hex digits of the SHA-1 kept in a run id (48 bits: no collision in any sweep)
RUN_ID_PREFIX = "r"  # run ids start with a letter: safe as folder names and CSV cells
INDEX_COLUMN, ID_COLUMN = "index", "run_id"  # the first two columns of sweep.csv
START_METHOD = "spawn"  # fork with numpy/BLAS threads may deadlock a worker
DASK_CONNECT_TIMEOUT = "30s"  # how long to try to reach a --scheduler address
MAX_IDS_IN_MESSAGE = 8  # run ids listed in an error message before "..."


# --------------------------------------------------------------------------------------
# Variations
# --------------------------------------------------------------------------------------
def _override_key(key: Any, where: str) -> str:
    """Check one variation key (a scenario key path) and return it without blanks."""
    if not isinstance(key, str):
        raise UserInputError(f"{where}: a key must be a scenario key path such as vehicle.speed, got {key!r}")
    key = key.strip()
    parse_override(f"{key}=0")  # raises ScenarioError naming a malformed key path
    return key


def grid_from_vary(texts: Sequence[str]) -> list[dict[str, Any]]:
    """The variations of ``--vary key.path=v1,v2,...`` options: their Cartesian product.

    Parameters
    ----------
    texts : sequence of str
        One ``key.path=v1,v2,...`` per varied key. The values are read as YAML
        (the scenario's rules: ``1e8`` is a number, ``"1:12"`` a string); a value
        may be a flow list or mapping, e.g. ``track.ballast.voids[0].gaps=[0,0,0,0,0,0],[0,1e-3,1e-3,1e-3,1e-3,0]``.

    Returns
    -------
    list of dict
        One ``{key: value}`` per run, in grid order (the last key varies fastest).

    Raises
    ------
    UserInputError
        A text that is not ``key=values``, a value list that is not YAML, a key
        given twice or without values.
    """
    spec: dict[str, list] = {}
    for text in texts:
        if not isinstance(text, str) or "=" not in text:
            raise UserInputError(f"--vary {text!r}: expected key.path=v1,v2,...")
        key, values_text = text.split("=", 1)
        where = f"--vary {text!r}"
        key = _override_key(key, where)
        try:
            _, values = parse_override(f"{key}=[{values_text}]")
        except ScenarioError as exc:
            raise UserInputError(f"{where}: the values are not a comma-separated YAML list ({exc.message})") from None
        if not values:
            raise UserInputError(f"{where}: no values given")
        if key in spec:
            raise UserInputError(f"{where}: {key} is varied twice; give all its values in one --vary")
        spec[key] = values
    return expand_grid(spec)


def expand_grid(spec: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """The Cartesian product of ``{key: values}``: one ``{key: value}`` per run (last key fastest)."""
    keys = list(spec)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(spec[k] for k in keys))]


def list_from_file(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The variations of ``--list FILE.yaml``: a YAML list of mappings ``{key.path: value}``.

    An empty mapping ``{}`` is a run of the base scenario. Keys missing from an
    item keep the base scenario's value.

    Raises
    ------
    UserInputError
        The file is missing, not YAML, or not a non-empty list of mappings.
    """
    data = read_yaml(path)  # ScenarioError (a UserInputError) names the file
    if not isinstance(data, list) or not data:
        raise UserInputError(f"{path}: expected a non-empty YAML list of mappings {{key.path: value}}, one per run")
    runs = []
    for i, item in enumerate(data):
        if item is None:
            item = {}
        if not isinstance(item, Mapping):
            raise UserInputError(f"{path}: item {i}: expected a mapping {{key.path: value}}, got {item!r}")
        runs.append({_override_key(k, f"{path}: item {i}"): v for k, v in item.items()})
    return runs


def _value_text(value: Any) -> str:
    """``value`` as YAML text that the scenario loader reads back to the same value.

    Numbers read from YAML keep their text (so ``rail: 60E1`` stays the string
    "60E1" where a string is expected); anything else is written as JSON, which
    is YAML flow syntax.
    """
    text = getattr(value, "yaml_text", None)
    return text if isinstance(text, str) else json.dumps(value)


def _digest(data: Any) -> str:
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha1(text.encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------
# Plan
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Run:
    """One run of a sweep.

    Attributes
    ----------
    index : int
        Position in the sweep (grid order), from 0.
    run_id : str
        Stable id: a digest of the run's validated scenario; names ``OUT/runs/<run_id>``.
    overrides : tuple of str
        ``key.path=value`` texts applied to the base scenario, in key order.
    values : dict
        Varied key -> the value the run uses (from its validated scenario, so a
        key a list item leaves out shows the base value).
    """

    index: int
    run_id: str
    overrides: tuple[str, ...]
    values: dict


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep: base scenario file, the varied keys and the runs in grid order."""

    base_path: Path
    varied_keys: tuple[str, ...]
    runs: tuple[Run, ...]


def plan_sweep(base_path: str | os.PathLike, variations: Sequence[Mapping[str, Any]]) -> SweepPlan:
    """Validate every run of a sweep and give each its id; nothing runs.

    Parameters
    ----------
    base_path : path-like
        The base scenario YAML.
    variations : sequence of mapping
        One ``{key.path: value}`` per run (:func:`grid_from_vary`, :func:`list_from_file`).

    Raises
    ------
    ScenarioError
        The base scenario or a run's scenario is invalid (names the key and value).
    UserInputError
        No runs, or two runs that are the same scenario.
    """
    base_path = Path(base_path)
    if not variations:
        raise UserInputError("the sweep has no runs: give --vary key=v1,v2,... or --list FILE.yaml")
    data = read_yaml(base_path)
    source, folder = str(base_path), base_path.parent
    scenario_from_dict(data, source=source, base_dir=folder)  # the base alone first: its errors are its own
    varied: dict[str, None] = {}
    for variation in variations:
        varied.update(dict.fromkeys(_override_key(k, "variation") for k in variation))
    runs: list[Run] = []
    seen: dict[str, Run] = {}
    for index, variation in enumerate(variations):
        items = sorted((_override_key(k, f"run {index}"), v) for k, v in variation.items())
        overrides = tuple(f"{k}={_value_text(v)}" for k, v in items)
        # The same call a worker makes (load_scenario = read_yaml + scenario_from_dict).
        raw = scenario_from_dict(data, source=source, overrides=overrides, base_dir=folder).raw
        run_id = RUN_ID_PREFIX + _digest(raw)[:RUN_ID_CHARS]
        run = Run(index, run_id, overrides, {k: keypath.get(raw, k) for k in varied})
        if run_id in seen:
            first = seen[run_id]
            raise UserInputError(f"run {index} ({', '.join(overrides) or 'no overrides'}) is the same scenario as "
                                 f"run {first.index} ({', '.join(first.overrides) or 'no overrides'}); "
                                 f"give each combination once")
        seen[run_id] = run
        runs.append(run)
    return SweepPlan(base_path, tuple(varied), tuple(runs))


# --------------------------------------------------------------------------------------
# Executors
# --------------------------------------------------------------------------------------
class DaskExecutor(cf.Executor):
    """A Dask ``distributed.Client`` seen as a :class:`concurrent.futures.Executor`.

    ``submit`` goes through ``Client.get_executor()`` (whose futures are plain
    ``concurrent.futures`` futures, so ``as_completed`` works unchanged);
    ``shutdown`` also closes the client, which ``ClientExecutor.shutdown`` does not.

    Parameters
    ----------
    address : str
        The scheduler, e.g. ``tcp://127.0.0.1:8786``.
    """

    def __init__(self, address: str):
        try:
            from distributed import Client
        except ImportError:
            raise UserInputError("--scheduler needs Dask: pip install 'dask[distributed]'") from None
        try:
            self._client = Client(address, timeout=DASK_CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise UserInputError(f"--scheduler {address}: cannot connect to a Dask scheduler ({exc})") from None
        # pure=False: every submit is a task of its own (no key deduplication by Dask).
        self._executor = self._client.get_executor(pure=False)

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            self._executor.shutdown(wait=wait and not cancel_futures)
        finally:
            self._client.close()


def make_executor(workers: int, scheduler: str | None) -> cf.Executor:
    """The executor that runs a sweep.

    Parameters
    ----------
    workers : int
        Local worker processes (ignored with ``scheduler``: the cluster has its own).
    scheduler : str or None
        Address of a Dask scheduler (``tcp://host:8786``); ``None`` runs locally.

    Returns
    -------
    concurrent.futures.Executor
        ``ProcessPoolExecutor`` with spawned workers, or a :class:`DaskExecutor`.
    """
    if scheduler:
        return DaskExecutor(scheduler)
    _check_workers(workers)
    return cf.ProcessPoolExecutor(max_workers=int(workers), mp_context=multiprocessing.get_context(START_METHOD))


def _check_workers(workers: Any) -> None:
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        raise UserInputError(f"workers must be an integer >= 1, got {workers!r}")


def _lost_worker(exc: BaseException) -> bool:
    """True when ``exc`` says the worker died (not that the run function failed)."""
    # Dask gives up on a task whose workers keep dying with distributed.scheduler.KilledWorker.
    return isinstance(exc, (cf.BrokenExecutor, cf.CancelledError)) or type(exc).__name__ == "KilledWorker"


# --------------------------------------------------------------------------------------
# One run (executed in a worker)
# --------------------------------------------------------------------------------------
def _scalar(value: Any) -> Any:
    """A JSON scalar for ``value`` (numpy scalars included), or ``None`` for anything else."""
    if isinstance(value, (bool, str)) or value is None:
        return value
    if type(value).__name__ == "bool_":  # numpy.bool_ is not a bool
        return bool(value)
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    return None


def _write_atomic(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old file or the whole new one."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "w", encoding="utf-8", newline="") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _execute(base_path: str, overrides: Sequence[str], run_dir: str, run_id: str, index: int,
             run_fn: Callable | None) -> dict:
    """Do one run in a worker: fresh run folder, scenario, ``run_fn``, ``result.json``; returns the record."""
    from orchestrator.inputs.scenario import load_scenario

    if run_fn is None:
        from orchestrator.sweeps.study import run_case as run_fn  # imported here: tests and other studies pass their own
    folder = Path(run_dir)
    if folder.exists():  # files of an attempt that was killed: start from scratch
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    scenario = load_scenario(base_path, overrides=list(overrides))
    returned = run_fn(scenario, folder)
    if not isinstance(returned, Mapping):
        raise TypeError(f"the run function must return a mapping name -> scalar, got {type(returned).__name__}")
    scalars = {str(k): s for k, v in returned.items() if (s := _scalar(v)) is not None}
    record = {"run_id": run_id, "index": index, "overrides": list(overrides), "result": scalars}
    _write_atomic(folder / RESULT_FILE, json.dumps(record, indent=1))
    return record


def _read_record(path: Path) -> dict | None:
    """The record in ``OUT/runs/<run_id>/result.json``, or ``None`` when absent, unreadable or another run's."""
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ok = isinstance(record, dict) and isinstance(record.get("result"), dict) and \
        record.get("run_id") == path.parent.name
    return record if ok else None


# --------------------------------------------------------------------------------------
# Table and plots
# --------------------------------------------------------------------------------------
def _rows(plan: SweepPlan, records: Mapping[str, dict]) -> list[dict]:
    """One row per finished run, in grid order: index, run id, varied values, returned scalars."""
    rows = []
    for run in plan.runs:
        record = records.get(run.run_id)
        if record is None:
            continue
        row = {INDEX_COLUMN: run.index, ID_COLUMN: run.run_id, **run.values}
        for name, value in record["result"].items():
            row[name if name not in row else f"result.{name}"] = value
        rows.append(row)
    return rows


def _cell(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, str):
        return value
    if isinstance(value, float):
        return repr(value)  # shortest text that reads back to the same float
    return json.dumps(value)  # ints, booleans (true/false), lists, mappings


def write_table(rows: Sequence[Mapping[str, Any]], path: str | os.PathLike) -> Path:
    """Write ``rows`` as CSV (columns in first-seen order; missing cells empty), atomically."""
    import csv
    import io

    columns: dict[str, None] = {}
    for row in rows:
        columns.update(dict.fromkeys(row))
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([_cell(row.get(c)) for c in columns])
    path = Path(path)
    _write_atomic(path, buffer.getvalue())
    return path


def _number(value: Any) -> float | None:
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
                lines.setdefault(tuple(_cell(r.get(k)) for k in others), []).append((_number(r[x_key]), y))
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
# The sweep
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
    shown = ", ".join(ids[:MAX_IDS_IN_MESSAGE])
    return shown + (f", ... ({len(ids)} in all)" if len(ids) > MAX_IDS_IN_MESSAGE else "")


def _one_line_error(exc: BaseException) -> str:
    text = re.sub(r"\s*[\r\n]+\s*", " ", str(exc)).strip()
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def run_sweep(base_path: str | os.PathLike, variations: Sequence[Mapping[str, Any]], out_dir: str | os.PathLike,
              run_fn: Callable | None = None, workers: int = 2, scheduler: str | None = None,
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
        values it returns are left out of the table (write arrays to ``run_dir``).
    workers : int
        Local worker processes (default 2).
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
    if scheduler is None and executor is None:
        _check_workers(workers)
    if run_fn is not None:
        try:
            pickle.dumps(run_fn)
        except Exception:  # noqa: BLE001 - any pickling failure means the same to the user
            raise UserInputError(f"run_fn {run_fn!r} cannot be sent to a worker: give a top-level function") from None
    out_dir = Path(out_dir)
    runs_dir = out_dir / RUNS_DIR
    runs_dir.mkdir(parents=True, exist_ok=True)

    records: dict[str, dict] = {}
    for run in plan.runs:
        record = _read_record(runs_dir / run.run_id / RESULT_FILE)
        if record is not None:
            records[run.run_id] = record
    todo = [run for run in plan.runs if run.run_id not in records]
    skipped = len(plan.runs) - len(todo)
    errors: dict[str, str] = {}
    lost: list[str] = []
    table = out_dir / TABLE_FILE
    write_table(_rows(plan, records), table)

    if todo:
        from tqdm import tqdm

        # No more local processes than runs: each spawned worker pays the imports.
        own = executor is None
        if own:
            executor = make_executor(workers if scheduler else min(workers, len(todo)), scheduler)
        bar = tqdm(total=len(todo), desc="sweep", unit="run", disable=not progress)
        clean = False
        try:
            futures: dict[cf.Future, Run] = {}
            for k, run in enumerate(todo):
                try:
                    futures[executor.submit(_execute, str(plan.base_path), run.overrides,
                                            str(runs_dir / run.run_id), run.run_id, run.index, run_fn)] = run
                except cf.BrokenExecutor:  # a worker died while the runs were being handed out
                    lost.extend(r.run_id for r in todo[k:])
                    bar.update(len(todo) - k)
                    break
            for future in cf.as_completed(futures):
                run = futures[future]
                try:
                    records[run.run_id] = future.result()
                except Exception as exc:  # noqa: BLE001 - a run's failure must not stop the others
                    # A worker that died after writing its result still finished the run.
                    record = _read_record(runs_dir / run.run_id / RESULT_FILE)
                    if record is not None:
                        records[run.run_id] = record
                    elif _lost_worker(exc):
                        lost.append(run.run_id)
                    else:
                        errors[run.run_id] = _one_line_error(exc)
                write_table(_rows(plan, records), table)
                bar.update(1)
            clean = True
        finally:
            bar.close()
            if own:
                executor.shutdown(wait=clean, cancel_futures=not clean)
            elif not clean:
                for future in futures:
                    future.cancel()

    rows = _rows(plan, records)
    write_table(rows, table)
    plots = tuple(plot_sweep(rows, plan.varied_keys, out_dir))
    order = {run.run_id: run.index for run in plan.runs}
    errors = {run_id: errors[run_id] for run_id in sorted(errors, key=order.__getitem__)}  # grid order
    unfinished = tuple(sorted([*errors, *lost], key=order.__getitem__))
    result = SweepResult(rows=rows, varied_keys=plan.varied_keys, out_dir=out_dir, table=table, runs_dir=runs_dir,
                         plots=plots, done=len(records) - skipped, skipped=skipped, failed=len(errors),
                         errors=errors, unfinished=unfinished)
    if lost:
        lost.sort(key=order.__getitem__)
        raise SweepIncomplete(
            f"a worker process died (killed or out of memory): {len(lost)} of {len(plan.runs)} runs did not "
            f"finish ({_ids(lost)}); the {len(rows)} finished runs are saved in {runs_dir} and {table}: "
            f"run the same command again to do only the missing runs", result)
    return result
