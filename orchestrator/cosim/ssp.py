"""The co-simulation system as an SSP file for other FMI tools (``turnout export-ssp``).

An SSP (System Structure and Parameterization, SSP 1.0) file is a zip archive::

    SystemStructure.ssd     the system: components, connectors, connections, default experiment
    resources/vehicle.fmu   the vehicle FMU (ours: bogie / quarter, or the scenario's third-party FMU)
    resources/track.fmu     the track FMU, built from the scenario's track
    resources/vehicle.ssv   parameter values of the vehicle (ssv:ParameterSet)
    resources/track.ssv     parameter values of the track

:func:`export_ssp` writes it for a scenario; :func:`write_ssp` is the generic writer
(components, parameter values, connections); :func:`read_ssp` reads back the subset of
SSP this module writes (plus inline parameter values). :func:`run_ssp_libcosim` and
:func:`run_ssp_fmpy` run an exported file and return time series.

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

With our vehicles the run must keep the wheels on the modelled panel over
``simulation.duration`` (the check of ``turnout run``, :func:`orchestrator.cosim.passage.check_passage`);
otherwise :class:`UserInputError`. A third-party vehicle's start position is its own
parameter and is not checked.

Default experiment: start 0, stop ``simulation.duration``, and the communication
step ``simulation.step`` in the OSP annotation that libcosim reads
(``ssd:DefaultExperiment/ssd:Annotations/ssc:Annotation[type="com.opensimulationplatform"]
/osp:Algorithm/osp:FixedStepAlgorithm@baseStepSize``); SSP 1.0 itself has no step size.

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
  log warning only; :func:`write_ssp` therefore checks every name against the FMU.
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
with FMPy). ``fmpy.ssp.simulation.simulate_ssp`` (FMPy 0.3.x) is not usable for this
system: it ignores the SSD's parameter bindings (only an explicit ``parameter_set``
argument is applied, and Booleans are set as ``value != 0.0``, so ``"false"`` becomes
true), ignores ``ssc:LinearTransformation`` (it looks for ``ssd:LinearTransformation``
and never applies it), starts every connected input at 0.0 (the vehicle's first step
sees no contact force, the track's sees every wheel at x = 0), skips the initialization-
mode exchange, ignores the OSP step size (default: stop time / 100) and steps while
``time < stop`` with accumulated ``time += h``. Run on the exported plain-track system
(``simulate_ssp(file, stop_time=0.002, step_size=2e-5)``) it starts the bogie at x = 0
instead of its ``x0`` (the rear wheelset off the panel) and the contact force grows to
2.1 times the static load within the 100 steps. :func:`run_ssp_fmpy` therefore uses
``read_ssd`` for parsing only and runs its own fixed-step Jacobi master with libcosim's
semantics (above) on ``fmpy.fmi2.FMU2Slave`` instances.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterable, Mapping, Sequence
from xml.etree import ElementTree as ET

import numpy as np

from orchestrator.inputs.errors import UserInputError

__all__ = [
    "Connection",
    "Component",
    "SspSystem",
    "export_ssp",
    "write_ssp",
    "read_ssp",
    "system_connections",
    "track_parameters",
    "vehicle_parameters",
    "default_x_start",
    "run_ssp_libcosim",
    "run_ssp_fmpy",
    "NS",
    "SSD_FILE",
]

SSD_FILE = "SystemStructure.ssd"
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
OSP_ANNOTATION = "com.opensimulationplatform"
VEHICLE, TRACK = "vehicle", "track"
N_WHEELS = {"bogie": 4, "quarter": 2}
NS_PER_S = 1_000_000_000
_ZIP_DATE = (2000, 1, 1, 0, 0, 0)  # fixed member dates: the same input gives the same archive

for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


# --------------------------------------------------------------------------------------
# Data
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Connection:
    """One SSD connection ``start_element.start_connector -> end_element.end_connector``.

    ``factor`` != 1 is written as ``ssc:LinearTransformation`` (end = factor * start).
    """

    start_element: str
    start_connector: str
    end_element: str
    end_connector: str
    factor: float = 1.0


@dataclass(frozen=True)
class Component:
    """A component of the system: an FMU and its parameter values (by variable name)."""

    name: str
    fmu: Path
    parameters: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class SspSystem:
    """What :func:`read_ssp` finds in an SSP file.

    Attributes
    ----------
    name : str
        System name.
    sources : dict
        Component name -> FMU path inside the archive (``resources/x.fmu``).
    parameters : dict
        Component name -> {variable name: value (float, int, bool or str)}.
    connectors : dict
        Component name -> {connector name: (kind, type)}.
    connections : tuple of Connection
    start_time, stop_time : float or None
        ``ssd:DefaultExperiment``.
    step_size : float or None
        The OSP ``baseStepSize`` annotation.
    """

    name: str
    sources: Dict[str, str]
    parameters: Dict[str, Dict[str, Any]]
    connectors: Dict[str, Dict[str, tuple]]
    connections: tuple
    start_time: float | None
    stop_time: float | None
    step_size: float | None


# --------------------------------------------------------------------------------------
# The scenario's system
# --------------------------------------------------------------------------------------
def _n_wheels(scenario) -> int:
    veh = scenario.vehicle
    if veh.builtin:
        return N_WHEELS[veh.fmu]
    if not veh.ports:
        raise UserInputError(f"vehicle.ports: the third-party vehicle FMU {veh.fmu} needs one ports entry "
                             "per wheel (DESIGN.md 4.4)")
    return len(veh.ports)


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

    from orchestrator.cosim.passage import start_position

    sc = scenario
    if sc.simulation.x_start is not None:  # the default, not the scenario's value
        import dataclasses
        sc = dataclasses.replace(sc, simulation=dataclasses.replace(sc.simulation, x_start=None))
    return start_position(sc, build_layout(scenario.track.layout))


def track_parameters(scenario) -> dict:
    """Parameter values of the track component (before filtering against the FMU)."""
    t, v = scenario.track, scenario.vehicle
    return {"speed": float(v.speed), "static_wheel_load": 0.5 * float(v.axle_load),
            "extrapolate": bool(scenario.simulation.extrapolation),
            "extrapolate_force": bool(scenario.simulation.extrapolation),
            "h1": float(t.ballast.stiffness_scale), "h2": float(t.rail_pad.stiffness_scale),
            "impact_angle": float(t.impact_angle)}


def vehicle_parameters(scenario) -> dict:
    """Parameter values of the vehicle component (see the module docstring)."""
    veh, sim = scenario.vehicle, scenario.simulation
    start_values = dict(veh.start_values)
    if not veh.builtin:
        return start_values
    x0 = float(sim.x_start) if sim.x_start is not None else default_x_start(scenario)
    values = {"speed": float(veh.speed), "axle_load": float(veh.axle_load), "x0": x0}
    for key in ("speed", "axle_load", "x0"):
        given = start_values.get(key, values[key])
        if isinstance(given, bool) or not isinstance(given, (int, float)) or float(given) != values[key]:
            where = {"speed": "vehicle.speed", "axle_load": "vehicle.axle_load", "x0": "simulation.x_start"}[key]
            raise UserInputError(f"vehicle.start_values: {key!r} = {start_values[key]!r} contradicts "
                                 f"{where} ({values[key]!r}); give it there only")
    values.update(start_values)
    return values


TRACK_RESOURCE = "resources/track_fmu.json"  # the track FMU's baked parameters (fmus.track_fmu)


def _track_fmu_matches(fmu: Path, track_params, n_wheels: int) -> bool:
    """True when ``fmu`` is a track FMU baked from ``track_params`` for ``n_wheels`` wheels."""
    try:
        with zipfile.ZipFile(fmu) as zf:
            baked = json.loads(zf.read(TRACK_RESOURCE))
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return False
    wanted = json.loads(json.dumps(dataclasses.asdict(track_params)))
    return baked.get("n_wheels") == n_wheels and baked.get("track") == wanted


def _track_fmu(scenario, n_wheels: int, fmu_dir: Path | None, tmp: Path) -> Path:
    if fmu_dir is not None and _track_fmu_matches(Path(fmu_dir) / "track.fmu", scenario.track, n_wheels):
        return Path(fmu_dir) / "track.fmu"
    from fmus.build import build_track_fmu

    values = track_parameters(scenario)
    defaults = {k: values[k] for k in ("speed", "static_wheel_load", "extrapolate", "extrapolate_force")}
    return Path(build_track_fmu(scenario.track, n_wheels, Path(fmu_dir) if fmu_dir is not None else tmp,
                                **defaults))


def _vehicle_fmu(scenario, fmu_dir: Path | None, tmp: Path) -> Path:
    kind = scenario.vehicle.fmu
    if not scenario.vehicle.builtin:
        path = Path(kind)
        if not path.is_file():
            raise UserInputError(f"vehicle.fmu: {kind}: file not found")
        return path
    if fmu_dir is not None and (Path(fmu_dir) / f"{kind}.fmu").is_file():
        return Path(fmu_dir) / f"{kind}.fmu"
    from fmus.build import build_fmu

    return Path(build_fmu(kind, Path(fmu_dir) if fmu_dir is not None else tmp))


def export_ssp(scenario, out_file: Path, fmu_dir: Path | None = None) -> Path:
    """Write the scenario's co-simulation system as an SSP file.

    Parameters
    ----------
    scenario : orchestrator.inputs.scenario.Scenario
    out_file : Path
        The ``.ssp`` file to write (its folder is created; an existing file is replaced).
    fmu_dir : Path, optional
        Folder of prebuilt FMUs: ``bogie.fmu`` / ``quarter.fmu`` are taken from there when
        present, and ``track.fmu`` when its baked parameters (``resources/track_fmu.json``)
        are this scenario's track and number of wheels; otherwise they are built into it
        (replacing a ``track.fmu`` of another track). Without it the FMUs are built in a
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
    try:
        _step_ns(scenario.simulation.step)
    except UserInputError as exc:
        raise UserInputError(f"simulation.step: {exc}") from None
    n = _n_wheels(scenario)
    vehicle_values = vehicle_parameters(scenario)
    if scenario.vehicle.builtin:  # the wheels must stay on the modelled panel (as in `turnout run`)
        from track.layout import build_layout

        from orchestrator.cosim.passage import check_passage

        check_passage(scenario, build_layout(scenario.track.layout), vehicle_values["x0"])
    with tempfile.TemporaryDirectory(prefix="xpanel_ssp_") as tmp:
        tmp = Path(tmp)
        vehicle_fmu = _vehicle_fmu(scenario, fmu_dir, tmp)
        track_fmu = _track_fmu(scenario, n, fmu_dir, tmp)
        track_md = _model_variables(track_fmu)
        # h1, h2, impact_angle: only the ones the track FMU declares (a plain-track FMU
        # may have no impact angle); the others are required
        optional = {"h1", "h2", "impact_angle"}
        track_values = {k: v for k, v in track_parameters(scenario).items()
                        if k not in optional or k in track_md}
        components = [Component(VEHICLE, vehicle_fmu, vehicle_values),
                      Component(TRACK, track_fmu, track_values)]
        sim = scenario.simulation
        return write_ssp(out_file, components, system_connections(scenario), name=scenario.name,
                         start_time=0.0, stop_time=float(sim.duration), step_size=float(sim.step))


