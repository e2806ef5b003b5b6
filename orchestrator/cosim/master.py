"""Co-simulation master: a vehicle unit and a track unit exchanging wheel motion and contact forces.

Units (the same interface for both backends):

- vehicle: input contact forces ``Fz`` (up +) -> outputs wheel ``x``, ``z`` (up +), ``vz``;
- track: inputs wheel ``x``, ``z``, ``vz`` -> outputs contact forces ``Fz`` (the Hertz
  contact lives on the track side, DESIGN.md §3 and §8).

Backends: ``fmu`` runs the FMUs (ours built with pythonfmu, or a third-party vehicle
FMU mapped through the scenario's ``ports``) through FMPy's low-level API;
``inprocess`` steps the same model objects (``vehicle.VehicleStepper``,
``track.cosim.TrackCosim``) without the FMU boundary; with Gauss–Seidel, after the first
step, in blocks of steps in one compiled call (:mod:`orchestrator.cosim.compiled_loop`: the
same numbers, a quarter less loop time, benchmarks/RESULTS.md).

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

Every run reports what it did (:mod:`orchestrator.cosim.stats`): steps and wall time per
phase from the master's clock, and the track's own counters (linear solves, contact
iterations, ...; the track FMU's from its monitoring outputs, read at terminate).

What the track records at the output times (``record_columns``) is what the
post-processing reads: :func:`merge_columns` joins the requests of its parts
(analysis, sensors); no request records the whole state.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from orchestrator.cosim.algorithms import ALGORITHMS
from orchestrator.cosim.compiled_loop import compiled_loop
from orchestrator.cosim.passage import POSITION_TOL, check_passage, n_wheels, our_ports, start_position, vehicle_kind
from orchestrator.cosim.scratch import scratch_dir
from orchestrator.cosim.stats import CosimStats, RunCounters
from orchestrator.cosim.units import CosimError, FmuTrack, FmuVehicle, InProcessTrack, InProcessVehicle
from orchestrator.inputs.errors import UserInputError
from track.timegrid import step_count

RECORD_FILE = "track_record.npz"   # the track FMU's recorded states (a temporary file, read once)
RECORD_KEYS = ("t", "q", "v", "a", "x", "Fz", "parts")   # what post-processing reads of it
RECORD_COLUMN_KEYS = tuple(f"{k}_columns" for k in ("q", "v", "a"))   # ... and which columns it holds


def merge_columns(*requests: dict) -> dict:
    """One ``record_columns`` request from several: per state field the union of the columns.

    Parameters
    ----------
    *requests : dict
        State field (``"q"``, ``"v"``, ``"a"``) -> column indices (``track.cosim.Record``).

    Returns
    -------
    dict
        Field -> sorted unique indices (ndarray of int), the fields any request names.
    """
    out: dict = {}
    for req in requests:
        for name, cols in req.items():
            out[name] = np.union1d(out.get(name, np.empty(0, np.intp)), np.asarray(cols, np.intp)).astype(np.intp)
    return out

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
    stats : orchestrator.cosim.stats.CosimStats
        Steps, wall time and its split, backend, algorithm (a dict: ``summary.json``'s
        ``wall_seconds``), and ``stats.counters``: the stepper's work and the wall time per
        phase (:class:`orchestrator.cosim.stats.RunCounters`).
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


def make_units(scenario, backend: str, algorithm: str, h: float, record_every: int, fmu_dir: Path | None,
               work_dir: Path, layout, record_dir: Path | None = None, record_columns: dict | None = None,
               record_rows: int = 0):
    """Vehicle and track units for a backend; returns (vehicle, track, x_front).

    The track FMU writes its recorded states (when ``record_every``) at terminate to
    ``record_dir/track_record.npz`` (default ``work_dir``); :func:`run_cosim` gives it a
    temporary folder and deletes the file once read.  ``record_columns`` (field -> column
    indices; ``None``: every column of q, v, a) says what the track records;
    ``record_rows`` how many output rows the in-process record reserves (the FMU sizes
    its record from the stop time the master gives it).
    """
    sim, veh = scenario.simulation, scenario.vehicle
    kind = vehicle_kind(scenario)
    m = n_wheels(scenario)
    x0 = start_position(scenario, layout)
    check_passage(scenario, layout, x0)
    algo = ALGORITHMS[algorithm]
    extrapolate = algo.inputs_at_start and sim.extrapolation
    extrapolate_force = sim.extrapolation and algo.extrapolate_force
    if backend == "inprocess":
        if kind == "external":
            raise UserInputError("vehicle.fmu: a third-party FMU needs the fmu backend")
        return (InProcessVehicle(kind, veh.speed, veh.axle_load, x0, veh.start_values, algo.hold),
                InProcessTrack(scenario, m, h, extrapolate, record_every, extrapolate_force, record_columns,
                               record_rows), x0)
    if algo.in_process_only:
        raise UserInputError(f"the {algo.name} algorithm runs in-process only")
    if backend != "fmu":
        raise UserInputError(f"backend {backend!r}: use 'fmu' or 'inprocess'")
    from orchestrator.cosim.build_job import cached_fmus

    fmus = cached_fmus(scenario, fmu_dir or work_dir / "fmus")
    if kind == "external":
        vpath = Path(veh.fmu)
        ports = list(veh.ports)
        params = {}
    else:
        vpath = fmus[kind]
        ports = our_ports(m)
        params = {"speed": veh.speed, "x0": x0, "axle_load": veh.axle_load}
    vehicle = FmuVehicle(vpath, ports, params, dict(veh.start_values))
    rec = Path(record_dir or work_dir) / RECORD_FILE
    track = FmuTrack(fmus["track"], m, {"speed": veh.speed, "static_wheel_load": 0.5 * veh.axle_load,
                                         "extrapolate": extrapolate, "record_every": record_every,
                                         "extrapolate_force": extrapolate_force,
                                         "record_file": str(rec) if record_every else "",
                                         "record_columns": _columns_text(record_columns)})
    track.record_file = rec
    return vehicle, track, x0


def _columns_text(columns: dict | None) -> str:
    """The track FMU's ``record_columns`` parameter: JSON of the field -> column lists; empty for all."""
    import json

    if columns is None:
        return ""
    return json.dumps({k: [int(i) for i in np.asarray(v).ravel()] for k, v in columns.items()},
                      separators=(",", ":"))


