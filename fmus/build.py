"""Build the project's FMUs with pythonfmu: ``build_fmu(kind, out_dir) -> Path`` and
``build_track_fmu(track_params, n_wheels, out_dir) -> Path``.

pythonfmu FMUs execute in the host's Python interpreter and share its ``sys.modules``
(a Python host such as FMPy, or our orchestrator, imports the FMU's modules next to
its own).  Two FMUs built from different versions of ``vehicle``, or an FMU loaded
in a process that already imported the source tree's ``vehicle``, would silently
share one module.  So each FMU bundles its code as one package with a unique name,
``xpanel_<kind>_<hash>`` (hash of the bundled sources), laid out as::

    resources/xpanel_<kind>_<hash>_slave.py     entry script: imports the slave class
    resources/xpanel_<kind>_<hash>/__init__.py
                                  /base.py      copy of fmus/base.py (fast.py: of fmus/fast.py)
                                  /<module>.py  copy of the slave module, e.g. vehicle_fmus.py
                                  /<package>/   copy of src/<package>, e.g. vehicle/
    resources/<data files>                      e.g. track_fmu.json: the baked track parameters
                                                and sensors
    resources/pythonfmu/                        added by pythonfmu
    resources/.../__pycache__/*.<tag>.pyc       the bundled modules' bytecode (below)
    binaries/linux64/<ClassName>.so             pythonfmu's C wrapper

Bytecode: a host unzips the FMU into a fresh folder, so without it every process that loads the
FMU compiles the bundled sources again (~0.1 s for the track FMU; pythonfmu leaves ``__pycache__``
out of the archive). The build adds the building Python's bytecode of each bundled module,
hash-checked (PEP 552 ``CHECKED_HASH``: valid whatever the files' times after unzipping, and a
changed source is compiled again); another Python version ignores them (its own cache tag).

Slave modules import ``.base`` relatively and their model package with
``from . import vehicle`` (falling back to ``import vehicle`` in the source tree);
model packages use relative imports only.  The FMU needs numpy and scipy in the
host's (or the embedded) Python.

Data files (the track FMU's baked parameters) go into ``resources/`` next to the
entry script; they do not enter the package hash, so track FMUs of different
scenarios share one bundled package (and its in-process cache of reduced bodies).

Self-contained loading (Linux x86-64): pythonfmu's wrapper is not linked with libpython,
so a host without Python in its process cannot load it (``undefined symbol:
_Py_NoneStruct``).  Where a C compiler and FMPy's FMI 2.0 headers are available, the
build compiles ``fmus/shim/fmi2_python_shim.c`` and puts it in the wrapper's place::

    binaries/linux64/<ClassName>.so            the shim: finds and starts Python, forwards
    binaries/linux64/<ClassName>_pythonfmu.so  pythonfmu's wrapper
    resources/xpanel_python.cfg                the building Python: executable, libpython,
                                               folders of numpy and scipy (:func:`python_config`)
    resources/requirements.txt                 what that Python needs (``pythonfmu deploy``)
    resources/default_experiment.json          the scenario's DefaultExperiment, if given

Without a compiler the FMU is built as pythonfmu builds it, with a warning (a Python
host such as FMPy still loads it).
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import platform
import shutil
import subprocess
import sys
import sysconfig
import tempfile
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Dict, Mapping, Optional, Sequence, Tuple

FMUS_DIR = Path(__file__).resolve().parent
SRC_DIR = FMUS_DIR.parent / "src"
SHIM_SOURCE = FMUS_DIR / "shim" / "fmi2_python_shim.c"
PYTHON_CONFIG_FILE = "xpanel_python.cfg"   # read by the shim (same name in SHIM_SOURCE)
WRAPPER_SUFFIX = "_pythonfmu.so"           # pythonfmu's wrapper next to the shim (same in SHIM_SOURCE)
REQUIREMENTS_FILE = "requirements.txt"     # found by ``pythonfmu deploy``
REQUIRED_MODULES = ("numpy", "scipy")      # imported by the bundled model code


@dataclass(frozen=True)
class FmuKind:
    """What goes into one FMU.

    Attributes
    ----------
    module : str
        Slave module in ``fmus/`` (without ``.py``).
    class_name : str
        The slave class; also the FMU's modelName / modelIdentifier.
    packages : tuple of str
        Model packages from ``src/`` to bundle.
    resources : callable, optional
        ``resources() -> {file name: bytes}``: data files for ``resources/`` when the
        kind is built by :func:`build_fmu` (the track FMU's default parameters).
    """

    module: str
    class_name: str
    packages: Tuple[str, ...]
    resources: Optional[Callable[[], Dict[str, bytes]]] = None


# The entry script.  pythonfmu 0.7's C wrapper (findClass in PySlaveInstance.cpp), at
# every fmi2Instantiate, imports this module, re-executes its source in the module's
# namespace to find the slave class, and then Py_DECREFs the module's __dict__, a
# borrowed reference (PyModule_GetDict).  Without compensation the second instance in a
# process finds an emptied module ("module has no attribute ...") or crashes.  Each
# execution of the first statement below keeps one more reference, which balances it.
#
# A module missing in the host's Python (scipy, say) is reported by its own name and
# with the way to install it, not as the bundled module that failed to import.
ENTRY_SCRIPT = '''"""pythonfmu entry script of the {kind} FMU (generated by fmus.build)."""
globals().setdefault("_namespace_refs", []).append(globals())  # see fmus.build.ENTRY_SCRIPT
try:
    from {package}.{module} import {class_name}
except ModuleNotFoundError as _exc:
    if not _exc.name or _exc.name.split(".")[0] == "{package}":
        raise
    raise ModuleNotFoundError(
        f"the {kind} FMU needs {{_exc.name.split('.')[0]}}: {{_exc}}; install the FMU's "
        f"resources/{requirements} into the Python that runs it (pythonfmu deploy -f {kind}.fmu)",
        name=_exc.name) from None
'''

TRACK_DEFAULT_WHEELS = 4  # build_fmu("track"): default track, wheels of the default vehicle (bogie);
                          # no sensors (resolving a layout needs orchestrator.inputs.sensor_layout: build_job)


def _default_track_resources() -> Dict[str, bytes]:
    from track.params import TrackParams

    from .track_fmu import RESOURCE_FILE, resource_payload
    return {RESOURCE_FILE: resource_payload(TrackParams(), TRACK_DEFAULT_WHEELS)}


FMU_KINDS: Dict[str, FmuKind] = {
    "bogie": FmuKind("vehicle_fmus", "Bogie", ("vehicle",)),
    "quarter": FmuKind("vehicle_fmus", "QuarterVehicle", ("vehicle",)),
    # build_track_fmu bakes a scenario's track; build_fmu("track") the default one
    "track": FmuKind("track_fmu", "Track", ("track",), _default_track_resources),
}


def register_fmu_kind(kind: str, module: str, class_name: str, packages: Tuple[str, ...],
                      resources: Optional[Callable[[], Dict[str, bytes]]] = None) -> None:
    """Make ``build_fmu(kind, ...)`` build another slave.

    ``resources() -> {file name: bytes}`` optionally gives data files for ``resources/``.
    """
    FMU_KINDS[kind] = FmuKind(module, class_name, tuple(packages), resources)


def _package_dir(package: str) -> Path:
    """Source directory of a model package: ``src/<package>`` of this checkout, else
    wherever it is importable from (an installed distribution)."""
    root = SRC_DIR / package
    if (root / "__init__.py").is_file():
        return root
    found = importlib.util.find_spec(package)
    if found is None or not found.submodule_search_locations:
        raise FileNotFoundError(f"model package {package!r} not found in {SRC_DIR} or on sys.path")
    return Path(list(found.submodule_search_locations)[0])


def _payload(spec: FmuKind) -> Dict[str, Path]:
    """Files to bundle: relative path inside the unique package -> source file."""
    files = {"base.py": FMUS_DIR / "base.py", "fast.py": FMUS_DIR / "fast.py",
             f"{spec.module}.py": FMUS_DIR / f"{spec.module}.py"}
    for package in spec.packages:
        root = _package_dir(package)
        for path in sorted(root.rglob("*.py")):
            if "__pycache__" not in path.parts:
                files[str(Path(package) / path.relative_to(root))] = path
    return files


def build_fmu(kind: str, out_dir: str | Path, stop_time: float | None = None, step_size: float | None = None,
              start_values: Mapping[str, float] | None = None) -> Path:
    """Build the FMU ``kind`` (a key of :data:`FMU_KINDS`) as ``out_dir/<kind>.fmu``.

    Parameters
    ----------
    kind : str
        ``"bogie"``, ``"quarter"``, ``"track"`` (the default track with 4 wheels; use
        :func:`build_track_fmu` for a scenario's track) or a kind added with
        :func:`register_fmu_kind`.
    out_dir : str or Path
        Destination directory (created if missing).
    stop_time, step_size : float, optional
        The ``DefaultExperiment`` [s] of the scenario the FMU is built for
        (``simulation.duration``, ``simulation.step``); None: the slave class's.
    start_values : mapping, optional
        Start values of the FMU's parameters by name, e.g. ``{"x0": 30.0, "speed": 27.8}``
        for a vehicle (the scenario's start position and speed), baked into the FMU
        (``resources/start_values.json``, see :mod:`fmus.base`).

    Returns
    -------
    Path
        The FMU file.
    """
    if kind not in FMU_KINDS:
        raise ValueError(f"unknown FMU kind {kind!r}; known: {', '.join(sorted(FMU_KINDS))}")
    spec = FMU_KINDS[kind]
    resources = dict(spec.resources() if spec.resources is not None else {})
    resources.update(_baked_run_files(stop_time, step_size, start_values))
    return _build(kind, Path(out_dir) / f"{kind}.fmu", resources)


def _baked_run_files(stop_time: float | None, step_size: float | None,
                     start_values: Mapping[str, float] | None) -> Dict[str, bytes]:
    """Resource files of the default experiment and the start values (fmus.base reads them)."""
    from .base import EXPERIMENT_FILE, START_VALUES_FILE

    files = {}
    if (stop_time is None) != (step_size is None):
        raise ValueError("give both stop_time and step_size (the scenario's duration and step) or neither")
    if stop_time is not None:
        if not (stop_time > 0.0 and step_size > 0.0 and step_size <= stop_time):
            raise ValueError(f"default experiment: need 0 < step_size <= stop_time, got step_size = "
                             f"{step_size!r} s, stop_time = {stop_time!r} s")
        files[EXPERIMENT_FILE] = json.dumps({"startTime": 0.0, "stopTime": float(stop_time),
                                             "stepSize": float(step_size)}).encode("utf-8")
    if start_values:
        files[START_VALUES_FILE] = json.dumps(dict(start_values)).encode("utf-8")
    return files


def build_track_fmu(track_params, n_wheels: int, out_dir: str | Path, name: str = "track",
                    sensors: Sequence[Any] = (), stop_time: float | None = None,
                    step_size: float | None = None, **defaults: Any) -> Path:
    """Build a track FMU with ``track_params`` baked in, as ``out_dir/<name>.fmu``.

    Parameters
    ----------
    track_params : track.params.TrackParams
        The scenario's track section (stored as JSON in ``resources/track_fmu.json``;
        the FMU parameters h1, h2, voids, impact angle, ... override it at run time).
    n_wheels : int
        Number of wheels (bogie 4, quarter vehicle 2).
    out_dir : str or Path
        Destination directory (created if missing).
    name : str
        File name of the FMU without ``.fmu``.
    sensors : sequence of track.sensors.Sensor
        Sensors resolved on a model of ``track_params`` (``orchestrator.inputs.sensor_layout.resolve``;
        ``orchestrator.cosim.build_job`` does it for a scenario), baked into the same resource
        file: one output per sensor (``fmus.track_fmu``).  Empty: no sensor outputs.
    stop_time, step_size : float, optional
        The scenario's ``simulation.duration`` and ``simulation.step`` [s], written as the
        FMU's ``DefaultExperiment``; None: 1 s and 20 us.
    **defaults
        Start values of the run parameters: ``speed`` [m/s], ``static_wheel_load``
        [N], ``extrapolate``, ``auto_offset`` (bool), ``record_every`` (int); see
        :data:`fmus.track_fmu.RUN_DEFAULTS`.

    Returns
    -------
    Path
        The FMU file.
    """
    from .track_fmu import RESOURCE_FILE, resource_payload

    payload = resource_payload(track_params, n_wheels, sensors, **defaults)
    resources = {RESOURCE_FILE: payload, **_baked_run_files(stop_time, step_size, None)}
    return _build("track", Path(out_dir) / f"{name}.fmu", resources)


def _build(kind: str, dest: Path, resources: Mapping[str, bytes]) -> Path:
    """Bundle the code of ``kind`` under its unique package name and build ``dest``."""
    from pythonfmu.builder import FmuBuilder  # optional dependency, only needed to build

    spec = FMU_KINDS[kind]
    files = _payload(spec)
    digest = hashlib.sha256(kind.encode())
    for rel, path in sorted(files.items()):
        digest.update(rel.encode() + b"\0" + path.read_bytes() + b"\0")
    package = f"xpanel_{kind}_{digest.hexdigest()[:12]}"
    dest.parent.mkdir(parents=True, exist_ok=True)

    with tempfile.TemporaryDirectory(prefix="xpanel_fmu_") as tmp:
        stage = Path(tmp) / package
        for rel, path in files.items():
            target = stage / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, target)
        (stage / "__init__.py").write_text(
            f'"""Code bundled into the {kind} FMU under a unique package name (fmus.build)."""\n')
        script = Path(tmp) / f"{package}_slave.py"
        script.write_text(ENTRY_SCRIPT.format(kind=kind, package=package, module=spec.module,
                                              class_name=spec.class_name, requirements=REQUIREMENTS_FILE))
        data_files = []
        resources = {**resources, REQUIREMENTS_FILE: requirements(),
                     PYTHON_CONFIG_FILE: python_config(f"the {kind} FMU")}
        for file_name, content in resources.items():
            target = Path(tmp) / file_name   # the builder's staging folder is the slave's resources
            target.write_bytes(content)
            data_files.append(target)
        path_before = list(sys.path)
        try:
            FmuBuilder.build_FMU(script, dest=dest, project_files=[stage, *data_files],
                                 canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        finally:
            # the builder imports the script from tmp and leaves it on sys.path and in
            # sys.modules; drop both so that loading the FMU imports its own copy
            sys.path[:] = path_before
            for name in [m for m in sys.modules if m == package or m.startswith(package + ".")
                         or m == script.stem]:
                del sys.modules[name]
        shim = compile_shim(Path(tmp) / "shim")
        if shim is not None:
            _install_shim(dest, spec.class_name, shim)
        _add_bytecode(dest, stage, Path(tmp) / "pyc")
    return dest


def _add_bytecode(fmu: Path, stage: Path, work: Path) -> None:
    """Append to ``fmu`` the hash-checked bytecode of the bundled package ``stage`` (a folder that
    is ``resources/<stage.name>`` in the FMU) and of pythonfmu's bundled modules, at the paths the
    import system looks for (``<folder>/__pycache__/<module>.<cache tag>.pyc``)."""
    import py_compile

    import pythonfmu

    if sys.implementation.cache_tag is None:   # an interpreter without bytecode caching
        return
    sources = [(path, Path("resources") / stage.name / path.relative_to(stage)) for path in sorted(stage.rglob("*.py"))]
    pfmu = Path(pythonfmu.__file__).parent
    sources += [(path, Path("resources") / "pythonfmu" / path.name) for path in sorted(pfmu.glob("*.py"))]
    with zipfile.ZipFile(fmu) as zf:
        present = set(zf.namelist())
    with zipfile.ZipFile(fmu, "a", zipfile.ZIP_DEFLATED) as zf:
        for source, arc in sources:
            if arc.as_posix() not in present:   # only a module the FMU holds as source
                continue
            arc_pyc = arc.parent / "__pycache__" / f"{arc.stem}.{sys.implementation.cache_tag}.pyc"
            target = work / arc_pyc
            py_compile.compile(str(source), cfile=str(target), dfile=arc.as_posix(), doraise=True,
                               invalidation_mode=py_compile.PycInvalidationMode.CHECKED_HASH)
            zf.write(target, arc_pyc.as_posix())


# ------------------------------------------------------------------ self-contained loading
def requirements() -> bytes:
    """``resources/requirements.txt``: the modules the bundled code imports, at least the
    versions the FMU was built and tested with (major.minor)."""
    from importlib.metadata import version

    lines = ["# Python packages the FMU needs in the Python that runs it (pythonfmu deploy -f X.fmu).",
             "# The model code itself (turnout-cosim's track/vehicle packages) and pythonfmu's",
             "# slave classes are bundled in resources/; only these third-party packages are not."]
    for module in REQUIRED_MODULES:
        major_minor = ".".join(version(module).split(".")[:2])
        lines.append(f"{module}>={major_minor}")
    return ("\n".join(lines) + "\n").encode("utf-8")


def _libpython() -> str:
    """Path of this Python's shared library, or its file name when no file is found
    (the shim then asks the dynamic loader's search path)."""
    cv = sysconfig.get_config_var
    name = cv("INSTSONAME") or cv("LDLIBRARY") or ""
    if not name or name.endswith(".a"):   # a statically linked executable: the distribution's .so
        name = f"libpython{cv('LDVERSION') or cv('py_version_short')}.so.1.0"
    dirs = [cv("LIBDIR"), Path(sys.base_prefix) / "lib"]
    if cv("MULTIARCH"):
        dirs += [Path(str(cv("LIBDIR"))) / cv("MULTIARCH"), Path("/usr/lib") / cv("MULTIARCH")]
    for d in dirs:
        if d and (Path(d) / name).is_file():
            return str(Path(d) / name)
    return name


def python_config(fmu: str) -> bytes:
    """``resources/xpanel_python.cfg``: the Python that builds the FMU, for the shim.

    Lines ``key=value``: ``fmu`` (the FMU's name in messages), ``executable``
    (``sys.executable``, not resolved, so a virtual environment is found from it),
    ``libpython`` (:func:`_libpython`) and one ``path`` per folder holding a required module
    or site-packages (added to ``sys.path`` by the shim when Python's start did not).
    """
    import site

    paths = []
    for module in REQUIRED_MODULES:
        found = importlib.util.find_spec(module)
        if found is not None and found.origin:
            paths.append(str(Path(found.origin).resolve().parent.parent))
    paths += [p for p in site.getsitepackages() if Path(p).is_dir()]
    lines = [f"# written by fmus.build: the Python that built {fmu} (read by fmus/shim/fmi2_python_shim.c)",
             f"fmu={fmu}", f"executable={sys.executable}", f"libpython={_libpython()}"]
    lines += [f"path={p}" for p in dict.fromkeys(paths)]
    return ("\n".join(lines) + "\n").encode("utf-8")


def find_c_compiler() -> str | None:
    """Path of the system C compiler (``cc``, else ``gcc``), or None."""
    return shutil.which("cc") or shutil.which("gcc")


def fmi2_headers_dir() -> Path | None:
    """Folder with ``fmi2Functions.h`` & co. inside the installed FMPy package, or None."""
    found = importlib.util.find_spec("fmpy")
    if found is None or not found.origin:
        return None
    path = Path(found.origin).resolve().parent / "c-code"
    return path if (path / "fmi2Functions.h").is_file() else None


def shim_platform_ok() -> bool:
    """True where the shim is built: Linux x86-64, the platform of pythonfmu's wrapper binary."""
    return platform.system() == "Linux" and platform.machine() in ("x86_64", "AMD64") and sys.maxsize > 2**32


def compile_shim(out_dir: Path) -> Path | None:
    """Compile :data:`SHIM_SOURCE` into ``out_dir``; None (with a warning) where it cannot be.

    Returns
    -------
    Path or None
        The shared library.
    """
    if not shim_platform_ok():
        return None   # pythonfmu has no linux64 wrapper to wrap elsewhere; nothing to warn about
    cc, headers = find_c_compiler(), fmi2_headers_dir()
    reason = None
    if not SHIM_SOURCE.is_file():   # an installation without the package data fmus/shim/*.c
        reason = f"{SHIM_SOURCE} not found"
    elif cc is None:
        reason = "no C compiler (cc or gcc) on PATH"
    elif headers is None:
        reason = "FMPy's FMI 2.0 headers (fmpy/c-code) not found"
    else:
        out_dir.mkdir(parents=True, exist_ok=True)
        lib = out_dir / "shim.so"
        cmd = [cc, "-std=c99", "-O2", "-fPIC", "-shared", f"-I{headers}", "-o", str(lib), str(SHIM_SOURCE),
               "-ldl", "-pthread"]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode == 0:
            return lib
        reason = f"compiling {SHIM_SOURCE.name} failed: {done.stderr.strip()[-500:]}"
    warnings.warn(f"{reason}: the FMU is built with pythonfmu's wrapper alone, which loads only in a "
                  "host that already runs Python (FMPy, libcosimpy); a C/C++ host needs "
                  "LD_PRELOAD=<libpython>", RuntimeWarning, stacklevel=3)
    return None


def _install_shim(fmu: Path, model_identifier: str, shim: Path) -> None:
    """Rewrite ``fmu``: the shim as ``binaries/linux64/<id>.so``, pythonfmu's wrapper renamed
    next to it as ``<id>_pythonfmu.so``."""
    binary = f"binaries/linux64/{model_identifier}.so"
    wrapper = f"binaries/linux64/{model_identifier}{WRAPPER_SUFFIX}"
    tmp = fmu.with_name(fmu.name + ".tmp")
    with zipfile.ZipFile(fmu) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
        for info in src.infolist():
            data = src.read(info.filename)
            if info.filename == binary:
                out.writestr(wrapper, data)
                out.write(shim, binary)
            else:
                out.writestr(info, data)
    tmp.replace(fmu)
