"""Parameter sweeps: variations, run ids, validation before running, resumable store, executors.

The run functions here are trivial top-level functions (picklable, so spawned
workers and Dask workers import them from this module): ``y = V * beta`` and a
call counter per run id. The counter lives outside the run folder, in
``<tmp>/calls/<run_id>``, because a run that is redone starts from an empty
folder (and a worker's run folder is its own temporary one): the tests hand the
run functions that folder with :func:`counted`.
"""
from __future__ import annotations

import csv
import functools
import importlib.util
import json
import os
import shutil
import signal
import sys
import tempfile
import types
from pathlib import Path

import pytest
from conftest import DEFAULT_SCENARIO, PLAIN_SCENARIO, SCENARIOS_DIR

from orchestrator.cli import main
from orchestrator.inputs.errors import ScenarioError, UserInputError
from orchestrator.inputs.scenario import load_scenario
from orchestrator.sweeps import sweep

SPEEDS = "2.78,27.78,55.56"  # m/s (10, 100, 200 km/h)
ANGLES = "0.006,0.012"  # rad (nominal, worn)
GRID = [f"vehicle.speed={SPEEDS}", f"track.crossing.impact_angle={ANGLES}"]
KILL_SPEED, KILL_ANGLE = 55.56, 0.012  # the run whose first attempt kills its worker (the last in GRID order)
FAIL_SPEED = 27.78  # runs at this speed raise in failing_run


# --------------------------------------------------------------------------------------
# Run functions (top level: they cross process boundaries)
# --------------------------------------------------------------------------------------
def _side_dir(calls_dir: Path, run_dir: Path) -> Path:
    """``<tmp>/calls/<run_id>`` (``run_dir`` is named after the run id): survives a redo."""
    side = Path(calls_dir) / run_dir.name
    side.mkdir(parents=True, exist_ok=True)
    return side


def _count_call(calls_dir: Path, run_dir: Path) -> None:
    """One more call of the run, written atomically: when the pool breaks, the other worker is killed wherever
    it is, and a count file truncated by a plain write but not yet written read '' (a flaky CI failure)."""
    counter = _side_dir(calls_dir, run_dir) / "count"
    n = int(counter.read_text()) if counter.exists() else 0
    tmp = counter.with_name(f"count.{os.getpid()}")
    tmp.write_text(str(n + 1))
    os.replace(tmp, counter)


def product_run(scenario, run_dir: Path, *, calls_dir: Path) -> dict:
    """``y = V * beta`` [m/s * rad]; writes ``y.txt`` and counts its calls."""
    _count_call(calls_dir, run_dir)
    y = scenario.vehicle.speed * scenario.track.impact_angle
    (run_dir / "y.txt").write_text(repr(y))
    return {"y": y, "name": scenario.name, "not_a_scalar": [1.0, 2.0]}


def killing_run(scenario, run_dir: Path, *, calls_dir: Path) -> dict:
    """As product_run, but the KILL run's first attempt writes a partial file and SIGKILLs its worker."""
    if (scenario.vehicle.speed, scenario.track.impact_angle) == (KILL_SPEED, KILL_ANGLE):
        marker = _side_dir(calls_dir, run_dir) / "killed_once"
        if not marker.exists():
            _count_call(calls_dir, run_dir)
            marker.write_text("x")
            (run_dir / "partial.txt").write_text("left by the killed attempt")
            os.kill(os.getpid(), signal.SIGKILL)
    return product_run(scenario, run_dir, calls_dir=calls_dir)


def failing_run(scenario, run_dir: Path, *, calls_dir: Path) -> dict:
    """As product_run, but raises for the runs at FAIL_SPEED."""
    if scenario.vehicle.speed == FAIL_SPEED:
        raise ValueError(f"diverged at\nV = {scenario.vehicle.speed}")
    return product_run(scenario, run_dir, calls_dir=calls_dir)


