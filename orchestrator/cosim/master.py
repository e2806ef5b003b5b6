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

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from orchestrator.cosim.algorithms import ALGORITHMS
from orchestrator.cosim.passage import (POSITION_TOL, check_passage, n_wheels, our_ports, start_position,
                                        vehicle_kind)
from orchestrator.cosim.units import CosimError, FmuTrack, FmuVehicle, InProcessTrack, InProcessVehicle
from orchestrator.inputs.errors import UserInputError

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


def make_units(scenario, backend: str, algorithm: str, h: float, record_every: int, fmu_dir: Path | None,
               work_dir: Path, layout):
    """Vehicle and track units for a backend; returns (vehicle, track, x_front)."""
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
                InProcessTrack(scenario, m, h, extrapolate, record_every, extrapolate_force), x0)
    if algo.in_process_only:
        raise UserInputError(f"the {algo.name} algorithm runs in-process only")
    if backend != "fmu":
        raise UserInputError(f"backend {backend!r}: use 'fmu' or 'inprocess'")
    from orchestrator.cosim.build_job import build_fmus

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
    scenario : orchestrator.inputs.scenario.Scenario
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
    step_fn = ALGORITHMS[algorithm].step
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


__all__ = ["CosimError", "CosimResult", "make_units", "run_cosim"]
