"""Surrogate calibration (DESIGN.md §5): parameters, surrogate and its CV, sensitivity and
narrowed bounds, bounded optimisation, the pipeline on a known objective, resume, the CLI,
and the recovery of hidden parameters from a synthetic measurement.

The fast pipeline tests use :func:`bowl_run`, a top-level (picklable) run function whose
objective is a known bowl in the parameters' unit coordinates, so the answer is exact and
the runs cost nothing; the recovery tests simulate (``scenarios/measurement``).
"""
from __future__ import annotations

import csv
import functools
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import SCENARIOS_DIR
from scipy.optimize import brentq

from orchestrator.cli import main
from orchestrator.inputs.causes import CATALOGUE
from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.scenario import load_scenario, scenario_from_dict
from orchestrator.inverse import calibrate as cal

MEASUREMENT = SCENARIOS_DIR / "measurement" / "crossing_quarter_120.yaml"
T = 21  # crossing transition sleeper of the measurement scenario (orchestrator.results.analysis.reference_point)

# The bowl's minimum, in parameter units (h1, h2, gap 3 of sleeper T [m]).
BOWL_TRUTH = {"h1": 0.6, "h2": 2.5, "gap3": 0.8e-3}
BOWL_FLOOR = 0.02  # J at the minimum (a noise floor, as nRMSE of 2 % noise)
BOWL_WEIGHTS = (4.0, 1.0, 0.05)  # curvature per axis: h1 sensitive, gap 3 nearly invisible


# --------------------------------------------------------------------------------------
# Run functions (top level: they cross process boundaries)
# --------------------------------------------------------------------------------------
def _bowl_units(scenario) -> np.ndarray:
    """Unit coordinates of (h1, h2, gap 3 at T) of a scenario, by the catalogue's maps."""
    gaps = next((v.gaps for v in scenario.track.ballast.voids if v.sleeper == T), (0.0,) * 6)
    h1 = CATALOGUE["ballast_stiffness"].to_unit([scenario.track.ballast.stiffness_scale])[0]
    h2 = CATALOGUE["rail_pad_stiffness"].to_unit([scenario.track.rail_pad.stiffness_scale])[0]
    g3 = CATALOGUE["ballast_void"].to_unit([gaps[2]] * 6)[0]
    return np.array([h1, h2, g3])


def _bowl_truth_units() -> np.ndarray:
    return np.array([CATALOGUE["ballast_stiffness"].to_unit([BOWL_TRUTH["h1"]])[0],
                     CATALOGUE["rail_pad_stiffness"].to_unit([BOWL_TRUTH["h2"]])[0],
                     CATALOGUE["ballast_void"].to_unit([BOWL_TRUTH["gap3"]] * 6)[0]])


def bowl_run(scenario, run_dir: Path, calls: Path | None = None) -> dict:
    """J = floor + sum_j w_j (u_j - u*_j)^2 and two 'channels'; counts its calls per run in ``calls``.

    A worker's run folder is its own temporary one (named after the run id), so the
    counter's folder is given (:func:`counted`).
    """
    if calls is None:
        raise TypeError("bowl_run needs calls=: use counted(bowl_run, tmp_path)")
    calls.mkdir(exist_ok=True)
    (calls / f"{run_dir.name}.{len(list(calls.glob(run_dir.name + '.*')))}").touch()
    d = _bowl_units(scenario) - _bowl_truth_units()
    return {"objective": BOWL_FLOOR + float(np.dot(BOWL_WEIGHTS, d * d)),
            "nrmse.A1": BOWL_FLOOR + abs(float(d[0])), "nrmse.B1": BOWL_FLOOR + abs(float(d[1]))}


def bowl_polish_run(scenario, run_dir: Path, calls: Path | None = None) -> dict:
    """As bowl_run, and its residual vector r with |r|^2 = J (what the polish's least squares reads)."""
    d = _bowl_units(scenario) - _bowl_truth_units()
    np.save(run_dir / cal.RESIDUALS_FILE, np.concatenate([np.sqrt(BOWL_WEIGHTS) * d, [np.sqrt(BOWL_FLOOR)]]))
    return bowl_run(scenario, run_dir, calls)


