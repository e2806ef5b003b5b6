"""Tests of ``turnout diagnose`` (issues 4 and 14; DESIGN.md §4.5).

Default suite (issue 14's fast subset): four field-like cases whose truth comes from a *different*
model than the one diagnosed — a null with a vehicle mismatch (drawn wheelset mass, k1, c1, damping, a
finer step; it is also the 3 % faster passage that once ended in a traceback), one void, a void two
sleepers beyond the sensors, and a void with a soft pad next to it (two effects; these three through a
wheelset 5 % heavier and half the time step) —,
plus unit tests of the significance rule, the
intervals and the non-finite handling against independent references. The same-model hidden-effect
cases of issue 4 below are ``slow``.

Same-model hidden-effect cases (``slow``): a seeded generator
(:func:`orchestrator.inverse.synthetic.hidden_effect`) draws an effect —
type, sleeper, magnitude — that only the test knows; the synthetic measurement
carries it plus 1 % white noise and an unknown trigger time. The diagnosis gets the
nominal scenario and the file, nothing else, and must

- name the cause (for a local cause: the sleeper exactly, or an ambiguity set of at
  most 2 sleepers that contains it); ``none`` for noise only;
- recover the effect's parameters within the tolerances below;
- reach a gain of at least 80 %; for a void, at least 70 % on a second passage at
  another speed that it did not fit (validation).

Parameter tolerances, and why:

- stiffness factors (bed h1, pads global or of one sleeper): 10 % — with 1 % noise
  the fit's own scatter is ~1 %; the margin covers the screening grid's interpolation
  when the fit stops early;
- impact angle: 1.5 mrad — the fit runs to ~0.1 mrad; the dipped-nose geometry makes
  the force rise with the angle only through the impact velocity, which the 2.5 kHz
  sampling resolves coarsely;
- ballast void: the six gaps are not all observable (a sleeper carries one or two
  accelerometers, at the rail seats): the test checks the gap *under the instrumented
  rail seat* (the profile interpolated there) within 0.25 mm, and the largest gap
  within 0.5 mm.
"""
import numpy as np
import pytest
import yaml

from orchestrator.inputs.scenario import bundled_scenario, load_scenario
from orchestrator.inputs.sensor_layout import layout_of, resolve
from orchestrator.inputs.errors import UserInputError
from orchestrator.inverse.diagnose import diagnose, hypothesis_gains
from orchestrator.inverse.synthetic import hidden_effect, synthesize
from track.model import build_track

SCENARIO = bundled_scenario("measurement/crossing_quarter_120.yaml")
VALIDATION_SPEED = 27.78      # m/s (100 km/h): the second passage of the void case
GAIN_MIN = 0.80
VALIDATION_GAIN_MIN = 0.70
SCALE_RTOL = 0.10
ANGLE_ATOL = 1.5e-3           # rad
SEAT_GAP_ATOL = 0.25e-3       # m
PEAK_GAP_ATOL = 0.5e-3        # m


@pytest.fixture(scope="module")
def setup():
    sc = load_scenario(SCENARIO)
    model = build_track(sc.track)
    sensors = resolve(layout_of(sc), model)
    sleepers = sorted({int(s.body.split("_")[1]) for s in sensors if s.body.startswith("sleeper_")})
    return sc, model, sensors, sleepers


def _gap_at(gaps, sleeper_body, y):
    ys = np.linspace(sleeper_body.coords()[0], sleeper_body.coords()[-1], len(gaps))
    return float(np.interp(y, ys, gaps))


# ------------------------------------------------------------------------------------ field-like (default suite)
def _field_passage(tmp_path, name: str) -> tuple[dict, object]:
    """A field-like passage (:mod:`orchestrator.inverse.fieldlike`: coloured noise and drift entering the
    accelerations before the displacement reconstruction, an unknown trigger) whose truth is another model.

    ``null_fast``: no track effect; the vehicle's wheelset mass, k1, c1 drawn within +-20 %, damping and
    a finer step drawn, and the passage 3 % faster than the scenario over the nominal 0.16 s — so the record
    reaches 2.6 ms past the end of the nominal run (the case that once ended in the PCHIP traceback).
    ``void_mild``: a void on an instrumented sleeper (a shape that is not a wedge, off the screening grid);
    ``two``: a void and a soft pad on the sleeper next to it; both through a mild mismatch (wheelset mass
    +5 %, half the time step: the discretisation error does not cancel). ``void_far``: a void two sleepers
    beyond the last instrumented one, through the same mild mismatch.
    Returns (the hidden case, for the test only; the measured file's path).
    """
    import copy
    from dataclasses import replace

    from orchestrator.inputs.scenario import scenario_from_dict
    from orchestrator.inverse.fieldlike import Mismatch, draw_case, synthesize_case

    sc = load_scenario(SCENARIO)
    out = tmp_path / "passage.csv"
    if name == "null_fast":
        raw = copy.deepcopy(sc.raw)
        raw["simulation"]["duration"] = 0.165          # 0.165 / 1.03 = 0.16 s of the faster truth
        long = scenario_from_dict(raw, source=str(SCENARIO), base_dir=SCENARIO.parent)
        case = draw_case(1, "null_vehicle")
        case = replace(case, mismatch=replace(case.mismatch, speed=1.03))
        return synthesize_case(long, case, out, crop=0.0)["case"], out
    mild = Mismatch({"wheelset_mass": 1.05}, 1.0, 1.0, 1.0, 2)
    if name == "void_far":   # the matrix's void_off_sensor seed 7202: a void on sleeper 25
        return synthesize_case(sc, replace(draw_case(7202, "void_off_sensor"), mismatch=mild), out)["case"], out
    family = "void_sensor" if name == "void_mild" else "two_void_pad"
    return synthesize_case(sc, replace(draw_case(1, family), mismatch=mild), out)["case"], out


def test_faster_passage_with_vehicle_mismatch_is_never_a_track_cause(tmp_path):
    """Issue 14's null with a vehicle mismatch and its traceback case at once: no track effect, another
    vehicle, a passage 3 % faster whose record reaches past the nominal run. The answer is ``none`` or
    ``unexplained`` (never a track cause) and, if ``unexplained``, says where (channels, a time window inside
    the record, a frequency band), if ``none``, what the record resolves (a limit per screened void site); some
    samples lay outside the simulated window and were masked, not a traceback."""
    case, passage = _field_passage(tmp_path, "null_fast")
    result = diagnose(SCENARIO, passage, tmp_path / "out", progress=False).to_json()
    a = result["answer"]
    print(f"\nnull_fast: {case['mismatch']}; answer {a['kind']}: {a['reason']}; {result['runs']} runs, "
          f"{result['wall_seconds']:.0f} s")
    assert a["kind"] in ("none", "unexplained") and not a["causes"], a
    assert result["named_cause"]["cause"] == a["kind"]
    from orchestrator.inputs.measured import read_measured

    measured = read_measured(passage, layout_of(load_scenario(SCENARIO)).types)
    assert result["baseline"]["n"] < measured.t.size * len(measured.channels)   # samples outside were masked ...
    assert any(d["stage"] == "baseline" and "outside the simulated window" in d["reason"]
               for d in result["dropped"]), result["dropped"]                   # ... and the answer says so
    if a["kind"] == "unexplained":
        w = a["where"]
        assert w["channels"] and measured.t[0] <= w["time_window"][0] < w["time_window"][1] <= measured.t[-1], w
        assert 0 <= w["band_hz"][0] < w["band_hz"][1], w
    report = (tmp_path / "out" / "report.md").read_text(encoding="utf-8")
    assert report.startswith("# Diagnosis")
    if a["kind"] == "none":   # what the record resolves: every screened void site, a limit within its grid
        voids = {r["sleeper"]: r for r in a["resolution"] if r["cause"] == "ballast_void" and r["proxy"] == "uniform"}
        assert sorted(voids) == list(range(18, 25)), voids
        assert all(r["limit"] is None or 0 < r["limit"] <= r["screened_to"] for r in voids.values()), voids
        assert "were not screened" in a["reason"] and "## What this record resolves" in report


def _named_right(named: dict, effect: dict) -> bool:
    """A named cause is the hidden effect: same cause, and for a local one the sleeper in an ambiguity set of <= 2."""
    if named["cause"] != effect["cause"]:
        return False
    if effect["sleeper"] is None:
        return "sleeper" not in named
    amb = named["ambiguity"]["sleepers"]
    return effect["sleeper"] in amb and len(amb) <= 2


