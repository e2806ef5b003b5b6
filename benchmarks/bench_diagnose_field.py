"""`turnout diagnose` on field-like passages: the confusion matrix of issue 14's acceptance.

For every family of :data:`orchestrator.inverse.fieldlike.FAMILIES` and ``--seeds`` seeds,
a case is drawn (:func:`~orchestrator.inverse.fieldlike.draw_case`: effects also beyond
the instrumented sleepers, voids that are not wedges, off-grid magnitudes, a truth
model with other vehicle parameters / speed / damping / step, a field sensor chain),
its passage is written (:func:`~orchestrator.inverse.fieldlike.synthesize_case`) and
diagnosed on the nominal scenario ``scenarios/measurement/crossing_quarter_120.yaml``
(:func:`orchestrator.inverse.diagnose.diagnose`, told nothing about the case). Each
answer is scored here, out of reach of the code under test:

* a null case (no effect) is right on ``none`` or ``unexplained`` — never a track cause
  (:data:`TRACK_CAUSES`; a vehicle or sensor cause the catalogue may gain is not one);
* a single effect is right if a named cause has its cause and scope and, for a local
  one, the sleeper exactly or in an ambiguity set of at most :data:`MAX_AMBIGUITY`
  sleepers (the convention of ``benchmarks/bench_diagnose.py``), and no other track cause
  is named;
* an effect beyond the instrumented sleepers is also right on ``unexplained`` located
  within :data:`NEAR` sleepers of it, or on the right cause with an ambiguity set of at
  most :data:`MAX_AMBIGUITY_OFF` sleepers that contains it;
* two effects are right if both are named (each as above).

Printed (and with ``--record`` appended to ``benchmarks/RESULTS.md``): the confusion matrix
(family x answered cause or ``none`` / ``unexplained`` / ``error``), the share right per
group against the acceptance, the misses (seed, truth, answer), the gains, and — where
``diagnosis.json`` has them — interval coverage and nuisance estimates. The answer is
read defensively (``answer`` kind, a list of named causes, intervals are read with
``.get``; today's ``diagnosis.json`` has only ``named_cause``: a cause or ``none``).
Every case's truth and answer go to ``OUT/rows.jsonl`` (``--report-only`` rebuilds the
tables from it).

Run: python benchmarks/bench_diagnose_field.py [--seeds 3] [--families a,b,...] [--workers 2] [--record]
     [--stage all|synth|diagnose] [--report-only] [--out DIR]
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
import traceback
from pathlib import Path

import numpy as np

from orchestrator.inputs.scenario import bundled_scenario, load_scenario
from orchestrator.inputs.sensor_layout import layout_of
from orchestrator.inverse.diagnose import diagnose
from orchestrator.inverse.fieldlike import FAMILIES, SLOW_FAMILIES, draw_case, instrumented_sleepers, synthesize_case
from orchestrator.inverse.jsonable import numpy_default

SCENARIO = bundled_scenario("measurement/crossing_quarter_120.yaml")
TRACK_CAUSES = ("ballast_void", "ballast_stiffness", "rail_pad_stiffness", "impact_angle")
MAX_AMBIGUITY = 2       # sleepers in an ambiguity set that still counts as located (bench_diagnose.py)
MAX_AMBIGUITY_OFF = 3   # ... for an effect beyond the sensors (the edge sleeper and its neighbours)
NEAR = 1                # sleepers between an `unexplained` location and an off-sensor effect, at most
GAIN_MIN, GAIN_MIN_MISMATCH = 0.80, 0.50   # the acceptance's gains without / with model-form mismatch
SEED0 = 7000            # seed of the k-th case of a family: SEED0 + 101 k (draw_case mixes in the family)


# ------------------------------------------------------------------------------------------ reading an answer
def _sleepers_in(obj) -> set[int]:
    """Every sleeper index under a key containing ``sleeper`` (ints, lists of ints, dicts keyed by index)."""
    out: set[int] = set()
    if isinstance(obj, dict):
        for k, v in obj.items():
            if "sleeper" in str(k):
                if isinstance(v, bool):
                    continue
                if isinstance(v, int):
                    out.add(v)
                elif isinstance(v, (list, tuple)):
                    out |= {x for x in v if isinstance(x, int) and not isinstance(x, bool)}
                elif isinstance(v, dict):
                    out |= {int(x) for x in v if str(x).lstrip("-").isdigit()}
            out |= _sleepers_in(v)
    elif isinstance(obj, list):
        for v in obj:
            out |= _sleepers_in(v)
    return out


def _named_list(res: dict) -> list[dict]:
    """The named causes: a list where the diagnosis gives one, else today's single ``named_cause``."""
    ans = res.get("answer")
    for lst in (res.get("named_causes"), ans.get("causes") if isinstance(ans, dict) else None):
        if isinstance(lst, list) and lst:
            return [c for c in lst if isinstance(c, dict) and c.get("cause") not in (None, "none", "unexplained")]
    nc = res.get("named_cause") or {}
    return [nc] if nc.get("cause") not in (None, "none", "unexplained") else []


