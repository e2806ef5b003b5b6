"""The two units of a co-simulation, one interface for both backends.

- vehicle: input contact forces ``Fz`` (up +) -> outputs wheel ``x``, ``z`` (up +), ``vz``;
- track: inputs wheel ``x``, ``z``, ``vz`` -> outputs contact forces ``Fz``.

The coupling values (the vehicle's ``outputs()``, the track's ``forces()``) are arrays a
later ``step`` of the unit does not change (the Jacobi master reads the vehicle's outputs at
``t_k``, steps the vehicle, then hands those ``t_k`` values to the track). A unit reads its
outputs once per communication point and hands the same arrays to every caller until its next
step: read them, do not modify them. The track's ``outputs()`` are for recording at once.

``InProcessVehicle`` / ``InProcessTrack`` step the model objects directly
(``vehicle.VehicleStepper``, ``track.cosim.TrackCosim``); ``FmuVehicle`` / ``FmuTrack``
run FMUs (ours, or a third-party vehicle mapped through the scenario's ``ports``) through
FMPy's low-level API.
"""
from __future__ import annotations

import ctypes
import os
import shutil
import time
from pathlib import Path

import numpy as np

from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.specs import PortMap


class CosimError(UserInputError):
    """The co-simulation stopped (a unit failed or the coupled solution diverged)."""


_UNZIPPED: dict[tuple, str] = {}   # (FMU file, size, mtime) -> the folder it is unzipped to, this process


def _unzipped(path: Path) -> str:
    """The folder ``path`` is unzipped to: once per process and FMU file (path, size, mtime), removed
    when the process ends.

    FMPy's ``extract`` makes a new temporary folder at each call and nothing removed them: every
    run via FMUs left ~2 MB behind in the temp folder (two FMUs with their bundled Python
    packages), every run of a sweep's worker too. A folder is not removed when its FMU is freed:
    the FMU's Python package was imported from it (pythonfmu), stays in ``sys.modules`` for the
    next instance of the same FMU, and may import a module of it later; so the next run reuses
    the folder. Removed by a ``multiprocessing`` finalizer, which runs at the exit of the main
    process (atexit) and of pool workers (which skip atexit); a killed process's by the next
    process's first scratch folder (:mod:`orchestrator.cosim.scratch`).
    """
    from fmpy import extract
    from multiprocessing.util import Finalize

    from orchestrator.cosim.scratch import make_scratch

    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    folder = _UNZIPPED.get(key)
    if folder is None or not os.path.isdir(folder):
        folder = str(extract(str(path), unzipdir=make_scratch("fmu")))   # named: a killed process's is found
        Finalize(None, shutil.rmtree, args=(folder,), kwargs={"ignore_errors": True}, exitpriority=0)
        _UNZIPPED[key] = folder
    return folder


