"""Writing an SSP file (:func:`write_ssp`): the SSD, the parameter sets, the archive.

Generic: any FMI 2.0 co-simulation FMUs as components, their parameter values and the
connections; every name is checked against the FMUs' modelDescription first. The
scenario's own system is :func:`orchestrator.cosim.ssp.system.export_ssp`.
"""
from __future__ import annotations

import math
import os
import re
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Iterable, Mapping, Sequence
from xml.etree import ElementTree as ET

import numpy as np

from orchestrator.cosim.ports import read_fmu_description
from orchestrator.cosim.ssp.ssd import OMS_ANNOTATION, OSP_ANNOTATION, SSD_FILE, Component, Connection, qname, step_ns
from orchestrator.inputs.errors import UserInputError

_ZIP_DATE = (2000, 1, 1, 0, 0, 0)  # fixed member dates: the same input gives the same archive
_FILE_MODE = 0o666  # the archive's permissions before the umask, as open() gives a new file


def identifier(name: str) -> str:
    """``name`` as an identifier (letters, digits, ``_``; not starting with a digit).

    SSP tools address systems and elements by name, and some (OMSimulator) accept only
    identifiers there: ``crossing-1-12-through-120`` -> ``crossing_1_12_through_120``.
    """
    out = re.sub(r"\W", "_", str(name), flags=re.ASCII) or "system"
    return "_" + out if out[0].isdigit() else out


@dataclass(frozen=True)
class _Var:
    """A model variable of an FMU, as the writer checks it."""

    name: str
    type: str          # Real | Integer | Boolean | String | Enumeration
    causality: str
    variability: str
    initial: str | None
    unit: str | None
    value_reference: int


def model_variables(fmu: Path) -> Dict[str, _Var]:
    """The variables of an FMI 2.0 co-simulation FMU by name (:class:`UserInputError` for any other file)."""
    md = read_fmu_description(fmu)
    return {v.name: _Var(v.name, v.type, v.causality, v.variability, v.initial,
                         getattr(v, "unit", None) or (v.declaredType.unit if getattr(v, "declaredType", None)
                                                      else None), v.valueReference)
            for v in md.modelVariables}


def _unit_definitions(fmus: Iterable[Path]) -> Dict[str, Dict[str, float]]:
    """Unit name -> SI base-unit exponents (and factor/offset), from the FMUs' UnitDefinitions."""
    units: Dict[str, Dict[str, float]] = {}
    for fmu in fmus:
        for u in read_fmu_description(fmu).unitDefinitions:
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
    root = ET.Element(qname("ssv", "ParameterSet"), {"version": "1.0", "name": name})
    params = ET.SubElement(root, qname("ssv", "Parameters"))
    for pname, value in values.items():
        var = variables[pname]
        p = ET.SubElement(params, qname("ssv", "Parameter"), {"name": pname})
        attrs = {"value": _fmt(value, var.type)}
        if var.type == "Real" and var.unit:
            attrs["unit"] = var.unit
        ET.SubElement(p, qname("ssv", var.type), attrs)
    return root


def _xml_bytes(root: ET.Element) -> bytes:
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def write_ssp(out_file: Path, components: Sequence[Component], connections: Sequence[Connection], *,
              name: str, start_time: float = 0.0, stop_time: float | None = None,
              step_size: float | None = None) -> Path:
    """Write an SSP file: one ``ssd:Component`` per FMU (``resources/<name>.fmu``), its
    connected variables as connectors, its parameter values as ``resources/<name>.ssv``,
    the connections, a default experiment with the step in libcosim's (OSP) annotation,
    and the system's fixed-step master with the same step in OMSimulator's annotation
    (:func:`_add_master`).

    Every connection end and parameter name is checked against the FMU's
    modelDescription (causality, type): a mismatch raises :class:`UserInputError`.
    The system is named :func:`identifier` ``(name)``, and ``name`` itself is kept as
    the description of the SSD and of its system. ``out_file`` may be a new file or an
    existing regular file (replaced); anything else there (a folder, a device) is refused.
    """
    out_file = Path(out_file)
    check_out_file(out_file)
    names = [c.name for c in components]
    if len(set(names)) != len(names):
        raise ValueError(f"component names must be unique, got {names}")
    if any(identifier(n) != n for n in names):
        raise ValueError(f"component names must be identifiers, got {names}")
    variables = {c.name: model_variables(Path(c.fmu)) for c in components}
    connectors = _connectors(connections, variables)
    for c in components:
        for pname, value in c.parameters.items():
            _check_value(c.name, variables[c.name].get(pname), pname, value)
    root = ET.Element(qname("ssd", "SystemStructureDescription"),
                      {"version": "1.0", "name": identifier(name), "description": str(name),
                       "generationTool": "turnout-cosim (orchestrator.cosim.ssp)"})
    system = ET.SubElement(root, qname("ssd", "System"), {"name": identifier(name), "description": str(name)})
    used_units = _add_components(system, components, connectors, variables)
    _add_connections(system, connections)
    _add_master(system, step_size)
    _add_units(root, components, used_units)
    _add_experiment(root, start_time, stop_time, step_size)
    return _write_archive(out_file, root, components, variables)


