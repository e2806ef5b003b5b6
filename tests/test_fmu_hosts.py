"""The FMUs in hosts other than our orchestrator: a C host without Python, FMPy.

The C host (``tests/fixtures/fmi2_host.c``) stands for any non-Python FMI tool: compiled
here with the system C compiler against FMPy's FMI 2.0 headers, linked with ``-ldl``
only, run in a subprocess with a clean environment (no PYTHONPATH, no LD_PRELOAD, no
virtual environment on PATH).  It loads each FMU's binary -- the shim of
``fmus/shim/fmi2_python_shim.c``, which finds and starts the Python the FMU was built
with -- instantiates two instances, steps them, frees them and must exit with status 0
(pythonfmu's wrapper alone corrupted the heap at exit: ``free(): corrupted unsorted
chunks``).  Also here: the missing-dependency message, the shipped requirements, the
DefaultExperiment and start values baked from the caller, and instance independence.
"""
from __future__ import annotations

import subprocess
import sys
import sysconfig
import textwrap
import zipfile
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from fmpy import extract, read_model_description  # noqa: E402
from fmpy.fmi2 import FMU2Slave  # noqa: E402

from fmus.build import (  # noqa: E402
    PYTHON_CONFIG_FILE,
    REQUIREMENTS_FILE,
    WRAPPER_SUFFIX,
    build_fmu,
    build_track_fmu,
    find_c_compiler,
    fmi2_headers_dir,
    shim_platform_ok,
)
from track.params import LayoutParams, TrackParams  # noqa: E402

if not shim_platform_ok():
    pytest.skip("the self-contained FMU binary (shim) is built on Linux x86-64 only", allow_module_level=True)
if find_c_compiler() is None:
    pytest.skip("no C compiler (cc or gcc) on PATH: neither the shim nor the C host can be built",
                allow_module_level=True)
if fmi2_headers_dir() is None:
    pytest.skip("FMPy's FMI 2.0 headers (fmpy/c-code) not found", allow_module_level=True)

HOST_SOURCE = Path(__file__).resolve().parent / "fixtures" / "fmi2_host.c"
PARAMS = TrackParams(layout=LayoutParams(type="plain", sleepers=16))   # small plain track: 0 .. 9 m
H = 1e-4                # s: communication step
N_STEPS = 300           # steps of the C host runs (30 ms)
SPEED = 5.0             # m/s
X_FRONT = 5.5           # m: front wheelset at t = 0 (rear at 3.0 m with the bogie's 2.5 m wheelbase)
DURATION = 0.5          # s: the DefaultExperiment baked into the FMUs here
CLEAN_ENV = {"PATH": "/usr/bin:/bin", "LANG": "C.UTF-8"}
MODELS = {"track": "Track", "bogie": "Bogie", "quarter": "QuarterVehicle"}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The three FMUs (track: plain, 4 wheels), extracted, and the compiled C host."""
    out = tmp_path_factory.mktemp("hosts")
    paths = {"track": build_track_fmu(PARAMS, 4, out, speed=SPEED, stop_time=DURATION, step_size=H),
             "bogie": build_fmu("bogie", out, stop_time=DURATION, step_size=H,
                                start_values={"x0": X_FRONT, "speed": SPEED}),
             "quarter": build_fmu("quarter", out)}
    files = {k: (p, Path(extract(str(p), unzipdir=str(out / f"{k}_x")))) for k, p in paths.items()}
    host = out / "fmi2_host"
    cmd = [find_c_compiler(), "-std=c99", "-O1", f"-I{fmi2_headers_dir()}", "-o", str(host), str(HOST_SOURCE), "-ldl"]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return files, host


def host_command(built, kind: str, n_steps: int = N_STEPS, instances: int = 2, unzipdir: Path | None = None):
    """The C host's command line for ``kind`` and the output names it prints, in order."""
    files, host = built
    path, default_dir = files[kind]
    unzipdir = unzipdir or default_dir
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    cmd = [str(host), str(unzipdir / "binaries" / "linux64" / f"{MODELS[kind]}.so"),
           (unzipdir / "resources").as_uri(), md.guid, repr(H), str(n_steps), "-n", str(instances)]
    if kind == "track":   # the wheels of a bogie at X_FRONT, moving at SPEED, resting at z = 0
        for i in range(4):
            cmd += ["-l", f"{vr[f'wheel{i + 1}_x']}={X_FRONT - 2.5 * (i // 2)}:{SPEED}"]
        outputs = [f"wheel{i + 1}_Fz" for i in range(4)]
    else:
        outputs = ["wheel1_x", "wheel1_z", "wheel2_vz"]
    for name in outputs:
        cmd += ["-o", str(vr[name])]
    return cmd, outputs


