"""End-to-end: the track-only run and the receptance job through the command line."""
import json

import h5py
import numpy as np

from orchestrator.cli import main
from orchestrator.scenario import load_scenario
from track.model import build_track
from track.params import GRAVITY
from track.post import ballast_forces
from track.statics import static_equilibrium

from conftest import DEFAULT_SCENARIO, PLAIN_SCENARIO


def test_run_writes_outputs_in_vertical_equilibrium(tmp_path, capsys):
    """Plain track, 10 ms at the scenario speed.

    At t = 0 the state is the static equilibrium, so the ballast reactions of all
    sleepers must carry the self-weight of rails and sleepers plus the four wheel
    loads (vertical equilibrium, to the static solver's 1e-10 residual). The recorded
    rail displacement under wheel 1 at t = 0 must equal an independent static
    solution with the same loads.
    """
    out = tmp_path / "run"
    rc = main(["run", str(PLAIN_SCENARIO), "--out", str(out), "--no-progress",
               "--set", "simulation.duration=0.01"])
    assert rc == 0
    for name in ("sensors.csv", "results.h5", "summary.json", "static.png", "envelopes.png", "frf.png",
                 "layout.png"):
        assert (out / name).stat().st_size > 0, name
    summary = json.loads((out / "summary.json").read_text())
    sc = load_scenario(PLAIN_SCENARIO)
    model = build_track(sc.track)
    with h5py.File(out / "results.h5") as f:
        q0, wheel_x, F = f["q"][0], f["wheel_x"][0], f["wheel_force"][:]
        assert abs(f["t"][-1] - 0.01) < 1e-12
    weight = sum(b.fom.s[-1] * b.fom.profile.base.mass_per_length
                 for b in model.bodies if b.kind in ("rail", "sleeper"))
    reaction = ballast_forces(model, q0).sum()
    assert abs(reaction - (weight * GRAVITY - F.sum())) < 1e-6 * reaction
    assert F.sum() == -2 * sc.vehicle.axle_load  # bogie: two axles
    sides = ["left", "right"] * 2
    st = static_equilibrium(model, [(model.rail_point(s, x), f) for s, x, f in zip(sides, wheel_x, F)])
    csv = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True)
    w1 = model.rail_point("left", wheel_x[0]).value(st.q, F[0])
    assert abs(csv["wheel1_rail_w"][0] - w1) < 1e-8 * abs(w1)  # the CSV keeps 9 significant digits
    assert summary["static"]["residual"] < 1e-6
    assert summary["dofs"]["reduced"] == model.n


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


def test_third_party_fmu_is_refused_clearly_by_the_track_only_run(tmp_path, capsys):
    fake = tmp_path / "other.fmu"
    fake.write_bytes(b"PK")
    yaml_text = DEFAULT_SCENARIO.read_text().replace("fmu: bogie", f"fmu: {fake}\n  ports: "
                                                     "[{x: a, z: b, vz: c, Fz: d}]")
    sc = tmp_path / "s.yaml"
    sc.write_text(yaml_text)
    rc = main(["run", str(sc), "--out", str(tmp_path / "o"), "--no-progress"])
    assert rc == 2
    assert "vehicle.fmu" in capsys.readouterr().err