class InProcessVehicle:
    """Our bogie / quarter vehicle stepped directly (no FMU boundary).

    ``start_values`` set fields of the parameter dataclass (as the FMU's parameters
    of the same names do).
    """

    def __init__(self, kind: str, speed: float, axle_load: float, x0: float, start_values: dict | None = None,
                 hold: str = "zoh"):
        import dataclasses

        from vehicle.bogie import BogieParams, bogie
        from vehicle.quarter import QuarterParams, quarter_vehicle
        from vehicle.stepper import VehicleStepper

        cls, build = (BogieParams, bogie) if kind == "bogie" else (QuarterParams, quarter_vehicle)
        names = {f.name for f in dataclasses.fields(cls)}
        extra = dict(start_values or {})
        unknown = sorted(set(extra) - names)
        if unknown:
            raise UserInputError(f"vehicle.start_values: {unknown[0]!r} is not a parameter of the {kind} "
                                 f"(have: {', '.join(sorted(names))})")
        self.model = build(cls(**{"axle_load": axle_load, **extra}))
        self.n = self.model.n_wheels
        self.speed, self.x0 = speed, x0
        st = self.model.static_state(np.zeros(self.n))
        self._stepper_cls, self._q0, self.Fz0 = VehicleStepper, st.q, st.Fz
        self.hold = hold
        self.stepper = None
        self.t = 0.0
        self._last = None     # the outputs since the last step (they change only with a step)

    def initialize(self, h: float) -> None:
        self.stepper = self._stepper_cls(self.model, h, hold=self.hold, q0=self._q0, Fz0=self.Fz0)
        self._last = None

    def get_state(self):
        return self.stepper.get_state(), self.t

    def set_state(self, s) -> None:
        self.stepper.set_state(s[0])
        self.t = s[1]
        self._last = None

    def step(self, t: float, h: float, Fz: np.ndarray) -> None:
        self._last = None
        self.stepper.step(Fz)
        self.t = t + h

    def advanced(self, steps: int, t: float) -> None:
        """The stepper's buffers were advanced ``steps`` steps to time ``t`` [s] by a compiled loop
        (``stepper.discrete_system``, :mod:`orchestrator.cosim.compiled_loop`): count them."""
        self.stepper.steps += steps
        self.t = t
        self._last = None

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wheel ``x`` [m], ``z`` [m] (up +), ``vz`` [m/s] at the unit's time: copies the caller owns.

        The stepper updates ``wheel_z`` / ``wheel_vz`` in place at every step, so views would
        turn the start-of-step values a Jacobi master holds while the vehicle steps into
        end-of-step ones (the track then extrapolated them a second time: peak forces 1 %
        off the FMU backend's on the default scenario). FMU outputs are copies by nature.
        Computed once per communication point.
        """
        if self._last is None:
            self._last = (self.model.wheel_x(self.t, self.x0, self.speed), self.stepper.wheel_z.copy(),
                          self.stepper.wheel_vz.copy())
        return self._last

    def terminate(self) -> None:
        pass


class InProcessTrack:
    """:class:`track.cosim.TrackCosim` stepped directly."""

    def __init__(self, scenario, n_wheels: int, h: float, extrapolate: bool, record_every: int,
                 extrapolate_force: bool, record_columns: dict | None = None, record_rows: int = 0):
        from orchestrator.inputs.track_model import track_model
        from track.cosim import TrackCosim

        t_start = time.perf_counter()
        self.model = track_model(scenario.track)
        self.wall_build = time.perf_counter() - t_start  # [s] (short when the bodies are cached)
        self.engine = TrackCosim(scenario.track, n_wheels, 0.5 * scenario.vehicle.axle_load, h,
                                 speed=scenario.vehicle.speed, extrapolate=extrapolate,
                                 record_every=record_every, model=self.model,
                                 extrapolate_force=extrapolate_force, record_columns=record_columns)
        self.engine.record.reserve(record_rows)

    def step(self, t: float, h: float, x, z, vz) -> None:
        self.engine.do_step(x, z, vz)

    def forces(self) -> np.ndarray:
        """The vehicle's input: the contact forces, extrapolated when asked [N] (a copy)."""
        return self.engine.Fz_coupling.copy()

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = self.engine
        return e.Fz, e.parts, e.rail_w

    def record(self) -> dict:
        """The recorded states (``track.cosim.Record.arrays``: views of the preallocated record)."""
        return self.engine.record.arrays()

    def work(self) -> dict:
        """The track's own work: counters of :class:`track.dynamics.Counters` and wall times [s]."""
        e, c = self.engine, self.engine.counters
        return {"track_steps": c.steps, "linear_solves": c.solves, "contact_iterations": c.contact_newton,
                "passes": c.iterations, "factorizations": c.factorizations, "wall_build": self.wall_build,
                "wall_statics": e.wall_statics, "wall_factor": e.wall_factor}

    def get_state(self):
        return self.engine.get_state()

    def set_state(self, s) -> None:
        self.engine.set_state(s)

    def terminate(self) -> None:
        pass


class FmuUnit:
    """An FMI 2.0 co-simulation FMU driven through FMPy's raw C functions.

    The per-step path uses preallocated ctypes arrays (no allocation, no logging
    wrapper); a status above fmi2Warning raises :class:`CosimError` naming the FMU,
    the call and the time.
    """

    def __init__(self, path: Path, name: str, start_values: dict | None = None):
        from fmpy import read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.path, self.name = Path(path), name
        self.md = read_model_description(str(path))
        if self.md.coSimulation is None:
            raise UserInputError(f"{path}: not a co-simulation FMU")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self._dir = _unzipped(self.path)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self._dir,
                             modelIdentifier=self.md.coSimulation.modelIdentifier, instanceName=name)
        self.fmu.instantiate(loggingOn=False)
        self._fn = self.fmu._functions
        self._c = self.fmu.component
        for key, value in (start_values or {}).items():
            self.set_start(key, value)

    def vr(self, name: str) -> int:
        v = self.vars.get(name)
        if v is None:
            import difflib
            hint = difflib.get_close_matches(name, list(self.vars), n=1)
            raise UserInputError(f"{self.path.name}: no variable {name!r}"
                                 + (f" (did you mean {hint[0]!r}?)" if hint else ""))
        return v.valueReference

    def set_start(self, name: str, value) -> None:
        v = self.vars.get(name)
        if v is None:
            self.vr(name)  # raises with a hint
        vr = [v.valueReference]
        if v.type == "Real":
            self.fmu.setReal(vr, [float(value)])
        elif v.type in ("Integer", "Enumeration"):
            self.fmu.setInteger(vr, [int(value)])
        elif v.type == "Boolean":
            self.fmu.setBoolean(vr, [bool(value)])
        else:
            self.fmu.setString(vr, [str(value)])

    def initialize(self, t0: float, stop_time: float | None = None) -> None:
        """setupExperiment (start ``t0`` [s], the stop time [s] when given), then initialization mode."""
        self.fmu.setupExperiment(startTime=t0, stopTime=stop_time)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def real_port(self, names: list[str]) -> "RealPort":
        return RealPort(self, [self.vr(n) for n in names])

    def do_step(self, t: float, h: float) -> None:
        status = self._fn["fmi2DoStep"](self._c, ctypes.c_double(t), ctypes.c_double(h), 1)
        if status > 1:
            raise self.step_error(t, h, status)

    def step_error(self, t: float, h: float, status: int) -> CosimError:
        """The error of an ``fmi2DoStep`` at ``t`` [s] with step ``h`` [s] that returned ``status``."""
        return CosimError(f"{self.name} FMU ({self.path.name}): fmi2DoStep at t = {t:.6g} s with step "
                          f"{h:.3g} s returned status {status} (discard/error); see its log, or reduce "
                          "simulation.step")

    def function(self, name: str, prototype) -> "ctypes._CFuncPtr":
        """The FMU's C function ``name`` as ``prototype`` (a ``ctypes.CFUNCTYPE``), for compiled callers."""
        return prototype(ctypes.cast(self._fn[name], ctypes.c_void_p).value)

    def terminate(self) -> None:
        try:
            self.fmu.terminate()
        finally:
            self.fmu.freeInstance()


