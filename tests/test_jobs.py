"""End-to-end through the command line: run (co-simulation), frf, divergence, backends, third-party FMU."""
import json

import h5py
import numpy as np
import pytest
from conftest import DEFAULT_SCENARIO, PLAIN_SCENARIO

from orchestrator.cli import main
from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.scenario import load_scenario, scenario_from_dict
from track.model import build_track
from track.params import GRAVITY
from track.post import ballast_forces

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
               "--save-states", *[a for s in QUICK for a in ("--set", s)]])  # states: only when asked
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


# ------------------------------------------------------------------ what `turnout run` writes
DOCUMENTED = ("signals/t", "signals/x", "signals/z", "signals/vz", "signals/Fz", "signals/parts", "signals/rail_z",
              "analysis/rail_M_max", "analysis/sleeper_M_max", "analysis/ballast_p_max")


@pytest.fixture(scope="module")
def default_runs(tmp_path_factory):
    """The default scenario shortened to 20 ms (the wheels reach the crossing transition sleeper only in
    full runs; the outputs are the same kind), through the FMUs, without and with --save-states."""
    runs = {}
    for states in (False, True):
        out = tmp_path_factory.mktemp("states" if states else "default")
        rc = main(["run", str(DEFAULT_SCENARIO), "--out", str(out), "--no-progress", "--set",
                   "simulation.duration=0.02"] + (["--save-states"] if states else []))
        assert rc == 0
        runs[states] = out
    return runs


def test_default_run_writes_outputs_not_states_and_no_record(default_runs):
    out = default_runs[False]
    assert not list(out.rglob("track_record*"))  # the FMU's record file is read and deleted
    summary = json.loads((out / "summary.json").read_text())
    sensor_ids = [c for c in np.genfromtxt(out / "sensors.csv", delimiter=",", names=True).dtype.names
                  if c != "time" and not c.startswith("wheel")]
    assert sensor_ids  # the default layout's sensors
    with h5py.File(out / "results.h5") as f:
        assert "track" not in f  # states only with --save-states
        for name in DOCUMENTED:
            assert name in f, name
        assert f["signals/Fz"].compression == "gzip" and f["signals/Fz"].shuffle
        rail, sleeper = summary["crossing_rail"], f"sleeper_{summary['transition_sleeper']}"
        assert f[f"bodies/{rail}/moment"].shape == (summary["steps"] + 1, f[f"bodies/{rail}/coord"].size)
        assert f[f"bodies/{sleeper}/ballast_pressure"].shape[0] == summary["steps"] + 1
        csv = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True)
        for sid in sensor_ids:
            # sensors.csv keeps 9 significant digits; the HDF5 copy is exact (lossless compression)
            assert np.allclose(f[f"sensors/{sid}"][:], csv[sid], rtol=1e-8, atol=1e-8 * np.abs(csv[sid]).max())
        # the envelope written is the one the summary reports
        assert f["analysis/rail_M_max"][:].max() == pytest.approx(summary["max_rail_moment"], rel=1e-12)


def test_summary_counters_report_steps_and_phase_walls(default_runs):
    """summary.json's counters: the master's steps and phase walls, and the track FMU's own counters
    (its monitoring outputs, read at terminate)."""
    summary = json.loads((default_runs[False] / "summary.json").read_text())
    c = summary["counters"]
    assert c["steps"] == summary["steps"] == 200    # 20 ms / 0.1 ms
    for k in ("wall_setup", "wall_initialize", "wall_loop", "wall_finish", "wall_post_processing", "wall_writing"):
        assert c[k] >= 0.0, k
    # the track FMU steps once per communication step, with at least one solve and contact sweep each
    assert c["track_steps"] == c["steps"]
    assert c["linear_solves"] >= c["track_steps"] and c["contact_iterations"] >= c["track_steps"]
    assert c["passes"] >= c["track_steps"] and c["factorizations"] >= 1
    assert c["wall_statics"] > 0.0 and c["wall_factor"] > 0.0
    # the phases are parts of the job's wall time
    parts = sum(c[k] for k in ("wall_setup", "wall_initialize", "wall_loop", "wall_finish",
                               "wall_post_processing", "wall_writing"))
    assert parts <= summary["wall_seconds"]["job_total"] * (1 + 1e-9)


