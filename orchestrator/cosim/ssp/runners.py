"""Running an SSP file in other FMI hosts: :func:`run_ssp_libcosim` (libcosim) and
:func:`run_ssp_fmpy` (FMPy with a master of libcosim's semantics); both return time series.

libcosim (Open Simulation Platform) through ``libcosimpy``
----------------------------------------------------------
* Installation: ``pip install libcosimpy`` installs a binary wheel from PyPI
  (libcosimpy 0.0.6, ``manylinux_2_28_x86_64`` for CPython 3.11 here; the wheel bundles
  ``libcosimc.so`` with libcosim statically linked, depends only on libstdc++/libc).
* Loading: ``CosimExecution.from_ssp_file(path, step_ns)`` accepts the ``.ssp`` zip
  (it unpacks it to a temporary folder) or a folder holding ``SystemStructure.ssd``.
  Times and step sizes are integer nanoseconds: a step must be a whole number of ns.
* Master algorithm: libcosim's ``fixed_step_algorithm`` - fixed-step **Jacobi**: all
  FMUs step from t to t + h in parallel (a thread pool), then all connected outputs are
  copied to the inputs (through the linear-transformation functions, in the same
  transfer, so a sign flip adds no delay). Initialisation: start values in the
  instantiated state, ``fmi2SetupExperiment`` + ``fmi2EnterInitializationMode``, then
  (number of FMUs + functions) rounds of get-outputs/transfer/set-inputs in
  initialization mode, ``fmi2ExitInitializationMode`` and one more transfer.
  Parameter values it cannot apply (unknown name, wrong causality) are skipped with a
  log warning only; :func:`orchestrator.cosim.ssp.writer.write_ssp` therefore checks every name against the FMU.
* pythonfmu FMUs load in-process. Their C wrapper (``binaries/linux64/<Model>.so``)
  does not link ``libpython`` (no ``DT_NEEDED``): its ``Py_*`` symbols must already be
  in the process's global scope. In a Python host they are, whether the interpreter
  was built with ``--enable-shared`` (``libpython3.x.so`` is a dependency of the
  executable: checked with pyenv's 3.11.7) or statically (the executable exports the
  C API with ``-Xlinker -export-dynamic``: checked with Debian's ``/usr/bin/python3.11``
  running this module's libcosim runner). libcosim calls the FMUs from its worker
  threads; the wrapper takes the GIL with ``PyGILState_Ensure`` and ctypes releases it
  around every libcosimc call, so there is no deadlock. The FMUs' Python code runs in
  the host's interpreter (its numpy/scipy, its ``sys.modules``).
  A C host (e.g. the ``cosim`` command-line tool) has no Python: ``dlopen`` of the
  wrapper fails with ``undefined symbol: _Py_NoneStruct``. Workaround: preload a shared
  libpython of the same version, ``LD_PRELOAD=/path/to/libpython3.11.so cosim run
  system.ssp`` (Debian/Ubuntu ship one in the ``libpython3.11`` package even for their
  statically linked ``python3``; pyenv/conda builds have ``lib/libpython3.11.so``); the
  wrapper then starts an interpreter itself (``Py_Initialize``), which must find numpy
  and scipy (``PYTHONPATH=<venv>/lib/python3.11/site-packages``). Checked with a
  minimal C host: instantiate, initialise, step and free work, but the process aborted
  at exit (``free(): corrupted unsorted chunks``, after ``fmi2FreeInstance``), i.e. in
  pythonfmu's interpreter teardown. A host process that embeds Python with its
  libpython loaded ``RTLD_LOCAL`` can do the same in-process with
  ``ctypes.CDLL(path_to_libpython, mode=ctypes.RTLD_GLOBAL)`` before loading the FMU.
  A Python built without any shared libpython cannot serve a C host: install or build
  one that has it.
* Results: :func:`run_ssp_libcosim` steps the execution one communication step at a
  time and reads the requested variables with a last-value observer (libcosimpy's
  time-series observer trims samples whose step number is 0, so it is not used).

FMPy (``fmpy.ssp``)
-------------------
``fmpy.ssp.ssd.read_ssd`` reads and schema-validates the file (SSP 1.0 schemas bundled
with FMPy). ``fmpy.ssp.simulation.simulate_ssp`` (FMPy 0.3.32, read from its source):

* parameter bindings: read but not applied; only its ``parameter_set`` argument is (names
  ``component.variable``, Booleans set as ``value != 0.0``, so ``"false"`` becomes true).
  Harmless for our FMUs: :func:`orchestrator.cosim.ssp.system.export_ssp` builds them
  with the scenario's values as their start values, the bindings repeat them;
* ``ssc:LinearTransformation``: never applied (its reader looks for
  ``ssd:LinearTransformation``, and the loop copies values unchanged); our own vehicles
  need none, a third-party vehicle with sign flips does;
* the communication step: its ``step_size`` argument (default ``stop_time / 100``), the
  annotations are not read; time advances as ``time += h`` while ``time < stop_time``;
* initialization: every connector is set to ``0.0``, the FMUs are initialized without
  any exchange, and the connections are applied only after all FMUs have stepped. Over
  the first step every connected input is therefore ``0.0``, whatever the start values
  or the outputs at t = 0: the vehicle gets no contact force, the track gets every wheel
  at x = 0, z = 0. The track puts itself in static equilibrium under the wheels at its
  first step, at the wheels' input positions, so this is not a start-up transient but a
  wrong state: on the turnout (first sleeper at x = 34.5 m) the track discards the step
  (``wheel1_x = 0.0000 m is outside the modelled panel``), on a plain track starting at
  x = 0 the four static loads land on the first sleeper and the next step diverges
  (contact force 1.1e7 N on wheel 4 at t = 2 h). No content of the SSP file changes
  that: ``simulate_ssp`` cannot run this system.

:func:`run_ssp_fmpy` therefore uses ``read_ssd`` for parsing only and runs its own
fixed-step Jacobi master with libcosim's semantics (above) on ``fmpy.fmi2.FMU2Slave``
instances.
"""
from __future__ import annotations

