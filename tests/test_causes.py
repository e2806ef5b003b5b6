"""The cause registry (``orchestrator.inputs.causes``): each entry enters the scenario where it says.

References are written out here, not taken from the registry: the scenario keys of
DESIGN.md §4.2 and the track FMU's declared parameters (read from a built FMU's
modelDescription.xml).
"""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.inputs.causes import CATALOGUE, DRAWS, Candidate, candidates, kind_of
from orchestrator.inputs.scenario import scenario_from_dict


def _raw(default_scenario_dict):
    return scenario_from_dict(default_scenario_dict, source="<test>").raw


# Where each cause lives in a scenario (DESIGN.md §4.2), written out independently of the registry.
EXPECTED_KEYS = {
    ("ballast_void", 21): "track.ballast.voids",
    ("ballast_stiffness", None): "track.ballast.stiffness_scale",
    ("rail_pad_stiffness", None): "track.rail_pad.stiffness_scale",
    ("rail_pad_stiffness", 21): "track.rail_pad.overrides",
    ("impact_angle", None): "track.crossing.impact_angle",
    ("rail_pad_damping", None): "track.rail_pad.damping",
    ("ballast_damping", None): "track.ballast.damping_per_length",
    ("wheelset_mass", None): "vehicle.start_values.wheelset_mass",
    ("primary_stiffness", None): "vehicle.start_values.k1",
    ("primary_damping", None): "vehicle.start_values.c1",
}
# Each cause's category, written out: what a diagnosis may name (track) and what it must not.
EXPECTED_CATEGORY = {
    "ballast_void": "track", "ballast_stiffness": "track", "rail_pad_stiffness": "track", "impact_angle": "track",
    "rail_pad_damping": "track", "ballast_damping": "track",
    "wheelset_mass": "vehicle", "primary_stiffness": "vehicle", "primary_damping": "vehicle",
    "speed": "measurement", "channel_gain": "sensor", "channel_offset": "sensor", "channel_dead": "sensor",
}


@pytest.mark.parametrize("cause, sleeper", sorted(EXPECTED_KEYS, key=str))
def test_each_cause_enters_its_scenario_key_and_reads_back(default_scenario_dict, cause, sleeper):
    raw = _raw(default_scenario_dict)
    kind = CATALOGUE[cause]
    assert kind.scenario_key(sleeper) == EXPECTED_KEYS[(cause, sleeper)]
    rng = np.random.default_rng(3)
    u = rng.uniform(0.05, 0.95, len(kind.names))
    values = kind.from_unit(u)
    new = kind.apply(raw, sleeper, values)
    # the values read back exactly, and validate as a scenario
    np.testing.assert_array_equal(kind.nominal(new, sleeper), values)
    scenario_from_dict(new, source="<variant>")
    # nothing else changed: the variant differs from the nominal at that key only
    key = EXPECTED_KEYS[(cause, sleeper)].split(".")
    a, b = raw, new
    for k in key:   # a key the variant creates (a vehicle start value) is absent from the nominal
        assert {x for x in set(a) | set(b) if a.get(x) != b.get(x)} == {k}
        a, b = a.get(k), b[k]
    # the original mapping is untouched
    assert _raw(default_scenario_dict) == raw


def test_a_void_of_zero_gaps_removes_the_entry_and_pads_keep_theirs(default_scenario_dict):
    raw = _raw(default_scenario_dict)
    void, pad = CATALOGUE["ballast_void"], CATALOGUE["rail_pad_stiffness"]
    with_void = void.apply(raw, 21, [0.0, 1e-3, 2e-3, 2e-3, 1e-3, 0.0])
    assert [v["sleeper"] for v in with_void["track"]["ballast"]["voids"]] == [21]
    assert void.apply(with_void, 21, np.zeros(6))["track"]["ballast"]["voids"] == []
    # negative gaps are clipped to 0 (a gap cannot be negative)
    assert min(void.apply(raw, 21, [-1e-3] + [1e-3] * 5)["track"]["ballast"]["voids"][0]["gaps"]) == 0.0
    # a pad scale of 1 is still written (an explicit override), and the nominal without one is 1
    assert pad.nominal(raw, 21).tolist() == [1.0]
    assert pad.apply(raw, 21, [1.0])["track"]["rail_pad"]["overrides"] == [{"sleeper": 21, "stiffness_scale": 1.0}]


