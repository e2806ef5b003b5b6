"""How well the diagnosis's noise level matches the noise the field-like chain really added (issue 14).

The diagnosis decides ``none`` vs a cause against a floor: each channel's noise sigma,
estimated from the measured record alone (:func:`orchestrator.inverse.objective.noise_sigma`,
first differences), and J_noise, the objective that noise alone would give
(:func:`orchestrator.inverse.significance.noise_objective`). This benchmark puts that
estimate next to the truth, per channel, on the cases of a ``bench_diagnose_field.py``
folder: the chain's own noise realisation (white + coloured + drift, reconstructed for
displacement channels) from :func:`orchestrator.inverse.detectability.case_detectability`
(the truth with and without the case's effects; no diagnosis is run or consulted).

Printed per sensor type, estimate / true noise RMS (median and 10-90 % range over all
channels of all cases) of two estimators:

* ``record``: first differences of the measured record (what the diagnosis uses);
* ``residual``: first differences of the record minus the case's no-effect truth (the
  case's own model with its mismatch, noise-free) — a stand-in for an estimator on the
  residual of a fitted reference model, which removes the signal's own roughness.

Per case: the true J floor (the chain's noise through the objective's normalisers), the
diagnosis's J_noise, J_noise with the accelerometers' level taken from the residual (the
other channels' from the record, as now), and what group E (the nose accelerometers) makes of each, and, over
the channels that are not reconstructed displacements, the largest ratio of the no-effect
residual's RMS to the true noise (where an effect shows above the noise, channel by
channel) and to the residual's own first-difference level (the statistic of
:func:`orchestrator.inverse.significance.loud_channels`, here on the no-effect truth's
residual rather than a fitted reference's).

Run: python benchmarks/bench_noise_floor.py --out DIR [--record]
(DIR: a folder of ``bench_diagnose_field.py`` whose case folders hold ``case.json``.)
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
from pathlib import Path

import numpy as np

from orchestrator.inputs.scenario import bundled_scenario, load_scenario
from orchestrator.inputs.sensor_layout import layout_of
from orchestrator.inverse.detectability import case_detectability
from orchestrator.inverse.fieldlike import FieldCase
from orchestrator.inverse.objective import noise_sigma, objective_from_channels

SCENARIO = bundled_scenario("measurement/crossing_quarter_120.yaml")   # as bench_diagnose_field.py


def channel_table(case: FieldCase, sc, types: dict) -> dict:
    """Channel id -> scale (std of the record), true noise RMS, the two estimates, no-effect residual RMS."""
    det = case_detectability(sc, case)
    out = {}
    for sid, clean in det.clean.items():
        noise = det.noise[sid]
        record = clean + noise
        residual = record - (clean - det.total.d[sid])          # the record minus the no-effect truth
        out[sid] = {"type": types[sid], "scale": float(np.std(record)), "true": float(np.sqrt(np.mean(noise ** 2))),
                    "record": noise_sigma(record), "residual": noise_sigma(residual),
                    "residual_rms": float(np.sqrt(np.mean(residual ** 2)))}
        out[sid]["mixed"] = out[sid]["residual" if types[sid] == "acceleration" else "record"]
    return out


def j_of(table: dict, key: str, lay, only: str | None = None) -> float:
    """J of per-channel values ``key`` over their normaliser (channels of group ``only``, or all)."""
    nr = {k: v[key] / v["scale"] for k, v in table.items() if v["scale"] > 0 and (only is None or lay.groups[k] == only)}
    return objective_from_channels(nr, lay.groups, lay.weights)[0]


def type_lines(tables: dict) -> list[str]:
    types = sorted({v["type"] for t in tables.values() for v in t.values()})
    out = ["| sensor type | channels | record / true: median [10 %, 90 %] | residual / true: median [10 %, 90 %] |",
           "|---|---|---|---|"]
    for ty in types:
        vals = [v for t in tables.values() for v in t.values() if v["type"] == ty and v["true"] > 0]
        cells = []
        for key in ("record", "residual"):
            r = np.array([v[key] / v["true"] for v in vals])
            cells.append(f"{np.median(r):.2f} [{np.percentile(r, 10):.2f}, {np.percentile(r, 90):.2f}]")
        out.append(f"| {ty} | {len(vals)} | {cells[0]} | {cells[1]} |")
    return out


def case_lines(tables: dict, cases: dict, lay) -> list[str]:
    out = ["| case | effects | true J floor | diagnosis's J_noise | J_noise, accelerometers from the residual | "
           "of which group E (true / est.) | largest residual RMS / true noise | largest residual RMS / its own "
           "first-difference level |", "|---|---|---|---|---|---|---|---|"]
    for name, t in tables.items():
        c = cases[name]
        eff = ", ".join(f"{e.cause}@{e.sleeper}" if e.sleeper is not None else e.cause for e in c.effects) or "none"
        e_true, e_est = (j_of(t, k, lay, "E") / len(lay.weights) for k in ("true", "record"))  # E's share of J
        judged = {k: v for k, v in t.items() if v["type"] != "displacement" and v["true"] > 0 and v["residual"] > 0}
        cells = []
        for key in ("true", "residual"):
            ratios = {k: v["residual_rms"] / v[key] for k, v in judged.items()}
            top = max(ratios, key=ratios.get)
            cells.append(f"{ratios[top]:.1f} ({top})")
        out.append(f"| {name} | {eff} | {j_of(t, 'true', lay):.4f} | {j_of(t, 'record', lay):.4f} | "
                   f"{j_of(t, 'mixed', lay):.4f} | {e_true:.4f} / {e_est:.4f} | {cells[0]} | {cells[1]} |")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", required=True, help="a bench_diagnose_field.py folder (case folders with case.json)")
    ap.add_argument("--record", action="store_true", help="append the tables to benchmarks/RESULTS.md")
    ap.add_argument("--note", default="", help="a line recorded under the command (with --record)")
    args = ap.parse_args()
    sc = load_scenario(SCENARIO)
    lay = layout_of(sc)
    folders = sorted(p.parent for p in Path(args.out).glob("*/case.json"))
    if not folders:
        raise SystemExit(f"{args.out}: no case folder with a case.json")
    cases = {f.name: FieldCase.from_dict(json.loads((f / "case.json").read_text())) for f in folders}
    tables = {}
    for name, case in cases.items():
        if case.chain is None:
            continue
        tables[name] = channel_table(case, sc, lay.types)
        print(f"{name}: done", flush=True)
    text = "\n".join(type_lines(tables) + [""] + case_lines(tables, cases, lay))
    print(text)
    if args.record:
        stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
        machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
        note = f"{args.note}\n\n" if args.note else ""
        with Path(__file__).with_name("RESULTS.md").open("a") as f:
            f.write(f"\n## Noise level of field-like records: the diagnosis's estimate against the chain's noise — "
                    f"{stamp}, {machine}\n\n`python benchmarks/bench_noise_floor.py --out {args.out}`\n\n{note}{text}\n")


if __name__ == "__main__":
    main()