def _connectors(connections: Sequence[Connection], variables: Mapping[str, Mapping[str, _Var]]
                ) -> Dict[str, Dict[str, str]]:
    """Every connected variable of each component, ``{component: {variable: "input" | "output"}}``,
    with its causality and type checked (:class:`UserInputError`) and no input connected twice."""
    connectors: Dict[str, Dict[str, str]] = {name: {} for name in variables}
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
    return connectors


def _add_components(system: ET.Element, components: Sequence[Component], connectors: Mapping[str, Mapping],
                    variables: Mapping[str, Mapping[str, _Var]]) -> set:
    """``ssd:Elements`` with one component each (connectors, parameter binding) under ``system``;
    returns the units the connectors and parameters use."""
    elements = ET.SubElement(system, qname("ssd", "Elements"))
    used_units = set()
    for c in components:
        comp = ET.SubElement(elements, qname("ssd", "Component"),
                             {"name": c.name, "type": "application/x-fmu-sharedlibrary",
                              "source": f"resources/{c.name}.fmu", "implementation": "CoSimulation"})
        if connectors[c.name]:
            cons = ET.SubElement(comp, qname("ssd", "Connectors"))
            for cname, kind in connectors[c.name].items():
                var = variables[c.name][cname]
                el = ET.SubElement(cons, qname("ssd", "Connector"), {"name": cname, "kind": kind})
                attrs = {}
                if var.type == "Real" and var.unit:
                    attrs["unit"] = var.unit
                    used_units.add(var.unit)
                ET.SubElement(el, qname("ssc", var.type), attrs)
        if c.parameters:
            binds = ET.SubElement(comp, qname("ssd", "ParameterBindings"))
            ET.SubElement(binds, qname("ssd", "ParameterBinding"),
                          {"type": "application/x-ssp-parameter-set", "source": f"resources/{c.name}.ssv"})
            used_units.update(variables[c.name][p].unit for p in c.parameters
                              if variables[c.name][p].type == "Real" and variables[c.name][p].unit)
    return used_units


def _add_connections(system: ET.Element, connections: Sequence[Connection]) -> None:
    """``ssd:Connections`` under ``system`` (a factor other than 1 as ``ssc:LinearTransformation``)."""
    if not connections:
        return
    conns = ET.SubElement(system, qname("ssd", "Connections"))
    for con in connections:
        el = ET.SubElement(conns, qname("ssd", "Connection"),
                           {"startElement": con.start_element, "startConnector": con.start_connector,
                            "endElement": con.end_element, "endConnector": con.end_connector})
        if con.factor != 1.0:
            ET.SubElement(el, qname("ssc", "LinearTransformation"), {"factor": repr(float(con.factor)),
                                                                     "offset": "0.0"})


def _add_units(root: ET.Element, components: Sequence[Component], used_units: set) -> None:
    """``ssd:Units`` under ``root``: the used units the FMUs define (SI base-unit exponents)."""
    defined = _unit_definitions(Path(c.fmu) for c in components)
    listed = sorted(u for u in used_units if u in defined)
    if listed:
        units = ET.SubElement(root, qname("ssd", "Units"))
        for u in listed:
            unit = ET.SubElement(units, qname("ssc", "Unit"), {"name": u})
            ET.SubElement(unit, qname("ssc", "BaseUnit"), {k: repr(v) if isinstance(v, float) else str(v)
                                                           for k, v in defined[u].items()})


