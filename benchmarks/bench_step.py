"""Speed of the compiled track step (issue "Speed and footprint", item 1).

Prints, for the default scenario (0.5 s, 40 sleepers) and for a 1 s passage on a
64-sleeper panel (transition sleeper 33, so the bogie meets the crossing half-way),
in-process and through the FMUs, with the compiled step and (in-process) with the
numpy reference path: loop wall [s], us per step, linear solves per step; then the
cost of one solve with the step matrix (SuperLU LU vs the LDL^T of track.kernel) and
of one product with K, and numba's first-call time (warm cache: loading only).

Run: python benchmarks/bench_step.py [--quick]   (the lead records the figures in RESULTS.md)
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from orchestrator.cosim.build_job import build_fmus
from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
CASES = {"default scenario (0.5 s, 40 sleepers)": [],
         "1 s passage, 64 sleepers": ["track.layout.sleepers=64", "track.layout.transition_sleeper=33",
                                      "simulation.duration=1.0"]}


def timed(sc, backend, fmu_dir=None):
    res = run_cosim(sc, backend=backend, fmu_dir=fmu_dir, record_states=False)
    if res.error is not None:
        raise RuntimeError(res.error)
    c = res.stats.counters
    sps = c.linear_solves / c.track_steps if c.track_steps else float("nan")  # FMU: not reported
    return c.wall_loop, c.steps, sps, float(res.Fz[1:].max())


def solve_costs(sc, repeat=2000):
    """us per solve with SuperLU (numpy path) and LDL^T (compiled path), per product with K."""
    from track.dynamics import TrackIntegrator
    from track.kernel import LDLFactor, _csr_matvec_sub, ldl_solve, prune
    from track.model import build_track

    model = build_track(sc.track)
    integ = TrackIntegrator(model, sc.simulation.step, np.zeros(model.n))
    f = LDLFactor(prune(integ.step_matrix))
    K = prune(integ._Kt)
    b, x, w, y = np.random.default_rng(0).standard_normal(model.n), np.empty(model.n), np.empty(model.n), \
        np.zeros(model.n)
    ldl_solve(f.perm, f.Lp, f.Li, f.Lx, f.d, b, x, w)
    out = {}
    for name, fn in (("SuperLU solve", lambda: integ._lu.solve(b)),
                     ("LDL^T solve (compiled)", lambda: ldl_solve(f.perm, f.Lp, f.Li, f.Lx, f.d, b, x, w)),
                     ("K product, scipy (unpruned)", lambda: integ._Kt @ b),
                     ("K product, compiled (pruned)", lambda: _csr_matvec_sub(K.indptr, K.indices, K.data, b, y))):
        fn()
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        out[name] = (time.perf_counter() - t0) / repeat * 1e6
    lu = integ._lu
    return model.n, lu.L.nnz + lu.U.nnz, f.nnz, integ._Kt.nnz, K.nnz, out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="0.05 s runs (smoke test)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    import track.kernel  # noqa: F401  (numba import + cache locator)
    from track.kernel import contact_step  # noqa: F401
    print(f"import track.kernel: {time.perf_counter() - t0:.2f} s")
    rows = []
    for label, over in CASES.items():
        sc = load_scenario(DEFAULT, over + (["simulation.duration=0.05"] if args.quick else []))
        n, nlu, nldl, nk, nkp, cost = solve_costs(sc)
        print(f"\n{label}: {n} reduced dofs; nnz(L+U) SuperLU {nlu}, nnz(L+D) LDL^T {nldl}; "
              f"nnz K {nk}, pruned {nkp}")
        for k, v in cost.items():
            print(f"  {k}: {v:.1f} us")
        with tempfile.TemporaryDirectory() as tmp:
            build_fmus(sc, Path(tmp))
            for backend, mode in (("inprocess", "compiled"), ("inprocess", "numpy"), ("fmu", "compiled")):
                os.environ["TURNOUT_TRACK_KERNEL"] = mode
                loop, steps, sps, peak = timed(sc, backend, Path(tmp) if backend == "fmu" else None)
                rows.append((label, backend, mode, loop, steps, sps, peak))
                print(f"  {backend:9s} {mode:8s} loop {loop:6.2f} s, {loop / steps * 1e6:6.1f} us/step, "
                      f"{sps:.3f} solves/step, peak Fz {peak:.1f} N")
        os.environ.pop("TURNOUT_TRACK_KERNEL", None)
    print("\n| case | backend | track step | loop wall [s] | us/step | solves/step | peak Fz [N] |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.2f} | {r[3] / r[4] * 1e6:.0f} | {r[5]:.3f} | {r[6]:.1f} |")
    for label in CASES:
        by = {(r[1], r[2]): r[3] for r in rows if r[0] == label}
        print(f"{label}: FMU / in-process (compiled) {by[('fmu', 'compiled')] / by[('inprocess', 'compiled')]:.2f}; "
              f"numpy / compiled in-process {by[('inprocess', 'numpy')] / by[('inprocess', 'compiled')]:.2f}")


if __name__ == "__main__":
    main()
