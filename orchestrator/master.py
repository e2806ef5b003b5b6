"""Co-simulation master: a vehicle unit and a track unit exchanging wheel motion and contact forces.

Units (the same interface for both backends):

- vehicle: input contact forces ``Fz`` (up +) -> outputs wheel ``x``, ``z`` (up +), ``vz``;
- track: inputs wheel ``x``, ``z``, ``vz`` -> outputs contact forces ``Fz`` (the Hertz
  contact lives on the track side, DESIGN.md §3 and §8).

Backends: ``fmu`` runs the FMUs (ours built with pythonfmu, or a third-party vehicle
FMU mapped through the scenario's ``ports``) through FMPy's low-level API;
``inprocess`` steps the same model objects (``vehicle.VehicleStepper``,
``track.cosim.TrackCosim``) without the FMU boundary.

Algorithms (registry :data:`ALGORITHMS`), fixed communication step ``h`` counted by
an integer (``t_k = t0 + k h``):

- ``gauss-seidel`` (vehicle first): the vehicle steps with the force held over the
  step; the track then receives the wheel motion at ``t_{k+1}`` and solves the contact
  at ``t_{k+1}`` implicitly with the track (DESIGN.md §8);
- ``jacobi``: both units step from the values at ``t_k``; with ``extrapolation`` the
  track extrapolates the wheel position over the step with ``vz`` (and ``x`` with the
  speed), without it it holds them.

With ``extrapolation`` (both algorithms) the vehicle's force input is the track's
``Fz_coupling``: the contact force extrapolated to the middle of the step, so the
held input integrates to second order (the track FMU computes it, so a host such as
libcosim running the exported SSP does exactly the same).
"""
from __future__ import annotations

import ctypes
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .errors import UserInputError
from .scenario import PortMap

POSITION_TOL = 1e-6  # m: the vehicle's wheel 1 must start where the scenario puts it
START_MARGIN_SLEEPERS = 2  # the rear wheelset starts this many sleepers inside the panel
END_MARGIN_SLEEPERS = 1    # the front wheelset must stay this many sleepers inside the panel


class CosimError(UserInputError):
    """The co-simulation stopped (a unit failed or the coupled solution diverged)."""


# ----------------------------------------------------------------------------- units
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

    def initialize(self, h: float) -> None:
        self.stepper = self._stepper_cls(self.model, h, hold=self.hold, q0=self._q0, Fz0=self.Fz0)

    def get_state(self):
        return self.stepper.get_state(), self.t

    def set_state(self, s) -> None:
        self.stepper.set_state(s[0])
        self.t = s[1]

    def step(self, t: float, h: float, Fz: np.ndarray) -> None:
        self.stepper.step(Fz)
        self.t = t + h

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.model.wheel_x(self.t, self.x0, self.speed), self.stepper.wheel_z, self.stepper.wheel_vz

    def terminate(self) -> None:
        pass


class InProcessTrack:
    """:class:`track.cosim.TrackCosim` stepped directly."""

    def __init__(self, scenario, n_wheels: int, h: float, extrapolate: bool, record_every: int,
                 extrapolate_force: bool):
        from track.cosim import TrackCosim
        from track.model import build_track

        self.model = build_track(scenario.track)
        self.engine = TrackCosim(scenario.track, n_wheels, 0.5 * scenario.vehicle.axle_load, h,
                                 speed=scenario.vehicle.speed, extrapolate=extrapolate,
                                 record_every=record_every, model=self.model,
                                 extrapolate_force=extrapolate_force)

    def step(self, t: float, h: float, x, z, vz) -> None:
        self.engine.do_step(x, z, vz)

    def forces(self) -> np.ndarray:
        """The vehicle's input: the contact forces, extrapolated when asked."""
        return self.engine.Fz_coupling

    def outputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = self.engine
        return e.Fz, e.parts, e.rail_w

    def record(self) -> dict:
        return self.engine.record.arrays()

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
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.path, self.name = Path(path), name
        self.md = read_model_description(str(path))
        if self.md.coSimulation is None:
            raise UserInputError(f"{path}: not a co-simulation FMU")
        self.vars = {v.name: v for v in self.md.modelVariables}
        self._dir = extract(str(path))
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

    def initialize(self, t0: float) -> None:
        self.fmu.setupExperiment(startTime=t0)
        self.fmu.enterInitializationMode()
        self.fmu.exitInitializationMode()

    def real_port(self, names: list[str]) -> "RealPort":
        return RealPort(self, [self.vr(n) for n in names])

    def do_step(self, t: float, h: float) -> None:
        status = self._fn["fmi2DoStep"](self._c, ctypes.c_double(t), ctypes.c_double(h), 1)
        if status > 1:
            raise CosimError(f"{self.name} FMU ({self.path.name}): fmi2DoStep at t = {t:.6g} s with step "
                             f"{h:.3g} s returned status {status} (discard/error); see its log, or reduce "
                             "simulation.step")

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
            raise CosimError(f"{self.unit.name} FMU: fmi2GetReal returned status {status}")
        return self.values

    def set(self, values: np.ndarray) -> None:
        self.values[:] = values
        status = self.unit._fn["fmi2SetReal"](self.unit._c, self._vr, self._n, self._buf)
        if status > 1:
            raise CosimError(f"{self.unit.name} FMU: fmi2SetReal returned status {status} "
                             f"(values {np.array2string(np.asarray(values), precision=4)})")