def run_cosim(scenario, backend: str = "fmu", work_dir: Path | None = None, fmu_dir: Path | None = None,
              progress: Callable[[int, int], None] | None = None, record_states: bool = True,
              algorithm: str | None = None, record_columns: dict | None = None) -> CosimResult:
    """Run the co-simulation of ``scenario``.

    Stages: :func:`_set_up` (the units and the time grid), :func:`_drive` (initialize,
    then the stepping loop of :func:`_step_loop` with ``t_k = t0 + k h``),
    :func:`_track_record` (the recorded track states) and :func:`_result`.

    Parameters
    ----------
    scenario : orchestrator.inputs.scenario.Scenario
    backend : str
        ``"fmu"`` or ``"inprocess"``.
    work_dir : Path, optional
        Folder for the built FMUs (default: a temporary folder). The track FMU's record goes
        to a temporary folder of its own and is deleted once read.
    fmu_dir : Path, optional
        Folder with prebuilt FMUs to reuse.
    progress : callable, optional
        ``progress(k, nsteps)`` at each output step.
    record_states : bool
        Record the track state (q, v, a) at the output times for post-processing.
    algorithm : str, optional
        Override ``simulation.algorithm``; ``"implicit"`` is the monolithic reference
        (in-process only).
    record_columns : dict, optional
        Record only these columns of the states (field -> indices, ``track.cosim.Record``;
        the record then carries ``<field>_columns``, and ``track.cosim.state_rows`` gives
        full rows); default every column of q, v and a.

    Returns
    -------
    CosimResult
        Its ``stats`` (:class:`orchestrator.cosim.stats.CosimStats`) carry the counters of
        the run (``stats.counters``); the track's internal ones in-process only.
    """
    run = _set_up(scenario, backend, work_dir, fmu_dir, record_states, algorithm or scenario.simulation.algorithm,
                  record_columns)
    signals = _Signals(run.nsteps // run.every + 1, run.vehicle.n)
    error, t_initialize, t_loop = _drive(run, signals, progress)
    record = _track_record(run) if record_states else None
    if record is not None and backend == "fmu":   # the FMU's instance and record were freed just now
        _release_freed_memory()
    return _result(run, signals, record, error, t_initialize, t_loop)


@dataclass
class _Run:
    """One run after set-up: the units, the time grid and the clock.

    ``step_fn`` the algorithm's step (:data:`ALGORITHMS`); ``nsteps`` communication steps
    of ``h`` [s] from ``t0`` [s], an output every ``every`` steps; ``t_wall`` the
    ``perf_counter`` at the start, ``t_setup`` [s] the time making the units took; ``tmp``
    the temporary work folder (``None`` with ``work_dir``); ``record_tmp`` the temporary
    folder the track FMU writes its record to (``None`` in-process or without a record).
    """

    backend: str
    algorithm: str
    step_fn: Callable
    vehicle: object
    track: object
    x0: float
    h: float
    every: int
    nsteps: int
    t_wall: float
    t_setup: float
    tmp: object = None
    t0: float = 0.0
    record_tmp: object = None

    def cleanup(self) -> None:
        """Remove the temporary folders (the work folder when not given, the record's always)."""
        for tmp in (self.tmp, self.record_tmp):
            if tmp is not None:
                tmp.cleanup()
        self.tmp = self.record_tmp = None


class _Signals:
    """Preallocated output arrays (``nout`` output times, ``m`` wheels); ``done`` rows are filled."""

    def __init__(self, nout: int, m: int):
        self.t = np.empty(nout)
        self.x, self.z, self.vz, self.Fz, self.rail_z = (np.empty((nout, m)) for _ in range(5))
        self.parts = np.empty((nout, m, 2))
        self.done = 0

    def put(self, j: int, t: float, x, z, vz, Fz, parts, rail_z) -> None:
        """Row ``j``: time [s], wheel x, z [m], vz [m/s], contact force and its parts [N], rail deflection [m]."""
        self.t[j], self.x[j], self.z[j], self.vz[j], self.Fz[j], self.parts[j], self.rail_z[j] = \
            t, x, z, vz, Fz, parts, rail_z
        self.done = j + 1


def _set_up(scenario, backend: str, work_dir: Path | None, fmu_dir: Path | None, record_states: bool,
            algorithm: str, record_columns: dict | None = None) -> _Run:
    """The work folder, the time grid and the two units (timed); returns the :class:`_Run`."""
    from track.layout import build_layout

    sim = scenario.simulation
    h = sim.step
    every = max(1, sim.output_every)
    nsteps = step_count(sim.duration, h)
    layout = build_layout(scenario.track.layout)
    tmp = None
    if work_dir is None:
        tmp = scratch_dir("job")
        work_dir = Path(tmp.name)
    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    # the FMU's record never lands in work_dir (it may be a results folder): a private temporary folder
    record_tmp = scratch_dir("record") \
        if record_states and backend == "fmu" else None
    step_fn = ALGORITHMS[algorithm].step
    t_wall = time.perf_counter()
    try:
        vehicle, track, x0 = make_units(scenario, backend, algorithm, h, every if record_states else 0, fmu_dir,
                                        work_dir, layout, None if record_tmp is None else Path(record_tmp.name),
                                        record_columns, nsteps // every + 1 if record_states else 0)
    except BaseException:
        for t in (tmp, record_tmp):
            if t is not None:
                t.cleanup()
        raise
    return _Run(backend, algorithm, step_fn, vehicle, track, x0, h, every, nsteps, t_wall,
                time.perf_counter() - t_wall, tmp, record_tmp=record_tmp)


def _start(run: _Run, signals: _Signals) -> np.ndarray:
    """Initialize both units, check the start position and record row 0; returns ``Fz(t0)`` [N]."""
    vehicle, track = run.vehicle, run.track
    if run.backend == "inprocess":
        vehicle.initialize(run.h)
    else:
        vehicle.initialize(run.t0)
        track.initialize(run.t0, run.t0 + run.nsteps * run.h)   # the stop time sizes the FMU's record
    Fz = np.array(vehicle.Fz0, float)
    x, z, vz = vehicle.outputs()
    if abs(x[0] - run.x0) > POSITION_TOL:
        raise UserInputError(
            f"vehicle: the vehicle FMU's wheel 1 starts at x = {x[0]:.4f} m but the scenario starts it at "
            f"{run.x0:.4f} m (simulation.x_start or the default); set the FMU's start position through "
            "vehicle.start_values")
    signals.put(0, run.t0, x, z, vz, Fz, np.nan, np.nan)
    return Fz


def _step_loop(run: _Run, signals: _Signals, Fz: np.ndarray, progress: Callable[[int, int], None] | None) -> None:
    """The ``nsteps`` communication steps from ``Fz(t0)`` [N], recording every ``every``-th into ``signals``."""
    step_fn, vehicle, track = run.step_fn, run.vehicle, run.track
    h, t0, every, nsteps = run.h, run.t0, run.every, run.nsteps
    for k in range(nsteps):
        if k == 1:   # the first step initialized the track: the rest in compiled blocks where both units allow
            loop = compiled_loop(run)
            if loop is not None:
                loop.advance(k, Fz, signals, progress)
                return
        t = t0 + k * h  # communication points from an integer counter
        step_fn(vehicle, track, t, h, Fz)
        Fz = track.forces()
        if (k + 1) % every == 0:
            Fz_rec, parts, rail_z = track.outputs()
            x, z, vz = vehicle.outputs()
            signals.put((k + 1) // every, t0 + (k + 1) * h, x, z, vz, Fz_rec, parts, rail_z)
            if progress is not None:
                progress(k + 1, nsteps)


def _drive(run: _Run, signals: _Signals, progress) -> tuple[str | None, float, float]:
    """Initialize and step the units, then terminate them.

    Returns (error message or ``None``, wall time of the initialization [s], wall time of
    the loop [s]); when the run stopped early the loop's time counts from the end of the
    set-up (initialization included, as ``summary.json`` has always had it).
    A unit's failure (:class:`CosimError`, divergence, non-convergence, a user error) after
    the first output keeps what was computed and returns its message; before it (nothing
    computed) it is raised, as :class:`UserInputError` or :class:`CosimError`.
    """
    from track.cosim import DivergenceError
    from track.dynamics import ConvergenceError

    error = setup_error = None
    t_initialize = 0.0
    try:
        Fz = _start(run, signals)
        t_loop = time.perf_counter()
        t_initialize = t_loop - run.t_wall - run.t_setup
        _step_loop(run, signals, Fz, progress)
        t_loop = time.perf_counter() - t_loop
    except (CosimError, DivergenceError, ConvergenceError, UserInputError) as exc:
        if signals.done == 0:  # failed while setting up: nothing computed, report it as such
            setup_error = exc
        error = str(exc)
        t_loop = time.perf_counter() - run.t_wall - run.t_setup
    finally:
        for u in (run.vehicle, run.track):
            try:
                u.terminate()
            except Exception:  # noqa: BLE001 - an FMU that failed may refuse to terminate
                pass
    if setup_error is not None:
        run.cleanup()
        raise setup_error if isinstance(setup_error, UserInputError) else CosimError(str(setup_error))
    return error, t_initialize, t_loop


def _track_record(run: _Run) -> dict | None:
    """The track states recorded at the output times (in-process: from the unit; FMU: its ``.npz``).

    The FMU's file is read once (the arrays of :data:`RECORD_KEYS`) and deleted.
    """
    if run.backend == "inprocess":
        return run.track.record()
    rec = getattr(run.track, "record_file", None)
    if rec is None or not rec.exists():
        return None
    try:
        with np.load(rec) as d:
            return {k: d[k] for k in RECORD_KEYS + RECORD_COLUMN_KEYS if k in d.files}
    finally:
        rec.unlink()


def _release_freed_memory() -> None:
    """Give the heap pages freed with the track FMU's instance back to the system (glibc).

    The FMU's record and model are freed with its instance; glibc may keep freed blocks
    in the process, so without this the post-processing's memory would add on top of
    memory that is no longer used (measured when the record was one small array per
    output step: 679 MB -> 458 MB resident after the run). A no-op where there is no glibc.
    """
    import ctypes
    import ctypes.util
    import gc

    gc.collect()  # the FMU's slave object may sit in a reference cycle: free it first
    name = ctypes.util.find_library("c")
    try:
        trim = ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):
        trim = None
    if trim is not None:
        trim(0)


def _result(run: _Run, signals: _Signals, record: dict | None, error: str | None, t_initialize: float,
            t_loop: float) -> CosimResult:
    """The :class:`CosimResult` of the ``signals.done`` recorded rows, with the run's stats and counters."""
    steps = min(run.nsteps, (signals.done - 1) * run.every)
    m = run.vehicle.n
    wall_total = time.perf_counter() - run.t_wall
    counters = RunCounters.measured(steps, run.t_setup, t_initialize, t_loop - t_initialize if error else t_loop,
                                    wall_total, run.track.work())
    stats = CosimStats({"backend": run.backend, "algorithm": run.algorithm, "step": run.h, "steps": steps,
                        "output_every": run.every, "wheels": m, "x_front_start": run.x0,
                        "wall_setup": run.t_setup, "wall_loop": t_loop, "wall_total": wall_total}, counters)
    run.cleanup()
    sl = slice(0, signals.done)
    s = signals
    return CosimResult(t=s.t[sl], x=s.x[sl], z=s.z[sl], vz=s.vz[sl], Fz=s.Fz[sl], parts=s.parts[sl],
                       rail_z=s.rail_z[sl], track_record=record, stats=stats, error=error,
                       track_model=run.track.model if run.backend == "inprocess" else None)


__all__ = ["CosimError", "CosimResult", "make_units", "run_cosim"]