def counted(run_fn, tmp_path: Path):
    """``run_fn`` counting its calls in ``tmp_path/calls`` (a picklable partial)."""
    return functools.partial(run_fn, calls_dir=tmp_path / "calls")


# --------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------
def read_table(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def calls(tmp_path: Path) -> dict[str, int]:
    folder = tmp_path / "calls"
    return {p.name: int((p / "count").read_text()) if (p / "count").exists() else 0
            for p in folder.iterdir()} if folder.exists() else {}   # 0: killed before its first count landed


def finished(out: Path) -> set[str]:
    return {p.parent.name for p in (out / sweep.RUNS_DIR).glob(f"*/{sweep.RESULT_FILE}")}


# --------------------------------------------------------------------------------------
# Variations and plan
# --------------------------------------------------------------------------------------
def test_grid_is_the_cartesian_product_in_order():
    runs = sweep.grid_from_vary(GRID)
    assert runs == [{"vehicle.speed": v, "track.crossing.impact_angle": b}
                    for v in (2.78, 27.78, 55.56) for b in (0.006, 0.012)]
    # Values are YAML: 1e8 is a number (YAML 1.2), a flow list is one value.
    runs = sweep.grid_from_vary(["track.rail_pad.stiffness=1e8,1.2e9",
                                 "track.ballast.voids[0].gaps=[0,0,0,0,0,0],[0,1e-3,1e-3,1e-3,1e-3,0]"])
    assert [r["track.rail_pad.stiffness"] for r in runs] == [1e8, 1e8, 1.2e9, 1.2e9]
    assert runs[1]["track.ballast.voids[0].gaps"] == [0, 1e-3, 1e-3, 1e-3, 1e-3, 0]


@pytest.mark.parametrize("texts, words", [
    (["vehicle.speed"], "key.path=v1,v2"),
    (["vehicle.speed="], "no values"),
    (["vehicle.speed=1,[2"], "YAML"),
    (["vehicle.speed=1,2", "vehicle.speed=3"], "varied twice"),
    (["vehicle..speed=1"], "key path"),
])
def test_grid_errors_name_the_option(texts, words):
    with pytest.raises(UserInputError, match="vehicle") as info:
        sweep.grid_from_vary(texts)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_list_form(tmp_path):
    path = tmp_path / "runs.yaml"
    path.write_text("- {vehicle.speed: 10.0, track.crossing.impact_angle: 0.018}\n"
                    "- {vehicle.speed: 20.0}\n"
                    "- {}\n", encoding="utf-8")
    variations = sweep.list_from_file(path)
    assert variations == [{"vehicle.speed": 10.0, "track.crossing.impact_angle": 0.018},
                          {"vehicle.speed": 20.0}, {}]
    plan = sweep.plan_sweep(DEFAULT_SCENARIO, variations)
    base = load_scenario(DEFAULT_SCENARIO)
    assert plan.varied_keys == ("vehicle.speed", "track.crossing.impact_angle")
    # A key an item leaves out shows the base value used by that run.
    assert [r.values for r in plan.runs] == [
        {"vehicle.speed": 10.0, "track.crossing.impact_angle": 0.018},
        {"vehicle.speed": 20.0, "track.crossing.impact_angle": base.track.impact_angle},
        {"vehicle.speed": base.vehicle.speed, "track.crossing.impact_angle": base.track.impact_angle}]


@pytest.mark.parametrize("text, words", [
    ("vehicle.speed: 10\n", "non-empty YAML list"),
    ("- {vehicle.speed: 10}\n- 3\n", "item 1"),
    ("- {vehicle.speed: [1\n", "invalid YAML"),
])
def test_list_form_errors_name_the_file(tmp_path, text, words):
    path = tmp_path / "runs.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(UserInputError) as info:
        sweep.list_from_file(path)
    assert str(path) in str(info.value) and words in str(info.value)


def test_run_ids_are_stable_unique_and_follow_the_scenario(tmp_path):
    variations = sweep.grid_from_vary(GRID)
    a = sweep.plan_sweep(DEFAULT_SCENARIO, variations)
    b = sweep.plan_sweep(DEFAULT_SCENARIO, sweep.grid_from_vary(GRID))
    ids = [r.run_id for r in a.runs]
    assert ids == [r.run_id for r in b.runs] and len(set(ids)) == len(ids) == 6
    assert [r.index for r in a.runs] == list(range(6))
    # The id is the run's scenario, not its position: reversed grid, same ids.
    reversed_plan = sweep.plan_sweep(DEFAULT_SCENARIO, variations[::-1])
    assert [r.run_id for r in reversed_plan.runs] == ids[::-1]
    # Another base scenario (one value changed) gives other ids.
    other = tmp_path / "other.yaml"
    other.write_text(DEFAULT_SCENARIO.read_text(encoding="utf-8").replace("name: ", "name: other-", 1),
                     encoding="utf-8")
    assert not set(ids) & {r.run_id for r in sweep.plan_sweep(other, variations).runs}


def test_same_scenario_twice_is_an_error():
    """3 and 3.0 (or 1e8 and 100000000) are the same scenario: one run, not two."""
    with pytest.raises(UserInputError, match=r"run 1 \(vehicle.speed=3.0\) is the same scenario as run 0"):
        sweep.plan_sweep(DEFAULT_SCENARIO, [{"vehicle.speed": 3}, {"vehicle.speed": 3.0}])


@pytest.mark.parametrize("vary, key, words", [
    (["vehicle.sped=10,20"], "vehicle.sped", "did you mean 'speed'"),
    ([f"vehicle.speed={SPEEDS},-1"], "vehicle.speed", "must be > 0"),  # the last run is the bad one
    (["track.crossing.impact_angle=0.006,fast"], "track.crossing.impact_angle", "the string 'fast'"),
])
def test_bad_key_or_value_stops_the_sweep_before_any_run(tmp_path, vary, key, words):
    out = tmp_path / "out"
    with pytest.raises(ScenarioError) as info:
        sweep.run_sweep(DEFAULT_SCENARIO, sweep.grid_from_vary(vary), out,
                        run_fn=counted(product_run, tmp_path), progress=False)
    assert info.value.key == key and words in str(info.value)
    assert not out.exists() and not calls(tmp_path)  # nothing ran, nothing written


# --------------------------------------------------------------------------------------
# Local runs, store, table
# --------------------------------------------------------------------------------------
def test_sweep_writes_one_row_per_run_and_a_rerun_redoes_nothing(tmp_path):
    out = tmp_path / "out"
    variations = sweep.grid_from_vary(GRID)
    res = sweep.run_sweep(DEFAULT_SCENARIO, variations, out,
                          run_fn=counted(product_run, tmp_path), workers=2, progress=False)
    plan = sweep.plan_sweep(DEFAULT_SCENARIO, variations)
    assert (res.done, res.skipped, res.failed) == (6, 0, 0)
    rows = read_table(out / sweep.TABLE_FILE)
    assert [r["run_id"] for r in rows] == [r.run_id for r in plan.runs]
    assert list(rows[0]) == ["index", "run_id", "vehicle.speed", "track.crossing.impact_angle", "y", "name"]
    for row in rows:
        # Floats are written with repr: they read back bit for bit.
        assert float(row["y"]) == float(row["vehicle.speed"]) * float(row["track.crossing.impact_angle"])
        assert (out / "runs" / row["run_id"] / "y.txt").read_text() == row["y"]
    assert [p.name for p in res.plots] == ["sweep_y.png"]  # "name" is a string: no plot
    again = sweep.run_sweep(DEFAULT_SCENARIO, variations, out, run_fn=counted(product_run, tmp_path), progress=False)
    assert (again.done, again.skipped) == (0, 6)
    assert read_table(out / sweep.TABLE_FILE) == rows
    assert set(calls(tmp_path).values()) == {1}


def test_extending_the_grid_runs_only_the_new_combinations(tmp_path):
    out = tmp_path / "out"
    sweep.run_sweep(DEFAULT_SCENARIO, sweep.grid_from_vary(GRID), out,
                    run_fn=counted(product_run, tmp_path), progress=False)
    more = [f"vehicle.speed=1.0,{SPEEDS}", f"track.crossing.impact_angle={ANGLES}"]
    res = sweep.run_sweep(DEFAULT_SCENARIO, sweep.grid_from_vary(more), out,
                          run_fn=counted(product_run, tmp_path), progress=False)
    assert (res.done, res.skipped) == (2, 6)
    assert [r["vehicle.speed"] for r in res.rows] == [1.0, 1.0, 2.78, 2.78, 27.78, 27.78, 55.56, 55.56]
    assert [r["index"] for r in res.rows] == list(range(8))


def test_failed_run_is_reported_and_retried_the_next_time(tmp_path):
    out = tmp_path / "out"
    variations = sweep.grid_from_vary(GRID)
    res = sweep.run_sweep(DEFAULT_SCENARIO, variations, out, run_fn=counted(failing_run, tmp_path), progress=False)
    assert (res.done, res.skipped, res.failed) == (4, 0, 2)
    bad = [r.run_id for r in sweep.plan_sweep(DEFAULT_SCENARIO, variations).runs
           if r.values["vehicle.speed"] == FAIL_SPEED]
    assert list(res.errors) == bad == list(res.unfinished)
    assert res.errors[bad[0]] == "ValueError: diverged at V = 27.78"
    assert "rerun the same command" in res.summary()
    assert len(read_table(out / sweep.TABLE_FILE)) == 4
    res = sweep.run_sweep(DEFAULT_SCENARIO, variations, out, run_fn=counted(product_run, tmp_path), progress=False)
    assert (res.done, res.skipped, res.failed) == (2, 4, 0)


def test_killed_worker_loses_nothing_and_the_rerun_does_only_the_missing_runs(tmp_path):
    """The last run SIGKILLs its worker the first time: the pool breaks.

    Nothing finished is lost (result files and table), the message says to
    rerun; the rerun completes every run exactly once: finished runs are not
    redone, every unfinished one is redone once, from an empty folder.
    """
    out = tmp_path / "out"
    variations = sweep.grid_from_vary(GRID)
    plan = sweep.plan_sweep(DEFAULT_SCENARIO, variations)
    killed = plan.runs[-1].run_id
    with pytest.raises(sweep.SweepIncomplete) as info:
        sweep.run_sweep(DEFAULT_SCENARIO, variations, out,
                        run_fn=counted(killing_run, tmp_path), workers=2, progress=False)
    message = str(info.value)
    assert "worker process died" in message and killed in message
    assert "run the same command again" in message and "\n" not in message
    first = finished(out)
    # Workers take runs in order, one at a time: when the last run starts, all but
    # at most the one on the other worker have finished.
    assert killed not in first and len(first) >= len(plan.runs) - 2
    assert {r["run_id"] for r in read_table(out / sweep.TABLE_FILE)} == first
    assert set(info.value.result.unfinished) == {r.run_id for r in plan.runs} - first
    calls_first = calls(tmp_path)

    res = sweep.run_sweep(DEFAULT_SCENARIO, variations, out,
                          run_fn=counted(killing_run, tmp_path), workers=2, progress=False)
    assert (res.done, res.skipped, res.failed) == (len(plan.runs) - len(first), len(first), 0)
    ids = [r["run_id"] for r in read_table(out / sweep.TABLE_FILE)]
    assert ids == [r.run_id for r in plan.runs]  # none lost, none twice, grid order
    calls_second = calls(tmp_path)
    for run in plan.runs:
        redone = 0 if run.run_id in first else 1
        assert calls_second[run.run_id] == calls_first.get(run.run_id, 0) + redone, run
    assert calls_second[killed] == 2
    assert not (out / "runs" / killed / "partial.txt").exists()  # the redo started from scratch


# --------------------------------------------------------------------------------------
# Dask
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def dask_cluster():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1,
                                       dashboard_address=":0")  # any free port: tests may run in parallel
    yield cluster
    cluster.close()