def failing_bowl_run(scenario, run_dir: Path, calls: Path | None = None) -> dict:
    """As bowl_run, but raises for the runs with h1 above its geometric mid-range (about half)."""
    if scenario.track.ballast.stiffness_scale > 1.0:
        raise RuntimeError("diverged")
    return bowl_run(scenario, run_dir, calls)


def counted(run_fn, tmp: Path):
    """``run_fn`` counting its calls in ``tmp/calls`` (a picklable partial)."""
    return functools.partial(run_fn, calls=tmp / "calls")


def _calls(tmp: Path) -> dict[str, int]:
    out: dict[str, int] = {}
    for f in (tmp / "calls").glob("*"):
        rid = f.name.split(".")[0]
        out[rid] = out.get(rid, 0) + 1
    return out


# --------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def measurement():
    return load_scenario(MEASUREMENT)


def test_default_parameters_are_seed_000s_eight(measurement):
    ps = cal.parse_params(None, measurement)
    assert [p.name for p in ps] == [f"gap{i}@{T}" for i in range(1, 7)] + ["h1", "h2"]
    assert all(p.sleeper == T and p.bounds == (0.0, CATALOGUE["ballast_void"].upper[0]) and not p.log
               for p in ps[:6])
    assert ps[6].bounds == (0.2, 5.0) and ps[6].log
    assert ps[7].bounds == (0.05, 20.0) and ps[7].log
    # log scale: the middle of the unit interval is the geometric mean of the bounds
    assert ps[6].from_unit(0.5) == pytest.approx(1.0, rel=1e-12)  # sqrt(0.2 * 5); round-off only
    assert ps[7].to_unit(ps[7].from_unit(0.3)) == pytest.approx(0.3, abs=1e-12)  # round trip; round-off only


def test_parameter_syntax(measurement):
    ps = cal.parse_params("h1=0.5:2, gap2@T+1=0:2e-3, pad@T-1, track.rail_pad.damping=1e4:4e4, angle", measurement)
    assert [p.name for p in ps] == ["h1", f"gap2@{T + 1}", f"pad@{T - 1}", "track.rail_pad.damping", "angle"]
    assert ps[0].bounds == (0.5, 2.0) and ps[0].log  # the catalogue's log scale is kept
    assert ps[1].bounds == (0.0, 2e-3) and ps[1].index == 1
    assert ps[3].bounds == (1e4, 4e4) and not ps[3].log and ps[3].key == "track.rail_pad.damping"
    # every parameter reaches the scenario, and the others keep their values
    values = [1.5, 1.2e-3, 3.0, 2.5e4, 0.01]
    raw = cal.apply_values(measurement.raw, ps, values)
    s = scenario_from_dict(raw, base_dir=MEASUREMENT.parent)
    assert s.track.ballast.stiffness_scale == 1.5
    assert [(v.sleeper, v.gaps) for v in s.track.ballast.voids] == [(T + 1, (0.0, 1.2e-3, 0.0, 0.0, 0.0, 0.0))]
    assert [(o.sleeper, o.stiffness_scale) for o in s.track.rail_pad.overrides] == [(T - 1, 3.0)]
    assert s.track.rail_pad.damping == 2.5e4 and s.track.impact_angle == 0.01
    assert s.track.rail_pad.stiffness_scale == measurement.track.rail_pad.stiffness_scale


@pytest.mark.parametrize("spec, words", [
    ("h3", ["h3", "unknown"]),
    ("gaps", ["gaps", "sleeper"]),
    ("h1@21", ["global"]),
    ("gaps@40", ["sleeper 40", "0..39"]),
    ("gaps@X", ["index or T"]),
    ("h1=2:1", ["LO < HI"]),
    ("h1=0:1:log", ["log scale needs LO > 0"]),
    ("h1=a:b", ["numbers"]),
    ("track.ballast.stiffness_scale", ["needs bounds"]),
    ("track.ballast.stifness=1:2", ["track.ballast.stifness"]),
    ("track.layout.route=1:2", ["track.layout.route", "through"]),
    ("h1,h1", ["h1 given twice"]),
    ("h1,track.ballast.stiffness_scale=0.5:2", ["both by name and as a key"]),
    ("h1,,h2", ["empty item"]),
])
def test_bad_parameters_are_user_errors(measurement, spec, words):
    with pytest.raises(UserInputError) as err:
        cal.parse_params(spec, measurement)
    assert all(w in str(err.value) for w in words), str(err.value)