def read_answer(res: dict, error: str | None = None) -> dict:
    """``{"kind", "causes", "where", "gain", "error"}`` of a ``diagnosis.json`` dict (module docstring)."""
    if error is not None:
        return {"kind": "error", "causes": [], "where": [], "gain": None, "error": error}
    named = _named_list(res)
    ans = res.get("answer")
    kind = ans.get("kind") if isinstance(ans, dict) else ans if isinstance(ans, str) else None
    if kind not in ("none", "unexplained"):
        nc = (res.get("named_cause") or {}).get("cause")
        kind = "cause" if named else nc if nc in ("none", "unexplained") else "none"
    causes = [{"cause": c.get("cause"), "sleeper": c.get("sleeper"),
               "ambiguity": sorted(set((c.get("ambiguity") or {}).get("sleepers") or []) | (
                   {c["sleeper"]} if c.get("sleeper") is not None else set())),
               "parameters": c.get("parameters") or {},
               "intervals": c.get("intervals") or c.get("interval") or (c.get("uncertainty") or {}).get("intervals"),
               "gain": c.get("gain")} for c in named]
    where = sorted(_sleepers_in(ans)) if kind == "unexplained" and isinstance(ans, dict) else []
    gain = (res.get("gain") or {}).get("total")
    return {"kind": kind, "causes": causes, "where": where, "gain": gain, "error": None,
            "nuisance": res.get("nuisance") or (ans.get("nuisance") if isinstance(ans, dict) else None)}


# ------------------------------------------------------------------------------------------ scoring
def _local_right(effect: dict, c: dict, max_set: int) -> bool:
    return c["sleeper"] == effect["sleeper"] or (effect["sleeper"] in c["ambiguity"] and len(c["ambiguity"]) <= max_set)


def _matches(effect: dict, c: dict, max_set: int = MAX_AMBIGUITY) -> bool:
    """A named cause ``c`` is the effect: same cause and scope, the sleeper located (module docstring)."""
    if c["cause"] != effect["cause"] or (effect["sleeper"] is None) != (c["sleeper"] is None):
        return False
    return effect["sleeper"] is None or _local_right(effect, c, max_set)


def score(case: dict, ans: dict, sleepers) -> tuple[bool, str]:
    """(right, why) of an answer to a case (module docstring's rules)."""
    effects = case["effects"]
    track = [c for c in ans["causes"] if c["cause"] in TRACK_CAUSES]
    if ans["kind"] == "error":
        return False, "the diagnosis failed"
    if not effects:
        return (not track), ("no track cause" if not track else "a track cause named for a null case")
    off = [e for e in effects if e["sleeper"] is not None and e["sleeper"] not in sleepers]
    if len(effects) == 1 and off:
        e = off[0]
        if ans["kind"] == "unexplained" and any(abs(k - e["sleeper"]) <= NEAR for k in ans["where"]):
            return True, "unexplained, located near the effect"
        if len(track) == 1 and _matches(e, track[0], MAX_AMBIGUITY_OFF):
            return True, "named, ambiguity set contains the off-sensor sleeper"
    unmatched = list(track)
    for e in effects:
        hit = next((c for c in unmatched if _matches(e, c)), None)
        if hit is None:
            return False, f"{_effect_label(e)} not named at its place"
        unmatched.remove(hit)
    return (not unmatched), ("all named" if not unmatched else "an extra track cause named")