def test_dask_cluster_gives_the_same_table_as_local_processes(tmp_path, dask_cluster):
    variations = sweep.grid_from_vary(GRID)
    local = sweep.run_sweep(DEFAULT_SCENARIO, variations, tmp_path / "local",
                            run_fn=counted(product_run, tmp_path), progress=False)
    dask = sweep.run_sweep(DEFAULT_SCENARIO, variations, tmp_path / "dask", run_fn=counted(product_run, tmp_path),
                           scheduler=dask_cluster.scheduler_address, progress=False)
    assert (local.done, dask.done, dask.failed) == (6, 6, 0)
    assert (tmp_path / "dask" / sweep.TABLE_FILE).read_text() == (tmp_path / "local" / sweep.TABLE_FILE).read_text()


def test_dask_reschedules_a_run_whose_worker_died(tmp_path, dask_cluster):
    """Dask retries the task of a dead worker itself: one call, every run once in the table."""
    variations = sweep.grid_from_vary(GRID)
    res = sweep.run_sweep(DEFAULT_SCENARIO, variations, tmp_path / "out", run_fn=counted(killing_run, tmp_path),
                          scheduler=dask_cluster.scheduler_address, progress=False)
    plan = sweep.plan_sweep(DEFAULT_SCENARIO, variations)
    assert (res.done, res.failed) == (6, 0), res.errors
    assert [r["run_id"] for r in res.rows] == [r.run_id for r in plan.runs]
    assert calls(tmp_path)[plan.runs[-1].run_id] == 2
    assert not (tmp_path / "out" / "runs" / plan.runs[-1].run_id / "partial.txt").exists()