import tempfile
import zipfile
from pathlib import Path
from typing import Any, Dict

import numpy as np

from orchestrator.cosim.ssp.reader import read_ssp
from orchestrator.cosim.ssp.ssd import NS_PER_S, step_ns
from track.timegrid import step_count


def _n_steps(step: float, duration: float) -> int:
    """Steps a host takes to reach ``duration`` [s] (at least one; :func:`track.timegrid.step_count`)."""
    if not (step > 0 and duration > 0):
        raise ValueError(f"step and duration must be positive, got {step}, {duration}")
    return step_count(duration, step, cover=True)


def _host_pythonfmu() -> None:
    """Import this interpreter's pythonfmu (if installed) before an FMU is loaded in-process.

    A pythonfmu FMU bundles a copy of pythonfmu in its ``resources/`` and puts that folder
    first on ``sys.path``; if nothing imported pythonfmu before, the FMU's copy becomes
    ``sys.modules["pythonfmu"]``, and an FMU built later in the same process (its builder
    takes the FMI binaries from next to that copy, in a folder the host has deleted by then)
    comes out without ``binaries/``.
    """
    try:
        import pythonfmu.builder  # noqa: F401
    except ImportError:
        pass


def _split(name: str) -> tuple[str, str]:
    """``"component.variable"`` -> (component, variable)."""
    comp, _, var = name.partition(".")
    if not var:
        raise ValueError(f"record: {name!r} is not of the form component.variable")
    return comp, var


