"""The resumable on-disk store of a sweep, and the one run a worker does into it.

Store (everything under ``OUT``)::

    OUT/runs/<run_id>/result.json   the run is finished iff this file exists
    OUT/runs/<run_id>/...           whatever the run function writes (arrays, ...)
    OUT/sweep.csv                   one row per finished run, in grid order (rewritten every few
                                    seconds while a sweep runs, and at its end)
    OUT/sweep_<scalar>.png          each returned scalar against the first varied key
                                    (:func:`orchestrator.sweeps.sweep.plot_sweep`)

Run ids come from :func:`orchestrator.sweeps.plan.plan_sweep`. On (re)start
finished runs are skipped; any other run is done from scratch (its folder is
emptied first, so no file of a killed attempt survives). ``result.json`` and
``sweep.csv`` are written atomically (temporary file in the same folder, then
``os.replace``), so a killed sweep never leaves half a file behind.

Only the client touches the store. A worker gets a :class:`RunJob`: the run's scenario
by value (raw scenario and the files it names,
:class:`orchestrator.cosim.portable.PortableScenario`) and its id, never a path of the
client (its working folder and file system may be another machine's). It runs in a
fresh folder of its own temporary space (:func:`execute_run`) and returns a
:class:`RunOutput`: the record (the returned scalars) and the bytes of every file the
run function wrote. The client writes them into ``OUT/runs/<run_id>/``,
``result.json`` last (:meth:`SweepStore.save`). The local and the Dask path run
identical code.
"""
from __future__ import annotations

import json
import numbers
import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from orchestrator.cosim.portable import PortableScenario
from orchestrator.cosim.scratch import scratch_dir
from orchestrator.sweeps.plan import Run, SweepPlan

__all__ = ["SweepStore", "RunJob", "RunOutput", "execute_run", "read_record", "table_rows", "cell_text",
           "write_table"]

RUNS_DIR = "runs"  # OUT/runs/<run_id>/: one folder per run
RESULT_FILE = "result.json"  # its presence marks a finished run
WORK_PREFIX = "turnout-run-"  # a worker's run folder: <its temp folder>/turnout-run-<pid>-<host>-XXXX/<run_id>
TABLE_FILE = "sweep.csv"
INDEX_COLUMN, ID_COLUMN = "index", "run_id"  # the first two columns of sweep.csv


@dataclass(frozen=True)
class SweepStore:
    """The store under ``out_dir`` (layout in the module docstring).

    Attributes
    ----------
    out_dir : Path
        ``OUT``.
    """

    out_dir: Path

    @classmethod
    def open(cls, out_dir: str | os.PathLike) -> SweepStore:
        """The store under ``out_dir``; creates ``OUT/runs`` if needed."""
        store = cls(Path(out_dir))
        store.runs_dir.mkdir(parents=True, exist_ok=True)
        return store

    @property
    def runs_dir(self) -> Path:
        """``OUT/runs``."""
        return self.out_dir / RUNS_DIR

    @property
    def table(self) -> Path:
        """``OUT/sweep.csv``."""
        return self.out_dir / TABLE_FILE

    def run_dir(self, run_id: str) -> Path:
        """``OUT/runs/<run_id>``."""
        return self.runs_dir / run_id

    def record(self, run_id: str) -> dict | None:
        """The finished run's record (its ``result.json``), or ``None``: see :func:`read_record`."""
        return read_record(self.run_dir(run_id) / RESULT_FILE)

    def finished(self, runs: Sequence[Run]) -> dict[str, dict]:
        """run id -> record of those of ``runs`` that are finished on disk."""
        records: dict[str, dict] = {}
        for run in runs:
            record = self.record(run.run_id)
            if record is not None:
                records[run.run_id] = record
        return records

    def save(self, output: RunOutput) -> dict:
        """Write a finished run a worker returned into ``OUT/runs/<run_id>/``; returns its record.

        The folder is emptied first (files of a killed attempt); the run's files are
        written, then ``result.json`` (atomically, last: a sweep killed in between leaves
        the run unfinished, to be redone).
        """
        run_id = output.record["run_id"]
        folder = self.run_dir(run_id)
        if folder.exists():
            shutil.rmtree(folder)
        folder.mkdir(parents=True)
        for name, data in output.files.items():
            path = folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        _write_atomic(folder / RESULT_FILE, json.dumps(output.record, indent=1))
        return output.record

    def write_table(self, plan: SweepPlan, records: Mapping[str, dict]) -> list[dict]:
        """Write ``OUT/sweep.csv`` from the finished runs' ``records``; returns its rows (:func:`table_rows`)."""
        rows = table_rows(plan, records)
        write_table(rows, self.table)
        return rows


