"""Workers elsewhere: a Dask cluster that is really another machine, workers that use their cores,
workers that die with their parent.

- The cluster's workers run in a working folder of their own with a temporary folder of
  their own (:class:`Elsewhere`), as on another machine: a relative scenario path of the
  client means nothing there, and the client's output folder is not theirs to write.
  A sweep and a diagnosis run through that cluster give the same numbers as local
  processes, and the workers leave nothing outside their temporary space.
- A worker process's BLAS is limited to one thread (threadpoolctl), unless told otherwise.
- SIGKILL of ``turnout sweep``'s main process leaves no worker computing on.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")
psutil = pytest.importorskip("psutil")

from conftest import DEFAULT_SCENARIO  # noqa: E402

from orchestrator.cosim.portable import FILES_DIR  # noqa: E402
from orchestrator.cosim.scratch import remove_orphans  # noqa: E402
from orchestrator.inputs.scenario import bundled_scenario, load_scenario  # noqa: E402
from orchestrator.inputs.sensor_layout import layout_of, resolve  # noqa: E402
from orchestrator.inverse.diagnose import diagnose  # noqa: E402
from orchestrator.inverse.synthetic import hidden_effect, synthesize  # noqa: E402
from orchestrator.sweeps import sweep  # noqa: E402
from orchestrator.sweeps.executors import make_executor  # noqa: E402
from orchestrator.sweeps.store import WORK_PREFIX  # noqa: E402
from orchestrator.sweeps.workers import THREAD_VARIABLES, THREADS_ENV, default_workers  # noqa: E402
from track.model import build_track  # noqa: E402

MEASUREMENT = bundled_scenario("measurement/crossing_quarter_120.yaml")
SHORT_DURATION = 0.1  # s: the measurement scenario cut short; its synthetic passage keeps > 100 samples (the minimum)
SEED = 7  # the synthetic measurement's effect and noise
DEATH_WAIT = 10.0  # s: how long orphaned workers may take to go (PR_SET_PDEATHSIG: at once; watchdog: 0.5 s)
RUNNING_CPU = 3.0  # s: CPU time after which a sweep worker is past its imports (~1-2 s) and inside a run


class Elsewhere(distributed.WorkerPlugin):
    """Moves a Dask worker into its own working folder and temporary folder, as on another machine."""

    name = "test-elsewhere"

    def __init__(self, cwd: str, tmp: str):
        self.cwd, self.tmp = cwd, tmp

    def setup(self, worker=None) -> None:
        os.chdir(self.cwd)
        tempfile.tempdir = self.tmp


@pytest.fixture(scope="module")
def cluster_elsewhere(tmp_path_factory):
    """A 2-process, 1-thread-each LocalCluster whose workers work in ``cwd`` and ``tmp`` of their own."""
    root = tmp_path_factory.mktemp("workers")
    cwd, tmp, space = root / "cwd", root / "tmp", root / "dask-space"
    for d in (cwd, tmp, space):
        d.mkdir()
    cluster = distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, dashboard_address=":0",
                                       local_directory=str(space))
    with distributed.Client(cluster) as client:
        client.register_plugin(Elsewhere(str(cwd), str(tmp)))
        assert set(client.run(os.getcwd).values()) == {str(cwd)}
    yield cluster, cwd, tmp
    cluster.close()


def _client_folder(folder: Path) -> Path:
    """The short measurement scenario and its sensor layout under ``folder`` (``scen/quarter.yaml``,
    ``sensors/layout.yaml``); returns ``folder``."""
    (folder / "scen").mkdir(parents=True)
    (folder / "sensors").mkdir()
    sc = load_scenario(MEASUREMENT)
    shutil.copy(sc.sensors, folder / "sensors" / "layout.yaml")
    text = MEASUREMENT.read_text(encoding="utf-8")
    text = text.replace("sensors: ../sensors/in2track_like.yaml", "sensors: ../sensors/layout.yaml")
    text = text.replace("duration: 0.16 ", f"duration: {SHORT_DURATION} ")
    (folder / "scen" / "quarter.yaml").write_text(text, encoding="utf-8")
    assert load_scenario(folder / "scen" / "quarter.yaml").simulation.duration == SHORT_DURATION
    return folder


def _same_diagnosis(a: dict, b: dict) -> None:
    """Every number of two diagnoses equal (wall times and output paths aside)."""
    for key in ("baseline", "causes", "named_cause", "gain", "validation", "runs"):
        assert a[key] == b[key], key


def test_sweep_and_diagnosis_on_a_cluster_elsewhere(tmp_path, monkeypatch, cluster_elsewhere):
    """A relative scenario path on the client, workers in another folder: local results, nothing left behind.

    Same code and inputs on both sides, BLAS on one thread: the numbers are equal bit for bit.
    """
    cluster, worker_cwd, worker_tmp = cluster_elsewhere
    monkeypatch.chdir(_client_folder(tmp_path / "client"))
    scen = Path("scen/quarter.yaml")
    sc = load_scenario(scen)
    sleepers = sorted({int(s.body.split("_")[1]) for s in resolve(layout_of(sc), build_track(sc.track))
                       if s.body.startswith("sleeper_")})
    synthesize(sc, hidden_effect(SEED, "ballast_stiffness", sleepers), Path("passage.csv"), seed=SEED)

    variations = sweep.grid_from_vary(["vehicle.speed=30.0,33.333"])
    local = sweep.run_sweep(scen, variations, Path("sweep-local"), workers=2, progress=False)
    remote = sweep.run_sweep(scen, variations, Path("sweep-dask"), scheduler=cluster.scheduler_address,
                             progress=False)
    assert (local.done, remote.done, remote.failed) == (2, 2, 0)
    assert Path("sweep-dask/sweep.csv").read_text() == Path("sweep-local/sweep.csv").read_text()
    for row in remote.rows:
        with np.load(Path("sweep-dask/runs") / row["run_id"] / "arrays.npz") as d, \
                np.load(Path("sweep-local/runs") / row["run_id"] / "arrays.npz") as l:
            assert sorted(d.files) == sorted(l.files) and len(d.files) > 3
            for name in d.files:
                assert np.array_equal(d[name], l[name]), name

    d_local = diagnose(scen, "passage.csv", "diag-local", workers=2, progress=False).to_json()
    d_dask = diagnose(scen, "passage.csv", "diag-dask", scheduler=cluster.scheduler_address,
                      progress=False).to_json()
    assert d_dask["runs"] > 20  # screening, confirmation and fits all went through the cluster
    _same_diagnosis(d_local, d_dask)
    assert json.loads(Path("diag-dask/baseline.json").read_text()) == \
        json.loads(Path("diag-local/baseline.json").read_text())

    # The workers wrote nothing in their working folder (so nothing through a relative path) and kept
    # their run folders to themselves (removed after each run); the layout reached them by value.
    assert list(worker_cwd.iterdir()) == []
    assert not list(worker_tmp.glob(WORK_PREFIX + "*"))
    shipped = list((worker_tmp / FILES_DIR).glob("*/layout.yaml"))
    assert shipped and all(p.read_bytes() == Path("sensors/layout.yaml").read_bytes() for p in shipped)


# --------------------------------------------------------------------------------------
# Threads per worker
# --------------------------------------------------------------------------------------
def blas_threads() -> dict:
    """BLAS libraries loaded in this process and the largest thread count among them (top level: picklable)."""
    from threadpoolctl import threadpool_info

    blas = [i for i in threadpool_info() if i["user_api"] == "blas"]
    return {"blas_libraries": len(blas), "max_threads": max((i["num_threads"] for i in blas), default=0)}


def blas_threads_run(scenario, run_dir: Path) -> dict:
    """A sweep's run function that reports :func:`blas_threads` of its worker."""
    return blas_threads()