def test_void_screening_proxies_are_the_uniform_gap_and_the_two_one_sided_wedges(default_scenario_dict):
    """A void is screened as a uniform gap (its grid) and as the wedges with 0 at one end and the
    magnitude at the other (orchestrator.inputs.causes.VOID_SHAPES); a scalar cause has the uniform
    proxy only. apply_scalar with a profile writes magnitude x profile."""
    raw = _raw(default_scenario_dict)
    void = CATALOGUE["ballast_void"]
    proxies = void.screen_proxies()
    assert proxies[0][0].tolist() == [1.0] * 6 and proxies[0][1] == void.grid
    ends = sorted((float(p[0]), float(p[-1])) for p, _ in proxies[1:])
    assert ends == [(0.0, 1.0), (1.0, 0.0)]
    for p, _ in proxies[1:]:
        assert np.all(np.diff(p) != 0) and np.all(np.sign(np.diff(p)) == np.sign(p[-1] - p[0]))   # monotonic
    gaps = void.apply_scalar(raw, 21, 2e-3, proxies[1][0])["track"]["ballast"]["voids"][0]["gaps"]
    assert np.allclose(gaps, 2e-3 * proxies[1][0])
    assert [p.tolist() for p, _ in CATALOGUE["ballast_stiffness"].screen_proxies()] == [[1.0]]


def test_scope_is_checked():
    with pytest.raises(ValueError, match="needs a sleeper"):
        CATALOGUE["ballast_void"].site(None)
    with pytest.raises(ValueError, match="needs no sleeper"):
        CATALOGUE["impact_angle"].site(3)


def test_candidates_place_local_causes_near_the_sensors():
    cands = candidates([5, 6], n_sleepers=8, reach=1)
    local = sorted({c.sleeper for c in cands if c.sleeper is not None})
    assert local == [4, 5, 6, 7]
    # every screened track cause appears at each scope it has
    track = {"ballast_void", "ballast_stiffness", "rail_pad_stiffness", "impact_angle"}
    assert {c.cause for c in cands} == track
    for name in track:
        kind = CATALOGUE[name]
        has_global = Candidate(name) in cands
        has_local = Candidate(name, 5) in cands
        assert (has_global, has_local) == (kind.local in (False, None), kind.local in (True, None)), name


def test_categories_and_what_a_diagnosis_screens():
    """Vehicle, speed and sensor causes are never track candidates; track damping is a nuisance."""
    assert {name: kind.category for name, kind in CATALOGUE.items()} == EXPECTED_CATEGORY
    everything = candidates([5], n_sleepers=8, reach=0, categories=("track", "vehicle", "measurement", "sensor"))
    assert {c.cause for c in everything} == {"ballast_void", "ballast_stiffness", "rail_pad_stiffness",
                                            "impact_angle", "wheelset_mass", "primary_stiffness",
                                            "primary_damping", "speed"}
    with pytest.raises(ValueError, match="category"):
        type(CATALOGUE["speed"])("x", False, ("x",), (0.0,), (1.0,), False, (), category="weather")