# --------------------------------------------------------------------------------------
# Generic writer
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Var:
    name: str
    type: str          # Real | Integer | Boolean | String | Enumeration
    causality: str
    variability: str
    initial: str | None
    unit: str | None
    value_reference: int


def _model_description(fmu: Path):
    from fmpy import read_model_description

    try:
        return read_model_description(str(fmu), validate=False)
    except Exception as exc:  # not a zip, no modelDescription.xml, bad XML
        raise UserInputError(f"{fmu}: not a readable FMU ({exc})") from None


def _model_variables(fmu: Path) -> Dict[str, _Var]:
    md = _model_description(fmu)
    if md.fmiVersion != "2.0" or md.coSimulation is None:
        raise UserInputError(f"{fmu}: needs to be an FMI 2.0 co-simulation FMU "
                             f"(fmiVersion {md.fmiVersion}, co-simulation: {md.coSimulation is not None})")
    return {v.name: _Var(v.name, v.type, v.causality, v.variability, v.initial,
                         getattr(v, "unit", None) or (v.declaredType.unit if getattr(v, "declaredType", None)
                                                      else None), v.valueReference)
            for v in md.modelVariables}


def _unit_definitions(fmus: Iterable[Path]) -> Dict[str, Dict[str, float]]:
    """Unit name -> SI base-unit exponents (and factor/offset), from the FMUs' UnitDefinitions."""
    units: Dict[str, Dict[str, float]] = {}
    for fmu in fmus:
        for u in _model_description(fmu).unitDefinitions:
            b = u.baseUnit
            if b is None:
                continue
            attrs = {k: getattr(b, k) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
                     if getattr(b, k, 0)}
            if getattr(b, "factor", 1.0) != 1.0:
                attrs["factor"] = b.factor
            if getattr(b, "offset", 0.0) != 0.0:
                attrs["offset"] = b.offset
            units.setdefault(u.name, attrs)
    return units


