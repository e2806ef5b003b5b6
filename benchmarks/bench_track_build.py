"""Size and one-time cost of the track model (issue: track model foundation).

Prints and appends to benchmarks/RESULTS.md: full and reduced dofs of the default
1:12 crossing panel (seed 000 Table 1: 798 dofs) and of the 1:15 R760 panel, the
mesh/assembly, Craig–Bampton and global-assembly times (cold cache, best of 3),
the static equilibrium time and the cost of a track step.

Run: python benchmarks/bench_track_build.py
"""
from __future__ import annotations

import datetime
import platform
import time
from pathlib import Path

import numpy as np

from track.dynamics import TrackIntegrator
from track.model import build_track, clear_rom_cache
from track.params import LayoutParams, TrackParams
from track.statics import static_equilibrium

CASES = {
    "60E1-500-1:12, 40 sleepers (default)": TrackParams(),
    "60E1-760-1:15, 40 sleepers": TrackParams(layout=LayoutParams(crossing="1:15", radius=760.0)),
    "plain, 40 sleepers": TrackParams(layout=LayoutParams(type="plain", sleepers=40)),
}
REPEAT = 3


def machine() -> str:
    import os
    return f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def main() -> None:
    rows = []
    for name, tp in CASES.items():
        best = None
        for _ in range(REPEAT):
            clear_rom_cache()
            t0 = time.perf_counter()
            m = build_track(tp)
            total = time.perf_counter() - t0
            if best is None or total < best[0]:
                best = (total, m)
        total, m = best
        t0 = time.perf_counter()
        build_track(tp)  # warm cache: only bushings change
        warm = time.perf_counter() - t0
        t0 = time.perf_counter()
        st = static_equilibrium(m, [])
        t_static = time.perf_counter() - t0
        integ = TrackIntegrator(m, 2e-5, st.q)
        t0 = time.perf_counter()
        for _ in range(500):
            integ.step(())
        t_step = (time.perf_counter() - t0) / 500
        modal = sum(b.rom.nr - b.rom.nb for b in m.bodies)
        rows.append((name, m.stats.fom_dofs, m.n, modal, m.ballast.dof.size, m.stats.bodies,
                     m.stats.t_mesh_assembly, m.stats.t_reduction, m.stats.t_global, total, warm, t_static,
                     st.iterations, t_step))
    hdr = ("| case | full dofs | reduced dofs | of which modal | ballast bushings | bodies | mesh+FE [s] "
           "| CB [s] | global [s] | build total [s] | rebuild, cached bodies [s] | static eq. [s] (Newton it.) "
           "| track step, 20 us, no wheels [us] |")
    lines = [hdr, "|" + "---|" * 13]
    for r in rows:
        lines.append(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {r[5]} | {r[6]:.3f} | {r[7]:.3f} | "
                     f"{r[8]:.3f} | {r[9]:.3f} | {r[10]:.3f} | {r[11]:.3f} ({r[12]}) | {1e6 * r[13]:.0f} |")
    text = "\n".join(lines)
    print(text)
    out = Path(__file__).with_name("RESULTS.md")
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    block = (f"\n## Track model size and build cost — {stamp}, {machine()}\n\n"
             f"`python benchmarks/bench_track_build.py` (seed 000 Table 1: 798 dofs for its beam model)\n\n{text}\n")
    with out.open("a") as f:
        f.write(block)


if __name__ == "__main__":
    main()
