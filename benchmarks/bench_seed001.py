"""The whole seed-001 study (issue: parameter studies): 6 speeds x 3 impact angles x 2 pads.

Runs `orchestrator.studies.figures.make_figures(study="seed001")` into a fresh folder with 2 local
worker processes (target: <= 15 min on this 2-core machine), prints and appends the wall
time, the number of runs and the figures written to benchmarks/RESULTS.md.

Run: python benchmarks/bench_seed001.py [--out DIR]
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import tempfile
import time
from pathlib import Path

from orchestrator.studies.figures import ANGLES, PADS, SPEEDS_KMH, make_figures


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: a temporary one)")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "figures"
        t0 = time.perf_counter()
        files = make_figures(out, study="seed001", workers=args.workers, progress=False)
        wall = time.perf_counter() - t0
    n = len(SPEEDS_KMH) * len(ANGLES) * len(PADS)
    text = (f"seed-001 study: {n} runs ({len(SPEEDS_KMH)} speeds x {len(ANGLES)} angles x {len(PADS)} pads), "
            f"{args.workers} workers: {wall:.0f} s wall ({wall / 60:.1f} min; target <= 15 min); "
            f"files: {', '.join(p.name for p in files)}")
    print(text)
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    with Path(__file__).with_name("RESULTS.md").open("a") as f:
        f.write(f"\n## Seed-001 study — {stamp}, {machine}\n\n`python benchmarks/bench_seed001.py`\n\n{text}\n")


if __name__ == "__main__":
    main()