def parse(stdout: str, outputs) -> np.ndarray:
    """Host output lines "instance vr value" -> array (instances, outputs)."""
    rows = [line.split() for line in stdout.strip().splitlines()]
    n = len(rows) // len(outputs)
    return np.array([float(r[2]) for r in rows]).reshape(n, len(outputs))


def fmpy_track_run(path: Path, unzipdir: Path, n_steps: int, instances: int = 1, parameters=None):
    """The C host's track run in FMPy (in this process), ``instances`` interleaved, instance j
    with the Real/Integer parameters ``parameters[j]``: final wheel forces, shape (instances, 4)."""
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    types = {v.name: v.type for v in md.modelVariables}
    fmus = []
    for j in range(instances):
        f = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir), modelIdentifier="Track", instanceName=f"i{j}")
        f.instantiate()
        f.setupExperiment(startTime=0.0)
        f.enterInitializationMode()
        for name, value in (parameters[j] if parameters else {}).items():
            if types[name] == "Integer":
                f.setInteger([vr[name]], [int(value)])
            else:
                f.setReal([vr[name]], [float(value)])
        f.exitInitializationMode()
        fmus.append(f)
    x_vr = [vr[f"wheel{i + 1}_x"] for i in range(4)]
    for k in range(n_steps):
        t = k * H
        for f in fmus:
            f.setReal(x_vr, [X_FRONT - 2.5 * (i // 2) + SPEED * t for i in range(4)])
            f.doStep(t, H)
    out = np.array([f.getReal([vr[f"wheel{i + 1}_Fz"] for i in range(4)]) for f in fmus])
    for f in fmus:
        f.terminate()
        f.freeInstance()
    return out


# ------------------------------------------------------------------------------- C host
def test_binary_is_the_shim_and_the_wrapper_sits_next_to_it(built):
    """The FMU's linux64 binary loads without Python symbols (the shim), pythonfmu's wrapper
    is shipped renamed next to it, and the building Python is recorded."""
    files, _ = built
    for kind, model in MODELS.items():
        binaries = files[kind][1] / "binaries" / "linux64"
        assert (binaries / f"{model}{WRAPPER_SUFFIX}").is_file()
        dyn = subprocess.run(["nm", "-D", "--undefined-only", str(binaries / f"{model}.so")],
                             capture_output=True, text=True, check=True).stdout
        assert "Py" not in dyn.replace("pthread", "")
        cfg = (files[kind][1] / "resources" / PYTHON_CONFIG_FILE).read_text()
        assert f"executable={sys.executable}\n" in cfg


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_c_host_without_python_runs_the_fmu_and_exits_cleanly(built, kind):
    """Two instances, N_STEPS steps, terminate, free, exit: status 0 and no message on
    stderr (the shim starts the recorded Python itself; pythonfmu's exit-time heap
    corruption would abort with status 134).  The results are the physics':

    * vehicles: wheel1_x = x0 + speed t exactly up to rounding (1e-12 relative), and the
      wheels stay at their static position under the static loads (|z| < 1e-12 m, |vz| <
      1e-9 m/s: rounding in 300 exact-discretisation steps);
    * track: the forces equal an FMPy run of the same inputs in this process (1e-12
      relative: same code and arithmetic, only the process differs);
    * both instances give bit-identical results (no shared state between instances).
    """
    cmd, outputs = host_command(built, kind)
    done = subprocess.run(cmd, env=CLEAN_ENV, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stderr == ""
    values = parse(done.stdout, outputs)
    assert values.shape == (2, len(outputs))
    assert np.array_equal(values[0], values[1])
    t_end = N_STEPS * H
    if kind == "track":
        path, unzipdir = built[0]["track"]
        np.testing.assert_allclose(values[0], fmpy_track_run(path, unzipdir, N_STEPS)[0], rtol=1e-12)
        # near the static wheel load (98.1 kN) after the drop-free start: within 5 %
        assert np.all(np.abs(values[0] / 98100.0 - 1.0) < 0.05)
    else:
        x0 = X_FRONT if kind == "bogie" else 0.0                # bogie: start values baked at build
        speed = SPEED if kind == "bogie" else 33.333
        np.testing.assert_allclose(values[0, 0], x0 + speed * t_end, rtol=1e-12)
        assert abs(values[0, 1]) < 1e-12 and abs(values[0, 2]) < 1e-9


def test_c_host_with_libpython_preloaded_exits_cleanly(built):
    """The work-around of the old FMUs (LD_PRELOAD of libpython): the shim then finds
    Python in the process but initialises it itself; exit status 0 with two bogie
    instances freed (before: ``free(): corrupted unsorted chunks``, status 134)."""
    cfg = (built[0]["bogie"][1] / "resources" / PYTHON_CONFIG_FILE).read_text()
    libpython = next(line.split("=", 1)[1] for line in cfg.splitlines() if line.startswith("libpython="))
    if not Path(libpython).is_file():
        pytest.skip(f"no shared libpython next to this Python ({libpython})")
    cmd, _ = host_command(built, "bogie")
    done = subprocess.run(cmd, env={**CLEAN_ENV, "LD_PRELOAD": libpython}, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]


def test_unloadable_python_is_reported_through_the_logger(built, tmp_path):
    """A recorded libpython that does not exist: fmi2Instantiate returns NULL and the host's
    logger gets one message naming the FMU, the library and the environment variables."""
    import shutil

    unzipdir = tmp_path / "moved"
    shutil.copytree(built[0]["quarter"][1], unzipdir)
    cfg = unzipdir / "resources" / PYTHON_CONFIG_FILE
    lines = [("libpython=/nonexistent/libpython3.99.so.1.0" if line.startswith("libpython=") else line)
             for line in cfg.read_text().splitlines()]
    cfg.write_text("\n".join(lines) + "\n")
    cmd, _ = host_command(built, "quarter", instances=1, unzipdir=unzipdir)
    done = subprocess.run(cmd, env=CLEAN_ENV, capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert "the quarter FMU needs the Python it was built with" in done.stderr
    assert "/nonexistent/libpython3.99.so.1.0" in done.stderr and "XPANEL_FMU_LIBPYTHON" in done.stderr
    assert "fmi2Instantiate returned NULL" in done.stderr


# ---------------------------------------------------------------------------- resources
def test_requirements_are_shipped_and_satisfied_by_the_building_python(built):
    """resources/requirements.txt (what ``pythonfmu deploy`` installs) names numpy and scipy
    with lower bounds this Python satisfies."""
    for kind in MODELS:
        with zipfile.ZipFile(built[0][kind][0]) as z:
            text = z.read(f"resources/{REQUIREMENTS_FILE}").decode()
        reqs = dict(line.split(">=") for line in text.splitlines() if line and not line.startswith("#"))
        assert sorted(reqs) == ["numpy", "scipy"]
        for name, floor in reqs.items():
            have = tuple(int(p) for p in version(name).split(".")[:2])
            assert have >= tuple(int(p) for p in floor.split("."))


def test_missing_dependency_is_named(built, tmp_path):
    """In a Python whose scipy cannot be imported, instantiating the track FMU fails with a
    message naming scipy and the requirements file (not "No module named 'track'"), given
    to the logger of a host that instantiates with loggingOn (pythonfmu logs only then)."""
    path, unzipdir = built[0]["track"]
    script = textwrap.dedent(f"""
        import sys
        sys.modules["scipy"] = None          # makes "import scipy" fail: ModuleNotFoundError
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
        messages = []
        cb = fmi2CallbackFunctions()
        cb.logger = fmi2CallbackLoggerTYPE(lambda c, n, s, cat, msg: messages.append(msg.decode()))
        md = read_model_description({str(path)!r})
        f = FMU2Slave(guid=md.guid, unzipDirectory={str(unzipdir)!r}, modelIdentifier="Track")
        try:
            f.instantiate(callbacks=cb, loggingOn=True)   # pythonfmu logs only then
        except Exception:
            pass
        print("\\n".join(messages))
    """)
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert "the track FMU needs scipy" in done.stdout, done.stdout + done.stderr
    assert REQUIREMENTS_FILE in done.stdout and "No module named 'track'" not in done.stdout


def test_default_experiment_and_start_values_come_from_the_caller(built):
    """DefaultExperiment = (0, stop_time, step_size) given to the build; the bogie's x0 and
    speed start values likewise; without them the slave class's defaults stay."""
    files, _ = built
    for kind in ("track", "bogie"):
        ex = read_model_description(str(files[kind][0])).defaultExperiment
        assert (float(ex.startTime), float(ex.stopTime), float(ex.stepSize)) == (0.0, DURATION, H)
    start = {v.name: v.start for v in read_model_description(str(files["bogie"][0])).modelVariables}
    assert (float(start["x0"]), float(start["speed"])) == (X_FRONT, SPEED)
    quarter = read_model_description(str(files["quarter"][0]))
    assert float(quarter.defaultExperiment.stopTime) == 1.0   # pythonfmu slave class default
    with pytest.raises(ValueError, match="stop_time"):
        build_fmu("quarter", files["quarter"][1].parent / "bad", stop_time=1.0)
    with pytest.raises(ValueError, match="not parameters"):
        build_fmu("quarter", files["quarter"][1].parent / "bad", start_values={"nonsense": 1.0})


# ------------------------------------------------------------------------- independence
def test_track_instances_in_one_process_are_independent(built):
    """Track instances interleaved in FMPy share the process's caches of reduced bodies
    (track.model) and of step-matrix factorizations with their influence rows
    (track.dynamics).  Two default instances, next to one with a ballast void (same step
    matrix, other gaps: the ballast-row cache is used differently) and one with stiffer pads
    (another matrix), give bit-identical forces, equal to a single instance's run."""
    path, unzipdir = built[0]["track"]
    void = {"void_sleeper": 7, **{f"void_gap_{j}": g for j, g in enumerate([0, 2e-4, 5e-4, 5e-4, 2e-4, 0], 1)}}
    solo = fmpy_track_run(path, unzipdir, 200, instances=1)
    mixed = fmpy_track_run(path, unzipdir, 200, instances=4, parameters=[void, {}, {"h2": 2.0}, {}])
    assert np.array_equal(mixed[1], solo[0]) and np.array_equal(mixed[3], solo[0])
    assert np.max(np.abs(mixed[2] - solo[0])) > 1.0   # N: the stiffer-pad instance is another track


def test_flags_declared_by_the_fmus(built):
    """The track FMU is fixed-step (it says so); the vehicles re-discretise on a step change
    (tests/test_fmu_vehicle.py::test_step_size_change_is_handled); every FMU can be
    instantiated several times per process and saves/serialises its state."""
    files, _ = built
    for kind in MODELS:
        cs = read_model_description(str(files[kind][0])).coSimulation
        assert cs.canHandleVariableCommunicationStepSize == (kind != "track")
        assert not cs.canBeInstantiatedOnlyOncePerProcess
        assert cs.canGetAndSetFMUstate and cs.canSerializeFMUstate


def test_python_config_records_numpy_and_scipy_folders(built):
    """The shim's configuration names the folders numpy and scipy are imported from."""
    import numpy
    import scipy

    cfg = (built[0]["track"][1] / "resources" / PYTHON_CONFIG_FILE).read_text().splitlines()
    paths = {line.split("=", 1)[1] for line in cfg if line.startswith("path=")}
    for module in (numpy, scipy):
        assert str(Path(module.__file__).resolve().parent.parent) in paths
    assert any(line.startswith("libpython=") and sysconfig.get_config_var("py_version_short") in line
               for line in cfg)



def test_without_a_c_compiler_the_build_warns_and_falls_back(tmp_path, monkeypatch):
    """No compiler: a RuntimeWarning saying what a C host then needs, and the FMU ships
    pythonfmu's wrapper as its binary (Python symbols unresolved), which FMPy still runs."""
    import fmus.build as fb

    monkeypatch.setattr(fb, "find_c_compiler", lambda: None)
    with pytest.warns(RuntimeWarning, match="no C compiler.*LD_PRELOAD"):
        path = fb.build_fmu("quarter", tmp_path)
    unzipdir = Path(extract(str(path), unzipdir=str(tmp_path / "x")))
    binary = unzipdir / "binaries" / "linux64" / "QuarterVehicle.so"
    assert not (binary.parent / f"QuarterVehicle{WRAPPER_SUFFIX}").exists()
    undefined = subprocess.run(["nm", "-D", "--undefined-only", str(binary)], capture_output=True, text=True,
                               check=True).stdout
    assert "_Py_NoneStruct" in undefined
    md = read_model_description(str(path))
    f = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipdir), modelIdentifier="QuarterVehicle")
    f.instantiate()
    f.setupExperiment(startTime=0.0)
    f.enterInitializationMode()
    f.exitInitializationMode()
    f.doStep(0.0, 1e-3)
    x = f.getReal([next(v.valueReference for v in md.modelVariables if v.name == "wheel1_x")])[0]
    f.terminate()
    f.freeInstance()
    np.testing.assert_allclose(x, 33.333 * 1e-3, rtol=1e-12)   # default speed, x0 = 0; rounding only