def _check_uncertainty(named: dict) -> None:
    """A named cause's intervals: one per parameter entry, ordered, inside the cause's bounds and around the
    fitted value (the interval is centred on it in the unit cube, then clipped); unidentified entries come
    with the sensor that would pin them."""
    from orchestrator.inputs.causes import CATALOGUE

    kind = CATALOGUE[named["cause"]]
    u = named["uncertainty"]
    values = kind.values_of(named["parameters"])
    assert len(u["intervals"]) == len(values) == len(u["identifiable"])
    for v, (lo, hi), lb, ub in zip(values, u["intervals"], kind.lower, kind.upper):
        assert lb - 1e-12 <= lo <= v * (1 + 1e-9) + 1e-12 and v * (1 - 1e-9) - 1e-12 <= hi <= ub + 1e-12, (v, lo, hi)
    assert len(u["pin_with"]) >= (not all(u["identifiable"])), u


def test_void_through_another_model_is_named_with_its_sleeper(tmp_path):
    """One void on an instrumented sleeper (a non-wedge shape, off the screening grid) seen through another
    model (wheelset mass +5 %, half the time step) and the field chain:
    ``named``, first cause the void with its sleeper (exact or an ambiguity set of <= 2), a gain of at least
    50 % (issue 14's floor with model-form mismatch), intervals for its six gaps."""
    case, passage = _field_passage(tmp_path, "void_mild")
    result = diagnose(SCENARIO, passage, tmp_path / "out", progress=False).to_json()
    a = result["answer"]
    print(f"\nvoid: truth {case['effects']}; answer {a['kind']}: {a['reason']}; {result['runs']} runs, "
          f"{result['wall_seconds']:.0f} s")
    assert a["kind"] == "named" and _named_right(a["causes"][0], case["effects"][0]), a
    assert result["named_cause"] == a["causes"][0]
    assert result["gain"]["total"] >= 0.5, result["gain"]
    assert not result["settings"]["looked_further"]   # named near the sensors: no run beyond them (step 3b)
    _check_uncertainty(a["causes"][0])
    # hypothesis_gains (what benchmarks/bench_diagnose_field.py --truth-gain uses): a consistency check, two code
    # paths of ours -- the named cause as a hypothesis on the same reference (the same nominal run and nuisance
    # fit) gives the diagnosis's own gain; 1e-9: the same runs, the parameters round-tripped through JSON exactly,
    # the only difference the order in which the two paths may sum a channel's residual. The hypothesis is the
    # cause as step 5c found it (its values before step 5c, a void is not fitted again in step 5d). Step 5c of a
    # hypothesis has no joint path (its values are given, not fitted): when the diagnosis kept its joint refit,
    # that point is one the hypothesis lacks among the same others, so its gain can only be lower
    hyp = [{**c, "parameters": c["evidence"].get("refit_nuisance", {}).get("parameters_before", c["parameters"])}
           for c in a["causes"]]
    got = hypothesis_gains(SCENARIO, passage, [hyp], tmp_path / "hyp", workers=2)
    if result["nuisance"].get("refit", {}).get("causes"):    # the joint refit kept
        assert got["hypotheses"][0]["gain"] <= result["gain"]["total"] + 1e-9, (got, result["gain"])
    else:
        assert got["hypotheses"][0]["gain"] == pytest.approx(result["gain"]["total"], abs=1e-9), (got, result["gain"])
    assert got["objective_nominal"] == pytest.approx(result["baseline"]["objective"], rel=1e-12)
    with pytest.raises(UserInputError, match="'ballast_hole' is not one of"):   # before any run
        hypothesis_gains(SCENARIO, passage, [[{"cause": "ballast_hole", "sleeper": 20, "parameters": {}}]],
                         tmp_path / "hyp")


def test_void_two_sleepers_beyond_the_sensors_is_named_there(tmp_path):
    """A void where round 1 does not look (sleeper 25; the sensors sit on 19-23, round 1 screens 18-24): round
    1 names nothing above the noise, so it looks further (diagnose step 3b) and names the void with its sleeper
    (exact or a set of <= 2 holding it). The void is the field matrix's void_off_sensor seed 7202, one the
    sensors see: there (no model mismatch) the truth itself removes 82 % of J on the diagnosis's reference,
    and looking only 1 sleeper beyond answered ``unexplained`` (RESULTS, session 21); here it comes through
    the mild mismatch of the other field-like cases, with which the truth itself removes only ~41 % of J
    (measured): issue 14's 50 % floor is out of any diagnosis's reach on this record, so the gain is held to
    the truth's own (:func:`hypothesis_gains`, the same reference) less 6 points — the lowest named-minus-truth
    of the field matrix's right single-effect answers with model mismatch, -5.9 points (RESULTS, 2026-11-27
    08:40, and the same in session 22's matrix), rounded up; measured 41.1 % against 40.7 % (38.7 % before the
    wedge fit's half-gap start, selection.CauseFitter.fit, session 22)."""
    from orchestrator.inverse.diagnose import FAR_REACH, SENSOR_REACH

    case, passage = _field_passage(tmp_path, "void_far")
    assert case["effects"][0]["sleeper"] == 25   # the draw of that seed (else the test tests another case)
    result = diagnose(SCENARIO, passage, tmp_path / "out", progress=False).to_json()
    a = result["answer"]
    print(f"\nvoid_far: truth {case['effects']}; answer {a['kind']}: {a['reason']}; {result['runs']} runs, "
          f"{result['wall_seconds']:.0f} s")
    assert a["kind"] == "named" and _named_right(a["causes"][0], case["effects"][0]), a
    truth = hypothesis_gains(SCENARIO, passage, [case["effects"]], tmp_path / "truth", workers=2)
    print(f"void_far: gain {result['gain']['total']:.3f}, the truth's own {truth['hypotheses'][0]['gain']:.3f}")
    assert result["gain"]["total"] >= truth["hypotheses"][0]["gain"] - 0.06, (result["gain"], truth)
    labels = result["settings"]["candidates"]   # round 1 widened: the far sleepers were screened, both sides
    assert {"ballast_void@25", "ballast_void@26", "ballast_void@16"} <= set(labels), labels
    assert result["settings"]["far_reach"] == FAR_REACH > SENSOR_REACH and result["settings"]["looked_further"]
    assert "it also looked up to" in (tmp_path / "out" / "report.md").read_text(encoding="utf-8")


def test_void_and_soft_pad_next_to_it_are_both_named(tmp_path):
    """Two effects at once (a void and a worn pad on the neighbouring sleeper), through a mildly different
    model: forward selection names both (each sleeper exact or in an ambiguity set of <= 2), each with a
    positive gain of its own over the model before it, and the two together gain at least 50 %."""
    case, passage = _field_passage(tmp_path, "two")
    result = diagnose(SCENARIO, passage, tmp_path / "out", progress=False).to_json()
    a = result["answer"]
    print(f"\ntwo: truth {case['effects']}; answer {a['kind']}: {a['reason']}; {result['runs']} runs, "
          f"{result['wall_seconds']:.0f} s")
    assert a["kind"] == "named" and len(a["causes"]) == 2, a
    for effect in case["effects"]:
        assert any(_named_right(c, effect) for c in a["causes"]), (effect, a["causes"])
    assert all(c["gain"] > 0 for c in a["causes"]) and result["gain"]["total"] >= 0.5, result["gain"]
    for c in a["causes"]:
        _check_uncertainty(c)
    # the backfitting (diagnose step 5b): a refit kept lowers J, and the extended model holds the reported values
    ext = yaml.safe_load((tmp_path / "out" / "extended.yaml").read_text())
    refits = [c["evidence"]["refit"] for c in a["causes"] if "refit" in c["evidence"]]
    assert refits, "neither cause was refitted with the other: the void fitted alone took up part of the pad"
    for refit in refits:
        assert refit["objective_after"] < refit["objective_before"], refit
    for c in a["causes"]:
        if c["cause"] == "ballast_void":
            (void,) = [v for v in ext["track"]["ballast"]["voids"] if v["sleeper"] == c["sleeper"]]
            assert void["gaps"] == c["parameters"]["gaps"], (void, c["parameters"])


@pytest.mark.slow
@pytest.mark.parametrize("kind, seed", [("none", 101), ("ballast_void", 102), ("ballast_stiffness", 103),
                                        ("rail_pad_stiffness_local", 104), ("impact_angle", 105)])