def _effect_label(e: dict) -> str:
    return e["cause"] + ("@sleeper" if e["cause"] == "rail_pad_stiffness" and e["sleeper"] is not None else "")


def answer_label(ans: dict) -> str:
    """The confusion matrix's column: the named causes (``+``-joined) or the kind."""
    if ans["kind"] != "cause":
        return ans["kind"]
    return "+".join(sorted(_effect_label(c) for c in ans["causes"]))


def coverage(case: dict, ans: dict) -> tuple[int, int]:
    """(intervals containing the truth, intervals checked) over the named causes that match an effect."""
    inside = total = 0
    for e in case["effects"]:
        for c in ans["causes"]:
            iv = c.get("intervals")
            if not isinstance(iv, dict) or not _matches(e, c, MAX_AMBIGUITY_OFF):
                continue
            for name, truth in e["parameters"].items():
                bounds = iv.get(name)
                pairs = list(zip(np.atleast_1d(truth), bounds if np.ndim(bounds) == 2 else [bounds])) \
                    if bounds is not None else []
                for t, b in pairs:
                    if b is not None and len(b) == 2:
                        total += 1
                        inside += int(b[0] <= t <= b[1])
    return inside, total


# ------------------------------------------------------------------------------------------ running
def run_case(sc, setup: tuple, family: str, seed: int, workers: int, folder: Path, stage: str = "all") -> dict | None:
    """Draw, synthesize and diagnose one case; its row (truth, answer, score, gain, wall).

    ``stage``: ``synth`` only writes the passage (and ``case.json``), ``diagnose`` only
    diagnoses the passage an earlier ``synth`` wrote (the same passages for two versions of
    the diagnosis, or a truth that needs another checkout), ``all`` both.
    """
    sleepers, channels = setup
    case = draw_case(seed, family, sleepers, channels, sc.vehicle.fmu)
    folder.mkdir(parents=True, exist_ok=True)
    if stage in ("all", "synth"):
        synthesize_case(sc, case, folder / "passage.csv")
        (folder / "case.json").write_text(json.dumps(case.as_dict(), indent=1))
    if stage == "synth":
        return None
    if json.loads((folder / "case.json").read_text()) != json.loads(json.dumps(case.as_dict())):
        raise SystemExit(f"{folder}: its case.json is not the case this code draws for {family} seed {seed}")
    t0 = time.perf_counter()
    try:
        res, error = diagnose(SCENARIO, folder / "passage.csv", folder / "out", workers=workers,
                              progress=False).to_json(), None
    except Exception as exc:   # noqa: BLE001 - a crash is an answer to record (issue 14: never a traceback)
        res, error = {}, f"{type(exc).__name__}: {exc}"
        (folder / "traceback.txt").write_text(traceback.format_exc())
    ans = read_answer(res, error)
    truth = case.as_dict()
    right, why = score(truth, ans, sleepers)
    return {"family": family, "seed": seed, "truth": truth, "answer": ans, "right": right, "why": why,
            "label": answer_label(ans), "coverage": coverage(truth, ans), "wall": time.perf_counter() - t0,
            "runs": res.get("runs")}