def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _fmt(value: Any, vtype: str) -> str:
    if vtype == "Boolean":
        return "true" if value else "false"
    if vtype in ("Integer", "Enumeration"):
        return str(int(value))
    if vtype == "Real":
        return repr(float(value))
    return str(value)


def _check_value(component: str, var: _Var | None, name: str, value: Any) -> None:
    if var is None:
        raise UserInputError(f"{component}: the FMU has no variable {name!r} to set")
    if var.causality not in ("parameter", "input") or var.variability == "constant" \
            or var.initial == "calculated":
        raise UserInputError(f"{component}: variable {name!r} (causality {var.causality}, variability "
                             f"{var.variability}) cannot be given a start value")
    if var.type == "Boolean":
        if not isinstance(value, (bool, np.bool_)) and value not in (0, 1):
            raise UserInputError(f"{component}: {name!r} is Boolean, got {value!r}")
    elif var.type in ("Real", "Integer", "Enumeration"):
        if isinstance(value, (bool, str)) or not isinstance(value, (int, float, np.number)):
            raise UserInputError(f"{component}: {name!r} is {var.type}, got {value!r}")
        if not math.isfinite(float(value)):
            raise UserInputError(f"{component}: {name!r} must be finite, got {value!r}")
        if var.type != "Real" and float(value) != int(value):
            raise UserInputError(f"{component}: {name!r} is {var.type}, got {value!r}")
    elif not isinstance(value, str):
        raise UserInputError(f"{component}: {name!r} is a String, got {value!r}")


