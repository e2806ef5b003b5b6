"""``turnout build-fmus``: build the track FMU of a scenario and our vehicle FMUs.

The track FMU bakes the scenario's ``track:`` section and has one set of wheel ports
per wheel of the scenario's vehicle (bogie 4, quarter vehicle 2, a third-party FMU
one per ``vehicle.ports`` entry).  The start values of its run parameters come from
the scenario: ``speed``, ``static_wheel_load = axle_load / 2`` and ``extrapolate``
(true when the track receives start-of-step inputs, i.e. with the Jacobi algorithm,
and ``simulation.extrapolation`` asks for it).  Both vehicle FMUs are built as well,
so one folder serves either vehicle.

The track FMU also gets one output per sensor of the scenario's layout (``sensors:``,
default ``scenarios/sensors/in2track_like.yaml``), resolved here on the scenario's
track model (relative positions such as ``sleeper: T``, ``x: T+0.3``) and baked in, so
the FMU needs no layout file at run time.  The default layout is drawn for a turnout
(crossing rail, pressure cells across a turnout sleeper); on a track it does not fit (a
plain track) the track FMU gets no sensor outputs and a warning says why.  A layout the
scenario names must fit.
"""
from __future__ import annotations

from pathlib import Path

from orchestrator.cosim.algorithms import ALGORITHMS
from orchestrator.cosim.passage import n_wheels
from orchestrator.inputs.sensor_layout import scenario_sensors

VEHICLE_KINDS = ("bogie", "quarter")


def build_fmus(scenario, out_dir: Path) -> dict[str, Path]:
    """Build ``track.fmu``, ``bogie.fmu`` and ``quarter.fmu`` into ``out_dir``.

    Parameters
    ----------
    scenario : orchestrator.inputs.scenario.Scenario
    out_dir : Path
        Destination folder (created if missing).

    Returns
    -------
    dict
        ``{"track": path, "bogie": path, "quarter": path}``.
    """
    from fmus.build import build_fmu, build_track_fmu  # pythonfmu is only needed here

    out_dir = Path(out_dir)
    veh, sim = scenario.vehicle, scenario.simulation
    extrapolate = ALGORITHMS[sim.algorithm].inputs_at_start and sim.extrapolation
    built = {"track": build_track_fmu(scenario.track, n_wheels(scenario), out_dir,
                                      sensors=scenario_sensors(scenario), speed=veh.speed,
                                      static_wheel_load=0.5 * veh.axle_load, extrapolate=extrapolate,
                                      extrapolate_force=sim.extrapolation)}
    for kind in VEHICLE_KINDS:
        built[kind] = build_fmu(kind, out_dir)
    return built
