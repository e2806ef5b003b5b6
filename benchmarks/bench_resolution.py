"""Does a ``none`` answer's stated resolution hold? Voids hidden at a multiple of the limit it states.

A ``none`` answer of ``turnout diagnose`` says, per screened candidate, the least effect
that would have lifted the record's residual above the noise
(:mod:`orchestrator.inverse.resolution`, from the screening runs: the reference model's
signature, first order, the nuisance fit not counted). This benchmark checks that claim the
way a user would meet it: on field-like null passages of issue 14's families
(:func:`orchestrator.inverse.fieldlike.draw_case`: another vehicle, speed, damping, time
step, a field sensor chain), for each null passage answered ``none``

1. its stated limit L at each of ``--sleepers`` is read from ``diagnosis.json``: of a uniform
   void (``--hide void``) or of a softer pad (``--hide soft_pad``);
2. the same case (the same truth model, the same chain and its noise seed) is written again
   with that effect at k x L under that sleeper, for each factor k of ``--factors`` (a void's
   gap k x L; a pad's stiffness factor L ** k, k times along the log axis the limit was found
   on) (:func:`orchestrator.inverse.fieldlike.synthesize_case`), and diagnosed, told nothing;
3. each answer is tabulated: ``none`` or *shown* (``named`` or ``unexplained``), and whether
   a named cause is that cause at that sleeper (an ambiguity set holding it counts).

What the limit promises: below it (k < 1) the residual may stay at the noise; from about it
(k >= 1) it should not. The limit is first order and its noise level is the white part
(module doc of :mod:`orchestrator.inverse.resolution`), so it is expected to err large:
effects at k < 1 already shown are the record resolving more than stated; effects at k > 1
answered ``none`` would be the statement claiming a resolution the record does not have.

Printed (and with ``--record`` appended to ``benchmarks/RESULTS.md``): per factor, ``none``
/ shown / named at the right sleeper over the passages, and every row.

Run: python benchmarks/bench_resolution.py [--hide void|soft_pad] [--families null_clean,null_vehicle] [--seeds 2]
     [--sleepers 19,21,24] [--factors 0.5,1,2] [--workers 2] [--out DIR] [--record]
"""
from __future__ import annotations

import argparse
import datetime
import json
import platform
import time
from dataclasses import replace
from pathlib import Path

from bench_diagnose_field import SCENARIO, case_seed, case_setup, read_answer
from orchestrator.inputs.causes import N_GAPS
from orchestrator.inputs.scenario import load_scenario
from orchestrator.inverse.diagnose import diagnose
from orchestrator.inverse.fieldlike import FieldCase, draw_case, synthesize_case
from orchestrator.inverse.synthetic import Effect

# What ``--hide`` hides at k x the stated limit L: (cause, proxy of the limit, the effect's parameters, its
# magnitude's words); a void's gap scales with k, a stiffness factor on its log axis (L ** k: k = 1 is L, the
# axis the limit was found on, as the screening interpolates it)
HIDDEN = {
    "void": ("ballast_void", "uniform", lambda L, k: {"gaps": [k * L] * N_GAPS}, lambda L, k: f"{1e3 * k * L:.3f} mm"),
    "soft_pad": ("rail_pad_stiffness", "softer", lambda L, k: {"stiffness_scale": L ** k}, lambda L, k: f"x{L ** k:.3f}"),
}


def _diagnosed(folder: Path, workers: int) -> dict:
    """``diagnosis.json`` of the passage in ``folder`` (diagnosed once, then read)."""
    path = folder / "out" / "diagnosis.json"
    if not path.is_file():
        diagnose(SCENARIO, folder / "passage.csv", folder / "out", workers=workers, progress=False)
    return json.loads(path.read_text())


def _limit(res: dict, cause: str, proxy: str, sleeper: int) -> float | None:
    """The stated limit of ``cause`` (its ``proxy``) at ``sleeper`` (None: not resolved, or not screened)."""
    for r in res["answer"].get("resolution") or []:
        if r["cause"] == cause and r["sleeper"] == sleeper and r["proxy"] == proxy:
            return r["limit"]
    return None


def _row(case: FieldCase, hide: str, sleeper: int, k: float, limit: float, res: dict) -> dict:
    cause, _, _, words = HIDDEN[hide]
    ans = read_answer(res)
    named_here = any(c["cause"] == cause and (c.get("sleeper") == sleeper or sleeper in c.get("ambiguity", []))
                     for c in ans["causes"])
    return {"family": case.family, "seed": case.seed, "hidden": hide, "sleeper": sleeper, "factor": k,
            "limit": limit, "effect": words(limit, k), "kind": ans["kind"],
            "causes": [c["cause"] + ("" if c.get("sleeper") is None else f"@{c['sleeper']}") for c in ans["causes"]],
            "named_here": named_here}