class FmuVehicle:
    """A vehicle FMU (ours or a third party's) seen in our convention."""

    def __init__(self, path: Path, ports: list[PortMap], params: dict, start_values: dict):
        self.unit = FmuUnit(path, "vehicle", {**params, **start_values})
        self.n = len(ports)
        self._x = self.unit.real_port([p.x for p in ports])
        self._z = self.unit.real_port([p.z for p in ports])
        self._vz = self.unit.real_port([p.vz for p in ports])
        self._F = self.unit.real_port([p.Fz for p in ports])
        self._zs = np.array([p.z_sign for p in ports], float)
        self._vzs = np.array([p.vz_sign for p in ports], float)
        self._Fs = np.array([p.Fz_sign for p in ports], float)

    def initialize(self, t0: float) -> None:
        self.unit.initialize(t0)
        self.Fz0 = self._Fs * self._F.get()

    def step(self, t: float, h: float, Fz: np.ndarray) -> None:
        self._F.set(self._Fs * Fz)
        self.unit.do_step(t, h)

    def outputs(self):
        return self._x.get().copy(), self._zs * self._z.get(), self._vzs * self._vz.get()

    def terminate(self) -> None:
        self.unit.terminate()


class FmuTrack:
    """Our track FMU."""

    def __init__(self, path: Path, n_wheels: int, params: dict):
        self.unit = FmuUnit(path, "track", params)
        w = range(1, n_wheels + 1)
        self._in = self.unit.real_port([f"wheel{i}_{s}" for s in ("x", "z", "vz") for i in w])
        self._out = self.unit.real_port([f"wheel{i}_{s}" for s in ("Fz", "Fz_rail", "Fz_nose", "rail_z")
                                         for i in w])
        self._Fz = self.unit.real_port([f"wheel{i}_Fz_coupling" for i in w])
        self.n = n_wheels
        self._inbuf = np.empty(3 * n_wheels)

    def initialize(self, t0: float) -> None:
        self.unit.initialize(t0)

    def step(self, t: float, h: float, x, z, vz) -> None:
        n = self.n
        b = self._inbuf
        b[:n], b[n:2 * n], b[2 * n:] = x, z, vz
        self._in.set(b)
        self.unit.do_step(t, h)

    def forces(self) -> np.ndarray:
        """The vehicle's input only (read every step; the rest at output steps)."""
        return self._Fz.get().copy()

    def outputs(self):
        o = self._out.get()
        n = self.n
        return o[:n].copy(), np.stack([o[n:2 * n], o[2 * n:3 * n]], axis=1), o[3 * n:].copy()

    def terminate(self) -> None:
        self.unit.terminate()


# ----------------------------------------------------------------------------- algorithms
def _gauss_seidel(vehicle, track, t: float, h: float, Fz: np.ndarray) -> None:
    """Vehicle first with Fz(t_k); the track gets the wheel motion at t_{k+1}."""
    vehicle.step(t, h, Fz)
    x, z, vz = vehicle.outputs()
    track.step(t, h, x, z, vz)


