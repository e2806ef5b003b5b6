"""End-to-end through the command line: run (co-simulation), frf, divergence, backends, third-party FMU."""
import json

import h5py
import numpy as np
import pytest

from orchestrator.cli import main
from orchestrator.inputs.errors import UserInputError
from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario, scenario_from_dict
from track.model import build_track
from track.params import GRAVITY
from track.post import ballast_forces

from conftest import DEFAULT_SCENARIO, PLAIN_SCENARIO

QUICK = ["vehicle.fmu=quarter", "simulation.duration=0.01"]


def test_run_writes_outputs_and_starts_in_vertical_equilibrium(tmp_path, capsys):
    """Plain track, quarter vehicle, 10 ms in-process.

    The first recorded track state is the coupled static equilibrium: the ballast
    reactions carry the self-weight of rails and sleepers plus the two static wheel
    loads (to the static solver's 1e-10 residual), and the contact forces written at
    t = 0 are the static wheel loads.
    """
    out = tmp_path / "run"
    rc = main(["run", str(PLAIN_SCENARIO), "--out", str(out), "--no-progress", "--backend", "inprocess",
               *[a for s in QUICK for a in ("--set", s)]])
    assert rc == 0
    for name in ("sensors.csv", "results.h5", "summary.json", "contact_forces.png", "displacements.png",
                 "envelopes.png", "moments.png", "layout.png"):
        assert (out / name).stat().st_size > 0, name
    sc = load_scenario(PLAIN_SCENARIO, QUICK)
    model = build_track(sc.track)
    with h5py.File(out / "results.h5") as f:
        q0 = f["track/q"][0]
        Fz = f["signals/Fz"][:]
        assert abs(f["signals/t"][-1] - 0.01) < 1e-12
    weight = sum(b.fom.s[-1] * b.fom.profile.base.mass_per_length for b in model.bodies)
    reaction = ballast_forces(model, q0).sum()
    assert abs(reaction - (weight * GRAVITY + sc.vehicle.axle_load)) < 1e-6 * reaction
    assert np.allclose(Fz[0], sc.vehicle.axle_load / 2, rtol=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["dofs"]["reduced"] == model.n and summary["steps"] == 500
    csv = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True)
    assert np.allclose(csv["wheel1_Fz"], Fz[:, 0], rtol=1e-8)  # CSV keeps 9 significant digits


def test_divergence_is_reported_with_time_and_step_and_results_kept(tmp_path, capsys):
    """Jacobi with extrapolation at a 2 ms step is unstable for this stiff contact."""
    out = tmp_path / "div"
    rc = main(["run", str(PLAIN_SCENARIO), "--out", str(out), "--no-progress", "--backend", "inprocess",
               "--set", "vehicle.fmu=quarter", "--set", "simulation.algorithm=jacobi",
               "--set", "simulation.step=0.002", "--set", "simulation.output_step=0.002",
               "--set", "simulation.duration=0.2"])
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "t = " in err and "0.002" in err and "step" in err
    csv = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True)
    assert 5 < csv["time"].size < 100  # what was computed before the failure is written
    assert json.loads((out / "summary.json").read_text())["error"]


def test_fmu_backend_agrees_with_in_process(tmp_path):
    """Same scenario through the FMUs and in-process: the same contact forces.

    Both step the same model objects; the FMU boundary only passes doubles, so the
    results agree to round-off (1e-9 relative to the static load).
    """
    sc = load_scenario(DEFAULT_SCENARIO, ["track.layout.sleepers=18", "track.layout.transition_sleeper=8",
                                          "simulation.duration=0.02"])
    a = run_cosim(sc, backend="fmu", work_dir=tmp_path / "w", record_states=False)
    b = run_cosim(sc, backend="inprocess", record_states=False)
    assert a.error is None and b.error is None
    assert np.allclose(a.Fz, b.Fz, rtol=0, atol=1e-9 * sc.vehicle.axle_load)
    assert np.allclose(a.z, b.z, rtol=0, atol=1e-15)


def test_third_party_c_vehicle_through_ports_matches_our_vehicle(tmp_path):
    """The C quarter vehicle (own names, z and forces positive downward) through ``ports``.

    Compared with our rigid quarter vehicle (the same equations, DESIGN.md §4.4) over
    the crossing at 120 km/h, 12 mrad: contact forces within 1 % of the peak. The C
    FMU integrates with RK4 at 10 us sub-steps, ours exactly: the difference is that.
    """
    from c_vehicle import build_c_vehicle_fmu, find_c_compiler
    if find_c_compiler() is None:
        pytest.skip("no C compiler")
    fmu = build_c_vehicle_fmu(tmp_path)
    base = load_scenario(DEFAULT_SCENARIO)
    from track.layout import build_layout
    x0 = build_layout(base.track.layout).x_transition - 1.5
    raw = {**base.raw}
    raw["track"] = {**raw["track"], "crossing": {"impact_angle": 0.012}}
    raw["simulation"] = {**raw["simulation"], "duration": 2.5 / 33.333, "x_start": x0}
    ports = [{"x": "axle1.s", "z": f"axle1.z{s}", "vz": f"axle1.vz{s}", "Fz": f"axle1.F{s}",
              "z_sign": -1, "vz_sign": -1, "Fz_sign": -1} for s in "LR"]
    ext = scenario_from_dict({**raw, "vehicle": {"fmu": str(fmu), "speed": 33.333, "ports": ports,
                                                  "start_values": {"s0": x0, "v": 33.333}}})
    ours = scenario_from_dict({**raw, "vehicle": {"fmu": "quarter", "speed": 33.333,
                                                   "start_values": {"flexible": False}}})
    a = run_cosim(ext, backend="fmu", work_dir=tmp_path / "a", record_states=False)
    b = run_cosim(ours, backend="inprocess", record_states=False)
    assert a.error is None and b.error is None
    assert np.allclose(a.x, b.x, atol=1e-9)
    peak = b.Fz.max()
    assert peak > 1.2 * 98100  # the crossing impact is in the window
    assert np.max(np.abs(a.Fz - b.Fz)) < 0.01 * peak, np.max(np.abs(a.Fz - b.Fz)) / peak
    # a third-party vehicle that starts elsewhere than the scenario says is refused clearly
    wrong = scenario_from_dict({**raw, "vehicle": {"fmu": str(fmu), "speed": 33.333, "ports": ports,
                                                    "start_values": {"s0": x0 + 1.0}}})
    with pytest.raises(UserInputError, match="starts at x"):
        run_cosim(wrong, backend="fmu", work_dir=tmp_path / "c", record_states=False)


def test_frf_job_and_bad_point(tmp_path, capsys):
    out = tmp_path / "frf"
    assert main(["frf", str(PLAIN_SCENARIO), "--out", str(out), "--fmax", "1400"]) == 0
    data = np.genfromtxt(out / "frf.csv", delimiter=",", names=True)
    # the default point is above the middle sleeper: its first resonance (track on
    # ballast) lies in 50-200 Hz for these pad/ballast values
    f_peak = data["frequency"][np.argmax(data["magnitude"][data["frequency"] < 500])]
    assert 50.0 < f_peak < 200.0, f_peak
    capsys.readouterr()
    assert main(["frf", str(PLAIN_SCENARIO), "--out", str(out), "--at", "rail_lfet:5.0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "rail_left" in err and "Traceback" not in err and len(err.splitlines()) == 1
