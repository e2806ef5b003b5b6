"""The full surrogate calibration of seed 000's 8 parameters (issue 4, item 5; DESIGN.md §5).

A synthetic measurement of the measurement scenario (quarter vehicle over the 1:12
crossing, 120 km/h; default sensor layout) is made with hidden parameters: a ballast void
under the crossing transition sleeper (6 gaps), the ballast stiffness scale h1 and the
rail-pad stiffness scale h2, 1 % noise (synthetic.DEFAULT_NOISE). ``orchestrator.inverse.calibrate.calibrate`` then runs
500 + 500 + 2^8 = 1256 simulations on 2 local worker processes (target: <= 30 min), the
confirmation runs and the least-squares polish. Printed and appended to
benchmarks/RESULTS.md: wall time (and the polish's share), runs/s, CV errors, recovered vs
true parameters (at the surrogate optimum and calibrated), the objective.

With ``--scaling`` the same calibration runs with 1, 2, ... up to the machine's cores workers,
and the wall time, speed-up and parallel efficiency T_1 / (N T_N) of each count are printed
and recorded (issue "Speed and footprint").

Run: python benchmarks/bench_calibrate.py [--out DIR] [--workers 2 | --scaling] [--n1 500] [--n2 500]
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from orchestrator.inputs.scenario import bundled_scenario, load_scenario, scenario_from_dict
from orchestrator.inverse import calibrate as cal
from orchestrator.inverse.synthetic import Effect, synthesize

SCENARIO = "measurement/crossing_quarter_120.yaml"
# Hidden truth: a void hump under the transition sleeper (0-0.9 mm, inside seed 000's 0-2.3 mm),
# a softer bed and stiffer pads. The field end keeps contact, so every pressure cell sees load.
TRUTH_GAPS = (0.30e-3, 0.70e-3, 0.90e-3, 0.60e-3, 0.25e-3, 0.05e-3)  # m
TRUTH_H1, TRUTH_H2 = 0.7, 1.8
NOISE_SEED = 3


def make_measurement(path: Path) -> dict:
    """Write the synthetic measurement; returns the truth {parameter name: value}."""
    base_path = bundled_scenario(SCENARIO)
    base = load_scenario(base_path)
    params = cal.parse_params(None, base)
    truth = dict(zip([p.name for p in params], [*TRUTH_GAPS, TRUTH_H1, TRUTH_H2]))
    raw = cal.apply_values(base.raw, [p for p in params if p.name in ("h1", "h2")], [TRUTH_H1, TRUTH_H2])
    scenario = scenario_from_dict(raw, source=str(base_path), base_dir=base_path.parent)
    sleeper = params[0].sleeper
    synthesize(scenario, Effect("ballast_void", sleeper, {"gaps": list(TRUTH_GAPS)}), path, seed=NOISE_SEED)
    return truth


def calibrate_once(measured: Path, out: Path, workers: int, n1: int, n2: int):
    """One calibration of ``measured`` with ``workers`` local workers: (result, wall [s], load averages)."""
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    res = cal.calibrate(bundled_scenario(SCENARIO), measured, out, n1=n1, n2=n2, workers=workers, progress=False)
    return res, time.perf_counter() - t0, (load0, os.getloadavg()[0])


def scaling(measured: Path, out: Path, n1: int, n2: int, max_workers: int) -> str:
    """The same calibration with 1 .. ``max_workers`` workers: wall, speed-up, parallel efficiency
    T_1 / (N T_N) (issue "Speed and footprint": printed at every count, so a bigger machine shows it)."""
    lines = ["| workers | wall [s] | speed-up | parallel efficiency | load average start / end |", "|---|---|---|---|---|"]
    t1 = None
    for n in range(1, max_workers + 1):
        _, wall, (l0, l1) = calibrate_once(measured, out / f"workers_{n}", n, n1, n2)
        t1 = t1 or wall
        lines.append(f"| {n} | {wall:.0f} | {t1 / wall:.2f} | {100 * t1 / (n * wall):.0f} % | {l0:.1f} / {l1:.1f} |")
        print(lines[-1], flush=True)
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", type=Path, default=None, help="output folder (default: a temporary one)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scaling", action="store_true",
                    help="run the calibration with 1, 2, ... up to the machine's cores workers and record the "
                         "parallel efficiency at each count (instead of one calibration with --workers)")
    ap.add_argument("--n1", type=int, default=500)
    ap.add_argument("--n2", type=int, default=500)
    args = ap.parse_args()
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "calibration"
        out.mkdir(parents=True, exist_ok=True)
        measured = out / "measured.csv"
        truth = make_measurement(measured)
        if args.scaling:
            table = scaling(measured, out, args.n1, args.n2, os.cpu_count() or 1)
            with Path(__file__).with_name("RESULTS.md").open("a") as f:
                f.write(f"\n## Calibration, parallel efficiency per worker count — {stamp}, {machine}\n\n"
                        f"`python benchmarks/bench_calibrate.py --scaling --n1 {args.n1} --n2 {args.n2}`\n\n{table}\n")
            return
        res, wall, (load0, load1) = calibrate_once(measured, out / "result", args.workers, args.n1, args.n2)
        s = res.summary
    pol = s["polish"]
    extra = pol.get("runs", 0) + (s["calibrated"]["source"] == "polish")  # polish runs + the final re-run
    runs = s["runs"]["total"] + 2 + extra  # + the confirmation runs (nominal, optimum)
    rows = []
    for p in res.params:
        t, v, o = truth[p.name], res.values[p.name], s["optimum"]["values"][p.name]
        err = (lambda x: f"{1e3 * (x - t):+.3f} mm") if p.unit == "m" else (lambda x: f"{100 * (x / t - 1):+.1f} %")
        show = (lambda x: f"{1e3 * x:.3f} mm") if p.unit == "m" else (lambda x: f"{x:.4g}")
        b = s["bounds"]["stage2"][p.name]
        rows.append(f"| {p.name} | {show(t)} | {show(o)} ({err(o)}) | {show(v)} | {err(v)} | "
                    f"{show(b[0])} - {show(b[1])} | {100 * s['sensitivity']['share'][p.name]:.1f} % |")
    sur1, sur = s["surrogate_stage1"], s["surrogate"]
    text = "\n".join([
        f"{s['runs']['stage1']} + {s['runs']['stage2_lhs']} + {s['runs']['stage2_corners']} corners = "
        f"{s['runs']['total']} runs (+2 confirmation, +{extra} polish), {args.workers} workers: **{wall:.0f} s wall "
        f"({wall / 60:.1f} min; target <= 30 min)**, {runs / wall:.2f} runs/s; load average "
        f"{load0:.1f} at the start, {load1:.1f} at the end (the machine was shared)",
        "",
        f"CV error of the objective's surrogate ({cal.CV_FOLDS}-fold, RMSE of held-out J / std of J): stage 1 "
        f"{sur1['cv_rmse']:.3g} ({100 * sur1['cv_rel']:.0f} %), all runs {sur['cv_rmse']:.3g} "
        f"({100 * sur['cv_rel']:.0f} %); local (best {100 * cal.LOCAL_SHARE:.0f} % of runs) "
        f"{sur['local_cv_rmse']:.3g}",
        "",
        f"J nominal {s['objective_before']:.4f} -> calibrated {s['objective_after']:.4f} "
        f"({s['calibrated']['source']}); surrogate optimum predicted {s['optimum']['predicted_objective']:.4f}, "
        f"simulated {s['optimum']['confirmed_objective']:.4f}; best run of the design {s['best_run']['objective']:.4f}; "
        f"noise floor of the measurement ~0.015 (1 % noise)",
        "",
        (f"Polish (least squares on real runs): {pol['runs']} runs in {pol['iterations']} parallel sweeps, "
         f"{pol['wall_time_s']:.0f} s of the wall time. Per start: " + "; ".join(
             f"from the {k}: J {v['objective']:.4f}, sum of squared residuals {v['cost_start']:.4g} -> "
             f"{v['cost']:.4g}, {v['runs']} runs" for k, v in pol["starts"].items()) +
         f". Calibrated: the polish from the {pol['start']}" if pol["done"] else "No polish"),
        "",
        "| parameter | true | surrogate optimum (error) | calibrated | error | narrowed bounds | sensitivity share |",
        "|---|---|---|---|---|---|---|",
        *rows,
    ])
    print(text)
    print(json.dumps({k: s[k] for k in ("optimum", "best_run", "polish", "calibrated")}, indent=1))
    with Path(__file__).with_name("RESULTS.md").open("a") as f:
        f.write(f"\n## Calibration, 8 parameters (6 gaps + h1 + h2) — {stamp}, {machine}\n\n"
                f"`python benchmarks/bench_calibrate.py`\n\n{text}\n")


if __name__ == "__main__":
    main()
