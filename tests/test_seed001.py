"""Seed 001's conclusions (Pålsson 2020, §6-7) asserted on our computed numbers.

60E1-R760-1:15 crossing panel, through route, quarter vehicle with a flexible
wheelset, 20 t (scenarios/seed001/crossing_1_15_quarter.yaml), each run from 2 m
ahead of the transfer point to 3 m behind it (orchestrator.sweeps.study.run_case), step
100 us (peak forces within 0.3 % of 10 us, tests/test_cosim.py).
"""
import numpy as np
import pytest
from conftest import REPO_ROOT, SCENARIOS_DIR

from orchestrator.inputs.scenario import load_scenario
from orchestrator.studies.figures import SEED001
from orchestrator.sweeps.study import run_case

KMH = 1 / 3.6
SOFT, STIFF = 1.2e8, 1.2e9
Q0 = 196200.0 / 2


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    cache = {}
    base = tmp_path_factory.mktemp("seed001")

    def get(kmh, angle, pad=SOFT):
        key = (kmh, angle, pad)
        if key not in cache:
            sc = load_scenario(SCENARIOS_DIR / SEED001, [
                f"vehicle.speed={kmh * KMH}", f"track.crossing.impact_angle={angle}",
                f"track.rail_pad.stiffness={pad}"])
            cache[key] = run_case(sc, base / f"{kmh}_{angle}_{pad:.0e}")
        return cache[key]
    return get


def test_a_delta_Q_proportional_to_speed_times_angle(runs):
    """(a) ΔQ grows proportionally with V·β: linear fit over 40/120/200 km/h x 6/12/18 mrad, R² >= 0.95."""
    vb, dq = [], []
    for kmh in (40, 120, 200):
        for ang in (0.006, 0.012, 0.018):
            vb.append(kmh * KMH * ang)
            dq.append(runs(kmh, ang)["delta_Q"])
    vb, dq = np.array(vb), np.array(dq)
    slope, icpt = np.polyfit(vb, dq, 1)
    r2 = 1 - np.sum((dq - slope * vb - icpt) ** 2) / np.sum((dq - dq.mean()) ** 2)
    print(f"(a) slope {slope / 1e3:.0f} kN/(m/s), intercept {icpt / 1e3:.1f} kN, R2 {r2:.3f}")
    assert r2 >= 0.95 and slope > 0


def test_b_stiff_pad_raises_the_dynamic_sleeper_moment(runs):
    """(b) 12 mrad: at 200 km/h the transition sleeper's peak moment is clearly higher with
    1200 than with 120 MN/m pads (ratio >= 1.2); at 10 km/h the two are close.

    Partial disagreement, documented: the seed finds the quasi-static moments "more or less
    identical"; ours differ by ~16 % at 10 km/h, because the stiff pad spreads the wheel
    load over fewer sleepers (a static effect of the pad/ballast stiffness ratio that
    our beam model shows plainly). The test asserts the seed's point, that the speed adds
    a clear difference on top: the ratio grows by at least 0.1 from 10 to 200 km/h
    (measured: 1.16 -> 1.31).
    """
    hi = runs(200, 0.012, STIFF)["max_sleeper_moment"] / runs(200, 0.012, SOFT)["max_sleeper_moment"]
    lo = runs(10, 0.012, STIFF)["max_sleeper_moment"] / runs(10, 0.012, SOFT)["max_sleeper_moment"]
    print(f"(b) stiff/soft sleeper moment: 200 km/h {hi:.2f}, 10 km/h {lo:.2f}")
    assert hi >= 1.2
    assert abs(lo - 1) < 0.2
    assert hi - lo >= 0.1


def test_c_transition_pressure_vs_field_side(runs):
    """(c) Ballast pressure under the crossing transition vs the field side, at the instant of
    maximum sleeper moment (seed Fig. 6).

    Agreement: at 18 mrad and 200 km/h the crossing side exceeds the field side; at 6 mrad
    it stays below up to 120 km/h (and quasi-statically). Disagreement, documented: at
    6 mrad and 200 km/h our crossing side exceeds the field side (by ~15 %), the seed's
    stays below. Cause: the size of the nominal impact. The crossing-side pressure grows
    with ΔQ (test (d)) while the field side's does not; in our model the quasi-static
    crossing/field ratio is ~0.7 and the sides swap once ΔQ/Q0 exceeds ~0.45, which our
    nominal crossing reaches between 120 and 160 km/h (ΔQ/Q0 = 0.71 at 200 km/h). The
    seed's 6 mrad impact must stay below that; its vehicle and crossing data (its ref. [4])
    are not given in the paper, so the difference cannot be attributed further here.
    """
    def ratio(kmh, ang):
        r = runs(kmh, ang)
        return r["ballast_pressure_crossing_side_at_max_sleeper"] / r["ballast_pressure_field_side_at_max_sleeper"]

    r18, r6_200, r6_120, r6_10 = ratio(200, 0.018), ratio(200, 0.006), ratio(120, 0.006), ratio(10, 0.006)
    dq6 = runs(200, 0.006)["delta_Q"] / Q0
    print(f"(c) crossing/field: 18 mrad 200 km/h {r18:.2f}; 6 mrad: 200 km/h {r6_200:.2f} (dQ/Q0 {dq6:.2f}), "
          f"120 km/h {r6_120:.2f}, 10 km/h {r6_10:.2f}")
    assert r18 > 1.2
    assert r6_120 < 1.0 and r6_10 < 1.0
    # the documented disagreement, held to its stated size and cause
    assert 1.0 < r6_200 < 1.3 and dq6 > 0.45


def test_d_moments_grow_with_impact_angle(runs):
    """(d) At 200 km/h rail and sleeper moments (and the transition pressure) grow with the impact angle."""
    r = [runs(200, a) for a in (0.006, 0.012, 0.018)]
    for key in ("max_rail_moment", "max_sleeper_moment", "max_ballast_pressure_crossing_side"):
        vals = [x[key] for x in r]
        print(f"(d) {key}: {np.round(np.array(vals) / 1e3, 1)}")
        assert vals[0] < vals[1] < vals[2], (key, vals)
    # and above the quasi-static reference
    assert r[0]["max_sleeper_moment"] > runs(10, 0.006)["max_sleeper_moment"]


def test_figures_command_writes_the_seed_figures(tmp_path, monkeypatch, capsys):
    """`turnout figures` end to end on a reduced grid (2 speeds instead of 6): every figure
    file is written and the table has one row per run; a second call resumes (no run redone)."""
    from orchestrator.cli import main
    from orchestrator.studies import figures

    monkeypatch.setattr(figures, "SPEEDS_KMH", (80, 200))
    monkeypatch.chdir(REPO_ROOT)  # an installed package finds the bundled scenarios from here
    out = tmp_path / "figs"
    assert main(["figures", "--study", "seed001", "--out", str(out), "--no-progress"]) == 0
    for name in ("fig3_dQ.png", "fig4_rail.png", "fig5_sleeper.png", "fig6_pressure.png", "fig7_pads.png"):
        assert (out / name).stat().st_size > 10_000, name
    rows = (out / "seed001_table.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 2 * 3 * 2
    mtimes = {p: p.stat().st_mtime_ns for p in (out / "seed001_runs" / "runs").glob("*/result.json")}
    assert main(["figures", "--study", "seed001", "--out", str(out), "--no-progress"]) == 0
    assert all(p.stat().st_mtime_ns == m for p, m in mtimes.items())
