"""Bad input gives one clear line and exit status 2, never a traceback (DESIGN.md §4.1).

The cases of a user's probe of the landed code (mutated scenarios, broken FMUs, vehicle
ports mapped onto the wrong variables, implausible numbers, bad measured files, an
``--out`` that is a device), and a property-based test: random mutations of the default
scenario, validated as ``turnout run --dry-run`` does (load, validate, build the layout,
place the vehicle; nothing simulated), are either valid or a one-line exit-2 error.
"""
from __future__ import annotations

import contextlib
import copy
import errno
import io
import math
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from orchestrator.cli import main
from orchestrator.inputs.errors import ScenarioError, UserInputError, UserInputWarning
from orchestrator.inputs.scenario import load_scenario, scenario_from_dict
from orchestrator.inputs.yaml_io import dump_yaml

REPO = Path(__file__).resolve().parents[1]
DEFAULT = REPO / "scenarios" / "crossing_1_12_through_120.yaml"


def cli(argv) -> tuple[int, str, str]:
    """``turnout ARGV`` -> (exit status, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main([str(a) for a in argv])
    return rc, out.getvalue(), err.getvalue()


def assert_one_line_exit_2(rc: int, err: str, *fragments: str) -> None:
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("turnout: error: ") and "Traceback" not in err, err
    for f in fragments:
        assert f in lines[0], (f, lines[0])


def dry_run(overrides=(), scenario=DEFAULT) -> tuple[int, str, str]:
    argv = ["run", scenario, "--dry-run"]
    for o in overrides:
        argv += ["--set", o]
    return cli(argv)


# --------------------------------------------------------------------------------------
# --dry-run itself
# --------------------------------------------------------------------------------------
def test_dry_run_reports_the_plan_of_a_valid_scenario():
    rc, out, err = dry_run()
    assert rc == 0, err
    s = load_scenario(DEFAULT)
    n = round(s.simulation.duration / s.simulation.step)
    assert f"{n} steps" in out and "40-sleeper panel" in out and "nothing simulated" in out


def test_dry_run_refuses_a_run_off_the_panel():
    rc, _, err = dry_run(["simulation.duration=3"])
    assert_one_line_exit_2(rc, err, "simulation.duration", "beyond the modelled panel")


# --------------------------------------------------------------------------------------
# Layout inconsistencies (item 3): every command loads the scenario first
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("override, key", [
    ("track.layout.sleepers=4", "track.layout.sleepers"),
    ("track.layout.transition_sleeper=0", "track.layout.sleepers"),   # "(with transition_sleeper)"
    ("track.layout.sleeper_spacing=100", "track.layout.sleeper_spacing"),
    ("track.layout.sleeper_spacing=0.001", "track.layout.sleeper_spacing"),
    ("track.layout.sleepers=100000", "track.layout.sleepers"),
    ("track.layout.crossing='1:1000000000'", "track.layout.crossing"),
    ("track.layout.radius=1.0", "track.layout.radius"),
    ("track.layout.radius=1e300", "track.layout.radius"),
    ("track.ballast.spacing=10", "track.ballast.spacing"),
    ("track.dipped_joint=0.01", "track.dipped_joint"),
])
def test_layout_inconsistencies_are_one_line_errors(override, key):
    rc, _, err = dry_run([override])
    assert_one_line_exit_2(rc, err, key)


@pytest.mark.parametrize("argv", [
    ["build-fmus", DEFAULT, "--out", "{tmp}/f"],
    ["export-ssp", DEFAULT, "--out", "{tmp}/s.ssp"],
    ["frf", DEFAULT, "--out", "{tmp}/r"],
    ["synthesize", DEFAULT, "--out", "{tmp}/m.csv"],
])
def test_other_commands_refuse_the_layout_before_building_anything(argv, tmp_path):
    argv = [str(a).format(tmp=tmp_path) for a in argv]
    flag = "--effect" if argv[0] == "synthesize" else "--set"
    rc, _, err = cli(argv + [flag, "track.layout.sleepers=4"])
    assert_one_line_exit_2(rc, err, "track.layout.sleepers")
    assert not any(tmp_path.iterdir())   # nothing written


def test_transition_sleeper_error_names_both_keys():
    rc, _, err = dry_run(["track.layout.transition_sleeper=0"])
    assert_one_line_exit_2(rc, err, "track.layout.sleepers", "transition_sleeper", "does not build")


# --------------------------------------------------------------------------------------
# Implausible numbers (item 9) and quoted numbers (item 11)
# --------------------------------------------------------------------------------------
@pytest.mark.parametrize("override, key, words", [
    ("track.rail_pad.stiffness=1e20", "track.rail_pad.stiffness", "120-1200 MN/m"),
    ("track.ballast.stiffness_per_length=1e15", "track.ballast.stiffness_per_length", "N/mm^3"),
    ("vehicle.axle_load=1e12", "vehicle.axle_load", "kN"),
    ("simulation.step=1e-12", "simulation.step", "10-200 us"),
    ("vehicle.start_values={wheelset_mass: -1500}", "vehicle.start_values.wheelset_mass", "positive"),
    ("vehicle.start_values={x0: abc}", "vehicle.start_values.x0", "expected a number"),
    ("track.rail_pad.stiffness='1.2e8'", "track.rail_pad.stiffness", "without quotes"),
])
def test_implausible_values_name_the_key_and_the_range(override, key, words):
    rc, _, err = dry_run([override])
    assert_one_line_exit_2(rc, err, key, words)


def test_huge_step_count_is_refused_with_an_estimate():
    # 20 s at 0.1 us: 2e8 steps, above MAX_STEPS (1e7); estimate at 0.45 ms/step = 25 h
    rc, _, err = dry_run(["simulation.step=1e-7", "simulation.duration=20", "simulation.output_step=1e-4"])
    assert_one_line_exit_2(rc, err, "simulation.step", "2e+08 steps", "25 h")


def test_allowed_fine_step_gets_an_estimate_in_the_dry_run():
    rc, out, err = dry_run(["simulation.step=1e-6"])
    assert rc == 0, err
    assert "500000 steps" in out and "min of stepping" in out   # 5e5 x 0.45 ms = 3.8 min


# --------------------------------------------------------------------------------------
# Vehicle FMUs: broken files (item 4), ports against causality and count (item 1)
# --------------------------------------------------------------------------------------
def _write_scenario(tmp_path: Path, vehicle: dict) -> Path:
    data = load_scenario(DEFAULT).raw
    data = copy.deepcopy(data)
    data["vehicle"] = vehicle
    path = tmp_path / "s.yaml"
    path.write_text(dump_yaml(data), encoding="utf-8")
    return path


PORT = {"x": "axle1.s", "z": "axle1.zL", "vz": "axle1.vzL", "Fz": "axle1.FL"}


@pytest.mark.parametrize("content", [b"", bytes(np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8)),
                                     "zip"])
def test_broken_fmu_is_a_one_line_error(tmp_path, content):
    fmu = tmp_path / "other.fmu"
    if content == "zip":
        with zipfile.ZipFile(fmu, "w") as zf:
            zf.writestr("binaries/readme.txt", "no model description")
    else:
        fmu.write_bytes(content)
    path = _write_scenario(tmp_path, {"fmu": str(fmu), "speed": 33.333, "ports": [PORT]})
    rc, _, err = cli(["run", path, "--dry-run"])
    assert_one_line_exit_2(rc, err, "vehicle.fmu", "not a readable FMU")
    from orchestrator.cosim.units import FmuVehicle  # the run's own loader refuses it the same way
    from orchestrator.inputs.specs import PortMap
    with pytest.raises(UserInputError, match="not a readable FMU"):
        FmuVehicle(fmu, [PortMap(**PORT)], {}, {})


def _ports(**change):
    """Both wheels of the C quarter vehicle; ``change`` = {wheel index: {attr: name}}."""
    ports = [{"x": "axle1.s", "z": f"axle1.z{s}", "vz": f"axle1.vz{s}", "Fz": f"axle1.F{s}",
              "z_sign": -1, "vz_sign": -1, "Fz_sign": -1} for s in "LR"]
    for i, attrs in change.items():
        ports[int(i)].update(attrs)
    return ports


@pytest.mark.parametrize("ports, words", [
    (_ports(**{"1": {"Fz": "axle1.zR"}}), ["vehicle.ports[1].Fz", "'axle1.zR'", "Real output", "Real input"]),
    (_ports(**{"0": {"z": "m_axle"}}), ["vehicle.ports[0].z", "'m_axle'", "parameter", "Real output"]),
    (_ports(**{"0": {"vz": "axle1.FR"}}), ["vehicle.ports[0].vz", "'axle1.FR'", "Real input"]),
    (_ports()[:1], ["vehicle.ports", "2 Real inputs", "map 1", "'axle1.FR'", "one ports entry per wheel"]),
])
def test_ports_are_checked_against_causality_and_count(c_vehicle_fmu, tmp_path, ports, words):
    """Fz on an output crashed the FMU (segfault) or gave "fmi2SetReal returned status 4"; z on a
    parameter or a wheel left out ran with wrong results. Now: refused when the FMU is loaded."""
    vehicle = {"fmu": str(c_vehicle_fmu), "speed": 33.333, "ports": ports, "start_values": {"v": 33.333}}
    rc, _, err = cli(["run", _write_scenario(tmp_path, vehicle), "--dry-run"])
    assert_one_line_exit_2(rc, err, *words)
    from orchestrator.cosim.units import FmuVehicle
    from orchestrator.inputs.specs import PortMap
    with pytest.raises(UserInputError, match=words[0].replace("[", r"\[").replace("]", r"\]")):
        FmuVehicle(c_vehicle_fmu, [PortMap(**p) for p in ports], {}, {})


def test_correct_ports_pass_and_start_values_are_typed(c_vehicle_fmu, tmp_path):
    vehicle = {"fmu": str(c_vehicle_fmu), "speed": 33.333, "ports": _ports(), "start_values": {"v": 33.333}}
    rc, out, err = cli(["run", _write_scenario(tmp_path, vehicle), "--dry-run"])
    assert rc == 0 and "external vehicle, 2 wheels" in out, err
    vehicle["start_values"] = {"v": "abc"}
    rc, _, err = cli(["run", _write_scenario(tmp_path, vehicle), "--dry-run"])
    assert_one_line_exit_2(rc, err, "vehicle.start_values.v", "is Real, got 'abc'")
    vehicle["start_values"] = {"axle1.zL": 0.0}
    rc, _, err = cli(["run", _write_scenario(tmp_path, vehicle), "--dry-run"])
    assert_one_line_exit_2(rc, err, "vehicle.start_values.axle1.zL", "only parameters and inputs")


def test_export_ssp_checks_ports_before_building_the_track(c_vehicle_fmu, tmp_path):
    vehicle = {"fmu": str(c_vehicle_fmu), "speed": 33.333, "ports": _ports()[:1], "start_values": {"v": 33.333}}
    rc, _, err = cli(["export-ssp", _write_scenario(tmp_path, vehicle), "--out", tmp_path / "x.ssp"])
    assert_one_line_exit_2(rc, err, "one ports entry per wheel")
    assert not (tmp_path / "x.ssp").exists()


# --------------------------------------------------------------------------------------
# Measured files (item 6) and write errors (item 11)
# --------------------------------------------------------------------------------------
def _measured_csv(path: Path, n: int, dt: float, columns=("A1", "A2"), time_header="time") -> Path:
    t = dt * np.arange(n)
    rows = [",".join([time_header, *columns])]
    rows += [",".join([repr(float(ti))] + [repr(2e5 * math.exp(-((ti - n * dt / 2) / (10 * dt)) ** 2))] * len(columns))
             for ti in t]
    path.write_text("\n".join(rows) + "\n")
    return path


def test_short_record_is_refused(tmp_path):
    from orchestrator.inputs.measured import MIN_RECORD_SAMPLES, read_measured

    for n in (3, 10):
        path = _measured_csv(tmp_path / f"m{n}.csv", n, 5e-4)
        with pytest.raises(UserInputError, match=f"{n} samples; at least {MIN_RECORD_SAMPLES} are needed"):
            read_measured(path, {"A1": "pressure", "A2": "pressure"})


def test_time_in_milliseconds_is_named(tmp_path):
    from orchestrator.inputs.measured import read_measured

    path = _measured_csv(tmp_path / "ms.csv", 400, 0.5)   # 2 kHz written in ms
    with pytest.raises(UserInputError, match=r"0\.5 s \(2 Hz\) is too coarse .* 'time \[ms\]'"):
        read_measured(path, {"A1": "pressure", "A2": "pressure"})
    path = _measured_csv(tmp_path / "ms_declared.csv", 400, 0.5, time_header="time [ms]")
    # rel 1e-9: the rate comes from time stamps written in ms and divided by 1000 (round-off only)
    assert read_measured(path, {"A1": "pressure", "A2": "pressure"}).rate == pytest.approx(2000.0, rel=1e-9)


def test_missing_channel_is_a_warning_on_one_line(tmp_path, monkeypatch):
    from orchestrator.inputs.measured import read_measured

    path = _measured_csv(tmp_path / "m.csv", 400, 5e-4, columns=("A1",))
    with pytest.warns(UserInputWarning, match="not in the file, left out of the comparison: A2"):
        data = read_measured(path, {"A1": "pressure", "A2": "pressure"})
    assert list(data.channels) == ["A1"]
    # the command line prints it as one line
    from orchestrator import cli as cli_module

    def handler(args):
        read_measured(path, {"A1": "pressure", "A2": "pressure"})
        return 0
    monkeypatch.setattr(cli_module, "_cmd_run", handler)
    rc, _, err = cli(["run", DEFAULT])
    assert rc == 0 and err.strip() == f"turnout: warning: {path}: sensors of the layout not in the file, " \
                                      "left out of the comparison: A2"


def test_header_only_file_gives_no_numpy_warning(tmp_path):
    from orchestrator.inputs.measured import read_measured

    path = tmp_path / "h.csv"
    path.write_text("time,A1\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserInputError, match="a header .* but no data rows"):
            read_measured(path, {"A1": "pressure"})


@pytest.mark.parametrize("code, text", [(errno.ENOSPC, "No space left on device"), (errno.EFBIG, "File too large")])
def test_write_error_without_a_file_name_names_the_output(monkeypatch, tmp_path, code, text):
    from orchestrator import cli as cli_module

    def handler(args):
        raise OSError(code, text)
    monkeypatch.setattr(cli_module, "_cmd_run", handler)
    rc, _, err = cli(["run", DEFAULT, "--out", tmp_path / "out"])
    assert_one_line_exit_2(rc, err, text, str(tmp_path / "out"))


# --------------------------------------------------------------------------------------
# Analysis with bushings coarser than the side windows (item 8)
# --------------------------------------------------------------------------------------
def test_side_region_is_never_empty():
    from orchestrator.results.analysis import SIDE_WINDOW, side_region

    y = np.array([0.5, 2.0])                     # 2 bushings on a 2.5 m sleeper (exact binary fractions)
    assert side_region(y, 0.625).tolist() == [True, False]   # within the window of the first
    far = 1.25                                   # 0.75 m from both: outside every window
    assert min(abs(y - far)) > SIDE_WINDOW
    assert side_region(y, far).tolist() == [True, True]      # the nearest (here both, equidistant)
    assert side_region(y, 1.0).tolist() == [True, False]     # 0.5 vs 1.0 m away: the first


# --------------------------------------------------------------------------------------
# Property: mutations of the default scenario never give a traceback
# --------------------------------------------------------------------------------------
def _paths(node, prefix=()):
    """Every key path (mappings, list items and leaves) of plain YAML data."""
    yield prefix
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _paths(v, prefix + (i,))


def _base() -> dict:
    """The default scenario with every key (defaults filled), one pad override and one void."""
    raw = copy.deepcopy(load_scenario(DEFAULT).raw)
    raw["track"]["rail_pad"]["overrides"] = [{"sleeper": 17, "stiffness_scale": 3.0}]
    raw["track"]["ballast"]["voids"] = [{"sleeper": 21, "gaps": [0.0, 4e-4, 9e-4, 9e-4, 4e-4, 0.0]}]
    return raw


BASE = _base()
PATHS = sorted(set(_paths(BASE)) - {()}, key=str)

_numbers = st.one_of(
    st.sampled_from([0, 0.0, -1, -1e-9, 1e-300, 1e300, -1e300, 1e12, 1e-12, math.nan, math.inf, -math.inf,
                     3, 4, 10**9, 0.5]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-10**12, max_value=10**12),
)
_strings = st.one_of(st.sampled_from(["", "abc", "1.2e8", "1:0", "1:-3", "2:12", "plain", "turnout",
                                      "bogie.fmu", "nan", "\u00e9\u00e8", "x" * 300]),
                     st.text(max_size=20))
_values = st.one_of(_numbers, _strings, st.none(), st.booleans(),
                    st.lists(st.integers(min_value=-3, max_value=50), max_size=7),
                    st.dictionaries(st.sampled_from(["a", "sleeper", "gaps", "type"]), st.integers(), max_size=2))


def _get(data, path):
    for tok in path:
        data = data[tok]
    return data


def _mutate(data: dict, draw) -> str:
    """One random change (drop / retype / number / unknown key / string) at a random key path."""
    path = draw(st.sampled_from(PATHS))
    parent, last = _get(data, path[:-1]), path[-1]
    kind = draw(st.sampled_from(["drop", "value", "number", "string", "unknown", "scale"]))
    if kind == "drop":
        del parent[last]
    elif kind == "value":
        parent[last] = draw(_values)
    elif kind == "number":
        parent[last] = draw(_numbers)
    elif kind == "string":
        parent[last] = draw(_strings)
    elif kind == "unknown":
        target = parent[last] if isinstance(parent[last], dict) else (parent if isinstance(parent, dict) else data)
        target[draw(st.from_regex(r"[a-z][a-z_]{0,8}", fullmatch=True))] = draw(_values)
    else:  # a plausible-looking number scaled by a power of ten (a unit mistake)
        value = parent[last]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            parent[last] = value * 10.0 ** draw(st.integers(min_value=-6, max_value=6))
        else:
            parent[last] = draw(_numbers)
    return f"{kind} at {path}"


@pytest.mark.parametrize("sep", ["\x1e", "\u2028", "\x0b", "\x85"])
def test_a_file_name_holding_a_line_separator_is_still_a_one_line_error(tmp_path, sep):
    """Found by the property test below (session 9: ``sensors: "0\\x1e"``): the message quotes the path it
    looked for, and ``str.splitlines`` also breaks at the record separator, vertical tab, NEL and the
    Unicode line separator, not only at CR / LF. Each must be folded, the key still named."""
    scenario = copy.deepcopy(BASE)
    scenario["sensors"] = f"0{sep}"
    path = tmp_path / "mutated.yaml"
    path.write_text(dump_yaml(scenario), encoding="utf-8")
    rc, _, err = cli(["run", path, "--dry-run"])
    assert_one_line_exit_2(rc, err, "sensors", "file not found")


@pytest.mark.parametrize("name", ["x" * 300, "a\x00b"])
def test_a_path_the_system_refuses_is_a_scenario_error(tmp_path, name):
    """Found by the property test below (session 11's CI: ``sensors: "xxx...x"``, 300 characters): the
    operating system refuses a file name over 255 bytes (ENAMETOOLONG) and Python one holding a NUL;
    both must be a one-line ScenarioError naming the key (they escaped as OSError / ValueError), and a
    one-line exit 2 on the CLI."""
    scenario = copy.deepcopy(BASE)
    scenario["sensors"] = name
    with pytest.raises(ScenarioError, match="sensors.*not a usable path") as exc:
        scenario_from_dict(scenario)
    assert "\n" not in str(exc.value)
    if "\x00" not in name:    # a NUL cannot pass through the YAML file unquoted: the API case above covers it
        path = tmp_path / "long.yaml"
        path.write_text(dump_yaml(scenario), encoding="utf-8")
        rc, _, err = cli(["run", path, "--dry-run"])
        assert_one_line_exit_2(rc, err, "sensors", "not a usable path")


def test_property_mutated_scenarios_are_valid_or_one_line_exit_2(tmp_path):
    """>= 200 random mutations, each validated as `turnout run --dry-run` does: exit 0 or a one-line exit 2.

    An exception other than a user error propagates out of main() and fails the test.
    """
    path = tmp_path / "mutated.yaml"
    outcomes = {0: 0, 2: 0}

    @settings(max_examples=250, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
    @given(st.data())
    def check(data):
        scenario = copy.deepcopy(BASE)
        what = _mutate(scenario, data.draw)
        path.write_text(dump_yaml(scenario), encoding="utf-8")
        rc, out, err = cli(["run", path, "--dry-run"])
        assert rc in (0, 2), (what, rc, err)
        if rc == 2:
            assert_one_line_exit_2(rc, err)
        else:
            assert "valid" in out and not err.strip(), (what, err)
        outcomes[rc] += 1

    check()
    assert outcomes[2] > 0 and sum(outcomes.values()) >= 200, outcomes


def test_property_mutated_dicts_raise_scenario_errors_only():
    """The same mutations through the Python API: a Scenario or a one-line ScenarioError."""
    @settings(max_examples=200, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
    @given(st.data())
    def check(data):
        scenario = copy.deepcopy(BASE)
        _mutate(scenario, data.draw)
        try:
            scenario_from_dict(scenario)
        except ScenarioError as exc:
            assert "\n" not in str(exc) and str(exc).startswith("<dict>")

    check()


# ------------------------------------------------------------------------------------------
# An output folder that already holds results (issue "no traceback on bad input", item 11)
# ------------------------------------------------------------------------------------------
def test_an_earlier_runs_folder_is_named_in_a_warning_and_a_file_as_out_is_an_error(tmp_path):
    import warnings

    from orchestrator.results.outdir import prepare_out_dir

    out = tmp_path / "o"
    with warnings.catch_warnings():
        warnings.simplefilter("error")        # a fresh folder: no warning at all
        prepare_out_dir(out)
    (out / "summary.json").write_text("{}")
    with pytest.warns(UserInputWarning, match="held the results of an earlier run"):
        prepare_out_dir(out)
    (tmp_path / "f").write_text("x")
    with pytest.raises(UserInputError, match="exists and is not a folder"):
        prepare_out_dir(tmp_path / "f")
