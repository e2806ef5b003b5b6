"""The scenario's co-simulation system (:func:`export_ssp`): its components, parameter
values and connections, written with :func:`orchestrator.cosim.ssp.writer.write_ssp`.

The system (DESIGN.md §4.4)
---------------------------
Two components, ``vehicle`` and ``track``. Per wheel ``i`` (front wheelset left,
right, then the next), four connections::

    vehicle.wheel{i}_x  -> track.wheel{i}_x
    vehicle.wheel{i}_z  -> track.wheel{i}_z      (x z_sign  for a third-party vehicle)
    vehicle.wheel{i}_vz -> track.wheel{i}_vz     (x vz_sign)
    track.wheel{i}_Fz_coupling -> vehicle.wheel{i}_Fz   (x Fz_sign; the contact force,
                                 extrapolated to mid-step with extrapolate_force)

A third-party vehicle uses its own variable names from ``vehicle.ports``. A sign of -1
becomes an ``ssc:LinearTransformation factor="-1"`` on that connection: the FMU's
value times the sign is the value in our convention, so vehicle -> track multiplies
by the sign and track -> vehicle multiplies by 1/sign = sign.

Parameter values:

* track: ``speed``, ``static_wheel_load = axle_load / 2``, ``extrapolate =
  simulation.extrapolation`` (true by default, and it should stay true: libcosim and
  FMPy are Jacobi masters, the track's wheel inputs are those of the previous
  communication point, and the stiff Hertz contact needs them extrapolated over the
  step, DESIGN.md §8; false holds them, as ``turnout run`` with ``algorithm: jacobi``
  and ``extrapolation: false`` does), ``h1`` (ballast stiffness scale), ``h2``
  (rail-pad stiffness scale) and ``impact_angle`` from the scenario (only those the
  track FMU declares).
* our vehicles: ``speed``, ``axle_load``, ``x0`` (track coordinate of the front
  wheelset at t = 0: ``simulation.x_start`` if set, else :func:`default_x_start`:
  the position where the rearmost wheelset stands ``START_MARGIN_SLEEPERS`` (2) sleeper
  spacings after the first sleeper, the choice ``turnout run`` makes too), then the
  scenario's ``vehicle.start_values``.
* a third-party vehicle: ``vehicle.start_values`` only (its speed and start position
  are its own parameters, e.g. ``{"v": 33.333, "s0": 4.1}``; the track's ``speed`` is
  the scenario's ``vehicle.speed``).

The FMUs carry the same values as their start values, so a host that ignores parameter
bindings (FMPy's ``simulate_ssp``) still runs the scenario: the track FMU is built with
the scenario's track and its run parameters' values as defaults, our vehicle FMU with
all of its values above (``resources/start_values.json``, :mod:`fmus.base`). A
third-party vehicle FMU is taken as it is: its ``vehicle.start_values`` arrive only
through the binding.

With our vehicles the run must keep the wheels on the modelled panel over
``simulation.duration`` (the check of ``turnout run``, :func:`orchestrator.cosim.passage.check_passage`);
otherwise :class:`UserInputError`. A third-party vehicle's start position is its own
parameter and is not checked.

Default experiment: start 0, stop ``simulation.duration``; the communication step
``simulation.step`` (SSP 1.0 itself has no step size) in the annotations of the two
hosts that read one (:func:`orchestrator.cosim.ssp.writer.write_ssp`): libcosim's
(``ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation[type="com.opensimulationplatform"]
/osp:Algorithm/osp:FixedStepAlgorithm@baseStepSize``) and OMSimulator's, which also makes
the system a co-simulation with a fixed-step master
(``ssd:System/ssd:Annotations/ssc:Annotation[type="org.openmodelica"]/oms:Annotations
/oms:SimulationInformation/oms:FixedStepMaster@stepSize``).
"""
from __future__ import annotations

import dataclasses
import json
import tempfile
import zipfile
from pathlib import Path

