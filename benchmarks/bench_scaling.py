"""How the co-simulation's cost grows with the panel size and the step (issue "Speed and footprint", item 6).

1. Sleepers: turnouts of 20 ... 160 sleepers (the transition sleeper at the middle, at most 25: the
   layout models no switch panel, so longer panels extend behind the crossing), the
   bogie over the same 0.2 s of passage at 120 km/h with the default 100 us step, in-process
   (the compiled track step). Prints reduced dofs, the loop's wall and us per step, and the
   exponent p of a least-squares fit wall ~ sleepers^p (target p <= 1.1).
   Behind the crossing the bearers lengthen and carry four rails until each track gets its own
   sleeper (track.layout._bearer), so the turnout's model grows a little faster than its sleeper
   count over the first ~50 sleepers; the same fit is also made against the reduced dofs.
2. Plain track (scenarios/plain_track.yaml) of 20 ... 160 sleepers, the same passage and step:
   every sleeper bay adds the same bodies, so wall ~ sleepers^p measures the step's own
   growth with the model's size, apart from how the turnout's layout grows.
3. Step: the default scenario's first 0.2 s at steps of 25 ... 200 us: wall per simulated
   second and us per step (the per-step cost should not depend on h; the count does).

Every case is run twice and the faster kept (numba compilation and the body cache warm up
in the first). Run: python benchmarks/bench_scaling.py   (record the output in RESULTS.md)
"""
from __future__ import annotations

import platform
import time
from pathlib import Path

import numpy as np

from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
PLAIN = ROOT / "scenarios" / "plain_track.yaml"
SLEEPERS = (20, 40, 80, 160)
STEPS = (25e-6, 50e-6, 100e-6, 200e-6)
DURATION = 0.2        # s of passage in every case
REPEAT = 2


def _loop_wall(overrides: list[str], scenario: Path = DEFAULT) -> tuple[float, int, int]:
    """(best loop wall [s], steps, reduced dofs) of the in-process run of ``scenario`` with ``overrides``."""
    sc = load_scenario(scenario, overrides=overrides)
    best, steps, dofs = np.inf, 0, 0
    for _ in range(REPEAT):
        res = run_cosim(sc, backend="inprocess", record_states=False)
        if res.error is not None:
            raise RuntimeError(f"{overrides}: {res.error}")
        best = min(best, res.stats.counters.wall_loop)
        steps, dofs = res.stats.counters.steps, res.track_model.n
    return best, steps, dofs


def sleepers_series(label: str, scenario: Path, overrides) -> float:
    """Loop wall against sleeper count for ``scenario`` (``overrides(n)``: its overrides at n sleepers);
    prints the table and the fitted exponents against sleepers and reduced dofs; returns the former."""
    print(f"{label}\n{'sleepers':>8} {'dofs':>6} {'steps':>6} {'loop [s]':>9} {'us/step':>8}")
    walls, sizes = [], []
    for n in SLEEPERS:
        wall, steps, dofs = _loop_wall([f"track.layout.sleepers={n}", f"simulation.duration={DURATION}",
                                        *overrides(n)], scenario)
        walls.append(wall)
        sizes.append(dofs)
        print(f"{n:8d} {dofs:6d} {steps:6d} {wall:9.3f} {1e6 * wall / steps:8.1f}")
    p = np.polyfit(np.log(SLEEPERS), np.log(walls), 1)[0]
    q = np.polyfit(np.log(sizes), np.log(walls), 1)[0]
    print(f"fitted exponent, {label}: wall ~ sleepers^{p:.2f} (target <= 1.1); wall ~ reduced dofs^{q:.2f}")
    return p


def step_study() -> None:
    print(f"{'step [us]':>9} {'steps':>6} {'loop [s]':>9} {'us/step':>8} {'wall per sim. s':>16}")
    for h in STEPS:
        wall, steps, _ = _loop_wall([f"simulation.step={h}", f"simulation.output_step={max(h, 1e-4)}",
                                     f"simulation.duration={DURATION}"])
        print(f"{1e6 * h:9.0f} {steps:6d} {wall:9.3f} {1e6 * wall / steps:8.1f} {wall / DURATION:16.2f}")


if __name__ == "__main__":
    print(f"bench_scaling: {time.strftime('%Y-%m-%d %H:%M')}, {platform.node()}, {platform.processor() or platform.machine()}")
    # turnout: the transition sleeper at the middle, at most 25 (no switch panel is modelled); behind the
    # crossing the bearers lengthen until each track has its own sleeper (track.layout._bearer)
    sleepers_series("turnout", DEFAULT, lambda n: [f"track.layout.transition_sleeper={min(n // 2 + 1, 25)}"])
    sleepers_series("plain track", PLAIN, lambda n: ["simulation.step=1e-4"])   # the turnout's step
    step_study()
