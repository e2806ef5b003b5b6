"""`turnout run` of the default scenario as a user runs it: whole-process wall, peak memory, output size.

Runs ``turnout run scenarios/crossing_1_12_through_120.yaml`` as a subprocess, once per
backend (``fmu``, ``inprocess``; ``--save-states`` adds a run with the states), and prints
for each: whole-process wall time [s], peak resident memory of the child [MB]
(``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss``, measured in a fresh helper process per
run so one run's peak does not hide the next), the results folder's size [MB] (and
results.h5's), and summary.json's phase walls and counters.

Targets (issue "Speed and footprint", items 4-5): whole process <= 3 s, peak <= 300 MB,
results folder <= 20 MB. Usage: ``.venv/bin/python benchmarks/bench_run.py [--save-states]``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
MB = 1024.0 ** 2

# A fresh interpreter per run: it runs `turnout run` as its child and reports the child's
# wall time and peak RSS (ru_maxrss of RUSAGE_CHILDREN is in kB on Linux).
_MEASURE = """
import json, resource, subprocess, sys, time
t = time.perf_counter()
rc = subprocess.run(sys.argv[1:], stdout=subprocess.DEVNULL).returncode
wall = time.perf_counter() - t
print(json.dumps({"rc": rc, "wall": wall,
                  "peak_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0}))
"""


def folder_size(path: Path) -> int:
    """Total size of the files under ``path`` [bytes]."""
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def measure(backend: str, out: Path, save_states: bool) -> dict:
    """One `turnout run` in a subprocess; its figures (see the module docstring)."""
    cmd = [sys.executable, "-m", "orchestrator.cli", "run", str(SCENARIO), "--out", str(out),
           "--no-progress", "--backend", backend] + (["--save-states"] if save_states else [])
    got = subprocess.run([sys.executable, "-c", _MEASURE, *cmd], capture_output=True, text=True, check=True,
                         cwd=ROOT)
    fig = json.loads(got.stdout.strip().splitlines()[-1])
    if fig["rc"] != 0:
        raise SystemExit(f"turnout run ({backend}) exited with {fig['rc']}")
    summary = json.loads((out / "summary.json").read_text())
    fig.update(folder_mb=folder_size(out) / MB, h5_mb=(out / "results.h5").stat().st_size / MB,
               record_left=any(out.rglob("track_record*")), counters=summary.get("counters", {}),
               job_total=summary["wall_seconds"].get("job_total"))
    return fig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save-states", action="store_true", help="also measure runs with --save-states")
    args = ap.parse_args()
    cases = [(b, False) for b in ("fmu", "inprocess")] + ([("fmu", True)] if args.save_states else [])
    if os.environ.get("PYTHONDONTWRITEBYTECODE"):   # README "Notes / known limitations"
        print("note: PYTHONDONTWRITEBYTECODE is set: each run compiles the checkout's modules again "
              "(~0.1 s that a Python keeping its bytecode does not pay)")
    with tempfile.TemporaryDirectory(prefix="bench_run_") as tmp:
        for backend, states in cases:
            fig = measure(backend, Path(tmp) / f"{backend}{'_states' if states else ''}", states)
            c = fig["counters"]
            phases = {k: c.get(k) for k in ("wall_setup", "wall_build", "wall_initialize", "wall_statics",
                                            "wall_factor", "wall_loop", "wall_finish", "wall_post_processing",
                                            "wall_writing")}
            print(f"turnout run --backend {backend}{' --save-states' if states else ''}: "
                  f"wall {fig['wall']:.2f} s (job {fig['job_total']:.2f} s), peak RSS {fig['peak_mb']:.0f} MB, "
                  f"results folder {fig['folder_mb']:.1f} MB (results.h5 {fig['h5_mb']:.1f} MB), "
                  f"track record left behind: {fig['record_left']}")
            print("  phases [s]: " + ", ".join(f"{k[5:]} {v:.2f}" for k, v in phases.items() if v is not None))
            print("  counters: " + ", ".join(f"{k} {c.get(k)}" for k in ("steps", "track_steps", "linear_solves",
                                                                         "contact_iterations", "factorizations")))


if __name__ == "__main__":
    main()