from orchestrator.cosim import passage
from orchestrator.cosim.ports import check_start_values, check_vehicle_fmu
from orchestrator.cosim.ssp.ssd import TRACK, VEHICLE, Component, Connection, step_ns
from orchestrator.cosim.ssp.writer import check_out_file, model_variables, write_ssp
from orchestrator.inputs.causes import CATALOGUE
from orchestrator.inputs.errors import UserInputError


def _n_wheels(scenario) -> int:
    """Wheels of the scenario's vehicle; a third-party FMU must list its ports."""
    veh = scenario.vehicle
    if not veh.builtin and not veh.ports:
        raise UserInputError(f"vehicle.ports: the third-party vehicle FMU {veh.fmu} needs one ports entry "
                             "per wheel (DESIGN.md 4.4)")
    return passage.n_wheels(scenario)


def system_connections(scenario) -> list[Connection]:
    """The connections of the scenario's system (4 per wheel, see the module docstring)."""
    veh = scenario.vehicle
    out = []
    for i in range(_n_wheels(scenario)):
        w = f"wheel{i + 1}_"
        if veh.builtin:
            x, z, vz, fz, sz, svz, sfz = w + "x", w + "z", w + "vz", w + "Fz", 1, 1, 1
        else:
            p = veh.ports[i]
            x, z, vz, fz, sz, svz, sfz = p.x, p.z, p.vz, p.Fz, p.z_sign, p.vz_sign, p.Fz_sign
        out += [Connection(VEHICLE, x, TRACK, w + "x"),
                Connection(VEHICLE, z, TRACK, w + "z", float(sz)),
                Connection(VEHICLE, vz, TRACK, w + "vz", float(svz)),
                # our Fz = FMU Fz * sign  ->  FMU Fz = our Fz / sign = our Fz * sign; the
                # coupling output (extrapolated to mid-step when extrapolate_force) feeds it
                Connection(TRACK, w + "Fz_coupling", VEHICLE, fz, float(sfz))]
    return out


def default_x_start(scenario) -> float:
    """Default track coordinate of the front wheelset at t = 0 [m]: the master's choice
    (:func:`orchestrator.cosim.passage.start_position`), so the SSP and ``turnout run`` agree."""
    from track.layout import build_layout

    sc = scenario
    if sc.simulation.x_start is not None:  # the default, not the scenario's value
        sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation, x_start=None))
    return passage.start_position(sc, build_layout(scenario.track.layout))


RUN_PARAMETERS = ("speed", "static_wheel_load", "extrapolate", "extrapolate_force")  # every track FMU has
                                                   # them (and bakes the scenario's values as their defaults)


def track_parameters(scenario) -> dict:
    """Parameter values of the track component (before filtering against the FMU).

    The run parameters (:data:`RUN_PARAMETERS`) and the bindings of the causes the
    registry maps onto global track-FMU parameters (:data:`orchestrator.inputs.causes.CATALOGUE`,
    ``fmu_parameters["global"]``: ``h1``, ``h2``, ``impact_angle``), with the scenario's
    values; they are bound only where the track FMU declares them (a plain-track FMU
    may have no impact angle).
    """
    v = scenario.vehicle
    values = {"speed": float(v.speed), "static_wheel_load": 0.5 * float(v.axle_load),
              "extrapolate": bool(scenario.simulation.extrapolation),
              "extrapolate_force": bool(scenario.simulation.extrapolation)}
    for kind in CATALOGUE.values():
        for name, value in zip(kind.fmu_parameters.get("global", ()), kind.nominal(scenario.raw, None)
                               if "global" in kind.fmu_parameters else ()):
            values[name] = float(value)
    return values


OWN_VEHICLE_PARAMETERS = ("speed", "axle_load", "x0")   # our vehicles' parameters the scenario always sets


