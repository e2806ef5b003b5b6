"""`turnout diagnose`: wall time on the default scenario, and the hidden-effect confusion matrix.

Two parts (issue: measurement loop):

1. ``--part time``: a synthetic passage of the *default* scenario
   (scenarios/crossing_1_12_through_120.yaml: bogie, 120 km/h, 0.5 s, default sensor
   layout) with a hidden void, diagnosed with 2 local workers; prints the wall time,
   the number of runs and what was found.
2. ``--part confusion``: many seeded hidden effects (every kind of
   :data:`orchestrator.inverse.synthetic.HIDDEN_KINDS` and ``none``) on the measurement scenario
   (scenarios/measurement/crossing_quarter_120.yaml); prints the confusion matrix
   (true kind x named cause), the share with the right sleeper (exact or within an
   ambiguity set of <= 2) and the gains.

Both append a dated section to benchmarks/RESULTS.md.

Run: python benchmarks/bench_diagnose.py [--part time|confusion|all] [--seeds N]
"""
from __future__ import annotations

import argparse
import datetime
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from orchestrator.inputs.scenario import bundled_scenario, load_scenario
from orchestrator.inverse.diagnose import diagnose
from orchestrator.inverse.fieldlike import instrumented_sleepers
from orchestrator.inverse.synthetic import HIDDEN_KINDS, hidden_effect, synthesize


def _label(kind: str, effect) -> str:
    return "rail_pad_stiffness@sleeper" if kind == "rail_pad_stiffness_local" else effect.cause


def _named_label(named: dict) -> str:
    if named["cause"] == "rail_pad_stiffness" and "sleeper" in named:
        return "rail_pad_stiffness@sleeper"
    return named["cause"]


def part_time(workers: int) -> str:
    path = bundled_scenario("crossing_1_12_through_120.yaml")
    sc = load_scenario(path)
    effect = hidden_effect(7, "ballast_void", instrumented_sleepers(sc))
    with tempfile.TemporaryDirectory() as tmp:
        synthesize(sc, effect, Path(tmp) / "passage.csv", seed=7)
        t0 = time.perf_counter()
        res = diagnose(path, Path(tmp) / "passage.csv", Path(tmp) / "out", workers=workers, progress=False).to_json()
        wall = time.perf_counter() - t0
    named = res["named_cause"]
    return (f"default scenario (bogie, 0.5 s at 1e-4 s), hidden void at sleeper {effect.sleeper} "
            f"(peak {1e3 * max(effect.parameters['gaps']):.2f} mm): `turnout diagnose` {wall:.0f} s wall, "
            f"{res['runs']} runs, {workers} workers; named {named['cause']} at sleeper {named.get('sleeper')}, "
            f"gain {100 * res['gain']['total']:.1f} %")


def confusion_rows(seeds: int, workers: int) -> list[tuple]:
    """(true label, named label, sleeper right, gain) of ``seeds`` hidden effects per kind."""
    path = bundled_scenario("measurement/crossing_quarter_120.yaml")
    sc = load_scenario(path)
    sleepers = instrumented_sleepers(sc)
    kinds = ("none",) + HIDDEN_KINDS
    rows = []
    for kind in kinds:
        for k in range(seeds):
            seed = 5000 + 97 * k + kinds.index(kind)
            effect = hidden_effect(seed, kind, sleepers)
            with tempfile.TemporaryDirectory() as tmp:
                synthesize(sc, effect, Path(tmp) / "p.csv", seed=seed)
                res = diagnose(path, Path(tmp) / "p.csv", Path(tmp) / "out", workers=workers,
                               progress=False).to_json()
            named = res["named_cause"]
            ok_sleeper = effect.sleeper is None or (
                named["cause"] == effect.cause and effect.sleeper in named["ambiguity"]["sleepers"]
                and len(named["ambiguity"]["sleepers"]) <= 2)
            rows.append((_label(kind, effect), _named_label(named), ok_sleeper, res["gain"]["total"]))
            print(rows[-1], flush=True)
    return rows


def part_confusion(seeds: int, workers: int) -> str:
    t0 = time.perf_counter()
    rows = confusion_rows(seeds, workers)
    wall = time.perf_counter() - t0
    labels = sorted({r[0] for r in rows} | {r[1] for r in rows})
    lines = ["| true \\ named | " + " | ".join(labels) + " |", "|---|" + "---|" * len(labels)]
    for t in labels:
        if any(r[0] == t for r in rows):
            lines.append(f"| {t} | " + " | ".join(str(sum(1 for r in rows if r[0] == t and r[1] == n))
                                                  for n in labels) + " |")
    right = sum(r[0] == r[1] for r in rows)
    gains = [r[3] for r in rows if r[0] != "none" and r[0] == r[1]]
    return ("\n".join(lines) + f"\n\n{len(rows)} diagnoses ({seeds} seeds per kind) in {wall / 60:.1f} min; "
            f"cause right in {right}/{len(rows)}; sleeper right (exact or ambiguity set <= 2) in "
            f"{sum(r[2] for r in rows)}/{len(rows)}; gain of the right effect causes: min "
            f"{100 * min(gains):.1f} %, median {100 * float(np.median(gains)):.1f} %"
            if gains else "\n".join(lines))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--part", choices=("time", "confusion", "all"), default="all")
    ap.add_argument("--seeds", type=int, default=3, help="seeds per effect kind in the confusion study")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    parts = []
    if args.part in ("time", "all"):
        parts.append(("turnout diagnose wall time", part_time(args.workers)))
    if args.part in ("confusion", "all"):
        parts.append(("hidden-effect confusion matrix", part_confusion(args.seeds, args.workers)))
    with Path(__file__).with_name("RESULTS.md").open("a") as f:
        for title, text in parts:
            print(text)
            f.write(f"\n## Diagnosis: {title} — {stamp}, {machine}\n\n"
                    f"`python benchmarks/bench_diagnose.py --part {args.part}`\n\n{text}\n")


if __name__ == "__main__":
    main()