def test_the_run_post_processes_with_one_blas_thread_and_gives_the_threads_back(tmp_path, monkeypatch):
    """While the figure process draws, run_scenario's process keeps one BLAS thread
    (jobs.RUN_BLAS_THREADS): the post-processing runs under it, and the caller's limit (two here,
    whatever the machine) is back once the job returns."""
    from threadpoolctl import threadpool_info, threadpool_limits

    from orchestrator.results import jobs

    seen = []
    post = jobs._post_process

    def spy(*args, **kwargs):
        seen.append({i["internal_api"]: i["num_threads"] for i in threadpool_info()})
        return post(*args, **kwargs)

    monkeypatch.setattr(jobs, "_post_process", spy)
    with threadpool_limits(limits=2):
        assert main(["run", str(PLAIN_SCENARIO), "--out", str(tmp_path / "r"), "--no-progress", "--backend",
                     "inprocess", *[a for s in QUICK for a in ("--set", s)]]) == 0
        after = {i["internal_api"]: i["num_threads"] for i in threadpool_info()}
    assert seen and set(seen[0].values()) == {1}, seen
    assert set(after.values()) == {2}, after


def test_in_process_summary_counters_have_the_track_counters(tmp_path):
    out = tmp_path / "ip"
    assert main(["run", str(PLAIN_SCENARIO), "--out", str(out), "--no-progress", "--backend", "inprocess",
                 *[a for s in QUICK for a in ("--set", s)]]) == 0
    c = json.loads((out / "summary.json").read_text())["counters"]
    step = load_scenario(PLAIN_SCENARIO, QUICK).simulation.step
    assert c["track_steps"] == c["steps"] == round(0.01 / step)   # every communication step steps the track
    # at least one linear solve and one contact iteration per track step
    assert c["linear_solves"] >= c["track_steps"] and c["contact_iterations"] >= c["track_steps"]
    with h5py.File(out / "results.h5") as f:
        assert "track" not in f


def test_saved_states_reproduce_the_rail_deflection_under_the_wheels(default_runs):
    """With --save-states the stored q recovers the run's rail deflection under each wheel (u = T q
    at the wheel's point, plus the truncated modes' static correction under its own load, as the
    track computes it) to the contact iteration's tolerance."""
    from track.cosim import wheel_sides

    out = default_runs[True]
    sc = load_scenario(DEFAULT_SCENARIO, ["simulation.duration=0.02"])
    model = build_track(sc.track)
    with h5py.File(out / "results.h5") as f:
        q, x, Fz, rail_z = (f[k][:] for k in ("track/q", "signals/x", "signals/Fz", "signals/rail_z"))
        assert q.shape == (rail_z.shape[0], model.n) and {"v", "a", "t"} <= set(f["track"])
        assert "track" not in h5py.File(default_runs[False] / "results.h5")
    sides = wheel_sides(x.shape[1])
    recovered = np.array([[model.rail_point(sides[i], x[j, i]).value(q[j], -Fz[j, i]) for i in range(x.shape[1])]
                          for j in range(1, len(q))])   # row 0 (the start) has no rail deflection yet
    # The track reports the deflection of its last contact iterate, the stored q is the step's final
    # state: they differ by the contact Newton's stopping tolerance (dynamics.CONTACT_REL_TOL = 1e-9 of
    # the wheel force, i.e. ~1e-9 of the deflection through the compliance), measured 1.3e-11 here.
    assert np.abs(recovered - rail_z[1:]).max() < 1e-9 * np.abs(rail_z[1:]).max()
    assert np.abs(rail_z[1:]).max() > 1e-4   # a loaded rail (about 1 mm): the comparison is not 0 = 0
    assert not list(out.rglob("track_record*"))


def test_recording_only_the_read_columns_changes_no_output(default_runs):
    """The default run records only the columns of the states that the analysis and the sensors read
    (about 300 of 1741); the --save-states run records them all. The columns not recorded are never
    read (analysis_columns, sensor_columns): the analysis rebuilds full rows with zeros there, so its
    outputs agree exactly; the sensors read the recorded columns as they are (the same products over
    fewer terms, summed by BLAS in another order), so theirs agree to round-off: 1e-12 of the
    channel's largest value."""
    files = [h5py.File(default_runs[states] / "results.h5") for states in (False, True)]
    names = []
    files[0].visititems(lambda k, o: names.append(k) if isinstance(o, h5py.Dataset) else None)
    assert any(k.startswith("bodies/") for k in names) and any(k.startswith("sensors/") for k in names)
    for k in names:
        x, y = files[0][k][()], files[1][k][()]
        if k.startswith("sensors/"):
            assert np.allclose(x, y, rtol=0, atol=1e-12 * np.nanmax(np.abs(y)), equal_nan=True), k
        else:
            assert np.array_equal(x, y, equal_nan=True), k
    a, b = (json.loads((default_runs[s] / "summary.json").read_text()) for s in (False, True))
    for k in ("max_rail_moment", "max_sleeper_moment", "max_ballast_pressure"):
        assert a[k] == b[k] != 0.0, k


