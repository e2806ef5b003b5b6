"""Co-simulation speed (issue: co-simulation): the default scenario through the FMUs.

Prints and appends to benchmarks/RESULTS.md:
- the default scenario (1:12 crossing panel, bogie, 120 km/h, as in
  scenarios/crossing_1_12_through_120.yaml) through the FMUs and in-process: wall
  time of the stepping loop, real-time factor, dofs, steps;
- one simulated second: the same scenario on a panel long enough for 1 s at
  120 km/h (64 sleepers, transition sleeper 33);
- the FMU backend / in-process ratio;
- our orchestrator vs libcosim on the same FMUs (Jacobi, same step), when
  libcosimpy is installed.

Run: python benchmarks/bench_cosim.py [--quick]
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import tempfile
import time
from pathlib import Path

from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
ONE_SECOND = ["track.layout.sleepers=64", "track.layout.transition_sleeper=33", "simulation.duration=1.0"]


def machine() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def timed(scenario, backend, fmu_dir, algorithm=None):
    res = run_cosim(scenario, backend=backend, fmu_dir=fmu_dir, record_states=False, algorithm=algorithm)
    assert res.error is None, res.error
    s = res.stats
    return {"loop": s["wall_loop"], "total": s["wall_total"], "steps": s["steps"], "simulated": res.t[-1],
            "peak": float(res.Fz[1:].max())}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="0.05 s runs only (smoke test)")
    ap.add_argument("--libcosim-only", action="store_true", help="only the libcosim comparison")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        cases = [] if args.libcosim_only else [("default scenario", [])]
        if not args.quick and not args.libcosim_only:
            cases.append(("1 s simulated (64-sleeper panel)", ONE_SECOND))
        for label, over in cases:
            if args.quick:
                over = over + ["simulation.duration=0.05"]
            sc = load_scenario(DEFAULT, over)
            from orchestrator.cosim.build_job import build_fmus
            fmu_dir = Path(tmp) / label.replace(" ", "_")
            build_fmus(sc, fmu_dir)
            from track.model import build_track
            n = build_track(sc.track).n
            for backend in ("fmu", "inprocess"):
                r = timed(sc, backend, fmu_dir)
                rows.append((label, backend, sc.simulation.step, r["steps"], r["simulated"], n, r["loop"],
                             r["total"], r["loop"] / r["simulated"], r["peak"]))
                print(rows[-1])
    lines = ["| case | backend | step [s] | steps | simulated [s] | reduced dofs | loop wall [s] | total wall [s] "
             "| real-time factor (wall/simulated) | peak Fz [N] |", "|" + "---|" * 10]
    for r in rows:
        lines.append(f"| {r[0]} | {r[1]} | {r[2]:g} | {r[3]} | {r[4]:.3f} | {r[5]} | {r[6]:.2f} | {r[7]:.2f} | "
                     f"{r[8]:.1f} | {r[9]:.0f} |")
    # our orchestrator vs libcosim: the same FMUs (the exported SSP), Jacobi, same step
    lib = None
    try:
        import libcosimpy  # noqa: F401
        lib = True
    except ImportError:
        print("libcosimpy not installed: the libcosim comparison is skipped")
    if lib:
        from orchestrator.cosim.ssp import export_ssp, run_ssp_libcosim
        over = ["simulation.algorithm=jacobi"] + (["simulation.duration=0.05"] if args.quick else [])
        sc = load_scenario(DEFAULT, over)
        with tempfile.TemporaryDirectory() as tmp:
            ssp = export_ssp(sc, Path(tmp) / "system.ssp")
            t0 = time.perf_counter()
            out = run_ssp_libcosim(ssp, sc.simulation.step, sc.simulation.duration, ["track.wheel1_Fz"],
                                   output_every=sc.simulation.output_every)
            t_lib = time.perf_counter() - t0
            fmu_dir = Path(tmp) / "fmus"
            from orchestrator.cosim.build_job import build_fmus
            build_fmus(sc, fmu_dir)
            t0 = time.perf_counter()
            r = run_cosim(sc, backend="fmu", fmu_dir=fmu_dir, record_states=False)
            t_our = time.perf_counter() - t0
        peak_lib, peak_our = float(out["track.wheel1_Fz"].max()), float(r.Fz[:, 0].max())
        rows_lib = (f"\nlibcosim vs our orchestrator, default scenario, jacobi, step {sc.simulation.step:g} s: "
                    f"libcosim {t_lib:.2f} s wall (incl. loading), ours {t_our:.2f} s (incl. instantiation); "
                    f"ratio ours/libcosim {t_our / t_lib:.2f}; peak wheel-1 force libcosim {peak_lib:.1f} N, "
                    f"ours {peak_our:.1f} N")
        print(rows_lib)
    by = {(r[0], r[1]): r for r in rows}
    for label, _ in cases:
        if (label, "fmu") in by and (label, "inprocess") in by:
            lines.append(f"\nFMU / in-process loop time, {label}: "
                         f"{by[(label, 'fmu')][6] / by[(label, 'inprocess')][6]:.2f}")
    if lib:
        lines.append(rows_lib)
    text = "\n".join(lines)
    print(text)
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    with (Path(__file__).with_name("RESULTS.md")).open("a") as f:
        f.write(f"\n## Co-simulation speed — {stamp}, {machine()}\n\n`python benchmarks/bench_cosim.py"
                f"{' --quick' if args.quick else ''}` (target: 1 s simulated via FMUs <= 10 s; "
                f"FMU/in-process <= 1.5)\n\n{text}\n")


if __name__ == "__main__":
    main()
