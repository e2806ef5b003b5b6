"""The dataclasses the ``vehicle:`` and ``simulation:`` sections of a scenario map onto.

The track section maps onto :mod:`track.params` (``TrackParams`` and its parts); the
whole validated scenario is :class:`orchestrator.inputs.scenario.Scenario`. The schema
(:mod:`orchestrator.inputs.schema`) takes its defaults from these classes, so each
default is written once.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from track.timegrid import step_count

__all__ = ["BUILTIN_VEHICLES", "STEP_MULTIPLE_RTOL", "SECONDS_PER_STEP", "REFERENCE_SLEEPERS", "PortMap",
           "VehicleSpec", "SimulationSpec", "step_estimate", "duration_text"]

BUILTIN_VEHICLES = ("bogie", "quarter")  # vehicle.fmu values that select our own FMUs
STEP_MULTIPLE_RTOL = 1e-9  # output_step / step must be this close to an integer
# Wall time of one communication step of the 40-sleeper default scenario (1741 reduced dofs):
# 2.23 s for 5000 steps in-process, 2.78 s through the FMUs (benchmarks/RESULTS.md, bench_cosim.py;
# 64 sleepers: 0.57 ms). A rough scale for estimates and refusals, not a promise.
SECONDS_PER_STEP = 4.5e-4
REFERENCE_SLEEPERS = 40


def step_estimate(n_steps: float, sleepers: int = REFERENCE_SLEEPERS) -> float:
    """Rough wall time [s] of ``n_steps`` communication steps on a panel of ``sleepers`` sleepers.

    Proportional to the number of sleepers (the reduced dofs grow with them), never below the
    40-sleeper figure (:data:`SECONDS_PER_STEP`: the per-step overhead does not shrink).
    """
    return float(n_steps) * SECONDS_PER_STEP * max(1.0, sleepers / REFERENCE_SLEEPERS)


def duration_text(seconds: float) -> str:
    """A wall time [s] as a person reads it: ``"2.2 s"``, ``"37 min"``, ``"25 h"``, ``"41 days"``."""
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.2g} {unit}"
    return f"{seconds:.2g} s"


@dataclass(frozen=True)
class PortMap:
    """Variable names of one wheel in a third-party vehicle FMU (DESIGN.md §4.4).

    The FMU's value times the sign is the value in our convention (z up, force
    on the wheel up).

    Attributes
    ----------
    x, z, vz : str
        Output variables: track coordinate [m], vertical position [m], vertical velocity [m/s].
    Fz : str
        Input variable: vertical contact force on the wheel [N].
    z_sign, vz_sign, Fz_sign : int
        +1 or -1.
    """

    x: str
    z: str
    vz: str
    Fz: str
    z_sign: int = 1
    vz_sign: int = 1
    Fz_sign: int = 1


@dataclass(frozen=True, kw_only=True)
class VehicleSpec:
    """The ``vehicle:`` section.

    Attributes
    ----------
    fmu : str
        ``"bogie"``, ``"quarter"`` or the absolute path of a third-party ``.fmu``.
    speed : float
        Constant vehicle speed [m/s].
    axle_load : float
        Static axle load [N].
    ports : tuple of PortMap
        One entry per wheel (wheelset by wheelset, left then right); only for a
        third-party FMU.
    start_values : dict
        FMU start values by variable name (float, int, bool or str).
    """

    fmu: str = "bogie"
    speed: float
    axle_load: float = 196200.0
    ports: tuple = ()
    start_values: dict = field(default_factory=dict, hash=False)

    @property
    def builtin(self) -> bool:
        """True when ``fmu`` names one of our own vehicle models."""
        return self.fmu in BUILTIN_VEHICLES


@dataclass(frozen=True)
class SimulationSpec:
    """The ``simulation:`` section.

    Attributes
    ----------
    duration : float
        Simulated time [s].
    step : float
        Communication step [s].
    output_step : float
        Output interval [s]; an integer multiple of ``step``.
    algorithm : str
        ``"gauss-seidel"`` or ``"jacobi"``.
    extrapolation : bool
        Extrapolate the wheel inputs of the track over a step.
    x_start : float or None
        Track coordinate of the first wheel at t = 0 [m]; ``None`` lets the job choose.
    """

    duration: float = 1.0
    step: float = 2.0e-5
    output_step: float = 1.0e-4
    algorithm: str = "gauss-seidel"
    extrapolation: bool = True
    x_start: float | None = None

    @property
    def output_every(self) -> int:
        """Number of communication steps per output step."""
        return int(round(self.output_step / self.step))

    @property
    def n_steps(self) -> int:
        """Number of communication steps that cover ``duration`` (last one may end past it)."""
        return step_count(self.duration, self.step, cover=True)