def test_hidden_effect_is_named_fitted_and_gains(setup, tmp_path, kind, seed):
    sc, model, sensors, sleepers = setup
    effect = hidden_effect(seed, kind, sleepers)
    synthesize(sc, effect, tmp_path / "passage.csv", seed=seed)
    validate = []
    if kind == "ballast_void":
        from orchestrator.cosim.sensing import variant_for_speed
        from orchestrator.inputs.scenario import scenario_from_dict
        slow = scenario_from_dict(variant_for_speed(sc.raw, VALIDATION_SPEED), source=str(SCENARIO),
                                  base_dir=SCENARIO.parent)
        synthesize(slow, effect, tmp_path / "passage_100.h5", seed=seed + 1000)
        validate = [f"{tmp_path / 'passage_100.h5'}@{VALIDATION_SPEED}"]

    result = diagnose(SCENARIO, tmp_path / "passage.csv", tmp_path / "out", validate=validate,
                      progress=False).to_json()

    named = result["named_cause"]
    print(f"\n{kind}: truth {effect.as_dict()}; named {named['cause']} {named.get('sleeper', '')} "
          f"{named['parameters']}; gain {result['gain']['total']:.3f}; validation "
          f"{[round(v['gain'], 3) for v in result['validation']]}; {result['runs']} runs")
    assert (tmp_path / "out" / "diagnosis.json").is_file() and (tmp_path / "out" / "extended.yaml").is_file()
    assert (tmp_path / "out" / "report.md").is_file()
    if effect.cause == "none":
        assert named["cause"] == "none", named
        return
    assert named["cause"] == effect.cause, (effect, named)
    if effect.sleeper is None:
        assert "sleeper" not in named
    else:
        amb = named["ambiguity"]["sleepers"]
        assert effect.sleeper in amb and len(amb) <= 2, (effect, named)
    p_true, p_fit = effect.parameters, named["parameters"]
    if effect.cause in ("ballast_stiffness", "rail_pad_stiffness"):
        assert p_fit["stiffness_scale"] == pytest.approx(p_true["stiffness_scale"], rel=SCALE_RTOL)
    elif effect.cause == "impact_angle":
        assert p_fit["impact_angle"] == pytest.approx(p_true["impact_angle"], abs=ANGLE_ATOL)
    else:
        body = model.sleeper(named["sleeper"])
        for s in sensors:
            if s.body == body.name:
                assert _gap_at(p_fit["gaps"], body, s.coord) == pytest.approx(
                    _gap_at(p_true["gaps"], body, s.coord), abs=SEAT_GAP_ATOL), s.id
        assert max(p_fit["gaps"]) == pytest.approx(max(p_true["gaps"]), abs=PEAK_GAP_ATOL)
    assert result["gain"]["total"] >= GAIN_MIN, result["gain"]
    for v in result["validation"]:
        assert v["gain"] >= VALIDATION_GAIN_MIN, v


@pytest.mark.slow
def test_confusion_over_many_seeds():
    """The hidden-effect study of benchmarks/bench_diagnose.py (3 seeds per kind): the cause is
    right in at least 90 % of the cases and every right local cause has its sleeper (exact
    or in an ambiguity set of <= 2). Its confusion matrix is recorded in RESULTS.md by the
    benchmark script."""
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "bench_diagnose", Path(__file__).resolve().parents[1] / "benchmarks" / "bench_diagnose.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rows = bench.confusion_rows(seeds=3, workers=2)
    right = [r for r in rows if r[0] == r[1]]
    assert len(right) >= 0.9 * len(rows), rows
    assert all(r[2] for r in right), rows


