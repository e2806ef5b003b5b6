"""Parallel efficiency of a sweep's local workers (issue "Speed and footprint", items 2 and 3).

A fixed batch of short runs of the measurement scenario (quarter vehicle over the 1:12
crossing; ``--runs`` speeds around 120 km/h, the study's run function
``orchestrator.sweeps.study.run_case``) is run as a sweep (``run_sweep``: runs and results
by value, one BLAS thread per worker) with 1, 2, ... up to the machine's cores worker
processes, each count in a fresh output folder. Two times per worker count N:

- *runs*: the batch on a fresh executor (``make_executor`` + ``execute_run`` of each run's
  ``RunJob``): spawning the workers, their imports and first model build included;
- *sweep*: the whole ``run_sweep`` (plan and validation, the runs, writing the results,
  the table and the plots ``sweep_<scalar>.png``, which the client draws serially).

Printed per N: wall times T_N [s], runs/s, speed-up T_1 / T_N and parallel efficiency
T_1 / (N T_N) of both, and the load average after (other processes on the machine lower
the efficiency: say so when recording).

Run: python benchmarks/bench_scaling_workers.py [--runs 12] [--max-workers N] [--threads 1]
(``--threads``: BLAS threads per worker, ``TURNOUT_WORKER_THREADS``); record the printed table
in benchmarks/RESULTS.md.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from orchestrator.inputs.scenario import bundled_scenario
from orchestrator.sweeps.executors import make_executor
from orchestrator.sweeps.plan import plan_sweep
from orchestrator.sweeps.store import RunJob, execute_run
from orchestrator.sweeps.sweep import run_sweep
from orchestrator.sweeps.workers import THREADS_ENV, default_workers

SCENARIO = "measurement/crossing_quarter_120.yaml"
SPEED_RANGE = (28.0, 39.0)  # m/s: the batch's speeds, evenly spread (about 100 ... 140 km/h)


def batch(runs: int) -> list[dict]:
    """The sweep's variations: ``runs`` speeds [m/s] in :data:`SPEED_RANGE`."""
    return [{"vehicle.speed": round(float(v), 3)} for v in np.linspace(*SPEED_RANGE, runs)]


def timed_runs(workers: int, variations: list[dict]) -> float:
    """Wall time [s] of the runs of ``variations`` on a fresh executor of ``workers`` local processes."""
    path = bundled_scenario(SCENARIO)
    jobs = [RunJob.of(run, str(path)) for run in plan_sweep(path, variations).runs]
    t0 = time.perf_counter()
    executor = make_executor(workers, None)
    try:
        outputs = [f.result() for f in [executor.submit(execute_run, job, None) for job in jobs]]
    finally:
        executor.shutdown()
    wall = time.perf_counter() - t0
    assert len(outputs) == len(jobs)
    return wall


def timed_sweep(workers: int, variations: list[dict], tmp: Path) -> float:
    """Wall time [s] of the sweep of ``variations`` on ``workers`` local processes (a fresh folder)."""
    out = tmp / f"w{workers}"
    t0 = time.perf_counter()
    res = run_sweep(bundled_scenario(SCENARIO), variations, out, workers=workers, progress=False)
    wall = time.perf_counter() - t0
    if res.done != len(variations):
        raise RuntimeError(f"{workers} workers: {res.summary()}")
    return wall


def _cells(n: int, runs: int, t1: float, tn: float) -> str:
    """``T_N | runs/s | speed-up | efficiency`` table cells."""
    return f"{tn:.1f} | {runs / tn:.2f} | {t1 / tn:.2f} | {t1 / (n * tn):.2f}"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=12, help="runs in the batch (default 12)")
    ap.add_argument("--max-workers", type=int, default=default_workers(),
                    help="largest worker count (default: this machine's cores)")
    ap.add_argument("--threads", type=int, default=None, help=f"BLAS threads per worker (sets {THREADS_ENV})")
    args = ap.parse_args()
    if args.threads is not None:
        os.environ[THREADS_ENV] = str(args.threads)
    variations = batch(args.runs)
    rows, runs, sweeps = [], {}, {}
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        timed_sweep(1, variations[:1], Path(tmp) / "warm")  # numba's cache and the body caches warm up once
        for n in range(1, args.max_workers + 1):
            runs[n] = timed_runs(n, variations)
            sweeps[n] = timed_sweep(n, variations, Path(tmp))
            rows.append(f"| {n} | {_cells(n, args.runs, runs[1], runs[n])} | "
                        f"{_cells(n, args.runs, sweeps[1], sweeps[n])} | {os.getloadavg()[0]:.1f} |")
            print(rows[-1], flush=True)
    threads = os.environ.get(THREADS_ENV, "1")
    text = "\n".join([
        f"{args.runs} runs of `{SCENARIO}` (speeds {SPEED_RANGE[0]:g}-{SPEED_RANGE[1]:g} m/s, `run_case`), "
        f"{threads} BLAS thread(s) per worker; load average {load0:.1f} before the first sweep",
        "",
        "| workers N | runs: T_N [s] | runs/s | speed-up | efficiency T_1/(N T_N) "
        "| sweep: T_N [s] | runs/s | speed-up | efficiency | load average after |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *rows,
    ])
    print()
    print(text)


if __name__ == "__main__":
    main()