def _jacobi(vehicle, track, t: float, h: float, Fz: np.ndarray) -> None:
    """Both units step from the values at t_k."""
    x, z, vz = vehicle.outputs()
    vehicle.step(t, h, Fz)
    track.step(t, h, x, z, vz)


IMPLICIT_TOL = 1e-3     # N: the monolithic reference iterates a step until Fz changes less
IMPLICIT_MAX_ITER = 50


def _implicit(vehicle, track, t: float, h: float, Fz: np.ndarray) -> None:
    """Monolithic reference: the step is repeated until the coupling forces converge.

    Vehicle with first-order hold of Fz over the step (so Fz(t_{k+1}) acts at the end
    of the step, as in the track), track with the end-of-step wheel motion: the
    converged step solves vehicle, contact and track simultaneously at t_{k+1}.
    In-process only (needs state save/restore of both units).
    """
    sv, st = vehicle.get_state(), track.get_state()
    guess = np.array(Fz, float)
    for _ in range(IMPLICIT_MAX_ITER):
        vehicle.step(t, h, guess)
        x, z, vz = vehicle.outputs()
        track.step(t, h, x, z, vz)
        new = track.forces()
        if np.max(np.abs(new - guess)) <= IMPLICIT_TOL:
            return
        guess = new.copy()
        vehicle.set_state(sv)
        track.set_state(st)
    raise CosimError(f"the monolithic step at t = {t:.6g} s did not converge in {IMPLICIT_MAX_ITER} iterations")


ALGORITHMS: dict[str, Callable] = {"gauss-seidel": _gauss_seidel, "jacobi": _jacobi, "implicit": _implicit}
# Does the track receive start-of-step inputs (and so extrapolate when asked)?
INPUTS_AT_START = {"gauss-seidel": False, "jacobi": True, "implicit": False}


# ----------------------------------------------------------------------------- run
@dataclass
class CosimResult:
    """Signals at the output times (our convention, SI units).

    Attributes
    ----------
    t : ndarray, shape (nt,)
    x, z, vz : ndarray, shape (nt, m)
        Wheel track coordinate [m], vertical position [m] (up +) and velocity [m/s].
    Fz : ndarray, shape (nt, m)
        Contact force on each wheel [N] (up +).
    parts : ndarray, shape (nt, m, 2)
        Force on the running/wing rail and on the nose [N].
    rail_z : ndarray, shape (nt, m)
        Rail deflection under each wheel [m].
    track_record : dict or None
        Track states at the output times (``q``, ``v``, ...), for post-processing.
    stats : dict
        Steps, wall time and its split, backend, algorithm.
    error : str or None
        Why the run stopped early (the arrays hold what was computed).
    track_model : track.model.TrackModel or None
        The in-process backend's track model (for post-processing without building it
        again); ``None`` with FMUs.
    """

    t: np.ndarray
    x: np.ndarray
    z: np.ndarray
    vz: np.ndarray
    Fz: np.ndarray
    parts: np.ndarray
    rail_z: np.ndarray
    track_record: dict | None = None
    stats: dict = field(default_factory=dict)
    error: str | None = None
    track_model: object = None


def vehicle_kind(scenario) -> str:
    """``bogie``, ``quarter`` or ``external``."""
    return scenario.vehicle.fmu if scenario.vehicle.fmu in ("bogie", "quarter") else "external"


def n_wheels(scenario) -> int:
    kind = vehicle_kind(scenario)
    return {"bogie": 4, "quarter": 2}.get(kind, len(scenario.vehicle.ports))


def wheelset_offsets(scenario) -> list[float]:
    """Offsets of our vehicle's wheelsets behind the front one [m] (<= 0), with the
    wheelbase of ``vehicle.start_values`` when it is given there."""
    if vehicle_kind(scenario) != "bogie":
        return [0.0]
    from vehicle.bogie import BogieParams

    return [0.0, -float(scenario.vehicle.start_values.get("wheelbase", BogieParams().wheelbase))]


def start_position(scenario, layout) -> float:
    """Front-wheelset x at t = 0: ``simulation.x_start``, or the position where the
    rearmost wheelset stands START_MARGIN_SLEEPERS spacings after the first sleeper."""
    if scenario.simulation.x_start is not None:
        return float(scenario.simulation.x_start)
    spacing = layout.params.sleeper_spacing
    return float(layout.sleepers[0].x - min(wheelset_offsets(scenario)) + START_MARGIN_SLEEPERS * spacing)


