"""The cause registry (``orchestrator.inputs.causes``): each entry enters the scenario where it says.

References are written out here, not taken from the registry: the scenario keys of
DESIGN.md §4.2 and the track FMU's declared parameters (read from a built FMU's
modelDescription.xml).
"""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.inputs.causes import CATALOGUE, DRAWS, Candidate, candidates
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
    for k in key[:-1]:
        assert {x for x in a if a[x] != b[x]} == {k}
        a, b = a[k], b[k]
    assert {x for x in a if a[x] != b[x]} == {key[-1]}
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


def test_scope_is_checked():
    with pytest.raises(ValueError, match="needs a sleeper"):
        CATALOGUE["ballast_void"].site(None)
    with pytest.raises(ValueError, match="needs no sleeper"):
        CATALOGUE["impact_angle"].site(3)


def test_candidates_place_local_causes_near_the_sensors():
    cands = candidates([5, 6], n_sleepers=8, reach=1)
    local = sorted({c.sleeper for c in cands if c.sleeper is not None})
    assert local == [4, 5, 6, 7]
    # every registry cause appears at each scope it has
    for name, kind in CATALOGUE.items():
        has_global = Candidate(name) in cands
        has_local = Candidate(name, 5) in cands
        assert (has_global, has_local) == (kind.local in (False, None), kind.local in (True, None)), name


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