@pytest.mark.parametrize("make, extra, words", [
    (None, ["--measured", "missing.csv"], "not found"),
    ("ok", ["--validate", "nofile"], "give FILE@SPEED"),
    ("ok", ["--validate", "p.csv@-3"], "give FILE@SPEED"),
    ("fast", [], "must be at most half the sampling interval"),
    ("foreign", [], "none of"),
])
def test_cli_bad_input_is_one_line_exit_2(tmp_path, capsys, monkeypatch, make, extra, words):
    """Bad measured data or options: exit 2, one line naming the problem, before any run."""
    from orchestrator.cli import main
    from orchestrator.inputs.measured import write_measured

    monkeypatch.chdir(tmp_path)
    t = np.arange(200) / 2500.0
    if make == "ok":
        write_measured(tmp_path / "p.csv", t, {"A1": 1e4 + 1e3 * np.sin(40 * t)})
    elif make == "fast":   # 20 kHz: the simulation's 5 kHz output cannot be compared with it
        write_measured(tmp_path / "p.csv", np.arange(200) / 20000.0, {"A1": 1e4 + 1e3 * np.sin(40 * t)})
    elif make == "foreign":
        write_measured(tmp_path / "p.csv", t, {"X9": np.sin(40 * t)})
    argv = ["diagnose", str(SCENARIO), "--no-progress", "--out", str(tmp_path / "out")]
    argv += extra if "--measured" in extra else ["--measured", "p.csv", *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and words in err, err


def test_diagnosis_round_trips_through_json():
    """A hand-made :class:`Diagnosis` (two named causes with intervals, a global candidate, a validation
    passage, a nuisance fit, a dropped variant) survives to_json -> JSON text -> from_json unchanged, and its
    JSON has the keys of diagnosis.json (README schema) in their order: a local cause carries ``sleeper``, a
    global one does not, only named causes carry ``ambiguity`` / ``uncertainty``. A first-schema file (no
    ``answer``, ``nuisance``, ``dropped``) is read with its answer derived from ``named_cause``. No simulation."""
    import json

    from orchestrator.inverse.diagnosis import Answer, Baseline, CauseFit, Diagnosis, Gain, Passage

    evidence = {"round": 1, "stage": "fitted", "objective_reduction": 0.3, "chi2": 1.2e4, "n_samples": 9000,
                "n_parameters": 6, "bic_eff": -1.2e3, "delta_bic_eff_vs_best": 0.0,
                "indistinguishable_from": ["ballast_void@22"], "significance": {"passes": True, "reasons": []}}
    unc = {"level": 0.9, "intervals": [[0.0, 2e-4]] * 6, "identifiable": [False] + [True] * 5,
           "unit_width": [0.6] + [0.05] * 5, "pin_with": ["a pressure cell under sleeper 21 at gap point 1 of 6"]}
    void = CauseFit("ballast_void", {"gaps": [0.0, 4e-4, 9e-4, 9e-4, 4e-4, 0.0]}, 0.06, 0.85, evidence, sleeper=21)
    bed = CauseFit("ballast_stiffness", {"stiffness_scale": 0.7}, 0.3, 0.27, dict(evidence, stage="confirmed"))
    named = CauseFit(void.cause, void.parameters, void.objective, void.gain, evidence, sleeper=21,
                     ambiguity={"candidates": ["ballast_void@21", "ballast_void@22"], "sleepers": [21, 22]},
                     uncertainty=unc)
    nose = CauseFit("impact_angle", {"impact_angle": 0.015}, 0.03, 0.5, dict(evidence, round=2),
                    ambiguity={"candidates": ["impact_angle"], "sleepers": []}, uncertainty=dict(unc, intervals=[[
                        0.013, 0.017]], identifiable=[True], unit_width=[0.13], pin_with=[]))
    diagnosis = Diagnosis(
        "scenarios/x.yaml", "p.csv", Answer("named", [named, nose], "two causes", None),
        Baseline(0.41, 1e-3, 1.6e4, 9000, {"A": 0.4}, {"A1": {"rmse": 1.2e4, "nrmse": 0.35}}, 1.6e4,
                 {"groups": {"A": 0.4}, "sleepers": {"21": 0.4}, "worst_channels": []}, {"A1": 120.0}),
        {"values": {"speed": 33.9}, "nominal": {"speed": 33.333}}, [void, bed], named, "extended.yaml",
        Gain(0.85, {"A1": 0.8}),
        [Passage("p2.h5", 27.78, 0.39, 0.07, 1 - 0.07 / 0.39, {"A1": {"nrmse_before": 0.3, "nrmse_after": 0.05}})],
        [{"variant": "ballast_void@21 at 0.0035", "stage": "screening", "reason": "the run stopped early: x"}],
        120, 300.5, {"delta_bic": 10.0, "confirm": 4, "fit": 2, "sensor_reach": 1, "candidates": ["ballast_void@21"]},
        {"runs": 15, "used": 12})

    data = json.loads(json.dumps(diagnosis.to_json()))
    assert Diagnosis.from_json(data) == diagnosis
    assert Diagnosis.from_json(data).to_json() == data
    assert list(data) == ["scenario", "measured", "answer", "baseline", "nuisance", "causes", "named_cause",
                          "extended_scenario", "gain", "validation", "dropped", "runs", "wall_seconds", "settings",
                          "runs_ahead"]
    assert list(data["answer"]) == ["kind", "causes", "reason", "where", "resolution"]
    limits = [{"cause": "ballast_void", "sleeper": 21, "proxy": "uniform", "nominal": 0.0, "limit": 3e-5,
               "screened_to": 3.5e-3, "unit": "m"}]
    quiet = Answer("none", [], "the residual is at the noise level", None, limits)
    assert Answer.from_json(json.loads(json.dumps(quiet.to_json()))) == quiet
    assert list(data["named_cause"]) == ["cause", "sleeper", "parameters", "objective", "gain", "evidence",
                                         "ambiguity", "uncertainty"]
    assert list(data["causes"][1]) == ["cause", "parameters", "objective", "gain", "evidence"]
    none = CauseFit("none", {}, 0.41, 0.0, {"best_candidate": "impact_angle", "delta_bic_vs_nominal": 3.0,
                                            "threshold": 10.0, "reason": "noise"})
    assert CauseFit.from_json(none.to_json()) == none and "sleeper" not in none.to_json()

    old = {k: v for k, v in data.items() if k not in ("answer", "nuisance", "dropped", "runs_ahead")}   # first schema
    read = Diagnosis.from_json(old)
    assert read.answer.kind == "named" and read.answer.causes == [named] and read.dropped == []
    assert read.runs_ahead == {}
    old["named_cause"] = none.to_json()
    assert Diagnosis.from_json(old).answer.kind == "none"


# ------------------------------------------------------------------------------------ significance (no simulation)
def _ar1(rng, n, rho):
    from scipy.signal import lfilter

    e = rng.normal(size=n)
    return lfilter([1.0], [1.0, -rho], e)[1000:]   # the first 1000 samples: the start-up transient dropped


@pytest.mark.parametrize("rho", [0.5, 0.8])
def test_effective_size_of_ar1_is_its_closed_form(rho):
    """N_eff of an AR(1) series against the closed form N (1 - rho) / (1 + rho) (independent: the process's
    autocorrelation rho^k summed analytically). Tolerance 8 %: the integrated time's estimator has a relative
    standard error ~ sqrt(2 (2M + 1) / N) over the M lags it sums (Sokal 1997, Monte Carlo methods in
    statistical mechanics, eq. 3.19): with N = 2e5 and M <~ 40 (rho = 0.8) that is <= 2.9 %, so 8 % is
    ~3 standard errors."""
    from orchestrator.inverse.significance import effective_size

    x = _ar1(np.random.default_rng(11), 201_000, rho)
    assert effective_size(x) == pytest.approx(x.size * (1 - rho) / (1 + rho), rel=0.08)


def test_effective_size_of_white_noise_is_n():
    """White noise: N_eff = N within 3 % (its tau = 1 + O(1/sqrt(N)) fluctuation of the first pair sums,
    N = 1e5: 2 x 0.3 % per lag pair, a few pairs). An anti-correlated series is clipped at N, never more."""
    from orchestrator.inverse.significance import effective_size

    x = np.random.default_rng(12).normal(size=100_000)
    assert effective_size(x) == pytest.approx(x.size, rel=0.03)
    assert effective_size(np.tile([1.0, -1.0], 500)) <= 1000


def _fake_target(channels, sigma):
    """A :class:`Target` of hand-built channels (a stand-in layout and record): two groups of two channels."""
    from types import SimpleNamespace

    from orchestrator.inverse.objective import Target

    groups = {k: ("P" if i < 2 else "Q") for i, k in enumerate(channels)}
    layout = SimpleNamespace(groups=groups, weights={"P": 1.0, "Q": 1.0}, types={k: "pressure" for k in channels})
    measured = SimpleNamespace(channels=channels, t=np.arange(next(iter(channels.values())).size) * 2e-4, dt=2e-4)
    return Target(measured, layout, sigma, shift=0.0, scale={k: float(np.std(v)) for k, v in channels.items()})


def _cmp_of(target, residuals):
    from orchestrator.inverse.objective import score

    on = {k: target.measured.channels[k] + r for k, r in residuals.items()}
    return score(target.measured, on, target.layout.groups, target.layout.weights, target.sigma, 0.0, target.scale)


def _bump_misfit(seed: int):
    """Four 8 Hz channels in two groups (sigma 1 % of each one's spread), a 20 ms bump shape and a seeded
    draw of that 1 % white noise: (channels, spreads, target, bump, noise) for the rule's hand-built cases."""
    rng = np.random.default_rng(seed)
    n = 800
    t = np.arange(n) * 2e-4
    channels = {k: np.sin(2 * np.pi * 8 * t + i) for i, k in enumerate(["P1", "P2", "Q1", "Q2"])}
    sd = {k: float(np.std(v)) for k, v in channels.items()}
    target = _fake_target(channels, {k: 0.01 * sd[k] for k in channels})
    bump = np.exp(-0.5 * ((t - 0.08) / 0.02) ** 2)
    noise = {k: rng.normal(0, 0.01 * sd[k], n) for k in channels}
    return channels, sd, target, bump, noise


def test_rule_rejects_a_small_systematic_improvement_and_accepts_a_real_one():
    """The issue's failure mode, built by hand: the nominal residual is a smooth misfit (10 % of each channel's
    spread, a 20 ms bump) plus 1 % white noise. A "cause" that shaves 2 % off the bump has a raw chi-square
    gain of thousands (the old rule, BIC on all samples, named it) but removes ~2 % of the explainable misfit
    (< MIN_SHARE): not named. A cause that removes the bump leaves noise only: named, share ~1. One that
    fits group P and doubles group Q's misfit fails the held-out-group guard and the never-worse rule."""
    from orchestrator.inverse.significance import MIN_SHARE, assess

    channels, sd, target, bump, noise = _bump_misfit(5)
    ref = _cmp_of(target, {k: 0.1 * sd[k] * bump + noise[k] for k in channels})
    shave = _cmp_of(target, {k: 0.098 * sd[k] * bump + noise[k] for k in channels})
    real = _cmp_of(target, noise)
    trade = _cmp_of(target, {k: (0.0 if k[0] == "P" else 0.2) * sd[k] * bump + noise[k] for k in channels})

    assert ref.chi2 - shave.chi2 > 1000   # what the raw-sample BIC saw as "very strong"
    small = assess(shave, 1, ref, 0, target)
    assert not small.passes and small.share < MIN_SHARE and small.gain > 0, small
    good = assess(real, 1, ref, 0, target)
    assert good.passes and good.share == pytest.approx(1.0, abs=0.05), good
    assert good.share_of == "misfit_above_noise"
    bad = assess(trade, 1, ref, 0, target)
    assert not bad.passes and any("held out" in r for r in bad.reasons), bad
    quiet = assess(real, 1, real, 0, _fake_target(channels, {k: 0.05 * sd[k] for k in channels}))   # below noise
    assert not quiet.passes and quiet.to_json()["share_of_explainable_misfit"] is None   # JSON null, never NaN


def test_share_of_a_misfit_within_the_noise_margin_is_measured_against_the_margin():
    """A reference residual just above the noise (1 % white noise plus a bump of 0.6 % of each channel's
    spread: J_ref ~1.04 J_noise) and a cause that removes the bump: it removes nearly all of J_ref - J_noise
    (~100 %, what the rule measured before 2026-11-27 and named) but ~4 % of J. Within the margin of
    ``none`` (J_ref <= 1.5 J_noise, README "turnout diagnose" (6)) the share is measured against that margin,
    0.5 J_noise: below the quarter, not named. Hand computation: J_noise is the channels' mean noise nRMSE,
    0.01 by construction (sigma = 1 % of each channel's std); the share is (J_ref - J_cause) / (0.5 x 0.01)."""
    from orchestrator.inverse.significance import MIN_SHARE, assess

    channels, sd, target, bump, noise = _bump_misfit(7)
    ref = _cmp_of(target, {k: 0.006 * sd[k] * bump + noise[k] for k in channels})
    cause = _cmp_of(target, noise)
    j_noise = 0.01
    assert 1.0 < ref.objective / j_noise < 1.1, ref.objective          # just above the noise
    old_share = (ref.objective - cause.objective) / (ref.objective - j_noise)
    assert old_share >= MIN_SHARE, old_share                             # the old measure named it
    ev = assess(cause, 1, ref, 0, target)
    assert ev.share == pytest.approx((ref.objective - cause.objective) / (0.5 * j_noise), rel=1e-9), ev
    assert ev.share < MIN_SHARE and not ev.passes and "share" in ev.failed, ev


def test_share_below_the_noise_objective_with_a_loud_channel_is_measured_against_the_margin():
    """J_noise read high by some channels puts J_ref below it while another channel holds a clear misfit (the
    field matrix of 2026-11-27: off-sensor voids at their true sleeper refused, J_ref 0.6 J_noise, pressure
    cell A6 23x its own noise level). Built by hand: group P's sigma is read at 20 % of each channel's
    spread where its residual is 1 % white noise; group Q's is right (1 %) and its residual is a 20 ms bump
    of 10 % of the spread on that noise, loud (RMS ~4.8x its first-difference level > LOUD_FACTOR 3).
    J_noise = (0.20 + 0.01) / 2, J_ref ~ (0.01 + 0.048) / 2 < J_noise. The share is then measured against
    0.5 J_noise, as within the noise margin: removing the bump removes ~0.019, a share ~0.36, named; a cause
    that removes a tenth of it is not. Without the loud channel (Q's residual white too) the share stays
    undefined (JSON null) and nothing passes."""
    from orchestrator.inverse.significance import MIN_SHARE, NONE_MARGIN, assess, loud_channels

    channels, sd, _, bump, noise = _bump_misfit(9)
    target = _fake_target(channels, {k: (0.20 if k[0] == "P" else 0.01) * sd[k] for k in channels})
    ref = _cmp_of(target, {k: (0.1 * sd[k] * bump if k[0] == "Q" else 0.0) + noise[k] for k in channels})
    real = _cmp_of(target, noise)
    tenth = _cmp_of(target, {k: (0.09 * sd[k] * bump if k[0] == "Q" else 0.0) + noise[k] for k in channels})
    j_noise = (0.20 + 0.01) / 2
    assert ref.objective < 0.5 * j_noise and set(loud_channels(ref, target)) == {"Q1", "Q2"}
    good = assess(real, 1, ref, 0, target)
    assert good.share == pytest.approx((ref.objective - real.objective) / (NONE_MARGIN * j_noise), rel=1e-9)
    assert good.passes and good.share >= MIN_SHARE, good
    assert good.share_of == "noise_margin" and good.to_json()["share_of"] == "noise_margin"
    small = assess(tenth, 1, ref, 0, target)
    assert not small.passes and "share" in small.failed and small.share < MIN_SHARE, small
    quiet_ref = _cmp_of(target, noise)
    quiet = assess(real, 1, quiet_ref, 0, target)
    assert not quiet.passes and quiet.to_json()["share_of_explainable_misfit"] is None
    assert quiet.to_json()["share_of"] is None


def test_share_is_measured_above_the_noise_and_the_models_own_step_error():
    """The explainable misfit a cause's share is measured against excludes the model's own time-step error
    (``Target.floor``, which every variant carries, so no cause can remove it): the floor is each channel's
    noise nRMSE and step error added in quadrature. Built by hand: noise 1 % of each channel's spread, a step
    error of 5 % on every channel, so J_floor = sqrt(0.01^2 + 0.05^2) = 0.05099; the reference's residual a
    bump of 30 % of the spread on the noise (J_ref ~0.14), a cause leaving 24 % of it. Against J_ref - J_noise its share
    is below the quarter; against J_ref - J_floor above it. Without a floor the share is the old one. (The bump is smooth: few
    effective samples, so this one also fails the significance part; only the share is checked here.)"""
    import math
    from dataclasses import replace

    from orchestrator.inverse.significance import MIN_SHARE, assess

    channels, sd, target, bump, noise = _bump_misfit(13)
    ref = _cmp_of(target, {k: 0.30 * sd[k] * bump + noise[k] for k in channels})
    cause = _cmp_of(target, {k: 0.24 * sd[k] * bump + noise[k] for k in channels})
    j_noise, j_floor = 0.01, math.hypot(0.01, 0.05)
    assert ref.objective > (1 + 0.5) * j_floor, ref.objective   # above the floor's margin
    old = (ref.objective - cause.objective) / (ref.objective - j_noise)
    new = (ref.objective - cause.objective) / (ref.objective - j_floor)
    assert old < MIN_SHARE <= new, (old, new)
    ev = assess(cause, 1, ref, 0, replace(target, floor={k: 0.05 for k in channels}))
    # rel 1e-9: the hand formula and the rule do the same arithmetic in another order (round-off only); the
    # noise nRMSE is 0.01 exactly by construction (sigma 1 % of the spread the target normalises by)
    assert ev.share == pytest.approx(new, rel=1e-9) and "share" not in ev.failed, ev
    assert ev.to_json()["objective_floor"] == pytest.approx(j_floor, rel=1e-9)
    assert ev.to_json()["objective_noise"] == pytest.approx(j_noise, rel=1e-9)
    bare = assess(cause, 1, ref, 0, target)
    assert bare.share == pytest.approx(old, rel=1e-9) and "share" in bare.failed, bare


def test_step_5c_keeps_the_best_point_of_all_paths(monkeypatch):
    """Step 5c (diagnose._nuisance_again) tries the nuisance refit, the speed found again on the refit's model,
    the joint refit with the named causes (last part), and the speed found again on the model given, and
    keeps the point of least J among those that fit better
    (diagnose._lower: J falls, and the chi-square or the deviance on the effective sample size falls with it).
    A logic check on hand-built residuals (the two nuisance steps replaced by fakes that return them). Group
    Q's sigma is read 5x low, as the reconstructed displacements' is (significance, "Known limits"). The model
    given: a bump of 10 % of P's spread, Q at its noise. Its points:

    - the refit: P's bump down to 4 %, a 2 % bump on Q. J falls, the chi-square rises (Q's low sigma),
      and the deviance falls: it fits better. The old rule (both chi-square and J) refused it.
    - the refit, then the speed: P's bump 2 %, a 1 kHz ringing of 2 % on Q. Its J is the least of all, but
      the chi-square and the deviance both rise (the ringing is nearly white: Q counts ~560 effective
      samples against P's ~12): not better.
    - the speed on the model given: P's bump 7 %. J and the chi-square fall: the old rule's answer.

    Kept: the refit. When the refit's point is the ringing one too, the speed on the model given is kept;
    when no point is better, the values given stand. The runs of all paths are counted either way."""
    from dataclasses import replace
    from types import SimpleNamespace

    from orchestrator.inputs.causes import Candidate
    from orchestrator.inverse import nuisance
    from orchestrator.inverse.diagnose import _lower, _nuisance_again
    from orchestrator.inverse.nuisance import NuisanceFit
    from orchestrator.inverse.significance import channel_neff, deviance

    channels, sd, _, bump, noise = _bump_misfit(21)
    target = _fake_target(channels, {k: (0.01 if k[0] == "P" else 0.002) * sd[k] for k in channels})
    ring = np.sin(2 * np.pi * 1000.0 * target.measured.t)

    def point(p, q, a=0.0):
        return _cmp_of(target, {k: (p * bump if k[0] == "P" else q * bump + a * ring) * sd[k] + noise[k]
                                for k in channels})

    given, refit, both, speed = point(0.10, 0.0), point(0.04, 0.02), point(0.02, 0.0, 0.02), point(0.07, 0.0)

    def dev_change(c):
        neff = channel_neff(c)
        return deviance(c, target.sigma, neff) - deviance(given, target.sigma, neff)

    # the points are what the docstring says they are
    assert both.objective < refit.objective < speed.objective < given.objective
    assert refit.chi2 > given.chi2 and dev_change(refit) < 0 and _lower(refit, given, target.sigma)
    assert both.chi2 > given.chi2 and dev_change(both) > 0 and not _lower(both, given, target.sigma)
    assert speed.chi2 < given.chi2 and _lower(speed, given, target.sigma)

    def run(refit_point, speed_point):
        def fake_refit(pool, tg, nz, raw, cmp):
            assert raw == {"model": "given"} and cmp is given
            nz.runs += 9
            return replace(nz, raw={"model": "refit"}, refit={"reason": "test"}), refit_point

        def fake_speed(pool, tg, nz, raw, cmp):
            nz.runs += 2
            after = {"given": ({"model": "speed"}, speed_point), "refit": ({"model": "refit, speed"}, both)}
            new_raw, new_cmp = after[raw["model"]]
            nz.speed_again, nz.raw = {"runs": 2}, new_raw
            return nz, new_raw, new_cmp

        monkeypatch.setattr(nuisance, "refit_with_causes", fake_refit)
        monkeypatch.setattr(nuisance, "speed_again", fake_speed)
        nz = NuisanceFit({"model": "given"}, {"speed": 30.0}, {"speed": 30.0}, {}, {}, {}, 0.0, given, 40)
        return _nuisance_again(SimpleNamespace(spare=0), SimpleNamespace(target=target), nz, {"model": "given"},
                               given)

    fit, raw, cmp, values = run(refit, speed)
    assert raw == {"model": "refit"} and cmp is refit and fit.refit == {"reason": "test"} and values is None
    assert fit.speed_again is None and fit.runs == 40 + 9 + 2 + 2
    assert fit.notes[-1].endswith("kept the refit"), fit.notes
    fit, raw, cmp, _ = run(both, speed)
    assert raw == {"model": "speed"} and cmp is speed and fit.refit is None and fit.runs == 53
    fit, raw, cmp, _ = run(both, point(0.11, 0.0))
    assert raw == {"model": "given"} and cmp is given and fit.runs == 53
    assert "none fits better" in fit.notes[-1], fit.notes

    # with a named cause, the joint refit of the nuisance values and the cause's parameters is a third path:
    # its point (P's bump 3 %, Q at its noise: J and the chi-square fall, below the refit's J) is kept, with
    # the cause's new values; the speed found again on its model (the ringing point) is not better
    joint = point(0.03, 0.0)
    assert joint.objective < refit.objective and _lower(joint, given, target.sigma)

    def fake_joint(pool, tg, nz, causes, cmp):
        assert cmp is given and [(s, list(v)) for _, s, v in causes] == [(19, [0.5])]
        nz.runs += 8
        return replace(nz, raw={"model": "refit"}, refit={"reason": "joint"}), joint, [np.array([0.7])]

    monkeypatch.setattr(nuisance, "refit_jointly", fake_joint)
    named = [SimpleNamespace(e=SimpleNamespace(candidate=Candidate("rail_pad_stiffness", 19)), values=np.array([0.5]))]
    nz = NuisanceFit({"model": "given"}, {"speed": 30.0}, {"speed": 30.0}, {}, {}, {}, 0.0, given, 40)
    fit, raw, cmp, values = _nuisance_again(SimpleNamespace(spare=0), SimpleNamespace(target=target), nz,
                                            {"model": "given"}, given, named)
    assert cmp is joint and fit.refit == {"reason": "joint"} and [list(v) for v in values] == [[0.7]]
    assert fit.runs == 40 + (9 + 2) + (8 + 2) + 2 and fit.notes[-1].endswith("kept the joint refit"), fit.notes


def test_step_4b_keeps_the_speed_found_again_only_where_it_fits_better(monkeypatch):
    """Step 4b's speed (diagnose._speed_between), a logic check on hand-built residuals: the speed found again
    (nuisance.speed_again, replaced by a fake returning a given point at 34 m/s) is kept only when it fits better
    by step 5c's rule (diagnose._lower). Kept: round 2's target takes the point's shift, the nuisance estimates
    (a copy) the new speed, their ``raw`` the nuisance model *without* the cause at it (the reference step 5b
    refits on), and the model returned is the point's. Not kept: everything given stands, the runs made are
    counted and a note says why."""
    from orchestrator.inverse import nuisance
    from orchestrator.inverse.diagnose import _speed_between
    from orchestrator.inverse.nuisance import NuisanceFit

    channels, sd, target, bump, noise = _bump_misfit(21)

    def point(p, shift):
        cmp = _cmp_of(target, {k: p * bump * sd[k] + noise[k] for k in channels})
        cmp.shift = shift
        return cmp

    given = point(0.10, 0.0)
    sc = load_scenario(SCENARIO)
    ext = {**sc.raw, "marker": "with the cause"}

    def run(chosen):
        def fake_speed(pool, tg, nz, raw, cmp, when):
            assert raw is ext and cmp is given and "ballast_void@21" in when
            nz.runs += 2
            nz.values["speed"] = 34.0
            return nz, {**raw, "marker": "with the cause at 34"}, chosen

        monkeypatch.setattr(nuisance, "speed_again", fake_speed)
        nz = NuisanceFit(sc.raw, {"speed": 33.333}, {}, {}, {}, {}, 0.0, given, 40)
        return nz, _speed_between(None, target, nz, ext, given, "ballast_void@21, before round 2")

    better = point(0.05, 1e-4)
    nz, (tg, fit, raw, cmp) = run(better)
    assert cmp is better and raw["marker"] == "with the cause at 34" and tg.shift == 1e-4 and target.shift == 0.0
    assert fit is not nz and fit.values["speed"] == 34.0 and nz.values["speed"] == 33.333 and fit.runs == 42
    assert fit.raw["vehicle"]["speed"] == 34.0 and "marker" not in fit.raw
    worse = point(0.12, 1e-4)
    nz, (tg, fit, raw, cmp) = run(worse)
    assert cmp is given and raw is ext and tg is target and fit is nz and nz.values["speed"] == 33.333
    assert nz.runs == 42 and nz.notes[-1].endswith("not kept"), nz.notes


def test_interval_of_a_linear_fit_is_the_textbook_one():
    """:func:`unit_covariance` of a straight-line least-squares problem with white errors (N_eff = N) equals
    the textbook covariance s^2 (X^T X)^-1 (numpy lstsq residuals; independent formula); with the residual
    counted as N_eff = N / 4 the variance is 4 x larger. A column of zeros (a parameter the data do not see)
    gets an infinite variance."""
    from orchestrator.inverse.uncertainty import unit_covariance

    rng = np.random.default_rng(3)
    x = np.linspace(0.0, 1.0, 400)
    X = np.column_stack([x, np.ones_like(x)])
    y = X @ [0.3, 0.5] + rng.normal(0, 0.05, x.size)
    beta, res, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ beta
    textbook = res[0] / (x.size - 2) * np.linalg.inv(X.T @ X)
    assert unit_covariance(X, r, x.size) == pytest.approx(textbook, rel=1e-9)
    assert unit_covariance(X, r, x.size / 4) == pytest.approx(4 * textbook, rel=1e-9)
    blind = unit_covariance(np.column_stack([x, 0 * x]), r, x.size)
    assert np.isinf(blind[1, 1]) and blind[0, 0] == pytest.approx(res[0] / (x.size - 2) / (x @ x), rel=1e-9)


def test_dense_search_skips_samples_outside_the_simulated_window():
    """The traceback of issue 14 at the unit level: signals holding NaN where the record lies outside the
    simulated window made the PCHIP raise; now those samples are masked and the best magnitude is the one
    whose signal matches the measurement (the middle of three, by construction)."""
    from types import SimpleNamespace

    from orchestrator.inverse.screening import dense_search

    t = np.arange(300) * 2e-4
    meas = {"P1": np.sin(40 * t), "P2": np.cos(40 * t), "Q1": np.sin(60 * t), "Q2": np.cos(60 * t)}
    target = _searchable_target(meas, {k: 1e-3 for k in meas})
    sig = [{k: (1 + a) * v for k, v in meas.items()} for a in (-0.2, 0.0, 0.2)]
    for s in sig:
        for v in s.values():
            v[:25] = np.nan   # the first 5 ms of the record: before the simulated window
    x, cmp = dense_search(target, SimpleNamespace(log=False), np.array([1.0, 2.0, 3.0]), sig)
    assert x == pytest.approx(2.0, abs=0.02) and np.isfinite(cmp.objective)


def _searchable_target(meas, sigma):
    """:func:`_fake_target` with what :func:`orchestrator.inverse.screening.dense_search` calls."""
    from orchestrator.inverse.objective import objective_rows

    target = _fake_target(meas, sigma)
    target.shift = 0.0
    target.score = lambda on: _cmp_of(target, {k: on[k] - meas[k] for k in on})
    target.objective_rows = lambda rows, ids, sizes: objective_rows(target.measured, rows, ids, sizes,
                                                                    target.layout.groups, target.layout.weights,
                                                                    target.scale)
    return target


def test_objective_of_many_rows_is_the_hand_computed_one():
    """:func:`orchestrator.inverse.objective.objective_rows` (how the dense search ranks its points) against J
    computed by hand: residuals constant per channel, so each channel's nRMSE is |c| / scale; J is the weighted
    mean of the group means (group P weight 1, Q weight 3 here). A channel with one valid sample in a row
    makes that row NaN. Tolerance 1e-12: sums of 50 equal squares, round-off only."""
    from types import SimpleNamespace

    from orchestrator.inverse.objective import objective_rows

    n = 50
    meas = {"P1": np.zeros(n), "P2": np.zeros(n), "Q1": np.zeros(n), "Q2": np.zeros(n)}
    scale = {"P1": 2.0, "P2": 4.0, "Q1": 1.0, "Q2": 5.0}
    groups = {"P1": "P", "P2": "P", "Q1": "Q", "Q2": "Q"}
    c = np.array([[1.0, -2.0, 0.5, 3.0], [0.2, 0.0, -1.0, 1.0], [1.0, 1.0, 1.0, 1.0]])
    ids = list(meas)
    rows = np.repeat(c, n, axis=1)
    rows[2, 2 * n + 1:3 * n] = np.nan            # row 3: channel Q1 has a single valid sample
    sizes = np.arange(5) * n
    got = objective_rows(SimpleNamespace(channels=meas), rows, ids, sizes, groups, {"P": 1.0, "Q": 3.0}, scale)
    for r in range(2):
        nr = [abs(c[r, i]) / scale[k] for i, k in enumerate(ids)]
        hand = (1.0 * (nr[0] + nr[1]) / 2 + 3.0 * (nr[2] + nr[3]) / 2) / 4.0
        assert got[r] == pytest.approx(hand, rel=1e-12, abs=1e-15), (r, got[r], hand)
    assert np.isnan(got[2])


@pytest.mark.parametrize("log", [False, True])
def test_dense_search_finds_the_point_scoring_every_point_finds(log):
    """Consistency check of two code paths of ours: the search ranks its 121 points by the objective J
    computed over blocks of points and scores the best few one by one; scoring every point one by one
    (the reference loop below, the search as it was) gives the same magnitude and the same comparison.
    Five runs whose signals move non-linearly with the magnitude, 1 % noise; the minimum lies between
    screening points, and a point near it has a J within round-off of a neighbour's only by
    chance (none here: the check is exact)."""
    from types import SimpleNamespace

    from scipy.interpolate import PchipInterpolator

    from orchestrator.inverse.screening import DENSE, dense_search

    rng = np.random.default_rng(11)
    t = np.arange(600) * 2e-4
    base = {"P1": np.sin(40 * t), "P2": np.cos(40 * t), "Q1": np.sin(60 * t) ** 2, "Q2": np.cos(90 * t)}
    xs = np.array([0.5, 1.0, 2.0, 4.0, 8.0]) if log else np.array([0.0, 0.25, 0.5, 0.75, 1.0])
    shape = (lambda x: np.log(x) / np.log(8.0)) if log else (lambda x: x)
    truth = 2.9 if log else 0.62
    meas = {k: v * (1 + 0.3 * shape(truth) ** 2) + rng.normal(0, 0.01, t.size) for k, v in base.items()}
    target = _searchable_target(meas, {k: 0.01 for k in meas})
    sig = [{k: v * (1 + 0.3 * shape(x) ** 2) for k, v in base.items()} for x in xs]
    x, cmp = dense_search(target, SimpleNamespace(log=log), xs, sig)

    u = np.log(xs) if log else xs
    ids = list(sig[0])
    interp = PchipInterpolator(u, np.stack([np.concatenate([s[k] for k in ids]) for s in sig]), axis=0)
    sizes = np.cumsum([0] + [sig[0][k].size for k in ids])
    best = None
    for ud in np.linspace(u[0], u[-1], DENSE):
        row = interp(ud)
        c = target.score({k: row[sizes[i]:sizes[i + 1]] for i, k in enumerate(ids)})
        if best is None or c.objective < best[1].objective:
            best = (float(np.exp(ud) if log else ud), c)
    assert x == best[0] and cmp.objective == best[1].objective
    assert abs(x - truth) < 0.1 * truth


def test_a_site_the_ranking_prefers_but_the_share_rejects_joins_the_named_causes_ambiguity_set():
    """The ranking (BIC on N_eff) and the share can disagree (diagnose module doc, step 4; measured in
    void_sensor+mismatch 7101: the true void at 19 ranked first but removed 23 % of the explainable misfit,
    the void at 18, ranked below it, 29 % and was named). Built by hand, no runs: three fitted candidates
    ranked void@19, pad@20, void@18; void@19 fails only the share, pad@20 fails the share and the
    significance, void@18 passes. The named cause is void@18 and its ambiguity set holds 19 (same cause,
    ranked above, failed only the share) but not the pad (another cause); a candidate that failed more than
    the share (here: as void@19 with a held-out group too) would not join."""
    from types import SimpleNamespace

    from orchestrator.inputs.causes import Candidate
    from orchestrator.inverse.diagnose import _named_entry, _Named, _preferred
    from orchestrator.inverse.screening import Evaluated
    from orchestrator.inverse.significance import Evidence

    def ev(failed):
        return Evidence(0.1, 0.2, 1.0, 0.5, 20.0, 1.0, 100, 50.0, {}, [f"fails {f}" for f in failed], list(failed))

    cmp = SimpleNamespace(objective=0.9, chi2=1.0, n=100)
    v19, p20, v18 = (Evaluated(Candidate(c, s), np.zeros(6 if c == "ballast_void" else 1), cmp, 1, "fitted")
                     for c, s in (("ballast_void", 19), ("rail_pad_stiffness", 20), ("ballast_void", 18)))
    for failed_19, joins in ((["share"], True), (["share", "held_out"], False)):
        tried = {v19.candidate: ev(failed_19), p20.candidate: ev(["significance", "share"]), v18.candidate: ev([])}
        rd = SimpleNamespace(real=[v19, p20, v18], twins={}, fitters={}, bic={v19.candidate: 0.0,
                             p20.candidate: 30.0, v18.candidate: 75.0}, reference=SimpleNamespace(cmp=cmp))
        pick = next(e for e in rd.real if tried[e.candidate].passes)   # what _pick does with these evidences
        assert pick is v18
        entry = _named_entry(_Named(pick, tried[v18.candidate], rd, {}, _preferred(rd, pick, tried)), 1, (18, 24))
        assert entry.sleeper == 18
        assert (19 in entry.ambiguity["sleepers"]) is joins, entry.ambiguity
        assert 20 not in entry.ambiguity["sleepers"], entry.ambiguity
        assert ("ranked_above" in entry.ambiguity) is joins


def test_the_verdict_says_a_cause_was_fitted_again_after_the_nuisance_refit():
    """A named cause whose value step 5d changed (evidence.refit_nuisance) is reported with the value it was
    named at and the extended model's J before and after, so the verdict's J (the naming round's) is not read
    as that of the value shown."""
    from orchestrator.inverse.diagnose_report import _refit_words
    from orchestrator.inverse.diagnosis import CauseFit

    c = CauseFit("rail_pad_stiffness", {"stiffness_scale": 4.0}, 0.0778, 0.7,
                 {"refit_nuisance": {"parameters_before": {"stiffness_scale": 3.83}, "objective_before": 0.05054,
                                     "objective_after": 0.04655}})
    words = _refit_words(c)
    assert "3.83" in words and "0.05054 → 0.04655" in words, words
    assert _refit_words(CauseFit("rail_pad_stiffness", {"stiffness_scale": 4.0}, 0.0778, 0.7, {})) == ""


def test_a_channel_reading_round_off_is_normalised_as_a_constant_one():
    """objective.channel_scales: a pressure cell whose record is round-off (1e-14 Pa about 0, as the solid
    crossing rail's recovered pressure under a hanging sleeper reads: field-like case void_sensor+solid 7606)
    is treated as an exactly constant cell is — the median spread of its group's live cells as its
    normaliser, their median noise-to-spread ratio (objective.noise_sigma over the std) as its noise — while a
    live cell of small spread (0.6 % of the group's largest, as in case two_void_pad 7101) keeps its own.
    A check of the rule; the spreads' hand value: the std of a sine of amplitude a is a / sqrt(2)."""
    from types import SimpleNamespace

    from orchestrator.inverse.objective import channel_scales, noise_sigma

    rng = np.random.default_rng(4)
    t = np.arange(4000) * 2e-4
    wave = np.sin(2 * np.pi * 25.0 * t)                 # 20 whole periods
    ch = {"A1": 2000.0 * wave + rng.normal(0, 20.0, t.size), "A2": 1000.0 * wave + rng.normal(0, 10.0, t.size),
          "A3": 1e-14 * rng.normal(size=t.size), "A4": np.zeros(t.size),
          "A5": 12.0 * wave + rng.normal(0, 0.12, t.size)}
    scale, sigma = channel_scales(SimpleNamespace(channels=ch), {k: "A" for k in ch})
    live = ("A1", "A2", "A5")
    median = float(np.median([np.std(ch[k]) for k in live]))
    assert median == pytest.approx(1000.0 / np.sqrt(2), rel=2e-2)          # 2 %: the noise's share of the std
    ratio = float(np.median([noise_sigma(ch[k]) / np.std(ch[k]) for k in live]))
    for dead in ("A3", "A4"):
        # rel 1e-9: the same arithmetic on the same numbers, only the summation order may differ
        assert scale[dead] == pytest.approx(median, rel=1e-9), dead
        assert sigma[dead] == pytest.approx(ratio * median, rel=1e-9), dead
    assert scale["A5"] == pytest.approx(np.std(ch["A5"]), rel=1e-12)       # its own std, unchanged
    assert sigma["A5"] == pytest.approx(noise_sigma(ch["A5"]), rel=1e-12)


def test_the_step_error_note_extrapolates_the_half_step_difference_to_the_converged_model():
    """The `unexplained` answer's note on the model's own time-step error (diagnose._step_words) weighs the error
    against the converged model, not the half-step run's difference: Richardson at first order (written here, not
    imported) doubles it, e(h) = 2 (y_h - y_h/2). A difference of 0.6 x the noise objective is then 1.2 x it:
    the note is given, with both figures; 0.4 x (0.8 x against the converged model) gives none, nor does a
    missing step error."""
    from orchestrator.inverse.diagnose import _step_words

    j_noise = 0.067
    err = {"step": 2e-4, "groups": {"A": 0.01, "E": 0.16}}
    loud = _step_words({**err, "objective": 0.6 * j_noise}, j_noise)
    assert "0.0402" in loud and f"{2 * 0.6 * j_noise:.3g}" in loud and "group E" in loud
    assert _step_words({**err, "objective": 0.4 * j_noise}, j_noise) == ""
    assert _step_words(None, j_noise) == ""


def test_step_3c_releases_a_channel_gain_only_for_a_cause_that_explains_the_record_better(monkeypatch):
    """Step 3c (diagnose._released), a logic check on hand-built records (the round judged again,
    selection.rejudged, replaced by a fake that returns one fitted candidate on the target it is given).
    The model's channels are four 8 Hz waves; sigma 1 % of each one's spread; step 2 took Q2 for
    mis-calibrated, gain 1.25.

    - A track effect that looks like a gain: the record's Q2 is the model's x 1.25, and Q1, on the same
      sleeper, carries a 20 ms bump of 3 % of its spread. The candidate reproduces both: its J is below the
      gain model's (which leaves Q1's bump) and its BIC on N_eff is more than DELTA_BIC below: released,
      the cause's round returned, the gain gone from the target and the nuisance estimates, a note says why.
    - A true gain fault: the record's Q2 is the model's x 1.25, the rest noise. The candidate reproduces Q2
      but moves Q1 by the same bump: it passes the naming rule against the model without the gain (it removes
      most of Q2's misfit) but fits worse than the gain: the gain stands, nothing changes but a note."""
    from dataclasses import replace
    from types import SimpleNamespace

    from orchestrator.inputs.causes import Candidate
    from orchestrator.inverse import diagnose as dg
    from orchestrator.inverse.nuisance import NuisanceFit
    from orchestrator.inverse.screening import Evaluated
    from orchestrator.inverse.selection import Round
    from orchestrator.inverse.significance import assess

    model, sd, _, bump, noise = _bump_misfit(31)
    on_cause = {k: model[k] * (1.25 if k == "Q2" else 1.0) + (0.03 * sd[k] * bump if k == "Q1" else 0.0)
                for k in model}

    def case(record):
        target = _fake_target({k: record[k] + noise[k] for k in model}, {k: 0.01 * sd[k] for k in model})
        target.gains = {"Q2": 1.25}
        ref = Evaluated(Candidate("none"), np.zeros(0), target.score(model), 0, "nominal")
        nz = NuisanceFit({}, {}, {}, {}, {}, {"Q2": 1.25}, 0.0, ref.cmp, 20)
        return SimpleNamespace(target=target), ref, nz

    def fake_rejudged(pool, target, raw, bare, rd):
        assert target.gains == {} and bare.cmp.objective > rd.reference.cmp.objective   # Q2's misfit is back
        e = Evaluated(Candidate("ballast_void", 20), np.zeros(6), target.score(on_cause), 6, "fitted")
        return Round(bare, 0, [e], [e], {}, {}, {})

    monkeypatch.setattr(dg, "rejudged", fake_rejudged)

    # a track effect that looks like a gain
    inp, ref, nz = case(on_cause)
    with_gain = inp.target
    # round 1 saw the cause on the gain's model: there it does not pass (the gain is applied to it too)
    assert not assess(with_gain.score(on_cause), 6, ref.cmp, 0, with_gain).passes
    got = dg._released(None, inp, {}, ref, nz, Round(ref, 0, [], [], {}, {}, {}))
    assert got is not None, nz.notes
    bare, again = got
    assert inp.target.gains == {} and nz.channel_gains == {} and nz.cmp is bare.cmp
    assert again.real[0].candidate == Candidate("ballast_void", 20) and "released" in nz.notes[-1], nz.notes
    assert again.real[0].cmp.objective < ref.cmp.objective

    # a true gain fault
    inp, ref, nz = case({k: model[k] * (1.25 if k == "Q2" else 1.0) for k in model})
    before, without = inp.target, replace(inp.target, gains={})
    # the candidate explains the channel against the model without the gain ...
    assert assess(without.score(on_cause), 6, without.score(model), 0, without).passes
    # ... but not as well as the gain does
    assert dg._released(None, inp, {}, ref, nz, Round(ref, 0, [], [], {}, {}, {})) is None
    assert inp.target is before and nz.channel_gains == {"Q2": 1.25} and "stands" in nz.notes[-1], nz.notes


def test_round_2_also_screens_the_local_candidates_where_the_residual_left_by_the_first_cause_peaks():
    """Step 5 (diagnose module doc): round 2 adds to the superposed ranking's choice round 1's local candidates
    at the sleeper nearest the residual's peak and at the sleeper of its loudest channel, and the global causes
    — not a named cause's site, not one already chosen — and none when that residual is at the noise level.
    Built by hand, no runs: sleepers at 0, 1, ..., 4 m, the wheel at x_start + V (t - shift) = 1.0 + 2.0 t; a
    residual loud on channel b (on sleeper 2; a Hann bump peaking at t = 0.5 s, so at x = 2.0 m: sleeper 2).
    Named: a void at 2; chosen by the ranking: the pad at 3 and the impact angle. Left: the pad at 2 and the
    global bed (the void at 1 is elsewhere). The same bump on channel a instead (on sleeper 1): the peak's
    sleeper is still 2, the loudest channel's 1, so the void at 1 joins. With the bed named instead of the void
    at 2, the bed is left out and the void at 2 is in. With the bump removed the residual is white noise at the
    channels' own sigma (J 1.0 against the noise's 1.0): nothing added."""
    from types import SimpleNamespace

    from orchestrator.inputs.causes import Candidate
    from orchestrator.inverse.diagnose import _at_the_residual
    from orchestrator.inverse.objective import Comparison

    rng = np.random.default_rng(14)
    n, dt = 1001, 1e-3
    t = np.arange(n) * dt
    noise = {"a": rng.normal(0.0, 1.0, n), "b": rng.normal(0.0, 1.0, n)}
    layout = SimpleNamespace(groups={"a": "A", "b": "A"}, weights={"A": 1.0}, types={"a": "pressure", "b": "pressure"})
    target = SimpleNamespace(layout=layout, scale={"a": 1.0, "b": 1.0}, sigma={"a": 1.0, "b": 1.0},
                             measured=SimpleNamespace(t=t, dt=dt))
    sensors = [SimpleNamespace(id="a", body="sleeper_1"), SimpleNamespace(id="b", body="sleeper_2")]
    void1, void2, pad2, pad3 = (Candidate("ballast_void", 1), Candidate("ballast_void", 2),
                                Candidate("rail_pad_stiffness", 2), Candidate("rail_pad_stiffness", 3))
    bed, nose = Candidate("ballast_stiffness"), Candidate("impact_angle")
    inp = SimpleNamespace(target=target, sensors=sensors, sleeper_x=np.arange(5.0), x_start=1.0,
                          cands=[void1, void2, pad2, pad3, bed, nose])
    named = [SimpleNamespace(e=SimpleNamespace(candidate=void2))]
    chosen = [pad3, nose]

    def cmp_of(res):
        return Comparison(0.0, {k: {"nrmse": float(np.sqrt(np.mean(r ** 2)))} for k, r in res.items()}, {"A": 1.0},
                          1.0, 0.0, 2 * n, res, {})

    loud = {"a": noise["a"], "b": 20.0 * np.hanning(n) + noise["b"]}
    assert _at_the_residual(inp, target, cmp_of(loud), 2.0, named, chosen) == [pad2, bed]
    on_a = {"a": 20.0 * np.hanning(n) + noise["a"], "b": noise["b"]}
    assert _at_the_residual(inp, target, cmp_of(on_a), 2.0, named, chosen) == [void1, pad2, bed]
    bed_named = [SimpleNamespace(e=SimpleNamespace(candidate=bed))]
    assert _at_the_residual(inp, target, cmp_of(loud), 2.0, bed_named, chosen) == [void2, pad2]
    assert _at_the_residual(inp, target, cmp_of(noise), 2.0, named, chosen) == []
