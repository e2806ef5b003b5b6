"""Shared fixtures: repository paths and scenarios.

Dict fixtures hand out fresh copies, so a test may change them freely.
"""
from __future__ import annotations

import copy
from pathlib import Path

import pytest

from orchestrator.inputs.scenario import load_scenario, read_yaml

REPO_ROOT = Path(__file__).resolve().parents[1]
SCENARIOS_DIR = REPO_ROOT / "scenarios"
DEFAULT_SCENARIO = SCENARIOS_DIR / "crossing_1_12_through_120.yaml"
PLAIN_SCENARIO = SCENARIOS_DIR / "plain_track.yaml"

# A scenario that gives every key that can be given with a built-in vehicle
# (ports need a third-party FMU; see the ``third_party_fmu`` fixture).
FULL_SCENARIO = {
    "name": "full",
    "track": {
        "model": "beam",
        "layout": {"type": "turnout", "crossing": "1:15", "radius": 760.0, "sleeper_spacing": 0.65,
                   "sleepers": 36, "route": "diverging", "hand": "right", "gauge": 1.435, "rail": "60E1",
                   "transition_sleeper": 21, "sleeper_length": 2.6},
        "rail_pad": {"stiffness": 1.2e8, "damping": 2.0e4, "stiffness_scale": 1.5,
                     "overrides": [{"sleeper": 17, "stiffness_scale": 3.0}], "two_bushings": True},
        "ballast": {"stiffness_per_length": 4.0e7, "damping_per_length": 3.0e4, "stiffness_scale": 0.8,
                    "voids": [{"sleeper": 21, "gaps": [0.0, 0.4e-3, 0.9e-3, 0.9e-3, 0.4e-3, 0.0]}],
                    "spacing": 0.25},
        "crossing": {"impact_angle": 0.012},
        "reduction": {"f_cut": 1500.0, "mode_factor": 2.5, "element_length": 0.08},
        "structural_damping": 1.0e-5,
    },
    "vehicle": {"fmu": "quarter", "speed": 27.78, "axle_load": 200000.0, "start_values": {"m_body": 24000.0}},
    "simulation": {"duration": 0.5, "step": 1.0e-5, "output_step": 5.0e-5, "algorithm": "jacobi",
                   "extrapolation": False, "x_start": 3.0},
    "sensors": None,
}


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO_ROOT


@pytest.fixture(scope="session")
def scenarios_dir() -> Path:
    return SCENARIOS_DIR


@pytest.fixture(scope="session")
def default_scenario_path() -> Path:
    """scenarios/crossing_1_12_through_120.yaml."""
    return DEFAULT_SCENARIO


@pytest.fixture(scope="session")
def plain_scenario_path() -> Path:
    """scenarios/plain_track.yaml."""
    return PLAIN_SCENARIO


@pytest.fixture(scope="session")
def default_scenario():
    """The default scenario, loaded (a frozen :class:`orchestrator.inputs.scenario.Scenario`)."""
    return load_scenario(DEFAULT_SCENARIO)


@pytest.fixture(scope="session")
def plain_scenario():
    """The plain-track scenario, loaded."""
    return load_scenario(PLAIN_SCENARIO)


@pytest.fixture
def default_scenario_dict() -> dict:
    """The default scenario file as a dict (as written, defaults not filled)."""
    return read_yaml(DEFAULT_SCENARIO)


@pytest.fixture(scope="session")
def make_full_scenario_dict():
    """Factory: a fresh dict that gives every key (usable inside hypothesis tests)."""
    return lambda: copy.deepcopy(FULL_SCENARIO)


@pytest.fixture
def third_party_fmu(tmp_path) -> Path:
    """An (empty) file named other.fmu: enough for the scenario loader, which checks existence only."""
    path = tmp_path / "other.fmu"
    path.write_bytes(b"")
    return path


@pytest.fixture(scope="session")
def c_vehicle_fmu(tmp_path_factory) -> Path:
    """The third-party C quarter-vehicle FMU (tests/c_vehicle.py), built once per session;
    skipped where no C compiler or no supported platform is."""
    from c_vehicle import build_c_vehicle_fmu, find_c_compiler, fmu_platform

    if find_c_compiler() is None:
        pytest.skip("no C compiler (cc or gcc) on PATH: cannot build the C vehicle FMU")
    try:
        fmu_platform()
    except RuntimeError as exc:
        pytest.skip(str(exc))
    return build_c_vehicle_fmu(tmp_path_factory.mktemp("c_vehicle"))