def test_unreachable_scheduler_is_a_user_error(tmp_path, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(sweep, "DASK_CONNECT_TIMEOUT", "1s")
    with pytest.raises(UserInputError, match="tcp://127.0.0.1:1"):
        sweep.run_sweep(DEFAULT_SCENARIO, [{"vehicle.speed": 3.0}], tmp_path / "o",
                        run_fn=counted(product_run, tmp_path),
                        scheduler="tcp://127.0.0.1:1", progress=False)


# --------------------------------------------------------------------------------------
# Plots
# --------------------------------------------------------------------------------------
def test_plots_one_per_numeric_scalar_one_line_per_combination(tmp_path):
    rows = [{"index": i, "run_id": f"r{i}", "a": a, "b": b, "y": a * b, "flag": True, "label": "x"}
            for i, (a, b) in enumerate([(1.0, 1), (2.0, 1), (1.0, 2), (2.0, 2)])]
    paths = sweep.plot_sweep(rows, ["a", "b"], tmp_path)
    assert [p.name for p in paths] == ["sweep_y.png"] and paths[0].stat().st_size > 0
    # A non-numeric first key has no abscissa: no plots.
    assert sweep.plot_sweep([dict(r, a="soft") for r in rows], ["a", "b"], tmp_path / "none") == []


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------
def test_cli_bad_key_is_one_line_exit_2_and_nothing_runs(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["sweep", str(DEFAULT_SCENARIO), "--vary", "vehicle.sped=10,20", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err == (f"turnout: error: {DEFAULT_SCENARIO}: vehicle.sped: unknown key 'sped' (did you mean 'speed'?) "
                   f"[override 'vehicle.sped=10']\n")
    assert not out.exists()


@pytest.mark.parametrize("argv", [
    ["sweep", str(DEFAULT_SCENARIO)],  # neither --vary nor --list
    ["sweep", str(DEFAULT_SCENARIO), "--vary", "vehicle.speed=1,2", "--list", "runs.yaml"],
    ["sweep", str(DEFAULT_SCENARIO), "--vary", "vehicle.speed=1,2", "--workers", "0"],
    ["sweep", str(DEFAULT_SCENARIO), "--vary", "vehicle.speed"],
    ["sweep", str(DEFAULT_SCENARIO), "--list", "missing.yaml"],
])
def test_cli_usage_errors_are_one_line(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("turnout: error: ") and err.count("\n") == 1 and "Traceback" not in err


def test_cli_help(capsys):
    with pytest.raises(SystemExit) as info:
        sys.exit(main(["sweep", "--help"]))
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert all(opt in text for opt in ("--vary", "--list", "--out", "--workers", "--scheduler", "--no-progress"))


def test_cli_delegates(monkeypatch, tmp_path, capsys):
    seen = {}

    def fake(base_path, variations, out_dir, run_fn=None, workers=2, scheduler=None, progress=True):
        seen.update(base_path=base_path, variations=variations, out_dir=out_dir, workers=workers,
                    scheduler=scheduler, progress=progress, run_fn=run_fn)
        return types.SimpleNamespace(failed=0, summary=lambda: "2 runs")

    monkeypatch.setattr(sweep, "run_sweep", fake)
    runs = tmp_path / "runs.yaml"
    runs.write_text("- {vehicle.speed: 10.0}\n- {vehicle.speed: 20.0}\n", encoding="utf-8")
    assert main(["sweep", str(DEFAULT_SCENARIO), "--list", str(runs), "--workers", "3",
                 "--scheduler", "tcp://h:8786", "--no-progress"]) == 0
    assert seen == dict(base_path=DEFAULT_SCENARIO, variations=[{"vehicle.speed": 10.0}, {"vehicle.speed": 20.0}],
                        out_dir=Path("results") / "crossing-1-12-through-120-sweep", workers=3,
                        scheduler="tcp://h:8786", progress=False, run_fn=None)
    assert capsys.readouterr().out == "turnout: sweep: 2 runs\n"


def test_cli_incomplete_sweep_exits_1_with_one_line(monkeypatch, tmp_path, capsys):
    def fake(*args, **kwargs):
        raise sweep.SweepIncomplete("a worker process died:\n1 of 2 runs did not finish", result=None)

    monkeypatch.setattr(sweep, "run_sweep", fake)
    assert main(["sweep", str(DEFAULT_SCENARIO), "--vary", "vehicle.speed=1,2", "--out", str(tmp_path)]) == 1
    assert capsys.readouterr().err == "turnout: error: a worker process died: 1 of 2 runs did not finish\n"


# --------------------------------------------------------------------------------------
# A real run (orchestrator.sweeps.study.run_case, the default run function)
# --------------------------------------------------------------------------------------
@pytest.mark.skipif(importlib.util.find_spec("orchestrator.sweeps.study") is None, reason="orchestrator.sweeps.study not there")
def test_real_sweep_through_the_cli_matches_single_runs(tmp_path, capsys):
    """Two 10 ms quarter-vehicle runs on a 12-sleeper plain track through ``turnout sweep``.

    Each row equals ``run_case`` called directly on the same scenario: the worker
    got the overrides. Same code, same inputs: the tolerance 1e-9 only allows for
    a different summation order in threaded BLAS.
    """
    from orchestrator.sweeps.study import run_case

    base = tmp_path / "tiny.yaml"
    base.write_text(PLAIN_SCENARIO.read_text(encoding="utf-8")
                    .replace("sleepers: 30", "sleepers: 12").replace("fmu: bogie", "fmu: quarter")
                    .replace("duration: 0.5", "duration: 0.01"), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["sweep", str(base), "--vary", "vehicle.speed=10,20", "--out", str(out), "--no-progress"]) == 0
    assert "2 runs: 2 done" in capsys.readouterr().out
    rows = read_table(out / sweep.TABLE_FILE)
    assert [float(r["vehicle.speed"]) for r in rows] == [10.0, 20.0]
    for row in rows:
        direct = run_case(load_scenario(base, [f"vehicle.speed={row['vehicle.speed']}"]), tmp_path / "direct")
        for name in ("max_Fz", "delta_Q", "max_rail_moment", "max_sleeper_moment", "max_ballast_pressure"):
            assert float(row[name]) == pytest.approx(direct[name], rel=1e-9), name
        assert (out / "runs" / row["run_id"] / "arrays.npz").stat().st_size > 0
        record = json.loads((out / "runs" / row["run_id"] / sweep.RESULT_FILE).read_text())
        assert record["run_id"] == row["run_id"] and record["index"] == int(row["index"])
    assert (out / "sweep_max_Fz.png").exists()


# --------------------------------------------------------------------------------------
# Runs by value
# --------------------------------------------------------------------------------------
def layout_run(scenario, run_dir: Path) -> dict:
    """Reports the sensor layout file the worker's scenario names, and writes a file into a sub-folder."""
    (run_dir / "sub").mkdir()
    (run_dir / "sub" / "layout_copy.yaml").write_bytes(Path(scenario.sensors).read_bytes())
    return {"sensors": scenario.sensors, "speed": scenario.vehicle.speed}


def test_a_run_travels_by_value_and_comes_back_by_value(tmp_path, monkeypatch):
    """A run's job holds the scenario and its layout file by value: it runs after the client's files are gone,
    in the worker's temporary space, and returns what the run function wrote."""
    from orchestrator.cosim.portable import FILES_DIR, file_keys
    from orchestrator.sweeps.store import RunJob, SweepStore, execute_run

    client = tmp_path / "client"
    (client / "sensors").mkdir(parents=True)
    measurement = SCENARIOS_DIR / "measurement" / "crossing_quarter_120.yaml"
    layout = SCENARIOS_DIR / "sensors" / "in2track_like.yaml"
    (client / "sensors" / "mine.yaml").write_bytes(layout.read_bytes())
    (client / "scen.yaml").write_text(measurement.read_text(encoding="utf-8").replace(
        "sensors: ../sensors/in2track_like.yaml", "sensors: sensors/mine.yaml"), encoding="utf-8")
    plan = sweep.plan_sweep(client / "scen.yaml", [{"vehicle.speed": 30.0}])
    assert [k for k, _ in file_keys(plan.runs[0].raw)] == [("sensors",)]  # vehicle.fmu: quarter is a keyword
    job = RunJob.of(plan.runs[0], str(client / "scen.yaml"))
    shutil.rmtree(client)  # the worker is elsewhere: nothing of the client's is there

    worker_tmp = tmp_path / "worker-tmp"
    worker_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(worker_tmp))
    output = execute_run(job, layout_run)
    local = Path(output.record["result"]["sensors"])
    assert local.parent.parent == worker_tmp / FILES_DIR and local.read_bytes() == layout.read_bytes()
    assert output.files == {"sub/layout_copy.yaml": layout.read_bytes()}
    assert [p.name for p in worker_tmp.iterdir()] == [FILES_DIR]  # the run folder is gone

    store = SweepStore.open(tmp_path / "out")
    (store.run_dir(job.run_id) / "stale.txt").parent.mkdir(parents=True)
    (store.run_dir(job.run_id) / "stale.txt").write_text("of a killed attempt")
    store.save(output)
    assert sorted(p.relative_to(store.run_dir(job.run_id)).as_posix()
                  for p in store.run_dir(job.run_id).rglob("*") if p.is_file()) == ["result.json",
                                                                                   "sub/layout_copy.yaml"]
    assert store.record(job.run_id)["result"]["speed"] == 30.0