def test_record_columns_cover_what_the_post_processing_reads():
    """analysis_columns and sensor_columns name few columns, and reading a record with only those
    columns gives the full record's moments, pressures and sensor signals (random states: any column
    read outside them would show)."""
    from orchestrator.cosim.master import merge_columns
    from orchestrator.cosim.sensing import read_sensors, sensor_columns
    from orchestrator.inputs.sensor_layout import scenario_sensors
    from orchestrator.results.analysis import analysis_columns
    from track.cosim import state_rows
    from track.model import reference_point
    from track.post import body_response, sleeper_pressure
    from track.sensors import compile_sensors

    sc = load_scenario(DEFAULT_SCENARIO)
    model = build_track(sc.track)
    compiled = compile_sensors(model, scenario_sensors(sc, model))
    cols = merge_columns(analysis_columns(model), sensor_columns(model, compiled))
    assert sum(c.size for c in cols.values()) < 0.25 * 3 * model.n   # measured 320 of 3 x 1741
    rng = np.random.default_rng(1)
    full = {"t": np.arange(7) * 1e-4, **{k: 1e-4 * rng.standard_normal((7, model.n)) for k in "qva"}}
    part = {"t": full["t"], **{k: full[k][:, c] for k, c in cols.items()},
            **{f"{k}_columns": c for k, c in cols.items()}}
    q_part = state_rows(part, "q", model.n)
    side, x_ref, k_tr = reference_point(model)
    for body in (model.layout.running_body(side, x_ref), f"sleeper_{k_tr}"):
        assert np.array_equal(body_response(model, body, q_part).moment,
                              body_response(model, body, full["q"]).moment), body
    assert np.array_equal(sleeper_pressure(model, k_tr, q_part, state_rows(part, "v", model.n))[1],
                          sleeper_pressure(model, k_tr, full["q"], full["v"])[1])
    a = read_sensors(model, compiled, part, 1e-4, 5.0, reconstruct=False)
    b = read_sensors(model, compiled, full, 1e-4, 5.0, reconstruct=False)
    for sid in b:
        # the record of some columns is read as it is (no full-width rows): the same products over
        # fewer terms, summed in another order by BLAS: round-off of the largest term (1e-12 of it)
        assert np.allclose(a[sid], b[sid], rtol=0, atol=1e-12 * np.abs(b[sid]).max()), sid


def test_fmus_are_built_once_per_build_inputs_and_copied_from_the_cache(tmp_path, monkeypatch):
    """cached_fmus builds a scenario's FMUs into the cache once; the next run copies them (the same
    bytes); another track builds another entry; TURNOUT_CACHE=off builds into the run's folder."""
    from orchestrator.cosim import build_job

    builds = []
    real = build_job._build_all
    monkeypatch.setattr(build_job, "_build_all", lambda inputs, out: builds.append(out) or real(inputs, out))
    sc = load_scenario(PLAIN_SCENARIO, QUICK)
    env = {"TURNOUT_CACHE": str(tmp_path / "cache")}
    first = build_job.cached_fmus(sc, tmp_path / "a", env)
    second = build_job.cached_fmus(sc, tmp_path / "b", env)
    assert len(builds) == 1 and builds[0].parent == tmp_path / "cache" / build_job.FMU_CACHE_FOLDER
    assert set(first) == {"track", "bogie", "quarter"}
    for kind, path in second.items():
        assert path.parent == tmp_path / "b" and path.read_bytes() == first[kind].read_bytes(), kind
    other = load_scenario(PLAIN_SCENARIO, QUICK + ["track.rail_pad.stiffness=1.5e8"])
    assert build_job.cache_key(build_job.build_inputs(other)) != build_job.cache_key(build_job.build_inputs(sc))
    build_job.cached_fmus(sc, tmp_path / "c", {"TURNOUT_CACHE": "off"})
    assert builds[-1] == tmp_path / "c" and len(builds) == 2
    assert len(list((tmp_path / "cache" / build_job.FMU_CACHE_FOLDER).iterdir())) == 1


_FMU_RUN_HERE_AND_IN_A_WORKER = """
import concurrent.futures as cf, multiprocessing, sys
from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario

def run(path, sets):
    return len(run_cosim(load_scenario(path, sets), backend="fmu").t)

if __name__ == "__main__":
    with cf.ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn")) as pool:
        n_worker = pool.submit(run, sys.argv[1], sys.argv[2:]).result()
    assert run(sys.argv[1], sys.argv[2:]) == n_worker   # a second time here: the FMUs' folders are reused
    assert run(sys.argv[1], sys.argv[2:]) == n_worker
"""


