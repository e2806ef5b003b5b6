"""Where the vehicle runs: its wheels, its start position and the stretch of panel a run covers."""
from __future__ import annotations

from dataclasses import dataclass

from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.specs import PortMap, duration_text, step_estimate

POSITION_TOL = 1e-6  # m: the vehicle's wheel 1 must start where the scenario puts it
START_MARGIN_SLEEPERS = 2  # the rear wheelset starts this many sleepers inside the panel
END_MARGIN_SLEEPERS = 1    # the front wheelset must stay this many sleepers inside the panel


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


@dataclass(frozen=True)
class RunPlan:
    """What a run of a scenario would do, checked without building the track model (``turnout run --dry-run``).

    Attributes
    ----------
    vehicle : str
        ``bogie``, ``quarter`` or ``external``.
    n_wheels : int
    sleepers : int
        Sleepers of the panel.
    panel : tuple of float
        Track coordinates of the first and last sleeper [m].
    x_start, x_end : float
        Front wheelset at t = 0 and at the end of the run [m].
    n_steps : int
        Communication steps.
    estimate : float
        Rough wall time of the stepping loop [s] (:func:`orchestrator.inputs.specs.step_estimate`).
    """

    vehicle: str
    n_wheels: int
    sleepers: int
    panel: tuple
    x_start: float
    x_end: float
    n_steps: int
    estimate: float

    def summary(self) -> str:
        """One line for the user."""
        return (f"{self.vehicle} vehicle, {self.n_wheels} wheels, front wheelset from x = {self.x_start:.2f} m to "
                f"{self.x_end:.2f} m on a {self.sleepers}-sleeper panel ({self.panel[0]:.2f}-{self.panel[1]:.2f} m); "
                f"{self.n_steps} steps, roughly {duration_text(self.estimate)} of stepping")


def plan_run(scenario) -> RunPlan:
    """Check what a run needs besides the scenario's own keys, without building the track model.

    Builds the layout, places the vehicle (:func:`start_position`, :func:`check_passage`),
    reads the sensor layout file and, for a third-party vehicle FMU, checks its ports and
    start values against its model description (:mod:`orchestrator.cosim.ports`).

    Raises
    ------
    UserInputError
        The first problem found.
    """
    from orchestrator.cosim.ports import check_vehicle_fmu
    from orchestrator.inputs.sensor_layout import layout_of
    from track.layout import build_layout

    layout = build_layout(scenario.track.layout)
    x0 = start_position(scenario, layout)
    check_passage(scenario, layout, x0)
    kind = vehicle_kind(scenario)
    if kind == "external":
        veh = scenario.vehicle
        check_vehicle_fmu(veh.fmu, veh.ports, veh.start_values)
    layout_of(scenario)
    sim = scenario.simulation
    n = sim.n_steps
    return RunPlan(kind, n_wheels(scenario), len(layout.sleepers), (layout.sleepers[0].x, layout.sleepers[-1].x),
                   x0, x0 + scenario.vehicle.speed * sim.duration, n,
                   step_estimate(n, len(layout.sleepers)))


__all__ = ["vehicle_kind", "n_wheels", "wheelset_offsets", "start_position", "check_passage", "our_ports",
           "plan_run", "RunPlan", "POSITION_TOL", "START_MARGIN_SLEEPERS", "END_MARGIN_SLEEPERS"]
