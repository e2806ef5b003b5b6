"""``turnout build-fmus``: build the track FMU of a scenario and our vehicle FMUs.

The track FMU bakes the scenario's ``track:`` section and has one set of wheel ports
per wheel of the scenario's vehicle (bogie 4, quarter vehicle 2, a third-party FMU
one per ``vehicle.ports`` entry).  The start values of its run parameters come from
the scenario: ``speed``, ``static_wheel_load = axle_load / 2`` and ``extrapolate_force``
(``simulation.extrapolation``); ``extrapolate`` keeps the FMU's default, true (a generic
fixed-step host gives start-of-step inputs; our master sets it per algorithm). Every FMU's
``DefaultExperiment`` is the scenario's duration and step. Both vehicle FMUs are built,
so one folder serves either vehicle; the scenario's own kind has its start position,
speed and axle load as start values.

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

from track.layout import build_layout

from orchestrator.cosim.passage import n_wheels, start_position
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
    experiment = {"stop_time": sim.duration, "step_size": sim.step}   # DefaultExperiment: the scenario's
    # The track FMU keeps its own default extrapolate = true (start-of-step inputs, what a generic
    # fixed-step host gives it); our master sets it per algorithm at run time.
    built = {"track": build_track_fmu(scenario.track, n_wheels(scenario), out_dir,
                                      sensors=scenario_sensors(scenario), speed=veh.speed,
                                      static_wheel_load=0.5 * veh.axle_load,
                                      extrapolate_force=sim.extrapolation, **experiment)}
    for kind in VEHICLE_KINDS:
        own = {"x0": start_position(scenario, build_layout(scenario.track.layout)), "speed": veh.speed,
               "axle_load": veh.axle_load} if kind == scenario.vehicle.fmu else None
        built[kind] = build_fmu(kind, out_dir, start_values=own, **experiment)
    return built