def vehicle_parameters(scenario) -> dict:
    """Parameter values of the vehicle component (see the module docstring)."""
    veh, sim = scenario.vehicle, scenario.simulation
    start_values = dict(veh.start_values)
    if not veh.builtin:
        return start_values
    x0 = float(sim.x_start) if sim.x_start is not None else default_x_start(scenario)
    values = {"speed": float(veh.speed), "axle_load": float(veh.axle_load), "x0": x0}
    for key in OWN_VEHICLE_PARAMETERS:
        given = start_values.get(key, values[key])
        if isinstance(given, bool) or not isinstance(given, (int, float)) or float(given) != values[key]:
            where = {"speed": "vehicle.speed", "axle_load": "vehicle.axle_load", "x0": "simulation.x_start"}[key]
            raise UserInputError(f"vehicle.start_values: {key!r} = {start_values[key]!r} contradicts "
                                 f"{where} ({values[key]!r}); give it there only")
    values.update(start_values)
    return values


TRACK_RESOURCE = "resources/track_fmu.json"          # the track FMU's baked parameters (fmus.track_fmu)
START_VALUES_RESOURCE = "resources/start_values.json"  # a vehicle FMU's baked start values (fmus.base)


def _baked(fmu: Path, member: str):
    """The JSON resource ``member`` of ``fmu``; None if the file or the member is missing or unreadable."""
    try:
        with zipfile.ZipFile(fmu) as zf:
            return json.loads(zf.read(member))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None


def _as_json(value):
    """``value`` as it reads back from JSON (tuples become lists, ...), to compare with a baked resource."""
    return json.loads(json.dumps(value))


def _track_fmu_matches(fmu: Path, track_params, n_wheels: int, defaults: dict) -> bool:
    """True when ``fmu`` is a track FMU baked from ``track_params`` for ``n_wheels`` wheels, with
    ``defaults`` as the start values of its run parameters."""
    baked = _baked(fmu, TRACK_RESOURCE)
    if not isinstance(baked, dict):
        return False
    return (baked.get("n_wheels") == n_wheels and baked.get("track") == _as_json(dataclasses.asdict(track_params))
            and all(baked.get("defaults", {}).get(k) == v for k, v in _as_json(defaults).items()))


def _track_fmu(scenario, n_wheels: int, fmu_dir: Path | None, tmp: Path) -> Path:
    """The scenario's track FMU, its run parameters' start values the scenario's
    (:data:`RUN_PARAMETERS`): the one in ``fmu_dir`` if it matches, else built (into ``fmu_dir`` or ``tmp``)."""
    values = track_parameters(scenario)
    defaults = {k: values[k] for k in RUN_PARAMETERS}
    if fmu_dir is not None and _track_fmu_matches(Path(fmu_dir) / "track.fmu", scenario.track, n_wheels, defaults):
        return Path(fmu_dir) / "track.fmu"
    from fmus.build import build_track_fmu

    sim = scenario.simulation
    return Path(build_track_fmu(scenario.track, n_wheels, Path(fmu_dir) if fmu_dir is not None else tmp,
                                stop_time=float(sim.duration), step_size=float(sim.step), **defaults))


def _vehicle_fmu(scenario, values: dict, fmu_dir: Path | None, tmp: Path) -> Path:
    """The vehicle FMU: the third-party file, or ours with ``values`` (:func:`vehicle_parameters`)
    as its start values: from ``fmu_dir`` if its baked start values are ``values``, else built
    (into ``fmu_dir`` or ``tmp``).

    Our vehicle's ``x0``, ``speed`` and ``axle_load`` are always its parameters; the
    scenario's other ``vehicle.start_values`` are checked against the FMU's variables
    (:class:`UserInputError`) before they are baked in (against an FMU of this kind
    already in the folder, else against one built with the own values first).
    """
    kind = scenario.vehicle.fmu
    if not scenario.vehicle.builtin:
        path = Path(kind)
        if not path.is_file():
            raise UserInputError(f"vehicle.fmu: {kind}: file not found")
        return path
    from fmus.build import build_fmu

    sim = scenario.simulation
    out_dir = Path(fmu_dir) if fmu_dir is not None else tmp
    path = out_dir / f"{kind}.fmu"
    if _baked(path, START_VALUES_RESOURCE) == _as_json(values):
        return path
    own = {k: values[k] for k in OWN_VEHICLE_PARAMETERS}

    def build(start_values: dict) -> Path:
        return Path(build_fmu(kind, out_dir, stop_time=float(sim.duration), step_size=float(sim.step),
                              start_values=start_values))

    if own == values:
        return build(own)
    # extra start values: check them against the FMU's variables (the same in every FMU of
    # this kind) before they are baked in; the FMU bakes parameters only (an input's start
    # value arrives through the binding alone)
    variables = model_variables(path if path.is_file() else build(own))
    check_start_values(variables, scenario.vehicle.start_values, f"the {kind} FMU")
    baked = {k: v for k, v in values.items() if variables[k].causality == "parameter"}
    return build(baked) if _baked(path, START_VALUES_RESOURCE) != _as_json(baked) else path