# --------------------------------------------------------------------------------------
# Surrogate, optimisation, sensitivity
# --------------------------------------------------------------------------------------
def _smooth(U):
    return np.sin(3 * U[:, 0]) + (U[:, 1] - 0.4) ** 2 + 0.5 * U[:, 0] * U[:, 2]


def test_surrogate_interpolates_a_smooth_function_and_its_cv_error_says_how_well():
    U = cal._lhs(3, 200, seed=1)
    s = cal.fit_surrogate(U, _smooth(U), ["f"])
    V = cal._lhs(3, 500, seed=2)
    err = np.sqrt(np.mean((s(V) - _smooth(V)) ** 2))
    # 200 points of a smooth function in 3-D: held-out error ~5 % of the spread (measured 0.049; the
    # thin-plate spline converges about as 1/n here: 0.097 at 100 points, 0.026 at 400)
    assert s.cv_rel[0] < 0.1, s.cv_rel
    # the CV error is an honest estimate of the error at new points (within a factor 3 either way)
    assert s.cv_rmse[0] / 3 < err < 3 * s.cv_rmse[0], (err, s.cv_rmse)


def test_noisy_data_get_smoothing_and_a_cv_error_near_the_noise():
    rng = np.random.default_rng(0)
    U = cal._lhs(3, 300, seed=3)
    sigma = 0.05
    s = cal.fit_surrogate(U, _smooth(U) + rng.normal(0, sigma, 300), ["f"])
    assert s.smoothing > 0  # interpolating noise is worse in cross-validation than smoothing it
    # held-out error cannot beat the noise, and a good smoother is not much worse than it
    assert 0.9 * sigma < s.cv_rmse[0] < 1.5 * sigma, s.cv_rmse
    V = cal._lhs(3, 500, seed=4)
    # the smoothed surface is closer to the truth than the noise (averaging over neighbours)
    assert np.sqrt(np.mean((s(V) - _smooth(V)) ** 2)) < sigma


def test_vector_surrogate_and_log_fit():
    U = cal._lhs(2, 120, seed=5)
    Y = np.column_stack([np.exp(3 * U[:, 0]), 1 + U[:, 1] ** 2])
    s = cal.fit_surrogate(U, Y, ["a", "b"], transform="log")
    assert s(U[:4]).shape == (4, 2) and s.names == ["a", "b"]
    V = cal._lhs(2, 50, seed=6)
    Yv = np.column_stack([np.exp(3 * V[:, 0]), 1 + V[:, 1] ** 2])
    rel = np.max(np.abs(s(V) / Yv - 1), axis=0)
    # log(exp(3 u0)) is linear, in the spline's polynomial tail: exact to round-off (1e-9)
    assert rel[0] < 1e-9, rel
    # log(1 + u1^2) is smooth, not polynomial: 120 points in 2-D give a few 1e-3 at worst (measured
    # 3.8e-3, at a point near the cube's edge)
    assert rel[1] < 1e-2, rel


def test_bounded_minimisation_finds_interior_and_boundary_minima():
    c = np.array([0.3, 1.4])  # second coordinate's minimum lies outside the box: the bound is active

    def f(U):
        return np.sum((np.atleast_2d(U) - c) ** 2, axis=1) + 0.1 * np.atleast_2d(U)[:, 0] ** 4

    u, value, runs = cal.minimise_surrogate(f, [0, 0], [1, 1], np.array([[0.9, 0.1], [0.1, 0.5]]))
    assert len(runs) == 2
    # interior-point iterates approach the active bound as the barrier goes to 0: 1e-5 is far above its tolerance
    assert u[1] == pytest.approx(1.0, abs=1e-5)
    # stationarity in u0: 2 (u0 - 0.3) + 0.4 u0^3 = 0; 1e-5: the finite-difference gradient's accuracy
    u0 = brentq(lambda x: 2 * (x - 0.3) + 0.4 * x ** 3, 0.0, 1.0)
    assert u[0] == pytest.approx(u0, abs=1e-5)