# --------------------------------------------------------------------------------------
# One run (executed in a worker: values in, values out)
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


@dataclass(frozen=True)
class RunJob:
    """What a worker gets for one run: nothing but values (module docstring).

    Attributes
    ----------
    scenario : PortableScenario
        The run's scenario and the files it names.
    run_id : str
    index : int
        Its position in the sweep.
    overrides : tuple of str
        Its ``key.path=value`` texts (kept in its record).
    """

    scenario: PortableScenario
    run_id: str
    index: int
    overrides: tuple

    @classmethod
    def of(cls, run: Run, source: str) -> RunJob:
        """The job of ``run`` of a sweep of the scenario file ``source`` (its files are read now)."""
        return cls(PortableScenario.of(run.raw, source), run.run_id, run.index, tuple(run.overrides))


@dataclass(frozen=True)
class RunOutput:
    """What a worker returns for one finished run.

    Attributes
    ----------
    record : dict
        ``run_id``, ``index``, ``overrides`` and ``result`` (name -> JSON scalar): ``result.json``.
    files : dict
        Path relative to the run folder (POSIX text) -> bytes of each file the run function wrote.
    """

    record: dict
    files: dict


def execute_run(job: RunJob, run_fn: Callable | None) -> RunOutput:
    """Do one run in a worker, in a fresh folder of its temporary space; returns the record and the files.

    ``run_fn(scenario, run_dir)`` gets that folder; everything it writes there comes back
    in the :class:`RunOutput` and the folder is removed.
    """
    if run_fn is None:
        from orchestrator.sweeps.study import (
            run_case as run_fn,  # imported here: tests and other studies pass their own
        )
    scenario = job.scenario.scenario()
    with scratch_dir("run") as work:   # named by its process: a killed worker's is removed later
        folder = Path(work) / job.run_id
        folder.mkdir()
        returned = run_fn(scenario, folder)
        if not isinstance(returned, Mapping):
            raise TypeError(f"the run function must return a mapping name -> scalar, got {type(returned).__name__}")
        files = {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
    scalars = {str(k): s for k, v in returned.items() if (s := _scalar(v)) is not None}
    record = {"run_id": job.run_id, "index": job.index, "overrides": list(job.overrides), "result": scalars}
    return RunOutput(record, files)


def read_record(path: Path) -> dict | None:
    """The record in ``OUT/runs/<run_id>/result.json``, or ``None`` when absent, unreadable or another run's."""
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    ok = isinstance(record, dict) and isinstance(record.get("result"), dict) and \
        record.get("run_id") == path.parent.name
    return record if ok else None


# --------------------------------------------------------------------------------------
# Table
# --------------------------------------------------------------------------------------
def table_rows(plan: SweepPlan, records: Mapping[str, dict]) -> list[dict]:
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


def cell_text(value: Any) -> str:
    """``value`` as a CSV cell: empty for ``None``, floats read back exactly, other non-strings as JSON."""
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
        writer.writerow([cell_text(row.get(c)) for c in columns])
    path = Path(path)
    _write_atomic(path, buffer.getvalue())
    return path