def check_passage(scenario, layout, x_front: float) -> None:
    """Refuse a run whose wheels would leave the modelled panel."""
    sim, veh = scenario.simulation, scenario.vehicle
    spacing = layout.params.sleeper_spacing
    x_end = x_front + veh.speed * sim.duration
    limit = layout.sleepers[-1].x - END_MARGIN_SLEEPERS * spacing
    if x_end > limit:
        t_max = (limit - x_front) / veh.speed
        raise UserInputError(
            f"simulation.duration: {sim.duration:g} s at {veh.speed:g} m/s takes the front wheelset from "
            f"x = {x_front:.2f} m to {x_end:.2f} m, beyond the modelled panel (wheels must stay before "
            f"{limit:.2f} m); use duration <= {max(t_max, 0):.3f} s, move simulation.x_start or add sleepers")
    if x_front < layout.sleepers[0].x:
        raise UserInputError(f"simulation.x_start: {x_front:.2f} m is before the first sleeper "
                             f"({layout.sleepers[0].x:.2f} m)")


def our_ports(n: int) -> list[PortMap]:
    return [PortMap(f"wheel{i}_x", f"wheel{i}_z", f"wheel{i}_vz", f"wheel{i}_Fz") for i in range(1, n + 1)]


def make_units(scenario, backend: str, algorithm: str, h: float, record_every: int, fmu_dir: Path | None,
               work_dir: Path, layout):
    """Vehicle and track units for a backend; returns (vehicle, track, x_front)."""
    sim, veh = scenario.simulation, scenario.vehicle
    kind = vehicle_kind(scenario)
    m = n_wheels(scenario)
    x0 = start_position(scenario, layout)
    check_passage(scenario, layout, x0)
    extrapolate = INPUTS_AT_START[algorithm] and sim.extrapolation
    # the monolithic reference iterates the forces itself: no extrapolation there
    extrapolate_force = sim.extrapolation and algorithm != "implicit"
    if backend == "inprocess":
        if kind == "external":
            raise UserInputError("vehicle.fmu: a third-party FMU needs the fmu backend")
        hold = "foh" if algorithm == "implicit" else "zoh"
        return (InProcessVehicle(kind, veh.speed, veh.axle_load, x0, veh.start_values, hold),
                InProcessTrack(scenario, m, h, extrapolate, record_every, extrapolate_force), x0)
    if algorithm == "implicit":
        raise UserInputError("the implicit (monolithic) reference runs in-process only")
    if backend != "fmu":
        raise UserInputError(f"backend {backend!r}: use 'fmu' or 'inprocess'")
    from .build_job import build_fmus

    fmus = build_fmus(scenario, fmu_dir or work_dir / "fmus")
    if kind == "external":
        vpath = Path(veh.fmu)
        ports = list(veh.ports)
        params = {}
    else:
        vpath = fmus[kind]
        ports = our_ports(m)
        params = {"speed": veh.speed, "x0": x0, "axle_load": veh.axle_load}
    vehicle = FmuVehicle(vpath, ports, params, dict(veh.start_values))
    rec = work_dir / "track_record.npz"
    track = FmuTrack(fmus["track"], m, {"speed": veh.speed, "static_wheel_load": 0.5 * veh.axle_load,
                                         "extrapolate": extrapolate, "record_every": record_every,
                                         "extrapolate_force": extrapolate_force,
                                         "record_file": str(rec) if record_every else ""})
    track.record_file = rec
    return vehicle, track, x0