def run_all(families, seeds: int, workers: int, out: Path, stage: str = "all") -> list[dict]:
    """Every family x seed, rows appended to ``out/rows.jsonl`` as they finish."""
    sc = load_scenario(SCENARIO)
    setup = (instrumented_sleepers(sc), tuple(layout_of(sc).ids))
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for k in range(seeds):
        for family in families:
            seed = SEED0 + 101 * k
            row = run_case(sc, setup, family, seed, workers, out / f"{family}_{seed}", stage)
            if row is None:
                print(f"{family:26s} seed {seed}: passage written", flush=True)
                continue
            rows.append(row)
            with (out / "rows.jsonl").open("a") as f:
                f.write(json.dumps(row, default=numpy_default) + "\n")
            print(f"{family:26s} seed {seed}: {'right' if row['right'] else 'WRONG'} ({row['why']}); answer "
                  f"{row['label']}, gain {_pct(row['answer']['gain'])}, {row['wall']:.0f} s", flush=True)
    return rows


# ------------------------------------------------------------------------------------------ the tables
def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f} %"


def _group(family: str) -> str:
    if family.endswith("+solid") or family == "null_solid":
        return "solid crossing rail as the truth"
    if family.startswith("null"):
        return "nulls (incl. mismatch-only)"
    if family.startswith("two_"):
        return "two effects"
    return "single effects" + (", with model mismatch" if family.endswith("+mismatch") else ", no mismatch")


def matrix(rows: list[dict]) -> str:
    """Markdown confusion matrix: family x answer."""
    families = list(dict.fromkeys(r["family"] for r in rows))
    labels = sorted({r["label"] for r in rows})
    lines = ["| true family \\ answer | " + " | ".join(labels) + " | right |", "|---|" + "---|" * (len(labels) + 1)]
    for fam in families:
        mine = [r for r in rows if r["family"] == fam]
        lines.append(f"| {fam} | " + " | ".join(str(sum(r["label"] == lab for r in mine) or "") for lab in labels)
                     + f" | {sum(r['right'] for r in mine)}/{len(mine)} |")
    return "\n".join(lines)


def _truth_text(truth: dict) -> str:
    parts = []
    for e in truth["effects"]:
        p = e["parameters"]
        v = f"peak {1e3 * max(p['gaps']):.2f} mm" if "gaps" in p else ", ".join(f"{k} {v:.4g}" for k, v in p.items())
        parts.append(f"{e['cause']}" + (f"@{e['sleeper']}" if e["sleeper"] is not None else "") + f" ({v})")
    m = truth["mismatch"]
    if m["vehicle"] or m["speed"] != 1.0:
        vehicle = ", ".join(f"{k} x{v:.2f}" for k, v in m["vehicle"].items())
        parts.append(f"mismatch: speed x{m['speed']:.3f}, {vehicle}"
                     + f", damping x{m['ballast_damping']:.2f}/x{m['pad_damping']:.2f}, step /{m['step_divisor']}")
    c = truth["chain"]
    if c["gain_channel"]:
        parts.append(f"channel {c['gain_channel']} gain {c['gain']:.3f}")
    return "; ".join(parts) or "nothing"


def _answer_text(ans: dict) -> str:
    if ans["kind"] == "error":
        return f"error: {ans['error'][:160]}"
    if ans["kind"] != "cause":
        return ans["kind"] + (f" near sleepers {ans['where']}" if ans["where"] else "")
    return "; ".join(f"{c['cause']}" + (f"@{c['sleeper']} (set {c['ambiguity']})" if c["sleeper"] is not None else "")
                     for c in ans["causes"])