class RealPort:
    """Preallocated get/set of a fixed list of Real variables of one FMU."""

    def __init__(self, unit: FmuUnit, vrs: list[int]):
        n = len(vrs)
        self.unit = unit
        self._vr = (ctypes.c_uint * n)(*vrs)
        self._buf = (ctypes.c_double * n)()
        self._n = n
        self.values = np.frombuffer(self._buf, dtype=np.float64)

    def get(self) -> np.ndarray:
        status = self.unit._fn["fmi2GetReal"](self.unit._c, self._vr, self._n, self._buf)
        if status > 1:
            raise self.get_error(status)
        return self.values

    def set(self, values: np.ndarray) -> None:
        self.values[:] = values
        status = self.unit._fn["fmi2SetReal"](self.unit._c, self._vr, self._n, self._buf)
        if status > 1:
            raise self.set_error(status)

    @property
    def references(self) -> int:
        """Address of the value references (``fmi2ValueReference[n]``), for compiled callers."""
        return ctypes.addressof(self._vr)

    def get_error(self, status: int) -> CosimError:
        return CosimError(f"{self.unit.name} FMU: fmi2GetReal returned status {status}")

    def set_error(self, status: int) -> CosimError:
        """The error of an ``fmi2SetReal`` of :attr:`values` that returned ``status``."""
        return CosimError(f"{self.unit.name} FMU: fmi2SetReal returned status {status} "
                          f"(values {np.array2string(np.asarray(self.values), precision=4)})")