def _add_experiment(root: ET.Element, start_time: float, stop_time: float | None,
                    step_size: float | None) -> None:
    """``ssd:DefaultExperiment`` under ``root``, the step [s] in the OSP annotation libcosim reads
    (:class:`UserInputError` if it is not a whole number of nanoseconds)."""
    exp_attrs = {"startTime": repr(float(start_time))}
    if stop_time is not None:
        exp_attrs["stopTime"] = repr(float(stop_time))
    exp = ET.SubElement(root, qname("ssd", "DefaultExperiment"), exp_attrs)
    if step_size is not None:
        step_ns(step_size)  # a whole number of nanoseconds, or UserInputError
        ann = ET.SubElement(ET.SubElement(exp, qname("ssd", "Annotations")), qname("ssc", "Annotation"),
                            {"type": OSP_ANNOTATION})
        ET.SubElement(ET.SubElement(ann, qname("osp", "Algorithm")), qname("osp", "FixedStepAlgorithm"),
                      {"baseStepSize": repr(float(step_size))})


OMS_MASTER = "oms-ma"        # OMSimulator's name of its fixed-step master algorithm
OMS_TOLERANCE = 1e-4         # OMSimulator's default tolerances; a fixed-step master of CS FMUs uses none


def _add_master(system: ET.Element, step_size: float | None) -> None:
    """The system's master algorithm for OMSimulator (``ssd:System/ssd:Annotations``), as
    OMSimulator writes it in the SSD files it exports::

        <ssc:Annotation type="org.openmodelica">
          <oms:Annotations>
            <oms:SimulationInformation>
              <oms:FixedStepMaster description="oms-ma" stepSize="2e-05" absoluteTolerance="0.0001"
                                   relativeTolerance="0.0001"/>

    OMSimulator takes the kind of a system from this annotation (a fixed-step master: a
    weakly coupled, co-simulation system); without it its import of the system fails.
    SSP 1.0 lets an annotation hold any element, so the file stays valid. Nothing is
    written without a step.
    """
    if step_size is None:
        return
    ann = ET.SubElement(ET.SubElement(system, qname("ssd", "Annotations")), qname("ssc", "Annotation"),
                        {"type": OMS_ANNOTATION})
    info = ET.SubElement(ET.SubElement(ann, qname("oms", "Annotations")), qname("oms", "SimulationInformation"))
    ET.SubElement(info, qname("oms", "FixedStepMaster"),
                  {"description": OMS_MASTER, "stepSize": repr(float(step_size)),
                   "absoluteTolerance": repr(OMS_TOLERANCE), "relativeTolerance": repr(OMS_TOLERANCE)})


def check_out_file(out_file: Path) -> None:
    """Refuse an ``out_file`` that exists and is not a regular file (a folder, a device, a pipe):
    writing the archive replaces what is there (:class:`UserInputError`)."""
    if out_file.exists() or out_file.is_symlink():
        if not out_file.is_file():
            kind = "a folder" if out_file.is_dir() else "not a regular file"
            raise UserInputError(f"{out_file}: exists and is {kind}; give a new path or an existing "
                                 ".ssp file to replace")


def _write_archive(out_file: Path, root: ET.Element, components: Sequence[Component],
                   variables: Mapping[str, Mapping[str, _Var]]) -> Path:
    """The zip: the SSD, each FMU and its parameter set; written to a temporary file and
    renamed, so ``out_file`` is never half written. Returns ``out_file``."""
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
        umask = os.umask(0)  # read the umask (there is no other portable way) and put it back
        os.umask(umask)
        os.chmod(tmp_name, _FILE_MODE & ~umask)  # mkstemp makes 0600; a written file is 0666 & ~umask
        check_out_file(out_file)  # again: something may have appeared there while writing
        os.replace(tmp_name, out_file)
    except BaseException:
        Path(tmp_name).unlink(missing_ok=True)
        raise
    return out_file


__all__ = ["write_ssp", "model_variables", "identifier", "check_out_file"]