def _parameter_set(name: str, values: Mapping[str, Any], variables: Mapping[str, _Var]) -> ET.Element:
    root = ET.Element(_q("ssv", "ParameterSet"), {"version": "1.0", "name": name})
    params = ET.SubElement(root, _q("ssv", "Parameters"))
    for pname, value in values.items():
        var = variables[pname]
        p = ET.SubElement(params, _q("ssv", "Parameter"), {"name": pname})
        attrs = {"value": _fmt(value, var.type)}
        if var.type == "Real" and var.unit:
            attrs["unit"] = var.unit
        ET.SubElement(p, _q("ssv", var.type), attrs)
    return root


def _xml_bytes(root: ET.Element) -> bytes:
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def write_ssp(out_file: Path, components: Sequence[Component], connections: Sequence[Connection], *,
              name: str, start_time: float = 0.0, stop_time: float | None = None,
              step_size: float | None = None) -> Path:
    """Write an SSP file: one ``ssd:Component`` per FMU (``resources/<name>.fmu``), its
    connected variables as connectors, its parameter values as ``resources/<name>.ssv``,
    the connections, and a default experiment with the OSP step-size annotation.

    Every connection end and parameter name is checked against the FMU's
    modelDescription (causality, type): a mismatch raises :class:`UserInputError`.
    """
    out_file = Path(out_file)
    names = [c.name for c in components]
    if len(set(names)) != len(names):
        raise ValueError(f"component names must be unique, got {names}")
    variables = {c.name: _model_variables(Path(c.fmu)) for c in components}

    # connectors: every connected variable, with its causality checked
    connectors: Dict[str, Dict[str, str]] = {c.name: {} for c in components}
    seen_inputs = set()
    for con in connections:
        for elem, conn, kind in ((con.start_element, con.start_connector, "output"),
                                 (con.end_element, con.end_connector, "input")):
            if elem not in variables:
                raise ValueError(f"connection {con}: no component {elem!r}")
            var = variables[elem].get(conn)
            if var is None:
                raise UserInputError(f"{elem}: the FMU has no variable {conn!r} (connection "
                                     f"{con.start_element}.{con.start_connector} -> "
                                     f"{con.end_element}.{con.end_connector})")
            if var.causality != kind:
                raise UserInputError(f"{elem}: variable {conn!r} has causality {var.causality}, "
                                     f"a connection needs an {kind} there")
            if var.type != "Real" and con.factor != 1.0:
                raise UserInputError(f"{elem}.{conn}: a sign flip needs a Real variable, it is {var.type}")
            connectors[elem][conn] = kind
        if (con.end_element, con.end_connector) in seen_inputs:
            raise ValueError(f"input {con.end_element}.{con.end_connector} is connected twice")
        seen_inputs.add((con.end_element, con.end_connector))
    for c in components:
        for pname, value in c.parameters.items():
            _check_value(c.name, variables[c.name].get(pname), pname, value)

    root = ET.Element(_q("ssd", "SystemStructureDescription"),
                      {"version": "1.0", "name": name, "generationTool": "turnout-cosim (orchestrator.cosim.ssp)"})
    system = ET.SubElement(root, _q("ssd", "System"), {"name": name})
    elements = ET.SubElement(system, _q("ssd", "Elements"))
    used_units = set()
    for c in components:
        comp = ET.SubElement(elements, _q("ssd", "Component"),
                             {"name": c.name, "type": "application/x-fmu-sharedlibrary",
                              "source": f"resources/{c.name}.fmu", "implementation": "CoSimulation"})
        if connectors[c.name]:
            cons = ET.SubElement(comp, _q("ssd", "Connectors"))
            for cname, kind in connectors[c.name].items():
                var = variables[c.name][cname]
                el = ET.SubElement(cons, _q("ssd", "Connector"), {"name": cname, "kind": kind})
                attrs = {}
                if var.type == "Real" and var.unit:
                    attrs["unit"] = var.unit
                    used_units.add(var.unit)
                ET.SubElement(el, _q("ssc", var.type), attrs)
        if c.parameters:
            binds = ET.SubElement(comp, _q("ssd", "ParameterBindings"))
            ET.SubElement(binds, _q("ssd", "ParameterBinding"),
                          {"type": "application/x-ssp-parameter-set", "source": f"resources/{c.name}.ssv"})
            used_units.update(variables[c.name][p].unit for p in c.parameters
                              if variables[c.name][p].type == "Real" and variables[c.name][p].unit)
    if connections:
        conns = ET.SubElement(system, _q("ssd", "Connections"))
        for con in connections:
            el = ET.SubElement(conns, _q("ssd", "Connection"),
                               {"startElement": con.start_element, "startConnector": con.start_connector,
                                "endElement": con.end_element, "endConnector": con.end_connector})
            if con.factor != 1.0:
                ET.SubElement(el, _q("ssc", "LinearTransformation"), {"factor": repr(float(con.factor)),
                                                                      "offset": "0.0"})
    defined = _unit_definitions(Path(c.fmu) for c in components)
    listed = sorted(u for u in used_units if u in defined)
    if listed:
        units = ET.SubElement(root, _q("ssd", "Units"))
        for u in listed:
            unit = ET.SubElement(units, _q("ssc", "Unit"), {"name": u})
            ET.SubElement(unit, _q("ssc", "BaseUnit"), {k: repr(v) if isinstance(v, float) else str(v)
                                                        for k, v in defined[u].items()})
    exp_attrs = {"startTime": repr(float(start_time))}
    if stop_time is not None:
        exp_attrs["stopTime"] = repr(float(stop_time))
    exp = ET.SubElement(root, _q("ssd", "DefaultExperiment"), exp_attrs)
    if step_size is not None:
        _step_ns(step_size)  # a whole number of nanoseconds, or UserInputError
        ann = ET.SubElement(ET.SubElement(exp, _q("ssd", "Annotations")), _q("ssc", "Annotation"),
                            {"type": OSP_ANNOTATION})
        ET.SubElement(ET.SubElement(ann, _q("osp", "Algorithm")), _q("osp", "FixedStepAlgorithm"),
                      {"baseStepSize": repr(float(step_size))})

    out_file.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=out_file.name + ".", suffix=".tmp", dir=out_file.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(tmp_name, "w") as zf:
            def put(arcname: str, data: bytes, compress: int = zipfile.ZIP_DEFLATED) -> None:
                info = zipfile.ZipInfo(arcname, _ZIP_DATE)
                info.compress_type = compress
                info.external_attr = 0o644 << 16
                zf.writestr(info, data)

            put(SSD_FILE, _xml_bytes(root))
            for c in components:
                put(f"resources/{c.name}.fmu", Path(c.fmu).read_bytes(), zipfile.ZIP_STORED)
                if c.parameters:
                    put(f"resources/{c.name}.ssv",
                        _xml_bytes(_parameter_set(f"{c.name}_parameters", c.parameters, variables[c.name])))
        os.replace(tmp_name, out_file)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return out_file