def test_sensitivity_narrows_the_sensitive_axis_only():
    def f(U):
        U = np.atleast_2d(U)
        return 10 * (U[:, 0] - 0.3) ** 2 + 1e-3 * U[:, 1]

    U = cal._lhs(2, 100, seed=7)
    y = f(U)
    tau = 0.1
    sens = cal.sensitivity(f, np.array([0.3, 0.0]), U, y, tau)
    # profile of u0: 10 (u - 0.3)^2 <= tau -> |u - 0.3| <= 0.1; the best runs lie inside; plus the 0.05 margin
    assert sens["lower"][0] == pytest.approx(0.15, abs=0.011)  # 0.01: profile grid step
    assert sens["upper"][0] == pytest.approx(0.45, abs=0.011)
    assert (sens["lower"][1], sens["upper"][1]) == (0.0, 1.0)  # the profile is flat to 1e-3 < tau: whole range
    assert sens["share"][0] > 0.99  # 0.9 against 0.001


# --------------------------------------------------------------------------------------
# The pipeline on a known objective; resume
# --------------------------------------------------------------------------------------
BOWL_PARAMS = f"h1,h2,gap3@{T}"


def test_pipeline_finds_the_minimum_of_a_known_objective(tmp_path):
    out = tmp_path / "out"
    res = cal.calibrate(MEASUREMENT, None, out, params=BOWL_PARAMS, n1=40, n2=30, seed=1, workers=2,
                        progress=False, run_fn=counted(bowl_run, tmp_path), polish_fn=counted(bowl_polish_run, tmp_path))
    s = json.loads((out / "calibration.json").read_text())
    assert s["runs"] == {"stage1": 40, "stage2_lhs": 30, "stage2_corners": 8, "total": 78, "without_objective": 0,
                         "done": 78, "already_finished": 0}
    # the CV error is reported relative to J's spread; 78 points of a log-fitted bowl in 3-D hold out to
    # ~15 % (measured 0.15-0.17: log J is sharp at the floor), far below 1 (no better than J's mean)
    assert s["surrogate"]["cv_rel"] < 0.3
    truth = _bowl_truth_units()
    # h1, h2 carry curvature w = 4 and 1: a surrogate error eps near the minimum moves the minimiser by up
    # to sqrt(eps / w); the local CV error (~0.007) gives 0.04 (h1) and 0.08 (h2); measured 0.004 and 0.016
    assert s["surrogate"]["local_cv_rmse"] < 0.02
    u_opt = np.array(list(s["optimum"]["u"].values()))
    assert abs(u_opt[0] - truth[0]) < 0.02 and abs(u_opt[1] - truth[1]) < 0.04, (u_opt, truth)
    # the polish (least squares on the runs' residuals) lands on the bowl's minimum on every axis, gap 3 too,
    # which the surrogate cannot see: the residuals are linear in u, so the forward differences are exact
    # and only the start's 1e-3 margin and round-off remain (1e-6 in the unit cube)
    assert s["polish"]["done"] and s["calibrated"]["source"] == "polish"
    assert np.allclose(res.u, truth, atol=1e-6), (res.u, truth)
    assert s["polish"]["cost"] == pytest.approx(BOWL_FLOOR, rel=1e-9) and s["objective_after"] == \
        pytest.approx(BOWL_FLOOR, rel=1e-9)
    # two starts (surrogate optimum, nominal), each converging in a few trust-region steps of 1 + 3 runs
    # (linear residuals: Gauss-Newton is exact once the trust region admits the step), far below max_nfev
    assert set(s["polish"]["starts"]) == {"surrogate optimum", "nominal"}
    assert all(v["runs"] <= 6 * (3 + 1) for v in s["polish"]["starts"].values()), s["polish"]["starts"]
    # narrowed bounds: h1 (sensitive) narrowed, gap 3 (weight 0.05, J rises < tau over the range) kept whole
    lo, hi = np.array(list(s["bounds"]["stage2_unit"].values())).T
    assert hi[0] - lo[0] < 0.6 and lo[0] <= truth[0] <= hi[0]
    assert (lo[2], hi[2]) == (0.0, 1.0)
    # the confirmation run reproduces the surrogate's prediction (same bowl): 1e-3 absolute on J ~ 0.02
    assert s["optimum"]["confirmed_objective"] == pytest.approx(s["optimum"]["predicted_objective"], abs=1e-3)
    # the calibrated scenario loads and carries the values
    calibrated = load_scenario(out / "calibrated.yaml")
    assert calibrated.track.ballast.stiffness_scale == pytest.approx(res.values["h1"], rel=1e-12)
    assert {"calibration_cv.png", "calibration_sensitivity.png"} <= {p.name for p in out.glob("*.png")}
    assert "| h1 |" in (out / "report.md").read_text()