def test_vehicle_causes_read_the_models_defaults_and_the_scenarios_start_values(default_scenario_dict):
    """Nominal of a vehicle cause: the start value if given, else the model's default (vehicle.quarter /
    vehicle.bogie, written out here); the variant is a vehicle the scenario loads with that value."""
    raw = _raw(default_scenario_dict)          # fmu: bogie, no start values
    assert raw["vehicle"]["fmu"] == "bogie"
    bogie = {"wheelset_mass": 1500.0, "primary_stiffness": 1.2e6, "primary_damping": 1.0e4}
    for name, default in bogie.items():
        assert CATALOGUE[name].nominal(raw, None).tolist() == [default], name
    raw["vehicle"]["fmu"] = "quarter"
    assert CATALOGUE["primary_damping"].nominal(raw, None).tolist() == [2.0e4]   # QuarterParams.c1
    raw["vehicle"]["start_values"] = {"k1": 9.0e5}
    assert CATALOGUE["primary_stiffness"].nominal(raw, None).tolist() == [9.0e5]
    new = CATALOGUE["wheelset_mass"].apply(raw, None, [1800.0])
    sc = scenario_from_dict(new, source="<variant>")
    assert dict(sc.vehicle.start_values) == {"k1": 9.0e5, "wheelset_mass": 1800.0}
    raw["vehicle"]["fmu"] = "other.fmu"        # a third-party FMU: no known default
    raw["vehicle"]["start_values"] = {}
    with pytest.raises(ValueError, match="unknown"):
        CATALOGUE["wheelset_mass"].nominal(raw, None)


def test_speed_cause_keeps_the_stretch_of_track(default_scenario_dict):
    """A speed variant covers the same distance: duration x speed is kept to within one output step."""
    raw = _raw(default_scenario_dict)
    kind = CATALOGUE["speed"]
    v0, d0, out = raw["vehicle"]["speed"], raw["simulation"]["duration"], raw["simulation"]["output_step"]
    for v in (0.97 * v0, 1.03 * v0):
        new = kind.apply(raw, None, [v])
        assert kind.nominal(new, None).tolist() == [v]
        d = new["simulation"]["duration"]
        assert v * d <= v0 * d0 + 1e-9 and v * d > v0 * d0 - v * out, (v, d)
        assert abs(d / out - round(d / out)) < 1e-6    # a whole number of output steps
        scenario_from_dict(new, source="<variant>")


def test_sensor_faults_act_on_the_channel_not_the_scenario(default_scenario_dict):
    raw = _raw(default_scenario_dict)
    x = np.array([0.0, 1.0, -2.0])
    for name, values, expected in (("channel_gain", [0.9], 0.9 * x), ("channel_offset", [0.5], x + 0.5 * 4.0),
                                   ("channel_dead", [-0.25], np.full(3, -1.0))):
        c = Candidate(name, channel="B3")
        kind = kind_of(c)
        assert kind.category == "sensor" and c.label == f"{name}@B3"
        assert kind.apply(raw, c.channel, values) == raw            # the scenario is untouched
        np.testing.assert_allclose(kind.site(c.channel).on(x, values, 4.0), expected)


def test_every_draw_is_a_registry_cause_inside_its_bounds():
    rng = np.random.default_rng(0)
    for d in DRAWS:
        kind = CATALOGUE[d.cause]
        for _ in range(50):
            sleeper, parameters = d.draw(rng, [19, 20, 21])
            assert (sleeper is not None) == d.local
            v = np.asarray(kind.values_of(parameters), float)
            assert np.all(v >= np.asarray(kind.lower)) and np.all(v <= np.asarray(kind.upper)), (d.label, v)


def test_registry_fmu_parameters_are_declared_by_the_track_fmu(tmp_path, default_scenario):
    """The SSP binds a cause through the track-FMU parameters the registry names: each must exist."""
    pytest.importorskip("pythonfmu")
    from fmpy import read_model_description

    from fmus.build import build_track_fmu

    fmu = build_track_fmu(default_scenario.track, 4, tmp_path)
    declared = {v.name: v.causality for v in read_model_description(str(fmu)).modelVariables}
    for kind in CATALOGUE.values():
        for scope, names in kind.fmu_parameters.items():
            for name in names:
                assert declared.get(name) == "parameter", (kind.name, scope, name)