def summary(rows: list[dict], seeds: int, wall: float | None) -> str:
    """The matrix, the share right per group, gains, misses, coverage, nuisance estimates."""
    out = [matrix(rows), ""]
    for g in dict.fromkeys(_group(r["family"]) for r in rows):
        mine = [r for r in rows if _group(r["family"]) == g]
        out.append(f"- {g}: right {sum(r['right'] for r in mine)}/{len(mine)}")
    gains = {}
    for r in rows:
        if r["truth"]["effects"] and r["right"] and r["answer"]["gain"] is not None:
            gains.setdefault(_group(r["family"]), []).append(r["answer"]["gain"])
    for g, v in gains.items():
        need = GAIN_MIN_MISMATCH if "with model mismatch" in g else GAIN_MIN
        out.append(f"- gain of right answers, {g}: min {_pct(min(v))}, median {_pct(float(np.median(v)))}; "
                   f">= {_pct(need)} in {sum(x >= need for x in v)}/{len(v)}")
    inside, total = (sum(r["coverage"][i] for r in rows) for i in (0, 1))
    out.append(f"- interval coverage: {inside}/{total} intervals contain the truth" if total
               else "- interval coverage: no intervals in diagnosis.json")
    nuis = [r for r in rows if r["answer"].get("nuisance")]
    out.append(f"- nuisance estimates reported in {len(nuis)}/{len(rows)} diagnoses")
    errors = [r for r in rows if r["answer"]["kind"] == "error"]
    out.append(f"- diagnoses that ended in an exception: {len(errors)}/{len(rows)}")
    out += ["", "Misses (family, seed: truth -> answer, gain):", ""]
    out += [f"- {r['family']}, seed {r['seed']}: {_truth_text(r['truth'])} -> {_answer_text(r['answer'])}, "
            f"gain {_pct(r['answer']['gain'])}" for r in rows if not r["right"]] or ["- none"]
    runs = [r["runs"] for r in rows if r["runs"]]
    wall = wall or sum(r["wall"] for r in rows)      # --report-only: the diagnoses' own wall times
    out += ["", f"{len(rows)} diagnoses ({seeds} seed(s) per family) in {wall / 60:.1f} min"
            + (f"; median {float(np.median([r['wall'] for r in rows])):.0f} s and {int(np.median(runs))} runs each"
               if runs else "")]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=3, help="seeds per family")
    ap.add_argument("--families", default=",".join(FAMILIES),
                    help=f"comma-separated families (default: all but the slow {', '.join(SLOW_FAMILIES)})")
    ap.add_argument("--workers", type=int, default=2, help="local workers of each diagnosis")
    ap.add_argument("--out", default="/tmp/bench_diagnose_field", help="folder of the cases and rows.jsonl")
    ap.add_argument("--record", action="store_true", help="append the result to benchmarks/RESULTS.md")
    ap.add_argument("--report-only", action="store_true", help="tables from OUT/rows.jsonl, no runs")
    ap.add_argument("--note", default="", help="a line recorded under the command (with --record)")
    ap.add_argument("--stage", choices=("all", "synth", "diagnose"), default="all",
                    help="synth: write the passages only; diagnose: diagnose those an earlier synth wrote")
    args = ap.parse_args()
    families = [f for f in args.families.split(",") if f]
    unknown = [f for f in families if f not in FAMILIES and f not in SLOW_FAMILIES]
    if unknown:
        raise SystemExit(f"unknown family {unknown[0]!r} (one of {', '.join({**FAMILIES, **SLOW_FAMILIES})})")
    out, t0 = Path(args.out), time.perf_counter()
    if args.report_only:
        rows, wall = [json.loads(s) for s in (out / "rows.jsonl").read_text().splitlines() if s.strip()], None
        rows = [r for r in rows if r["family"] in families]
    else:
        rows = run_all(families, args.seeds, args.workers, out, args.stage)
        wall = time.perf_counter() - t0
        if args.stage == "synth":
            return
    text = summary(rows, args.seeds, wall)
    print(text)
    if args.record:
        stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
        machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
        cmd = f"python benchmarks/bench_diagnose_field.py --seeds {args.seeds} --workers {args.workers}" + (
            f" --families {args.families}" if families != list(FAMILIES) else "")
        with Path(__file__).with_name("RESULTS.md").open("a") as f:
            note = f"{args.note}\n\n" if args.note else ""
            f.write(f"\n## Diagnosis on field-like passages: confusion matrix — {stamp}, {machine}\n\n`{cmd}`\n\n"
                    f"{note}{text}\n")


if __name__ == "__main__":
    main()