def _series(record: list[str], kept: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Empty output arrays: the ``kept`` output times and one array per recorded name."""
    return np.empty(kept), {name: np.empty(kept) for name in record}


# --------------------------------------------------------------------------------------
# libcosim
# --------------------------------------------------------------------------------------
def run_ssp_libcosim(ssp_file: Path, step: float, duration: float, record: list[str],
                     output_every: int = 1, log_level: str = "warning") -> dict[str, np.ndarray]:
    """Run an SSP file with libcosim (libcosimpy) and return time series.

    Parameters
    ----------
    ssp_file : Path
        The ``.ssp`` file (or a folder with ``SystemStructure.ssd``).
    step : float
        Communication step [s] (overrides the file's; a whole number of ns).
    duration : float
        Simulated time [s]; ``ceil(duration / step)`` steps are taken.
    record : list of str
        ``"component.variable"`` names (Real variables), e.g. ``"track.wheel1_Fz"``.
        An input reads the value the FMU used over the step that just ended (libcosim
        hands the newly transferred values over at the next step).
    output_every : int
        Keep every n-th communication point.
    log_level : str
        libcosim's console log level (``trace`` ... ``fatal``; its default is ``debug``,
        very verbose). The level is process-wide: it stays set after the call.

    Returns
    -------
    dict
        ``"time"`` (the communication points after each kept step, from libcosim's
        clock) and one array per recorded name.

    Raises
    ------
    ImportError
        libcosimpy is not installed.
    RuntimeError
        libcosim failed to load the file or to step (with libcosim's last error message).
    """
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level

    log_output_level(CosimLogLevel[log_level.upper()])
    ns = step_ns(step)
    n = _n_steps(step, duration)
    execution, observer = _libcosim_execution(ssp_file, ns)
    by_slave = _libcosim_references(execution, ssp_file, record)
    times, out = _libcosim_steps(execution, observer, by_slave, record, step, n, output_every)
    execution.stop()
    return {"time": times, **out}


def _libcosim_execution(ssp_file: Path, ns: int):
    """libcosim's execution of the file with a step of ``ns`` nanoseconds and a last-value observer on it."""
    from libcosimpy._internal import get_last_error_message
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimObserver import CosimObserver

    _host_pythonfmu()
    try:
        execution = CosimExecution.from_ssp_file(str(Path(ssp_file).resolve()), ns)
    except AssertionError:
        raise RuntimeError(f"libcosim cannot load {ssp_file}: {get_last_error_message()}") from None
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)
    return execution, observer


def _libcosim_references(execution, ssp_file: Path, record: list[str]) -> Dict[int, list]:
    """The recorded names by slave: ``{slave index: [(name, value reference), ...]}``."""
    index = {info.name.decode(): info.index for info in execution.slave_infos()}
    refs: Dict[str, tuple[int, int]] = {}
    for name in record:
        comp, var = _split(name)
        if comp not in index:
            raise ValueError(f"record: no component {comp!r} in {ssp_file}; have {sorted(index)}")
        variables = {v.name.decode(): v for v in execution.slave_variables(index[comp])}
        if var not in variables:
            raise ValueError(f"record: component {comp!r} has no variable {var!r}")
        refs[name] = (index[comp], variables[var].reference)
    by_slave: Dict[int, list] = {}
    for name, (s, r) in refs.items():
        by_slave.setdefault(s, []).append((name, r))
    return by_slave


def _libcosim_steps(execution, observer, by_slave: Dict[int, list], record: list[str], step: float, n: int,
                    output_every: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Step the execution ``n`` times, one communication step at a time; returns the kept
    times [s] (libcosim's clock) and values."""
    from libcosimpy._internal import get_last_error_message

    times, out = _series(record, n // output_every)
    k_out = 0
    for k in range(1, n + 1):
        if not execution.step(1):
            raise RuntimeError(f"libcosim: step {k} (t = {(k - 1) * step:.9g} s) failed: "
                               f"{get_last_error_message()}")
        if k % output_every:
            continue
        times[k_out] = execution.status().current_time / NS_PER_S
        for s, items in by_slave.items():
            values = observer.last_real_values(s, [r for _, r in items])
            for (name, _), value in zip(items, values):
                out[name][k_out] = value
        k_out += 1
    return times, out


# --------------------------------------------------------------------------------------
# FMPy
# --------------------------------------------------------------------------------------
class _FmpyMaster:
    """Fixed-step Jacobi master over FMPy FMU2Slave instances with libcosim's semantics."""

    def __init__(self, ssp_file: Path, unzip_dir: Path):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.ssp.ssd import read_ssd

        read_ssd(str(ssp_file), validate=True)  # FMPy's reader + SSP 1.0 schema check
        _host_pythonfmu()
        self.system = read_ssp(ssp_file)
        with zipfile.ZipFile(ssp_file) as zf:
            zf.extractall(unzip_dir)
        self.fmus, self.vars = {}, {}
        for name, source in self.system.sources.items():
            fmu_path = unzip_dir / source
            md = read_model_description(str(fmu_path), validate=False)
            self.vars[name] = {v.name: v for v in md.modelVariables}
            fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu_path), str(unzip_dir / (name + "_fmu"))),
                            modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
            self.fmus[name] = fmu
        self.pending: Dict[tuple, float] = {}

    def set(self, comp: str, name: str, value: Any) -> None:
        var, fmu = self.vars[comp][name], self.fmus[comp]
        if var.type == "Real":
            fmu.setReal([var.valueReference], [float(value)])
        elif var.type in ("Integer", "Enumeration"):
            fmu.setInteger([var.valueReference], [int(value)])
        elif var.type == "Boolean":
            fmu.setBoolean([var.valueReference], [bool(value)])
        else:
            fmu.setString([var.valueReference], [str(value)])

    def get_real(self, comp: str, name: str) -> float:
        return self.fmus[comp].getReal([self.vars[comp][name].valueReference])[0]

    def transfer(self) -> None:
        for c in self.system.connections:
            self.pending[(c.end_element, c.end_connector)] = \
                c.factor * self.get_real(c.start_element, c.start_connector)

    def push_inputs(self) -> None:
        for (comp, name), value in self.pending.items():
            self.set(comp, name, value)

    def initialize(self, start: float) -> None:
        for comp, fmu in self.fmus.items():
            fmu.instantiate()
            for name, value in self.system.parameters[comp].items():
                self.set(comp, name, value)
            fmu.setupExperiment(startTime=start)
            fmu.enterInitializationMode()
        for _ in range(len(self.fmus)):  # as libcosim: n rounds of set/get/transfer
            self.push_inputs()
            self.transfer()
        for fmu in self.fmus.values():
            fmu.exitInitializationMode()
        self.transfer()

    def step(self, t: float, h: float) -> None:
        self.push_inputs()
        for comp, fmu in self.fmus.items():
            try:  # FMPy raises FMICallException for a status worse than fmi2Warning
                fmu.doStep(currentCommunicationPoint=t, communicationStepSize=h)
            except Exception as exc:
                raise RuntimeError(f"{comp}: doStep at t = {t:.9g} s failed: {exc}") from None
        self.transfer()

    def free(self) -> None:
        for fmu in self.fmus.values():
            try:
                fmu.terminate()
            finally:
                fmu.freeInstance()


def run_ssp_fmpy(ssp_file: Path, step: float, duration: float, record: list[str],
                 output_every: int = 1) -> dict[str, np.ndarray]:
    """Run an SSP file written by :func:`orchestrator.cosim.ssp.writer.write_ssp` with FMPy and a
    fixed-step Jacobi master that follows libcosim's semantics (see the module docstring: FMPy's own
    ``simulate_ssp`` cannot run it). Same arguments and result as :func:`run_ssp_libcosim`;
    times are ``k * step`` (libcosim's are whole nanoseconds)."""
    n = _n_steps(step, duration)
    record = list(record)
    for name in record:
        _split(name)
    with tempfile.TemporaryDirectory(prefix="xpanel_ssp_fmpy_") as tmp:
        master = _FmpyMaster(Path(ssp_file), Path(tmp))
        for name in record:
            comp, var = _split(name)
            if comp not in master.vars or var not in master.vars[comp]:
                raise ValueError(f"record: no variable {name!r} in {ssp_file}")
        start = master.system.start_time or 0.0
        times, out = _series(record, n // output_every)
        try:
            master.initialize(start)
            k_out = 0
            for k in range(n):
                master.step(start + k * step, step)
                if (k + 1) % output_every:
                    continue
                times[k_out] = start + (k + 1) * step
                for name in record:
                    out[name][k_out] = master.get_real(*_split(name))
                k_out += 1
        finally:
            master.free()
    return {"time": times, **out}


__all__ = ["run_ssp_libcosim", "run_ssp_fmpy"]