def run_cosim(scenario, backend: str = "fmu", work_dir: Path | None = None, fmu_dir: Path | None = None,
              progress: Callable[[int, int], None] | None = None, record_states: bool = True,
              algorithm: str | None = None) -> CosimResult:
    """Run the co-simulation of ``scenario``.

    Parameters
    ----------
    scenario : orchestrator.scenario.Scenario
    backend : str
        ``"fmu"`` or ``"inprocess"``.
    work_dir : Path, optional
        Folder for built FMUs and the track record (default: a temporary folder).
    fmu_dir : Path, optional
        Folder with prebuilt FMUs to reuse.
    progress : callable, optional
        ``progress(k, nsteps)`` at each output step.
    record_states : bool
        Record the track state (q, v) at the output times for post-processing.
    algorithm : str, optional
        Override ``simulation.algorithm``; ``"implicit"`` is the monolithic reference
        (in-process only).

    Returns
    -------
    CosimResult
    """
    import tempfile

    from track.layout import build_layout

    sim = scenario.simulation
    h = sim.step
    every = max(1, int(round(sim.output_step / h)))
    nsteps = int(round(sim.duration / h))
    layout = build_layout(scenario.track.layout)
    tmp = None
    if work_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix="turnout_")
        work_dir = Path(tmp.name)
    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    algorithm = algorithm or sim.algorithm
    step_fn = ALGORITHMS[algorithm]
    t_wall = time.perf_counter()
    vehicle, track, x0 = make_units(scenario, backend, algorithm, h, every if record_states else 0, fmu_dir,
                                    work_dir, layout)
    t_setup = time.perf_counter() - t_wall
    m = vehicle.n
    nout = nsteps // every + 1
    T = np.empty(nout)
    X, Z, VZ, F, RZ = (np.empty((nout, m)) for _ in range(5))
    P = np.empty((nout, m, 2))
    error = None
    setup_error = None
    done = 0
    try:
        t0 = 0.0
        if backend == "inprocess":
            vehicle.initialize(h)
        else:
            vehicle.initialize(t0)
            track.initialize(t0)
        Fz = np.array(vehicle.Fz0, float)
        x, z, vz = vehicle.outputs()
        if abs(x[0] - x0) > POSITION_TOL:
            raise UserInputError(
                f"vehicle: the vehicle FMU's wheel 1 starts at x = {x[0]:.4f} m but the scenario starts it at "
                f"{x0:.4f} m (simulation.x_start or the default); set the FMU's start position through "
                "vehicle.start_values")
        T[0], X[0], Z[0], VZ[0], F[0], RZ[0] = t0, x, z, vz, Fz, np.nan
        P[0] = np.nan
        done = 1
        t_loop = time.perf_counter()
        for k in range(nsteps):
            t = t0 + k * h  # communication points from an integer counter
            step_fn(vehicle, track, t, h, Fz)
            Fz = track.forces()
            if (k + 1) % every == 0:
                Fz_rec, parts, rail_z = track.outputs()
                j = (k + 1) // every
                x, z, vz = vehicle.outputs()
                T[j], X[j], Z[j], VZ[j], F[j], P[j], RZ[j] = t0 + (k + 1) * h, x, z, vz, Fz_rec, parts, rail_z
                done = j + 1
                if progress is not None:
                    progress(k + 1, nsteps)
        t_loop = time.perf_counter() - t_loop
    except Exception as exc:  # noqa: BLE001 - any failure keeps what was computed
        from track.cosim import DivergenceError
        from track.dynamics import ConvergenceError
        if not isinstance(exc, (CosimError, DivergenceError, ConvergenceError, UserInputError)):
            raise
        if done == 0:  # failed while setting up: nothing computed, report it as such
            setup_error = exc
        error = str(exc)
        t_loop = time.perf_counter() - t_wall - t_setup
    finally:
        for u in (vehicle, track):
            try:
                u.terminate()
            except Exception:  # noqa: BLE001 - an FMU that failed may refuse to terminate
                pass
    if setup_error is not None:
        if tmp is not None:
            tmp.cleanup()
        raise setup_error if isinstance(setup_error, UserInputError) else CosimError(str(setup_error))
    record = None
    if record_states:
        if backend == "inprocess":
            record = track.record()
        elif getattr(track, "record_file", None) is not None and track.record_file.exists():
            with np.load(track.record_file) as d:
                record = {k: d[k] for k in d.files}
    stats = {"backend": backend, "algorithm": algorithm, "step": h, "steps": min(nsteps, (done - 1) * every),
             "output_every": every, "wheels": m, "x_front_start": x0,
             "wall_setup": t_setup, "wall_loop": t_loop, "wall_total": time.perf_counter() - t_wall}
    if tmp is not None:
        tmp.cleanup()
    sl = slice(0, done)
    return CosimResult(t=T[sl], x=X[sl], z=Z[sl], vz=VZ[sl], Fz=F[sl], parts=P[sl], rail_z=RZ[sl],
                       track_record=record, stats=stats, error=error,
                       track_model=track.model if backend == "inprocess" else None)