# --------------------------------------------------------------------------------------
# Reader (the subset written above, plus inline ParameterValues)
# --------------------------------------------------------------------------------------
def _parse_value(el: ET.Element) -> tuple[str, Any]:
    vtype = el.tag.split("}")[1]
    text = el.get("value")
    if vtype == "Real":
        return vtype, float(text)
    if vtype in ("Integer", "Enumeration"):
        return vtype, int(text)
    if vtype == "Boolean":
        if text.strip() not in ("true", "false", "1", "0"):
            raise ValueError(f"invalid Boolean value {text!r}")
        return vtype, text.strip() in ("true", "1")
    return vtype, text


def _read_parameter_set(el: ET.Element) -> Dict[str, Any]:
    out = {}
    for p in el.findall("ssv:Parameters/ssv:Parameter", NS):
        value_el = next(iter(p))
        out[p.get("name")] = _parse_value(value_el)[1]
    return out


def read_ssp(ssp_file: Path) -> SspSystem:
    """Read an SSP file (zip) written by :func:`write_ssp` (flat system, FMU components)."""
    with zipfile.ZipFile(ssp_file) as zf:
        root = ET.fromstring(zf.read(SSD_FILE))
        system = root.find("ssd:System", NS)
        sources, params, connectors = {}, {}, {}
        for comp in system.findall("ssd:Elements/ssd:Component", NS):
            cname = comp.get("name")
            sources[cname] = comp.get("source")
            connectors[cname] = {c.get("name"): (c.get("kind"), next(iter(c)).tag.split("}")[1])
                                 for c in comp.findall("ssd:Connectors/ssd:Connector", NS)}
            values: Dict[str, Any] = {}
            for b in comp.findall("ssd:ParameterBindings/ssd:ParameterBinding", NS):
                if b.get("source"):
                    ps = ET.fromstring(zf.read(b.get("source")))
                    values.update(_read_parameter_set(ps))
                for ps in b.findall("ssd:ParameterValues/ssv:ParameterSet", NS):
                    values.update(_read_parameter_set(ps))
            params[cname] = values
        connections = []
        for c in system.findall("ssd:Connections/ssd:Connection", NS):
            lt = c.find("ssc:LinearTransformation", NS)
            factor = float(lt.get("factor", "1")) if lt is not None else 1.0
            if lt is not None and float(lt.get("offset", "0")) != 0.0:
                raise ValueError("LinearTransformation offsets are not supported by read_ssp")
            connections.append(Connection(c.get("startElement"), c.get("startConnector"),
                                          c.get("endElement"), c.get("endConnector"), factor))
        exp = root.find("ssd:DefaultExperiment", NS)
        start = stop = step = None
        if exp is not None:
            start = float(exp.get("startTime")) if exp.get("startTime") else None
            stop = float(exp.get("stopTime")) if exp.get("stopTime") else None
            for ann in exp.findall("ssd:Annotations/ssc:Annotation", NS):
                if ann.get("type") == OSP_ANNOTATION:
                    fs = ann.find("osp:Algorithm/osp:FixedStepAlgorithm", NS)
                    if fs is not None:
                        step = float(fs.get("baseStepSize"))
    return SspSystem(root.get("name"), sources, params, connectors, tuple(connections), start, stop, step)