def export_ssp(scenario, out_file: Path, fmu_dir: Path | None = None) -> Path:
    """Write the scenario's co-simulation system as an SSP file.

    Parameters
    ----------
    scenario : orchestrator.inputs.scenario.Scenario
    out_file : Path
        The ``.ssp`` file to write (its folder is created; an existing regular file is replaced,
        anything else there is refused). The system is named after ``scenario.name`` made an
        identifier (``crossing_1_12_through_120``; OMSimulator accepts no other names), and the
        name itself is its description.
    fmu_dir : Path, optional
        Folder of prebuilt FMUs, taken from there when they carry this scenario's values:
        ``bogie.fmu`` / ``quarter.fmu`` when their baked start values
        (``resources/start_values.json``) are :func:`vehicle_parameters`, ``track.fmu``
        when its baked track, number of wheels and run-parameter defaults
        (``resources/track_fmu.json``) are this scenario's; otherwise they are built into it
        (replacing the FMU of another scenario). Without it the FMUs are built in a
        temporary folder.

    Returns
    -------
    Path
        ``out_file``.

    Raises
    ------
    UserInputError
        A third-party FMU or a port/parameter name that does not fit, contradictory
        start values, a step that is not a whole number of nanoseconds.
    """
    out_file = Path(out_file)
    check_out_file(out_file)  # before the FMUs are built
    try:
        step_ns(scenario.simulation.step)
    except UserInputError as exc:
        raise UserInputError(f"simulation.step: {exc}") from None
    n = _n_wheels(scenario)
    vehicle_values = vehicle_parameters(scenario)
    if not scenario.vehicle.builtin:  # ports and start values against the FMU, before the track FMU is built
        check_vehicle_fmu(scenario.vehicle.fmu, scenario.vehicle.ports, vehicle_values)
    if scenario.vehicle.builtin:  # the wheels must stay on the modelled panel (as in `turnout run`)
        from track.layout import build_layout

        passage.check_passage(scenario, build_layout(scenario.track.layout), vehicle_values["x0"])
    with tempfile.TemporaryDirectory(prefix="xpanel_ssp_") as tmp:
        tmp = Path(tmp)
        vehicle_fmu = _vehicle_fmu(scenario, vehicle_values, fmu_dir, tmp)
        track_fmu = _track_fmu(scenario, n, fmu_dir, tmp)
        declared = model_variables(track_fmu)
        # the bindings only where the track FMU declares them; the run parameters are required
        track_values = {k: v for k, v in track_parameters(scenario).items()
                        if k in RUN_PARAMETERS or k in declared}
        components = [Component(VEHICLE, vehicle_fmu, vehicle_values),
                      Component(TRACK, track_fmu, track_values)]
        sim = scenario.simulation
        return write_ssp(out_file, components, system_connections(scenario), name=scenario.name,
                         start_time=0.0, stop_time=float(sim.duration), step_size=float(sim.step))


__all__ = ["export_ssp", "system_connections", "track_parameters", "vehicle_parameters", "default_x_start",
           "RUN_PARAMETERS"]