class FmuVehicle:
    """A vehicle FMU (ours or a third party's) seen in our convention."""

    def __init__(self, path: Path, ports: list[PortMap], params: dict, start_values: dict):
        from orchestrator.cosim.ports import check_vehicle_fmu

        check_vehicle_fmu(path, ports, {**params, **start_values})  # before the FMU is loaded (ports.py)
        self.unit = FmuUnit(path, "vehicle", {**params, **start_values})
        self.n = len(ports)
        # one port for the outputs (x, z, vz of every wheel: one fmi2GetReal per read)
        self._out = self.unit.real_port([p.x for p in ports] + [p.z for p in ports] + [p.vz for p in ports])
        self._F = self.unit.real_port([p.Fz for p in ports])
        self._zs = np.array([p.z_sign for p in ports], float)
        self._vzs = np.array([p.vz_sign for p in ports], float)
        self._Fs = np.array([p.Fz_sign for p in ports], float)
        self._last = None     # the outputs read since the last step (they change only with a step)

    def initialize(self, t0: float) -> None:
        self.unit.initialize(t0)
        self.Fz0 = self._Fs * self._F.get()
        self._last = None

    def step(self, t: float, h: float, Fz: np.ndarray) -> None:
        self._last = None
        self._F.set(self._Fs * Fz)
        self.unit.do_step(t, h)

    def outputs(self):
        """Wheel ``x``, ``z``, ``vz`` in our convention (read once per communication point)."""
        if self._last is None:
            o, n = self._out.get(), self.n
            self._last = o[:n].copy(), self._zs * o[n:2 * n], self._vzs * o[2 * n:]
        return self._last

    def terminate(self) -> None:
        self.unit.terminate()


class FmuTrack:
    """Our track FMU."""

    COUNTERS = ("track_steps", "linear_solves", "contact_iterations", "passes", "factorizations")
    WALLS = ("wall_statics", "wall_factor")   # [s]

    def __init__(self, path: Path, n_wheels: int, params: dict):
        self.unit = FmuUnit(path, "track", params)
        self._work: dict = {}
        w = range(1, n_wheels + 1)
        self._in = self.unit.real_port([f"wheel{i}_{s}" for s in ("x", "z", "vz") for i in w])
        # one port for what is read each step: the vehicle's input first, then the recorded outputs
        self._out = self.unit.real_port([f"wheel{i}_{s}" for s in ("Fz_coupling", "Fz", "Fz_rail", "Fz_nose",
                                                                    "rail_z") for i in w])
        self.n = n_wheels
        self._inbuf = np.empty(3 * n_wheels)
        self._last = None     # the outputs read since the last step

    def initialize(self, t0: float, stop_time: float | None = None) -> None:
        self.unit.initialize(t0, stop_time)
        self._last = None

    def step(self, t: float, h: float, x, z, vz) -> None:
        n = self.n
        b = self._inbuf
        b[:n], b[n:2 * n], b[2 * n:] = x, z, vz
        self._last = None
        self._in.set(b)
        self.unit.do_step(t, h)

    def _read(self) -> np.ndarray:
        if self._last is None:
            self._last = self._out.get().copy()
        return self._last

    def forces(self) -> np.ndarray:
        """The vehicle's input (``Fz_coupling``) [N]: one read per step, which also serves :meth:`outputs`."""
        return self._read()[:self.n].copy()

    def outputs(self):
        o, n = self._read(), self.n
        return o[n:2 * n], o[2 * n:4 * n].reshape(2, n).T, o[4 * n:]   # views of this step's copy

    def work(self) -> dict:
        """The track FMU's work counters and wall times [s] (its monitoring outputs), as read at
        terminate; empty before (or when the FMU could not be read)."""
        return dict(self._work)

    def _read_work(self) -> dict:
        """The FMU's outputs :attr:`COUNTERS` (Integer) and :attr:`WALLS` (Real, [s])."""
        fmu = self.unit.fmu
        counters = fmu.getInteger([self.unit.vr(k) for k in self.COUNTERS])
        walls = fmu.getReal([self.unit.vr(k) for k in self.WALLS])
        return {**{k: int(v) for k, v in zip(self.COUNTERS, counters)},
                **{k: float(v) for k, v in zip(self.WALLS, walls)}}

    def terminate(self) -> None:
        """Read the work counters, then terminate and free the FMU."""
        try:
            self._work = self._read_work()
        except Exception:  # noqa: BLE001 - a failed FMU may refuse reads; the counters are then missing
            self._work = {}
        self.unit.terminate()


__all__ = ["CosimError", "InProcessVehicle", "InProcessTrack", "FmuUnit", "RealPort", "FmuVehicle", "FmuTrack"]
