"""Scenario loading (orchestrator.inputs.scenario) and the command line's handling of user errors."""
from __future__ import annotations

import copy
import dataclasses
import math
import pickle
import re
import sys
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orchestrator.cli import main
from orchestrator.inputs.errors import ScenarioError, UserInputError
from orchestrator.inputs.scenario import (
    PortMap,
    Scenario,
    SimulationSpec,
    dump_scenario,
    load_scenario,
    scenario_from_dict,
    scenario_keys,
)
from orchestrator.inputs.yaml_io import YamlLoader as _Loader  # the scenario files' YAML rules, to read README cells
from track.params import (
    BallastParams,
    LayoutParams,
    PadOverride,
    RailPadParams,
    ReductionParams,
    VoidSpec,
)


def key_path(path) -> str:
    """("track", "ballast", "voids", 0, "gaps") -> "track.ballast.voids[0].gaps"."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def get_in(d, path):
    for p in path:
        d = d[p]
    return d


def set_in(d, path, value):
    get_in(d, path[:-1])[path[-1]] = value


def del_in(d, path):
    del get_in(d, path[:-1])[path[-1]]


def error_of(data, **kwargs) -> ScenarioError:
    with pytest.raises(ScenarioError) as info:
        scenario_from_dict(data, source="<test>", **kwargs)
    return info.value


def assert_one_line_error(err: ScenarioError, key: str):
    text = str(err)
    assert "\n" not in text and "\r" not in text, text
    assert err.key == key, text
    assert text.startswith(f"<test>: {key}: "), text


# --------------------------------------------------------------------------------------
# Mapping onto the dataclasses
# --------------------------------------------------------------------------------------
def test_default_scenario_maps_onto_dataclasses(default_scenario):
    s = default_scenario
    assert isinstance(s, Scenario)
    assert s.name == "crossing-1-12-through-120"
    lay = s.track.layout
    assert (lay.type, lay.crossing, lay.radius, lay.sleeper_spacing, lay.sleepers, lay.route, lay.hand) == \
        ("turnout", "1:12", 500.0, 0.6, 40, "through", "left")
    assert lay.crossing_n == 12.0
    # 1.2e8 etc. are written without a signed exponent: YAML 1.1 would leave them strings.
    assert s.track.rail_pad.stiffness == 1.2e8 and isinstance(s.track.rail_pad.stiffness, float)
    assert s.track.ballast.stiffness_per_length == 4.0e7
    assert s.track.ballast.damping_per_length == 3.0e4
    assert s.track.impact_angle == 0.006
    assert (s.vehicle.fmu, s.vehicle.speed, s.vehicle.axle_load) == ("bogie", 33.333, 196200.0)
    assert s.vehicle.builtin and s.vehicle.ports == ()
    sim = s.simulation
    assert (sim.duration, sim.step, sim.output_step, sim.algorithm, sim.extrapolation) == \
        (0.5, 1.0e-4, 1.0e-4, "gauss-seidel", True)
    assert sim.output_every == 1
    assert sim.n_steps == 5000
    assert s.sensors is None

    # Keys the file leaves out take the dataclass defaults.
    d = LayoutParams()
    assert (lay.gauge, lay.rail, lay.transition_sleeper, lay.sleeper_length) == \
        (d.gauge, d.rail, d.transition_sleeper, d.sleeper_length)
    assert s.track.reduction == ReductionParams()
    assert s.track.rail_pad.overrides == () and s.track.rail_pad.two_bushings == RailPadParams().two_bushings
    assert s.track.ballast.voids == () and s.track.ballast.spacing == BallastParams().spacing
    assert s.track.structural_damping == 0.0
    assert sim.x_start is None

    # raw holds every key with its default filled in
    assert s.raw["track"]["reduction"] == dataclasses.asdict(ReductionParams())
    assert s.raw["track"]["layout"]["gauge"] == d.gauge


def test_plain_scenario_has_no_turnout_keys(plain_scenario):
    lay = plain_scenario.track.layout
    assert (lay.type, lay.sleepers, lay.sleeper_spacing) == ("plain", 30, 0.6)
    assert set(plain_scenario.raw["track"]["layout"]) == {"type", "sleeper_spacing", "sleepers", "gauge",
                                                          "rail", "sleeper_length"}
    # ...so the raw dict loads again
    assert scenario_from_dict(plain_scenario.raw) == dataclasses.replace(plain_scenario, source="<dict>")


def test_every_key_maps(make_full_scenario_dict):
    s = scenario_from_dict(make_full_scenario_dict())
    t = s.track
    assert t.layout == LayoutParams(type="turnout", crossing="1:15", radius=760.0, sleeper_spacing=0.65,
                                    sleepers=36, route="diverging", hand="right", gauge=1.435, rail="60E1",
                                    transition_sleeper=21, sleeper_length=2.6)
    assert t.rail_pad == RailPadParams(stiffness=1.2e8, damping=2.0e4, stiffness_scale=1.5,
                                       overrides=(PadOverride(17, 3.0),), two_bushings=True)
    assert t.ballast == BallastParams(stiffness_per_length=4.0e7, damping_per_length=3.0e4, stiffness_scale=0.8,
                                      voids=(VoidSpec(21, (0.0, 0.4e-3, 0.9e-3, 0.9e-3, 0.4e-3, 0.0)),),
                                      spacing=0.25)
    assert t.reduction == ReductionParams(f_cut=1500.0, mode_factor=2.5, element_length=0.08)
    assert (t.impact_angle, t.structural_damping, t.model) == (0.012, 1.0e-5, "beam")
    assert (s.vehicle.fmu, s.vehicle.speed, s.vehicle.axle_load) == ("quarter", 27.78, 200000.0)
    assert s.vehicle.start_values == {"m_body": 24000.0}
    assert s.simulation == SimulationSpec(duration=0.5, step=1.0e-5, output_step=5.0e-5, algorithm="jacobi",
                                          extrapolation=False, x_start=3.0)


def test_third_party_fmu_ports(make_full_scenario_dict, third_party_fmu):
    data = make_full_scenario_dict()
    data["vehicle"]["fmu"] = third_party_fmu.name  # relative to base_dir
    data["vehicle"]["ports"] = [
        {"x": "axle1.s", "z": "axle1.zL", "vz": "axle1.vzL", "Fz": "axle1.FL", "z_sign": -1, "vz_sign": -1},
        {"x": "axle1.s", "z": "axle1.zR", "vz": "axle1.vzR", "Fz": "axle1.FR", "Fz_sign": -1},
    ]
    s = scenario_from_dict(data, base_dir=third_party_fmu.parent)
    assert s.vehicle.fmu == str(third_party_fmu.resolve()) and not s.vehicle.builtin
    assert s.vehicle.ports == (PortMap("axle1.s", "axle1.zL", "axle1.vzL", "axle1.FL", -1, -1, 1),
                               PortMap("axle1.s", "axle1.zR", "axle1.vzR", "axle1.FR", 1, 1, -1))


def _readme_section(repo_root: Path, title: str) -> str:
    text = (repo_root / "README.md").read_text(encoding="utf-8")
    match = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", text, re.S | re.M)
    assert match, f"README has no '## {title}' section"
    return match.group(1)


def test_readme_documents_exactly_the_accepted_keys_and_defaults(repo_root):
    section = _readme_section(repo_root, "Scenario YAML")
    # | `key` | type (may hold escaped \| pipes) | default | meaning |
    rows = re.findall(r"^\| `([^`]+)` \|(?:[^|\\\n]|\\.)*\|([^|\n]*)\|", section, re.M)
    documented = {key: cell.strip() for key, cell in rows}
    keys = scenario_keys()
    assert set(documented) == set(keys)
    for key, cell in documented.items():
        info = keys[key]
        if info.required:
            assert cell == "required", key
            continue
        text = cell.split(" (")[0].strip("`").strip('"')  # `null` (= N // 2 + 1) -> null
        documented_default = text if isinstance(info.default, str) else yaml.load(text, Loader=_Loader)
        assert documented_default == info.default, \
            f"README says {key} defaults to {text}, the code says {info.default!r}: update the README table"


def test_readme_example_is_accepted(repo_root, tmp_path):
    section = _readme_section(repo_root, "Scenario YAML")
    example = re.search(r"```yaml\n(.*?)```", section, re.S).group(1)
    path = tmp_path / "example.yaml"
    path.write_text(example, encoding="utf-8")
    s = load_scenario(path)
    assert s.track.layout.crossing == "1:15" and s.track.ballast.voids[0].sleeper == 21
    # the example gives every key a built-in vehicle can have
    given = {key for key in scenario_keys() if not key.startswith("vehicle.ports")}
    flat = set()

    def walk(d, prefix):
        for k, v in d.items():
            p = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict) and k != "start_values":
                walk(v, p)
            elif isinstance(v, list) and v and isinstance(v[0], dict):
                walk(v[0], p + "[]")
            else:
                flat.add(p)

    walk(yaml.safe_load(example), "")
    assert flat == given


def test_caller_dict_is_not_modified(make_full_scenario_dict):
    data = make_full_scenario_dict()
    before = copy.deepcopy(data)
    scenario_from_dict(data, overrides=["track.ballast.stiffness_scale=2", "track.ballast.voids[0].sleeper=3"])
    assert data == before


# --------------------------------------------------------------------------------------
# Errors: unknown keys, types, values
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("path, wrong, hint", [
    (("track", "rail_pad", "stifness"), "stiffness", "did you mean 'stiffness'?"),
    (("sensor",), None, "did you mean 'sensors'?"),
    (("track", "ballast", "voids", 0, "gap"), None, "did you mean 'gaps'?"),
    (("simulation", "Step"), None, "did you mean 'step'?"),
    (("vehicle", "zzz"), None, "allowed here: fmu, speed"),
])
def test_unknown_key_names_path_and_suggests(make_full_scenario_dict, path, wrong, hint):
    data = make_full_scenario_dict()
    if wrong:
        get_in(data, path[:-1])[path[-1]] = get_in(data, path[:-1]).pop(wrong)
    else:
        set_in(data, path, 1)
    err = error_of(data)
    assert_one_line_error(err, key_path(path))
    assert hint in str(err)


@pytest.mark.parametrize("path, value, fragment", [
    (("vehicle", "speed"), True, "expected a number, got a boolean"),
    (("track", "rail_pad", "stiffness"), "stiff", "expected a number, got the string 'stiff'"),
    (("track", "rail_pad", "stiffness"), "nan", "expected a number"),
    (("track", "layout", "sleepers"), 40.5, "expected an integer"),
    (("track", "layout", "sleepers"), False, "expected an integer"),
    (("simulation", "extrapolation"), "yes", "expected true or false"),
    (("simulation", "extrapolation"), 1, "expected true or false"),
    (("track", "layout"), 5, "expected a mapping"),
    (("track", "ballast", "voids"), {"sleeper": 3}, "expected a list"),
    (("track", "ballast", "voids", 0, "gaps", 2), "deep", "expected a number"),
    (("track", "model"), 1, "expected beam | solid"),
    (("track", "layout", "crossing"), 12, "expected a string"),
    (("vehicle", "start_values", "m_body"), [1.0], "expected a number, boolean or string"),
    (("vehicle", "start_values"), [1.0], "expected a mapping"),
])
def test_wrong_type(make_full_scenario_dict, path, value, fragment):
    data = make_full_scenario_dict()
    set_in(data, path, value)
    err = error_of(data)
    assert_one_line_error(err, key_path(path))
    assert fragment in err.message


def test_quoted_numbers_are_type_errors_and_yaml_numbers_are_numbers(make_full_scenario_dict, tmp_path):
    """A quoted number is a wrong type (the file loader reads 1.2e8 unquoted as a float)."""
    for path, value, what in ((("track", "rail_pad", "stiffness"), "1.2e8", "a number"),
                              (("track", "layout", "sleepers"), "30", "an integer")):
        data = make_full_scenario_dict()
        set_in(data, path, value)
        err = error_of(data)
        assert_one_line_error(err, key_path(path))
        assert f"expected {what}, got the string {value!r} (write numbers without quotes)" in err.message
    # the file loader reads YAML 1.2 numbers; 1:12 is not the sexagesimal 72
    path = tmp_path / "s.yaml"
    path.write_text("name: s\ntrack: {layout: {crossing: 1:12}, ballast: {stiffness_per_length: 1e8}}\n"
                    "vehicle: {speed: 10}\n", encoding="utf-8")
    s = load_scenario(path)
    assert s.track.ballast.stiffness_per_length == 1e8 and s.track.layout.crossing == "1:12"


def _bad_value_cases():
    gap_path = ("track", "ballast", "voids", 0, "gaps")
    return [
        (("track", "rail_pad", "stiffness"), -1.2e8, "must be > 0"),
        (("track", "rail_pad", "stiffness"), 0.0, "must be > 0"),
        (("track", "ballast", "stiffness_per_length"), math.nan, "finite"),
        (("track", "ballast", "damping_per_length"), math.inf, "finite"),
        (("track", "ballast", "damping_per_length"), -1.0, "must be >= 0"),
        (("track", "ballast", "voids", 0, "sleeper"), 36, "outside 0..35"),
        (("track", "ballast", "voids", 0, "sleeper"), -1, "must be >= 0"),
        (("track", "rail_pad", "overrides", 0, "sleeper"), 99, "outside 0..35"),
        (("track", "layout", "transition_sleeper"), 36, "outside 0..35"),
        (gap_path + (3,), 0.05, "must be < 0.05"),
        (gap_path + (0,), -1e-4, "must be >= 0"),
        (gap_path, [0.0] * 5, "exactly 6 items"),
        (("track", "crossing", "impact_angle"), 0.06, "must be <= 0.05"),
        (("track", "layout", "sleepers"), 3, "must be >= 4"),
        (("track", "layout", "sleeper_length"), 1.4, "must exceed the gauge"),
        (("track", "layout", "crossing"), "1:1", "n > 1"),
        (("track", "layout", "crossing"), "12", '"1:n"'),
        (("track", "layout", "rail"), "UIC60", "one of '60E1'"),
        (("track", "reduction", "mode_factor"), 0.5, "must be >= 1"),
        (("vehicle", "speed"), 130.0, "must be <= 120 m/s"),
        (("vehicle", "fmu"), "bogey", "did you mean 'bogie'?"),
        (("vehicle", "fmu"), "missing.fmu", "file not found"),
        (("vehicle", "ports"), [{"x": "a", "z": "b", "vz": "c", "Fz": "d"}], "only for a third-party FMU"),
        (("simulation", "output_step"), 1.5e-5, "integer multiple of step"),
        (("simulation", "output_step"), 3.3e-5, "integer multiple of step"),
        (("simulation", "output_step"), 1.0, "must not exceed duration"),
        (("simulation", "algorithm"), "jacoby", "did you mean 'jacobi'?"),
        (("sensors",), "no/such/layout.yaml", "file not found"),
        (("name",), "my scenario", "a name of letters"),
    ]


@pytest.mark.parametrize("path, value, fragment", _bad_value_cases())
def test_non_physical_values(make_full_scenario_dict, path, value, fragment):
    data = make_full_scenario_dict()
    set_in(data, path, value)
    err = error_of(data)
    assert_one_line_error(err, key_path(path))
    assert fragment in err.message


def test_duplicate_sleeper_entries(make_full_scenario_dict):
    data = make_full_scenario_dict()
    data["track"]["ballast"]["voids"].append(copy.deepcopy(data["track"]["ballast"]["voids"][0]))
    err = error_of(data)
    assert_one_line_error(err, "track.ballast.voids[1].sleeper")
    assert "already given in track.ballast.voids[0]" in err.message
    data = make_full_scenario_dict()
    data["track"]["rail_pad"]["overrides"].append({"sleeper": 17, "stiffness_scale": 2.0})
    assert_one_line_error(error_of(data), "track.rail_pad.overrides[1].sleeper")


def test_plain_layout_rejects_turnout_keys(make_full_scenario_dict):
    data = make_full_scenario_dict()
    data["track"]["layout"] = {"type": "plain", "sleepers": 30, "radius": 500.0}
    err = error_of(data)
    assert_one_line_error(err, "track.layout.radius")
    assert "only allowed with type: turnout" in err.message
    data["track"]["layout"] = {"type": "plain", "sleepers": 30}
    data["track"]["model"] = "solid"
    assert_one_line_error(error_of(data), "track.model")


def test_third_party_fmu_needs_ports(make_full_scenario_dict, third_party_fmu):
    data = make_full_scenario_dict()
    data["vehicle"]["fmu"] = str(third_party_fmu)
    assert_one_line_error(error_of(data), "vehicle.ports")
    port = {"x": "s", "z": "z", "vz": "v", "Fz": "F"}
    data["vehicle"]["ports"] = [port, dict(port, z_sign=-1)]
    err = error_of(data)  # both wheels feed the same force input
    assert_one_line_error(err, "vehicle.ports[1].Fz")
    data["vehicle"]["ports"] = [dict(port, vz_sign=2)]
    assert_one_line_error(error_of(data), "vehicle.ports[0].vz_sign")
    data["vehicle"]["ports"] = [{"x": "s", "z": "z", "vz": "v"}]
    assert "required key is missing" in str(error_of(data))


def test_required_keys(make_full_scenario_dict):
    for path in (("name",), ("vehicle",), ("vehicle", "speed"), ("track", "ballast", "voids", 0, "gaps")):
        data = make_full_scenario_dict()
        del_in(data, path)
        err = error_of(data)
        assert_one_line_error(err, key_path(path))
        assert err.message == "required key is missing"


# --------------------------------------------------------------------------------------
# Overrides
# --------------------------------------------------------------------------------------
def test_overrides(default_scenario_path, third_party_fmu):
    s = load_scenario(default_scenario_path, overrides=[
        "track.ballast.stiffness_scale=2",
        "track.reduction.f_cut=1000",  # a section the file leaves out
        "track.ballast.voids=[{sleeper: 21, gaps: [0, 1e-3, 1e-3, 1e-3, 1e-3, 0]}]",
        "track.ballast.voids[0].sleeper=20",  # applied in order
        "simulation.algorithm=jacobi",
        "vehicle.start_values.m_body=24000",
        "track.layout.crossing=1:15",
    ])
    assert s.track.ballast.stiffness_scale == 2.0
    assert s.track.reduction.f_cut == 1000.0
    assert s.track.ballast.voids == (VoidSpec(20, (0.0, 1e-3, 1e-3, 1e-3, 1e-3, 0.0)),)
    assert s.simulation.algorithm == "jacobi"
    assert s.vehicle.start_values == {"m_body": 24000}
    assert s.track.layout.crossing_n == 15.0
    # with_overrides starts from the validated scenario
    t = s.with_overrides(["vehicle.speed=20"])
    assert t.vehicle.speed == 20.0 and t.track == s.track


@pytest.mark.parametrize("override, key, fragment", [
    ("track.ballast.stifness_scale=2", "track.ballast.stifness_scale", "did you mean 'stiffness_scale'?"),
    ("trak.ballast.stiffness_scale=2", "trak", "did you mean 'track'?"),
    ("track.ballast.stiffness_scale=-2", "track.ballast.stiffness_scale", "must be > 0"),
    ("track.ballast.stiffness_scale", None, "key.path=value"),
    ("track..ballast=2", None, "not a key path"),
    ("track.ballast.voids[0].sleeper=3", "track.ballast.voids[0]", "out of range"),
    ("track.ballast[0]=3", "track.ballast", "is a mapping"),
    ("vehicle.speed.kmh=3", "vehicle.speed", "single value"),
    ("track.ballast.stiffness_scale=[1, 2", "track.ballast.stiffness_scale", "invalid YAML"),
])
def test_bad_override(default_scenario_path, override, key, fragment):
    with pytest.raises(ScenarioError) as info:
        load_scenario(default_scenario_path, overrides=[override])
    err = info.value
    assert err.key == key and fragment in err.message
    assert "\n" not in str(err) and str(err).startswith(str(default_scenario_path))


# --------------------------------------------------------------------------------------
# Files
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("text, fragment", [
    ("name: x\ntrack: {layout: [1, 2}\n", "line 2"),
    ("name: x\nname: y\n", "line 2, column 1: invalid YAML: duplicate key 'name' (first at line 1)"),
    ("- name: x\n", "must be a mapping"),
    ("", "empty"),
    ("name: x\n\tvehicle: 1\n", "line 2"),
])
def test_bad_files(tmp_path, text, fragment):
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert fragment in str(info.value) and "\n" not in str(info.value)
    assert str(info.value).startswith(str(path))


def test_missing_file_and_folder(tmp_path):
    with pytest.raises(ScenarioError, match="file not found"):
        load_scenario(tmp_path / "nope.yaml")
    with pytest.raises(ScenarioError, match="is a folder"):
        load_scenario(tmp_path)


def test_yaml_merge_keys_may_override(tmp_path):
    path = tmp_path / "merge.yaml"
    path.write_text("name: m\nvehicle:\n  <<: {speed: 10, axle_load: 1.0e5}\n  speed: 20\n", encoding="utf-8")
    s = load_scenario(path)
    assert (s.vehicle.speed, s.vehicle.axle_load) == (20.0, 1.0e5)


def test_paths_resolve_against_the_scenario_folder_and_dump_round_trips(tmp_path, make_full_scenario_dict):
    (tmp_path / "sensors").mkdir()
    (tmp_path / "sensors" / "layout.yaml").write_text("sensors: []\n", encoding="utf-8")
    (tmp_path / "veh.fmu").write_bytes(b"")
    data = make_full_scenario_dict()
    data["sensors"] = "sensors/layout.yaml"
    data["vehicle"]["fmu"] = "veh.fmu"
    data["vehicle"]["ports"] = [{"x": "s", "z": "z", "vz": "v", "Fz": "F"}]
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(data), encoding="utf-8")
    s = load_scenario(tmp_path / "scen.yaml")
    assert s.sensors == str((tmp_path / "sensors" / "layout.yaml").resolve())

    out = tmp_path / "out" / "extended.yaml"
    out.parent.mkdir()
    dump_scenario(s, out)
    assert "../sensors/layout.yaml" in out.read_text(encoding="utf-8")
    again = load_scenario(out)
    assert (again.track, again.vehicle, again.simulation, again.sensors) == \
        (s.track, s.vehicle, s.simulation, s.sensors)
    assert again.raw == s.raw


def test_scenario_is_plain_data(default_scenario):
    """Scenarios go to worker processes (pickle) and raw back to YAML: only builtin types inside."""
    assert pickle.loads(pickle.dumps(default_scenario)) == default_scenario

    def types_in(x):
        yield type(x)
        if isinstance(x, dict):
            for k, v in x.items():
                yield type(k)
                yield from types_in(v)
        elif isinstance(x, list):
            for v in x:
                yield from types_in(v)

    assert set(types_in(default_scenario.raw)) <= {dict, list, str, int, float, bool, type(None)}


def test_scenario_error_format_and_pickle():
    err = ScenarioError("must be > 0,\n got -1", key="track.rail_pad.stiffness", source="a.yaml")
    assert str(err) == "a.yaml: track.rail_pad.stiffness: must be > 0, got -1"
    assert str(ScenarioError("file not found", source="a.yaml")) == "a.yaml: file not found"
    back = pickle.loads(pickle.dumps(err))
    assert (back.key, back.source, str(back)) == (err.key, err.source, str(err))
    assert isinstance(err, UserInputError) and isinstance(err, ValueError)


# --------------------------------------------------------------------------------------
# Fuzzing: mutations of a valid scenario must each give one clear error
# --------------------------------------------------------------------------------------
N_FULL = 36  # sleepers in the conftest's full scenario
GAUGE = 1.435

_nonfinite = st.sampled_from([math.nan, math.inf, -math.inf])
_gt0 = st.floats(max_value=0.0)
_ge0 = st.floats(max_value=-1e-12)
_not_integer = st.floats(min_value=0.01, max_value=1e6).filter(lambda x: not x.is_integer())
_bad_index = st.integers(max_value=-1) | st.integers(min_value=N_FULL, max_value=10**9) | _not_integer

# numeric leaf -> strategy of invalid values (non-finite values are added for all)
BAD_NUMBERS = {
    ("track", "layout", "radius"): _gt0,
    ("track", "layout", "sleeper_spacing"): _gt0,
    ("track", "layout", "sleepers"): st.integers(max_value=3) | _not_integer,
    ("track", "layout", "gauge"): _gt0,
    ("track", "layout", "transition_sleeper"): _bad_index,
    ("track", "layout", "sleeper_length"): st.floats(max_value=GAUGE),
    ("track", "rail_pad", "stiffness"): _gt0,
    ("track", "rail_pad", "damping"): _ge0,
    ("track", "rail_pad", "stiffness_scale"): _gt0,
    ("track", "rail_pad", "overrides", 0, "sleeper"): _bad_index,
    ("track", "rail_pad", "overrides", 0, "stiffness_scale"): _gt0,
    ("track", "ballast", "stiffness_per_length"): _gt0,
    ("track", "ballast", "damping_per_length"): _ge0,
    ("track", "ballast", "stiffness_scale"): _gt0,
    ("track", "ballast", "spacing"): _gt0,
    ("track", "ballast", "voids", 0, "sleeper"): _bad_index,
    **{("track", "ballast", "voids", 0, "gaps", k): _ge0 | st.floats(min_value=0.05) for k in range(6)},
    ("track", "crossing", "impact_angle"): _ge0 | st.floats(min_value=0.05, exclude_min=True),
    ("track", "reduction", "f_cut"): _gt0,
    ("track", "reduction", "mode_factor"): st.floats(max_value=1.0, exclude_max=True),
    ("track", "reduction", "element_length"): _gt0,
    ("track", "structural_damping"): _ge0,
    ("vehicle", "speed"): _gt0 | st.floats(min_value=120.0, exclude_min=True),
    ("vehicle", "axle_load"): _gt0,
    ("simulation", "duration"): _gt0,
    ("simulation", "step"): _gt0,
    ("simulation", "output_step"): _gt0,
    ("simulation", "x_start"): st.nothing(),
}
NULLABLE = {("track", "layout", "transition_sleeper"), ("simulation", "x_start"), ("sensors",)}
CHOICES = {
    ("track", "model"): ("beam", "solid"),
    ("track", "layout", "type"): ("plain", "turnout"),
    ("track", "layout", "route"): ("through", "diverging"),
    ("track", "layout", "hand"): ("left", "right"),
    ("track", "layout", "rail"): ("60E1",),
    ("simulation", "algorithm"): ("gauss-seidel", "jacobi"),
    ("vehicle", "fmu"): ("bogie", "quarter"),
}
BOOLS = [("track", "rail_pad", "two_bushings"), ("simulation", "extrapolation")]
MAPPINGS = [(), ("track",), ("track", "layout"), ("track", "rail_pad"), ("track", "rail_pad", "overrides", 0),
            ("track", "ballast"), ("track", "ballast", "voids", 0), ("track", "crossing"), ("track", "reduction"),
            ("vehicle",), ("simulation",)]
LISTS = [("track", "rail_pad", "overrides"), ("track", "ballast", "voids"), ("track", "ballast", "voids", 0, "gaps")]
REQUIRED = [("name",), ("vehicle",), ("vehicle", "speed"), ("track", "rail_pad", "overrides", 0, "sleeper"),
            ("track", "rail_pad", "overrides", 0, "stiffness_scale"), ("track", "ballast", "voids", 0, "sleeper"),
            ("track", "ballast", "voids", 0, "gaps")]
TURNOUT_ONLY = ["crossing", "radius", "route", "hand", "transition_sleeper"]

_words = st.from_regex(r"[A-Za-z_][A-Za-z_ ]{0,9}", fullmatch=True)  # never a number
_junk = st.one_of(st.booleans(), _words, st.lists(st.integers(), max_size=2),
                  st.dictionaries(st.text(max_size=3), st.integers(), max_size=2))


def _mutate(data: dict, draw) -> tuple:
    """Apply one random invalid change to ``data``; return the key path it must be blamed on."""
    kind = draw(st.sampled_from(["number", "number_type", "choice", "bool", "mapping", "list", "unknown",
                                 "required", "gaps_length", "duplicate", "plain"]))
    if kind == "number":
        path = draw(st.sampled_from(sorted(BAD_NUMBERS, key=str)))
        set_in(data, path, draw(BAD_NUMBERS[path] | _nonfinite))
    elif kind == "number_type":
        path = draw(st.sampled_from(sorted(BAD_NUMBERS, key=str)))
        set_in(data, path, draw(_junk if path in NULLABLE else _junk | st.none()))
    elif kind == "choice":
        path, allowed = draw(st.sampled_from(sorted(CHOICES.items(), key=str)))
        value = draw(st.text(max_size=12) | st.integers() | st.none() | st.booleans())
        if value in allowed:
            value = str(value) + "x"
        set_in(data, path, value)
    elif kind == "bool":
        path = draw(st.sampled_from(BOOLS))
        set_in(data, path, draw(st.integers() | st.floats() | _words | st.none()))
    elif kind == "mapping":
        path = draw(st.sampled_from(MAPPINGS[1:]))
        set_in(data, path, draw(st.integers() | _words | st.lists(st.integers(), max_size=2)))
    elif kind == "list":
        path = draw(st.sampled_from(LISTS))
        set_in(data, path, draw(st.integers() | _words | st.dictionaries(st.just("a"), st.integers())))
    elif kind == "unknown":
        path = draw(st.sampled_from(MAPPINGS))
        here = get_in(data, path)
        key = draw(st.from_regex(r"[a-z][a-z0-9_]{0,10}", fullmatch=True)
                   .filter(lambda k: k not in here and k != "ports"))
        here[key] = draw(st.integers() | _words)
        path = path + (key,)
    elif kind == "required":
        path = draw(st.sampled_from(REQUIRED))
        del_in(data, path)
    elif kind == "gaps_length":
        path = ("track", "ballast", "voids", 0, "gaps")
        set_in(data, path, draw(st.lists(st.just(0.0), max_size=10).filter(lambda g: len(g) != 6)))
    elif kind == "duplicate":
        lst = draw(st.sampled_from([("track", "rail_pad", "overrides"), ("track", "ballast", "voids")]))
        get_in(data, lst).append(copy.deepcopy(get_in(data, lst)[0]))
        path = lst + (1, "sleeper")
    else:  # plain layout with one turnout-only key left
        key = draw(st.sampled_from(TURNOUT_ONLY))
        layout = data["track"]["layout"]
        for k in TURNOUT_ONLY:
            if k != key:
                del layout[k]
        layout["type"] = "plain"
        path = ("track", "layout", key)
    return path


def test_fuzz_bad_scenarios_give_one_line_errors(make_full_scenario_dict):
    seen = []

    @settings(max_examples=300, deadline=None, database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
    @given(st.data())
    def check(data):
        scenario = make_full_scenario_dict()
        path = _mutate(scenario, data.draw)
        err = error_of(scenario)
        assert_one_line_error(err, key_path(path))
        seen.append(path)

    scenario_from_dict(make_full_scenario_dict())  # the unmutated scenario is valid
    check()
    assert len(seen) >= 200


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
def test_cli_bad_scenario_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nvehicle: {speed: 10}\ntrack: {rail_pad: {stifness: 1.0e8}}\n", encoding="utf-8")
    assert main(["run", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err == f"turnout: error: {bad}: track.rail_pad.stifness: unknown key 'stifness' " \
                  f"(did you mean 'stiffness'?)\n"


@pytest.mark.parametrize("argv", [
    ["run"],  # no scenario
    ["fly", "x.yaml"],  # unknown command
    [],
    ["run", "missing.yaml"],
    ["frf", "scenarios/x.yaml", "--fmax", "-3"],
    ["frf", "scenarios/x.yaml", "--at", "crossing"],
])
def test_cli_usage_errors_are_one_line(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("turnout: error: ") and err.count("\n") == 1 and "Traceback" not in err


@pytest.mark.parametrize("command", ["run", "frf"])
def test_cli_help_exits_0(command, capsys):
    with pytest.raises(SystemExit) as info:
        sys.exit(main([command, "--help"]))
    assert info.value.code == 0
    assert "--out" in capsys.readouterr().out


@pytest.fixture
def fake_jobs(monkeypatch):
    from orchestrator.results import jobs

    calls = []
    monkeypatch.setattr(jobs, "run_scenario", lambda scenario, out_dir, progress=True, backend="fmu",
                        save_states=False: calls.append(("run", scenario, out_dir, progress, backend)) or {})
    monkeypatch.setattr(jobs, "frf_job", lambda scenario, out_dir, at, fmax:
                        calls.append(("frf", scenario, out_dir, at, fmax)) or {})
    return calls


def test_cli_run_delegates(fake_jobs, default_scenario_path, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["run", str(default_scenario_path), "--out", str(out), "--set", "vehicle.speed=20",
                 "--no-progress", "--backend", "inprocess"]) == 0
    (_, scenario, out_dir, progress, backend), = fake_jobs
    assert scenario.vehicle.speed == 20.0 and out_dir == out and progress is False and backend == "inprocess"
    assert str(out) in capsys.readouterr().out.strip().splitlines()[-1]


def test_cli_frf_delegates(fake_jobs, default_scenario_path):
    assert main(["frf", str(default_scenario_path), "--at", "crossing:42.0"]) == 0
    (_, scenario, out_dir, at, fmax), = fake_jobs
    assert at == "crossing:42.0" and fmax == scenario.track.reduction.f_cut
    assert out_dir == Path("results") / "crossing-1-12-through-120-frf"


def test_cli_user_error_from_job(monkeypatch, default_scenario_path, capsys):
    def fail(scenario, out_dir, at, fmax):
        raise UserInputError("no rail body named 'nose'\n(have: crossing)")

    from orchestrator.results import jobs

    monkeypatch.setattr(jobs, "frf_job", fail)
    assert main(["frf", str(default_scenario_path), "--at", "nose:1"]) == 2
    assert capsys.readouterr().err == "turnout: error: no rail body named 'nose' (have: crossing)\n"


def test_the_fine_measurement_scenario_is_the_coarse_one_at_half_the_step():
    """Consistency check (two files of ours): scenarios/measurement/crossing_quarter_120_fine.yaml, the
    field-data scenario of issue 14's matrix, differs from the test suite's crossing_quarter_120.yaml only
    in its name and its time step, half of it (the output step, the sensors' 5 kHz, stays), so the
    matrix and the tests diagnose the same model but for the step."""
    here = Path(__file__).resolve().parents[1] / "scenarios" / "measurement"
    coarse, fine = (load_scenario(here / f).raw for f in ("crossing_quarter_120.yaml",
                                                         "crossing_quarter_120_fine.yaml"))
    assert fine["simulation"]["step"] == 0.5 * coarse["simulation"]["step"]
    assert fine["simulation"]["output_step"] == coarse["simulation"]["output_step"]
    for raw in (coarse, fine):
        raw.pop("name")
        raw["simulation"].pop("step")
    assert fine == coarse
