"""Speed of the compiled track step (issue "Speed and footprint", item 1).

Prints, for the default scenario (0.5 s, 40 sleepers) and for a 1 s passage on a
64-sleeper panel (transition sleeper 33, so the bogie meets the crossing half-way),
in-process (blocks of steps in one compiled call, orchestrator.cosim.compiled_loop; the
compiled track step called once a step; the numpy reference path) and through the FMUs (the
compiled FMU loop and the FMUs' compiled steps in their shim, fmus.fast):
loop wall [s] (the two compiled in-process runs and the FMU run alternating, median of three; the
first FMU run's loop, which loads the FMUs' compiled code, is printed too), us per step,
linear solves per step; then the
cost of one solve with the step matrix (SuperLU LU vs the LDL^T of track.kernel) and
of one product with K, the cost of the compiled step's stages (one bogie on the panel,
repeated calls of each stage on the step's own data), and numba's first-call time
(warm cache: loading only).

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
from orchestrator.cosim.compiled_loop import COMPILED_LOOP_ENV
from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
# (backend, track step): in-process with the compiled loop (track.fused, the default), with the compiled
# step called once per step by the master (TURNOUT_COMPILED_LOOP=0), with the numpy reference step; FMUs
RUNS = (("inprocess", "compiled loop"), ("inprocess", "compiled step"), ("inprocess", "numpy"), ("fmu", "compiled"))
ALTERNATIONS = 3   # the first two alternate this many times (median loop wall): the host's speed drifts
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
    from track.kernel import LDLFactor, _sym_matvec_sub, ldl_solve, lower_rows, prune
    from track.model import build_track

    model = build_track(sc.track)
    integ = TrackIntegrator(model, sc.simulation.step, np.zeros(model.n))
    f = LDLFactor(prune(integ.step_matrix))
    K = prune(integ._Kt)
    Krows = lower_rows(K)
    b, x, w, y = np.random.default_rng(0).standard_normal(model.n), np.empty(model.n), np.empty(model.n), \
        np.zeros(model.n)
    ldl_solve(f.perm, f.Lp, f.Li, f.Lx, f.d, b, x, w)
    out = {}
    for name, fn in (("SuperLU solve", lambda: integ._lu.solve(b)),
                     ("LDL^T solve (compiled)", lambda: ldl_solve(f.perm, f.Lp, f.Li, f.Lx, f.d, b, x, w)),
                     ("K product, scipy (unpruned)", lambda: integ._Kt @ b),
                     ("K product, compiled (pruned, lower triangle)", lambda: _sym_matvec_sub(*Krows, b, y))):
        fn()
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        out[name] = (time.perf_counter() - t0) / repeat * 1e6
    lu = integ._lu
    return model.n, lu.L.nnz + lu.U.nnz, f.nnz, integ._Kt.nnz, K.nnz, out


def _best_us(fn, repeat: int) -> float:
    """Best of 3 means of ``repeat`` calls [us]."""
    fn()
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        for _ in range(repeat):
            fn()
        best = min(best, (time.perf_counter() - t0) / repeat * 1e6)
    return best


def stage_costs(sc, repeat=1000):
    """us per call of the compiled step's stages, for a bogie 1 m ahead of the crossing transition.

    The whole step (CompiledContacts.step: Python + one kernel call), the kernel call alone,
    a wheel entering an element whose influence rows are solved (the kernel's own element load),
    and the predictor (with the K and C products), solve and corrector stages.
    """
    from track import kernel as K
    from track.cosim import TrackCosim

    h = sc.simulation.step
    tc = TrackCosim(sc.track, 4, 0.5 * sc.vehicle.axle_load, h, speed=sc.vehicle.speed, kernel=True)
    x0 = tc.model.layout.x_transition - 1.0
    x = np.array([x0, x0, x0 - 2.5, x0 - 2.5])
    z = np.zeros(4)
    for k in range(5):
        tc.do_step(x + k * sc.vehicle.speed * h, z, z)
    cc, it = tc._compiled, tc.integ
    xs, zw = x + 5 * sc.vehicle.speed * h, z + tc.offset
    n, m = tc.model.n, 4
    new, Fc1, out = np.empty((4, n)), np.empty(m), np.empty((m, 4))
    f = cc.f

    args = list(cc._args)
    s0, sx, sn = K._STEP_SLOTS
    args[s0:s0 + 5] = it.q, it.v, it.a, it.F, it.Fc
    args[sx:sx + 2] = xs, zw
    args[sn:sn + 6] = new[0], new[1], new[2], new[3], Fc1, out
    k0 = int(cc.ent[0, 0])
    par, w = cc.par, cc.work
    qp, vp, rhs, y, acc_lin, sw, unit = (w[j * n:(j + 1) * n] for j in range(7))
    a1, bh2, gh = 1.0 + par[K.P_ALPHA], par[K.P_BETA] * h * h, par[K.P_GAMMA] * h
    Fn = it.Fc + 1.0
    return {
        "CompiledContacts.step": _best_us(lambda: cc.step(xs, z + tc.offset, tc.c_h), repeat),
        "kernel call": _best_us(lambda: K.contact_step(*args), repeat),
        "element entry (rows solved)": _best_us(lambda: K._load_entry(
            0, k0, *cc._rows, f.perm, f.Lp, f.Li, f.Lx, f.d, cc.T, cc.gd, cc.nr, cc.R, cc.zrow, cc.fresh, cc.ent,
            cc.cnt), repeat),
        "predictor (with K, C products)": _best_us(lambda: K._predict(
            h, par[K.P_ALPHA], par[K.P_BETA], par[K.P_GAMMA], par[K.P_BETA_S], it.q, it.v, it.a, it.F,
            tc.model.f_gravity, *cc._K, *cc._C, qp, vp, sw, y, rhs), repeat),
        "LDL^T solve": _best_us(lambda: K.ldl_solve(f.perm, f.Lp, f.Li, f.Lx, f.d, rhs, acc_lin, unit), repeat),
        "corrector (4 wheels x 4 rows)": _best_us(lambda: K._corrector(
            a1, bh2, gh, qp, vp, acc_lin, Fn, it.Fc, cc.W, cc.Zr, cc.zrow, new[2], new[0], new[1]), repeat),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="0.05 s runs (smoke test)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    import track.kernel  # noqa: F401  (numba import + cache locator)
    from track.kernel import contact_step  # noqa: F401
    print(f"import track.kernel: {time.perf_counter() - t0:.2f} s")
    rows: dict = {}
    for label, over in CASES.items():
        sc = load_scenario(DEFAULT, over + (["simulation.duration=0.05"] if args.quick else []))
        n, nlu, nldl, nk, nkp, cost = solve_costs(sc)
        print(f"\n{label}: {n} reduced dofs; nnz(L+U) SuperLU {nlu}, nnz(L+D) LDL^T {nldl}; "
              f"nnz K {nk}, pruned {nkp}")
        for k, v in cost.items():
            print(f"  {k}: {v:.1f} us")
        with tempfile.TemporaryDirectory() as tmp:
            build_fmus(sc, Path(tmp))
            walls: dict = {}
            alternating = (RUNS[0], RUNS[1], RUNS[3])
            for backend, mode in alternating * ALTERNATIONS + (RUNS[2],):
                os.environ["TURNOUT_TRACK_KERNEL"] = "numpy" if mode == "numpy" else "compiled"
                os.environ[COMPILED_LOOP_ENV] = "0" if mode == "compiled step" else "1"
                loop, steps, sps, peak = timed(sc, backend, Path(tmp) if backend == "fmu" else None)
                walls.setdefault((backend, mode), []).append(loop)
                if backend == "fmu" and len(walls[(backend, mode)]) == 1:
                    print(f"  (first FMU run in this process, with the FMUs' first-call loading: loop {loop:.2f} s)")
                loop = float(np.median(walls[(backend, mode)]))
                rows[(label, backend, mode)] = (label, backend, mode, loop, steps, sps, peak)   # first place kept
                print(f"  {backend:9s} {mode:13s} loop {loop:6.2f} s, {loop / steps * 1e6:6.1f} us/step, "
                      f"{sps:.3f} solves/step, peak Fz {peak:.1f} N")
        os.environ.pop("TURNOUT_TRACK_KERNEL", None)
        os.environ.pop(COMPILED_LOOP_ENV, None)
        print("  compiled step, per stage (after the runs: its influence rows would count as theirs):")
        for k, v in stage_costs(sc).items():
            print(f"    {k}: {v:.1f} us")
    print("\n| case | backend | track step | loop wall [s] | us/step | solves/step | peak Fz [N] |")
    print("|---|---|---|---|---|---|---|")
    for r in rows.values():
        print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.2f} | {r[3] / r[4] * 1e6:.0f} | {r[5]:.3f} | {r[6]:.1f} |")
    for label in CASES:
        by = {(r[1], r[2]): r[3] for r in rows.values() if r[0] == label}
        fmu, loop, step = (by[("fmu", "compiled")], by[("inprocess", "compiled loop")],
                           by[("inprocess", "compiled step")])
        print(f"{label}: FMU / in-process {fmu / loop:.2f} (compiled loop), {fmu / step:.2f} (compiled step); "
              f"stepped / compiled loop in-process {step / loop:.2f}; numpy / compiled loop "
              f"{by[('inprocess', 'numpy')] / loop:.2f}")


if __name__ == "__main__":
    main()