def test_runs_via_fmus_leave_nothing_in_the_temp_folder(tmp_path):
    """FMPy unzips each FMU to a new temporary folder; they used to stay (~2 MB a run via FMUs,
    and every run of a sweep's worker). The installed ``turnout`` script (its ``console`` entry),
    a process running three co-simulations and a spawned pool worker running one each leave an
    empty temp folder behind (``TMPDIR``, which Python's ``tempfile`` and FMPy's ``extract`` use)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp)}
    sets = [a for s in QUICK for a in ("--set", s)]
    done = subprocess.run([str(Path(sys.executable).with_name("turnout")), "run", str(PLAIN_SCENARIO), "--out",
                           str(tmp_path / "run"), "--no-progress", *sets], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "run" / "results.h5").is_file()
    script = tmp_path / "fmu_runs.py"   # a file: a spawned worker imports its __main__ by path
    script.write_text(_FMU_RUN_HERE_AND_IN_A_WORKER)
    done = subprocess.run([sys.executable, str(script), str(PLAIN_SCENARIO), *QUICK], env=env, capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr
    assert sorted(p.name for p in tmp.iterdir()) == []


_END_PROCESS = """
import atexit, sys, threading, time
from orchestrator.cli import _end_process

atexit.register(lambda: open(sys.argv[1], "w").write("handlers ran"))
sys.stdout.write("unflushed line")                  # no newline: still in the buffer
if sys.argv[2] == "thread":                         # a library's non-daemon thread still running
    threading.Thread(target=time.sleep, args=(0.3,)).start()
status = _end_process(int(sys.argv[3]))
sys.stdout.write(f" returned {status}")
sys.exit(status)
"""


@pytest.mark.parametrize("thread", ["none", "thread"])
def test_the_console_ends_the_process_after_its_exit_handlers(tmp_path, thread):
    """``turnout``'s console entry ends the process without the interpreter's teardown
    (orchestrator.cli._end_process): the exit status is the command's, the atexit handlers have run
    and the standard streams are flushed; with a non-daemon thread still running it returns and the
    process exits normally (the thread is joined), with the same status and handlers."""
    import subprocess
    import sys

    script = tmp_path / "end.py"
    script.write_text(_END_PROCESS)
    for status in (0, 2):
        marker = tmp_path / f"handlers_{status}"
        done = subprocess.run([sys.executable, str(script), str(marker), thread, str(status)],
                              capture_output=True, text=True)
        assert done.returncode == status, done.stderr
        assert marker.read_text() == "handlers ran"
        returned = f" returned {status}" if thread == "thread" else ""
        assert done.stdout == "unflushed line" + returned


def test_only_a_one_command_process_freezes_its_imports():
    """``turnout``'s console entry marks the process as running one command (cli._ONE_COMMAND): the
    objects of the command's imports are then frozen out of the collector's passes (gc.freeze); a
    process that calls main() and goes on (tests, notebooks) freezes nothing."""
    import subprocess
    import sys

    probe = ("import gc, sys; from orchestrator import cli; cli._ONE_COMMAND = sys.argv[1] == 'one'; "
             "cli._jobs(); print(gc.get_freeze_count())")
    frozen = {kind: int(subprocess.run([sys.executable, "-c", probe, kind], capture_output=True, text=True,
                                       check=True).stdout) for kind in ("one", "library")}
    assert frozen["library"] == 0
    assert frozen["one"] > 10_000   # numpy, scipy, numba and the model's modules: ~1e5 objects


def test_the_progress_bar_times_its_rate_from_after_the_first_step(capsys):
    """The first step of a run carries the kernel's loading or compilation (seconds): the bar's rate and remaining
    time count from its end. Here a first step of 0.6 s, then 49 steps in 0.6 s, of 100: timed from the start the
    bar showed 1/100 at 1.7 step/s with ~59 s to go; it must never show more than 5 s to go (what is left takes
    0.6 s; 5 s leaves room for a slow machine's sleeps)."""
    import re
    import time

    from orchestrator.results.jobs import _progress_bar

    update, close = _progress_bar(True, 100, "co-simulation")
    time.sleep(0.6)
    update(1, 100)
    time.sleep(0.6)
    update(50, 100)
    close()
    err = capsys.readouterr().err
    left = [int(m) * 60 + int(s) for m, s in re.findall(r"<(\d+):(\d+)", err)]
    assert left and max(left) <= 5, err
    assert "100/100" not in err and "50/100" in err