# --------------------------------------------------------------------------------------
# Runners
# --------------------------------------------------------------------------------------
def _step_ns(step: float) -> int:
    ns = round(step * NS_PER_S)
    if ns <= 0 or abs(ns - step * NS_PER_S) > 1e-6 * max(1, ns):
        raise UserInputError(f"step {step!r} s is not a whole number of nanoseconds (libcosim's time unit)")
    return int(ns)


def _n_steps(step: float, duration: float) -> int:
    if not (step > 0 and duration > 0):
        raise ValueError(f"step and duration must be positive, got {step}, {duration}")
    return max(1, math.ceil(duration / step * (1.0 - 1e-9)))


def _split(name: str) -> tuple[str, str]:
    comp, _, var = name.partition(".")
    if not var:
        raise ValueError(f"record: {name!r} is not of the form component.variable")
    return comp, var


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
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver
    from libcosimpy._internal import get_last_error_message

    log_output_level(CosimLogLevel[log_level.upper()])
    step_ns = _step_ns(step)
    n = _n_steps(step, duration)
    try:
        execution = CosimExecution.from_ssp_file(str(Path(ssp_file).resolve()), step_ns)
    except AssertionError:
        raise RuntimeError(f"libcosim cannot load {ssp_file}: {get_last_error_message()}") from None
    observer = CosimObserver.create_last_value()
    execution.add_observer(observer)

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

    kept = n // output_every
    out = {name: np.empty(kept) for name in record}
    times = np.empty(kept)
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
    execution.stop()
    return {"time": times, **out}


class _FmpyMaster:
    """Fixed-step Jacobi master over FMPy FMU2Slave instances with libcosim's semantics."""

    def __init__(self, ssp_file: Path, unzip_dir: Path):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        from fmpy.ssp.ssd import read_ssd

        read_ssd(str(ssp_file), validate=True)  # FMPy's reader + SSP 1.0 schema check
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
    """Run an SSP file written by :func:`write_ssp` with FMPy and a fixed-step Jacobi
    master that follows libcosim's semantics (see the module docstring: FMPy's own
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
        kept = n // output_every
        out = {name: np.empty(kept) for name in record}
        times = np.empty(kept)
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