def _local_worker_blas_threads() -> int:
    """The largest BLAS thread count in a worker of a fresh one-process executor."""
    executor = make_executor(1, None)
    try:
        return executor.submit(blas_threads).result()["max_threads"]
    finally:
        executor.shutdown()


@pytest.fixture
def blas_default_env(monkeypatch):
    """No thread variables in this process's environment, which spawned workers inherit.

    Starting a Dask LocalCluster sets ``OMP_NUM_THREADS=1`` (and MKL's, OpenBLAS's) in the
    client process for good (its nanny's ``pre-spawn-environ``); without this, every later
    worker would start with one BLAS thread whatever the executor does.
    """
    for name in THREAD_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    monkeypatch.delenv(THREADS_ENV, raising=False)


def test_a_local_worker_has_one_blas_thread(tmp_path, blas_default_env):
    """Sweep workers and executor workers: one BLAS thread each (OpenBLAS would take one per core)."""
    res = sweep.run_sweep(DEFAULT_SCENARIO, [{"vehicle.speed": 20.0}, {"vehicle.speed": 30.0}], tmp_path / "s",
                          run_fn=blas_threads_run, workers=2, progress=False)
    assert [(r["blas_libraries"] >= 1, r["max_threads"]) for r in res.rows] == [(True, 1), (True, 1)]
    assert _local_worker_blas_threads() == 1


def test_a_cluster_worker_has_one_blas_thread(cluster_elsewhere):
    cluster, _, _ = cluster_elsewhere
    with distributed.Client(cluster) as client:
        sweep_executor = make_executor(None, cluster.scheduler_address)  # registers the plugin
        sweep_executor.shutdown()
        info = client.run(blas_threads)
    assert len(info) == 2 and all(v["blas_libraries"] >= 1 and v["max_threads"] == 1 for v in info.values()), info