def test_resume_does_not_redo_finished_runs(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(cal.CalibrationIncomplete, match="rerun the same command"):
        cal.calibrate(MEASUREMENT, None, out, params=BOWL_PARAMS, n1=30, n2=12, seed=2, workers=2, progress=False,
                      run_fn=counted(failing_bowl_run, tmp_path), polish_fn=counted(bowl_polish_run, tmp_path))
    first = _calls(tmp_path)
    finished = {p.parent.name for p in (out / "stage1" / "runs").glob("*/result.json")}
    assert 0 < len(finished) < 30 and set(first) == finished  # some runs failed, the others are stored
    res = cal.calibrate(MEASUREMENT, None, out, params=BOWL_PARAMS, n1=30, n2=12, seed=2, workers=2, progress=False,
                        run_fn=counted(bowl_run, tmp_path), polish_fn=counted(bowl_polish_run, tmp_path))
    assert res.summary["polish"]["done"]
    assert res.stages["stage1"].skipped == len(finished) and res.stages["stage1"].done == 30 - len(finished)
    calls = _calls(tmp_path)
    assert all(calls[r] == 1 for r in finished)  # a finished run is never redone
    assert len(calls) > 30 + 12 + 8 + 2  # design, corners, confirmation: and the polish's runs are counted too
    with open(out / "stage1" / "sweep.csv", newline="") as f:
        ids = [row["run_id"] for row in csv.DictReader(f)]
    assert len(ids) == 30 == len(set(ids))  # each run exactly once
    # a third call redoes nothing at all
    again = cal.calibrate(MEASUREMENT, None, out, params=BOWL_PARAMS, n1=30, n2=12, seed=2, workers=2,
                          progress=False, run_fn=counted(bowl_run, tmp_path), polish_fn=counted(bowl_polish_run, tmp_path))
    assert again.stages["stage1"].done == again.stages["stage2"].done == 0
    assert _calls(tmp_path) == calls  # ... the polish's runs included: its iteration replays from disk
    assert np.array_equal(again.u, res.u)


def test_result_round_trips_through_its_json(tmp_path):
    """calibration.json is CalibrationResult.to_json, and from_json gives back the same result."""
    out = tmp_path / "out"
    res = cal.calibrate(MEASUREMENT, None, out, params=BOWL_PARAMS + ",track.rail_pad.damping=1e4:4e4", n1=12,
                        n2=6, seed=3, workers=1, progress=False, run_fn=counted(bowl_run, tmp_path), polish=0)
    text = (out / "calibration.json").read_text()
    assert res.to_json() == text
    back = cal.CalibrationResult.from_json(text, out)
    assert back.to_json() == text  # the file format survives the round trip to the letter
    assert back.params == res.params and back.values == res.values and back.summary == res.summary
    assert back.scenario_file == res.scenario_file == out / "calibrated.yaml" and back.stages == {}
    # u is stored for the surrogate optimum and the polish (exact); a best run's is its values mapped back, which
    # round-off alone moves (1e-12 in the unit cube)
    assert np.allclose(back.u, res.u, rtol=0, atol=1e-12), (back.u, res.u)
    assert cal.CalibrationResult.read(out).to_json() == text


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("extra, words", [
    (["--measured", "nope.csv"], ["nope.csv", "no such file"]),
    (["--measured", "X", "--params", "h9"], ["h9"]),
    (["--measured", "X", "--n1", "0"], ["--n1", ">= 1"]),
    (["--measured", "X", "--n1", "5"], ["n1 = 5", "too small", "8 parameters"]),
    (["--measured", "X", "--polish", "-1"], ["--polish", ">= 0"]),
    ([], ["--measured"]),
])
def test_cli_bad_input_is_one_line_exit_2(tmp_path, capsys, extra, words):
    measured = tmp_path / "m.csv"
    measured.write_text("time,A1\n0,1\n")
    extra = [str(measured) if e == "X" else e for e in extra]
    code = main(["calibrate", str(MEASUREMENT), "--out", str(tmp_path / "o"), "--no-progress", *extra])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and err.startswith("turnout: error:"), err
    assert all(w in err for w in words), err


def test_cli_delegates(monkeypatch, tmp_path, capsys):
    seen = {}

    def fake(base_path, measured, out_dir, **kw):
        seen.update(base_path=base_path, measured=measured, out_dir=out_dir, **kw)
        return cal.CalibrationResult([], {}, np.zeros(0), {"objective_before": 1.0, "objective_after": 0.1},
                                     Path(out_dir), Path(out_dir) / "calibrated.yaml", {})

    monkeypatch.setattr(cal, "calibrate", fake)
    code = main(["calibrate", str(MEASUREMENT), "--measured", "m.csv", "--params", "h1,h2", "--n1", "30", "--n2",
                 "20", "--seed", "3", "--workers", "1", "--scheduler", "tcp://h:8786", "--out", str(tmp_path),
                 "--no-progress"])
    assert code == 0 and "J 1 -> 0.1" in capsys.readouterr().out
    assert seen == dict(base_path=MEASUREMENT, measured=Path("m.csv"), out_dir=tmp_path, params="h1,h2", n1=30,
                        n2=20, seed=3, workers=1, scheduler="tcp://h:8786", progress=False, polish=15)


# --------------------------------------------------------------------------------------
# Recovery of hidden parameters from a synthetic measurement (real simulations)
# --------------------------------------------------------------------------------------
def _synthetic(tmp_path: Path, h1: float, h2: float, gaps) -> Path:
    from orchestrator.inverse.synthetic import Effect, synthesize

    base = load_scenario(MEASUREMENT)
    raw = cal.apply_values(base.raw, cal.parse_params("h1,h2", base), [h1, h2])
    truth = scenario_from_dict(raw, source=str(MEASUREMENT), base_dir=MEASUREMENT.parent)
    path = tmp_path / "measured.csv"
    synthesize(truth, Effect("ballast_void", T, {"gaps": list(gaps)}), path, seed=11)
    return path


SMALL_TRUTH = {"h1": 0.6, "h2": 2.0, "gap3": 0.8e-3}
SMALL_PARAMS = "h1=0.3:1.5,h2=0.5:5,gap3@T=0:2e-3"  # a factor 2-3 around nominal, voids up to 2 mm (log scales kept)


def test_small_calibration_recovers_hidden_parameters(tmp_path):
    """h1, h2 and one void gap, in bounds an engineer would give, from 40 + 30 + 8 runs (1 % noise)."""
    t = SMALL_TRUTH
    measured = _synthetic(tmp_path, t["h1"], t["h2"], [0, 0, t["gap3"], 0, 0, 0])
    out = tmp_path / "cal"
    res = cal.calibrate(MEASUREMENT, measured, out, params=SMALL_PARAMS, n1=40, n2=30, seed=0, workers=2,
                        progress=False)
    s = res.summary
    assert s["runs"]["total"] == 78
    assert 0 < s["surrogate"]["cv_rel"] < 0.5  # reported; measured 0.17 (J's spread is 0.02-0.9)
    v = res.values
    # measured: h1 +0.8 %, h2 +1.8 %, gap 3 +0.004 mm; the tolerances leave room for another noise draw
    # (1 % noise on every channel, more on the displacements integrated from noisy accelerations: J's floor is
    # ~0.015-0.02, and a J error of 0.01 moves the scales by a few %)
    assert v["h1"] == pytest.approx(t["h1"], rel=0.05)
    assert v["h2"] == pytest.approx(t["h2"], rel=0.05)
    assert v[f"gap3@{T}"] == pytest.approx(t["gap3"], abs=0.05e-3)
    # the calibrated model is at the noise floor: J <= 1.5 x 0.02 (measured 0.019 from 0.58 nominal)
    assert s["objective_after"] < 0.03 < s["objective_before"]
    # the surrogate's prediction at its optimum is within its local CV error band of the simulated J (0.008 vs 0.019)
    assert abs(s["optimum"]["predicted_objective"] - s["optimum"]["confirmed_objective"]) < \
        2 * s["surrogate"]["local_cv_rmse"]
    assert (out / "calibration_signals.png").is_file()


FULL_TRUTH = {"gaps": (0.30e-3, 0.70e-3, 0.90e-3, 0.60e-3, 0.25e-3, 0.05e-3), "h1": 0.7, "h2": 1.8}  # as the benchmark
# Tolerances of the recovery (1 % noise on every channel, synthetic.DEFAULT_NOISE). The surrogate alone does not get there: in
# benchmarks/bench_calibrate.py (RESULTS.md) the 8-D spline holds out to ~30 % of J's spread and its optimum had
# gaps off by up to 1 mm. The polish (least squares on real runs) recovered, from that optimum and also from the
# nominal model, every gap within 0.002 mm and h1, h2 within 1 %, at the noise floor. The tolerances are 50x the
# gap error and 5x the scale error measured, so that another noise draw or start passes, and still far inside
# what separates a void from none: 0.1 mm is 2.5 % of the 0-4 mm bounds and a sixth of the mean true gap.
FULL_GAP_TOL = 0.1e-3  # m
FULL_SCALE_TOL = {"h1": 0.05, "h2": 0.05}  # relative
FULL_J_FACTOR = 0.05  # J_after / J_before: at the noise floor (measured 0.0145 of 0.89 nominal)


def test_polish_alone_recovers_the_eight_parameters_from_the_nominal_model(tmp_path):
    """Stage 7 by itself on seed 000's 8 parameters: from the nominal model (no void, h1 = h2 = 1) to the truth.

    The default suite cannot afford the 1256-run design; this is the step that identifies the gaps
    (the slow test and the benchmark run the whole pipeline).
    """
    import functools

    from orchestrator.cosim.sensing import simulate_sensors
    from orchestrator.inputs.sensor_layout import layout_of
    from orchestrator.inverse.objective import Target

    t = FULL_TRUTH
    measured = _synthetic(tmp_path, t["h1"], t["h2"], t["gaps"])
    out = tmp_path / "cal"
    out.mkdir()
    scenario = cal._snapshot(load_scenario(MEASUREMENT), out)
    params = cal.parse_params(None, scenario)
    target = Target.read(measured, layout_of(scenario))
    nominal = simulate_sensors(scenario, target.layout, reconstruct=False)
    shift = float(target.align_to(nominal.t, nominal.signals))
    fn = functools.partial(cal.objective_run, measured=str(measured), shift=shift, save_residuals=True)
    u0 = np.array([p.to_unit(v) for p, v in zip(params, [0.0] * 6 + [1.0, 1.0])])
    found = cal._polish(out / cal.BASE_FILE, scenario.raw, params, {"nominal": u0}, out / "polish", fn,
                        cal.POLISH_MAX_NFEV, 2, None, False)
    values = dict(zip([p.name for p in params], cal._values(params, found["u"])))
    gaps = np.array([values[f"gap{i}@{T}"] for i in range(1, 7)])
    assert np.abs(gaps - np.array(t["gaps"])).max() < FULL_GAP_TOL, gaps
    assert values["h1"] == pytest.approx(t["h1"], rel=FULL_SCALE_TOL["h1"])
    assert values["h2"] == pytest.approx(t["h2"], rel=FULL_SCALE_TOL["h2"])
    # J's noise floor is ~0.015 (measured at the truth); the nominal model is at ~0.9
    assert found["objective"] < 0.03 and found["cost"] < 0.01 * found["cost_start"]


@pytest.mark.slow
def test_full_calibration_recovers_seed_000s_eight_parameters(tmp_path):
    """6 void gaps + h1 + h2 from 500 + 500 + 256 runs and the polish (as benchmarks/bench_calibrate.py; ~25 min)."""
    t = FULL_TRUTH
    measured = _synthetic(tmp_path, t["h1"], t["h2"], t["gaps"])
    res = cal.calibrate(MEASUREMENT, measured, tmp_path / "cal", n1=500, n2=500, seed=0, workers=2, progress=False)
    s = res.summary
    assert s["runs"]["total"] == 1256 and s["polish"]["done"]
    assert 0 < s["surrogate"]["cv_rel"] < 1  # reported (RESULTS.md); < 1: the spline predicts better than J's mean
    gaps = np.array([res.values[f"gap{i}@{T}"] for i in range(1, 7)])
    assert np.abs(gaps - np.array(t["gaps"])).max() < FULL_GAP_TOL
    assert res.values["h1"] == pytest.approx(t["h1"], rel=FULL_SCALE_TOL["h1"])
    assert res.values["h2"] == pytest.approx(t["h2"], rel=FULL_SCALE_TOL["h2"])
    assert s["objective_after"] < FULL_J_FACTOR * s["objective_before"]