def run(families, seeds: int, sleepers, factors, workers: int, out: Path, hide: str = "void") -> tuple[list[dict],
                                                                                                     list[str]]:
    """Every (null passage, sleeper, factor): its row; and the null passages left out (not ``none``)."""
    sc = load_scenario(SCENARIO)
    setup = case_setup(sc)
    rows, skipped = [], []
    for family in families:
        for i in range(seeds):
            seed = case_seed(i)
            case = draw_case(seed, family, *setup, sc.vehicle.fmu)
            folder = out / f"{family}_{seed}"
            if not (folder / "passage.csv").is_file():
                folder.mkdir(parents=True, exist_ok=True)
                synthesize_case(sc, case, folder / "passage.csv")
            null = _diagnosed(folder, workers)
            if null["answer"]["kind"] != "none":
                skipped.append(f"{family} {seed}: {null['answer']['kind']}")
                continue
            cause, proxy, parameters, _ = HIDDEN[hide]
            for s in sleepers:
                limit = _limit(null, cause, proxy, s)
                if limit is None:
                    skipped.append(f"{family} {seed} sleeper {s}: no limit stated")
                    continue
                for k in factors:
                    hidden = replace(case, effects=(Effect(cause, s, parameters(limit, k)),))
                    sub = folder / f"{hide}_{s}_x{k:g}"
                    if not (sub / "passage.csv").is_file():
                        sub.mkdir(parents=True, exist_ok=True)
                        synthesize_case(sc, hidden, sub / "passage.csv")
                        (sub / "case.json").write_text(json.dumps(hidden.as_dict(), indent=1))
                    rows.append(_row(case, hide, s, k, limit, _diagnosed(sub, workers)))
                    r = rows[-1]
                    print(f"{family} {seed} {cause}@{s} x{k:g} ({r['effect']}): {r['kind']} {r['causes']}", flush=True)
    return rows, skipped


def report(rows: list[dict], skipped: list[str]) -> str:
    """Per factor: none / shown / named at the sleeper; the rows; what was left out."""
    cause = HIDDEN[rows[0]["hidden"]][0] if rows else "the effect"
    lines = ["| factor k (effect = k x stated limit) | passages | `none` | shown (named or unexplained) | "
             f"named {cause} at the sleeper |", "|---|---|---|---|---|"]
    for k in sorted({r["factor"] for r in rows}):
        rs = [r for r in rows if r["factor"] == k]
        none = sum(r["kind"] == "none" for r in rs)
        lines.append(f"| {k:g} | {len(rs)} | {none} | {len(rs) - none} | {sum(r['named_here'] for r in rs)} |")
    lines += ["", "| family | seed | sleeper | stated limit | k | hidden | answer |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lim = HIDDEN[r["hidden"]][3](r["limit"], 1.0)
        lines.append(f"| {r['family']} | {r['seed']} | {r['sleeper']} | {lim} | {r['factor']:g} | "
                     f"{r['effect']} | {r['kind']}{' ' + ', '.join(r['causes']) if r['causes'] else ''} |")
    if skipped:
        lines += ["", "Left out: " + "; ".join(skipped) + "."]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="null_clean,null_vehicle")
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--sleepers", default="19,21,24")
    ap.add_argument("--factors", default="0.5,1,2")
    ap.add_argument("--hide", choices=sorted(HIDDEN), default="void",
                    help="a uniform void (gap k x L) or a soft pad (stiffness factor L ** k) at the stated limit L")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--out", type=Path, default=Path("results/bench_resolution"))
    ap.add_argument("--record", action="store_true")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows, skipped = run(args.families.split(","), args.seeds, [int(s) for s in args.sleepers.split(",")],
                        [float(k) for k in args.factors.split(",")], args.workers, args.out, args.hide)
    (args.out / "rows.json").write_text(json.dumps(rows, indent=1))
    text = report(rows, skipped)
    wall = time.perf_counter() - t0
    print(text)
    print(f"wall {wall:.0f} s")
    if args.record:
        head = (f"## A `none` answer's stated resolution, {HIDDEN[args.hide][0]} hidden at k x the limit — "
                f"{datetime.datetime.now():%Y-%m-%d %H:%M}, {platform.machine()}, {args.workers} workers, "
                f"Python {platform.python_version()}")
        cmd = (f"`python benchmarks/bench_resolution.py --hide {args.hide} --families {args.families} --seeds "
               f"{args.seeds} --sleepers {args.sleepers} --factors {args.factors}`")
        path = Path(__file__).with_name("RESULTS.md")
        with path.open("a", encoding="utf-8") as fh:
            fh.write(f"\n{head}\n\n{cmd} ({wall:.0f} s)\n\n{text}\n")


if __name__ == "__main__":
    main()