@pytest.mark.skipif(default_workers() < 2, reason="needs 2 cores to tell 2 threads from the default")
def test_threads_per_worker_can_be_raised(blas_default_env, monkeypatch):
    """Told otherwise (TURNOUT_WORKER_THREADS=2), a worker keeps two BLAS threads."""
    monkeypatch.setenv(THREADS_ENV, "2")
    assert _local_worker_blas_threads() == 2


def test_bad_threads_per_worker_is_a_user_error(monkeypatch):
    from orchestrator.inputs.errors import UserInputError

    monkeypatch.setenv(THREADS_ENV, "many")
    with pytest.raises(UserInputError, match=f"{THREADS_ENV}='many'"):
        make_executor(1, None)


# --------------------------------------------------------------------------------------
# Workers die with their parent
# --------------------------------------------------------------------------------------
def _alive(pids) -> list[int]:
    """Those of ``pids`` still running (a zombie waiting to be reaped is not running)."""
    out = []
    for pid in pids:
        try:
            if psutil.Process(pid).status() != psutil.STATUS_ZOMBIE:
                out.append(pid)
        except psutil.NoSuchProcess:
            pass
    return out


def test_killing_the_sweep_leaves_no_worker_alive(tmp_path):
    """SIGKILL of ``turnout sweep`` while its two workers compute: both are gone within seconds.

    The runs are many and long (a fine time step) so that the workers are in the middle of one
    when the main process dies; without the parent-death signal they would run on. (Four runs were
    not enough once the step was compiled: 16 000 quarter-vehicle steps take ~0.3 s, and the sweep
    was over before both workers had spent RUNNING_CPU; 100 runs last ~50 s on 2 cores.)
    """
    base = tmp_path / "slow.yaml"
    base.write_text(MEASUREMENT.read_text(encoding="utf-8").replace("\n  step: 2.0e-4 ", "\n  step: 1.0e-5 ")
                    .replace("sensors: ../sensors/", f"sensors: {MEASUREMENT.parent.parent}/sensors/"),
                    encoding="utf-8")
    assert load_scenario(base).simulation.step == 1.0e-5
    speeds = ",".join(f"{30 + 0.1 * i:.1f}" for i in range(100))
    argv = [str(Path(sys.executable).with_name("turnout")), "sweep", str(base), "--vary", f"vehicle.speed={speeds}",
            "--workers", "2", "--out", str(tmp_path / "out"), "--no-progress"]
    tmp = tmp_path / "tmp"   # the sweep's temporary folder: what the killed workers leave behind
    tmp.mkdir()
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
                            env={**os.environ, "TMPDIR": str(tmp)})
    try:
        main = psutil.Process(proc.pid)
        workers: list = []
        deadline = time.monotonic() + 120.0  # s: spawning 2 workers and importing numpy/numba on a busy machine
        while time.monotonic() < deadline and proc.poll() is None:
            kids = main.children(recursive=True)
            workers = [k for k in kids if "spawn_main" in " ".join(_cmdline(k)) and
                       "resource_tracker" not in " ".join(_cmdline(k))]
            if len(workers) == 2 and all(_cpu(w) > RUNNING_CPU for w in workers):
                break
            time.sleep(0.2)
        assert proc.poll() is None, proc.stderr.read().decode()[-2000:]
        assert len(workers) == 2, [(_cmdline(k)) for k in main.children(recursive=True)]
        everyone = [k.pid for k in main.children(recursive=True)]
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        deadline = time.monotonic() + DEATH_WAIT
        while _alive(everyone) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _alive(everyone) == []
        # the killed workers' scratch folders (orchestrator.cosim.scratch; not the shared turnout-files cache)
        # go with the next process's first one
        left = sorted(p.name for p in tmp.glob("turnout-*-[0-9]*-*"))
        assert left, "the workers were killed mid-run: their run folders must be there to remove"
        removed = remove_orphans(str(tmp))
        assert sorted(Path(p).name for p in removed) == left and not list(tmp.glob("turnout-*-[0-9]*-*")), \
            (left, removed)
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in _alive(_descendants_of_session(proc.pid)):
            os.kill(pid, signal.SIGKILL)


def _cmdline(p) -> list[str]:
    try:
        return p.cmdline()
    except psutil.Error:
        return []


def _cpu(p) -> float:
    try:
        t = p.cpu_times()
        return t.user + t.system
    except psutil.Error:
        return 0.0


def _descendants_of_session(sid: int) -> list[int]:
    """Processes of the session the sweep started (cleanup after a failed test)."""
    out = []
    for p in psutil.process_iter():
        try:
            if os.getsid(p.pid) == sid:
                out.append(p.pid)
        except (OSError, psutil.Error):
            pass
    return out
