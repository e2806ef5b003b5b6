"""Reading an SSP file back (:func:`read_ssp`): the subset :mod:`orchestrator.cosim.ssp.writer`
writes, plus inline parameter values."""
from __future__ import annotations

import zipfile
from pathlib import Path
from typing import Any, Dict
from xml.etree import ElementTree as ET

from orchestrator.cosim.ssp.ssd import NS, OMS_ANNOTATION, OSP_ANNOTATION, SSD_FILE, Connection, SspSystem


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


def _step_size(experiment: ET.Element | None, system: ET.Element) -> float | None:
    """The communication step [s]: libcosim's (OSP) annotation of the default experiment,
    else OMSimulator's fixed-step master of the system; None if neither is there."""
    for ann in experiment.findall("ssd:Annotations/ssc:Annotation", NS) if experiment is not None else ():
        fs = ann.find("osp:Algorithm/osp:FixedStepAlgorithm", NS)
        if ann.get("type") == OSP_ANNOTATION and fs is not None:
            return float(fs.get("baseStepSize"))
    for ann in system.findall("ssd:Annotations/ssc:Annotation", NS):
        fs = ann.find("oms:Annotations/oms:SimulationInformation/oms:FixedStepMaster", NS)
        if ann.get("type") == OMS_ANNOTATION and fs is not None and fs.get("stepSize"):
            return float(fs.get("stepSize"))
    return None


def read_ssp(ssp_file: Path) -> SspSystem:
    """Read an SSP file (zip) written by :func:`orchestrator.cosim.ssp.writer.write_ssp` (flat system,
    FMU components)."""
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
        start = stop = None
        if exp is not None:
            start = float(exp.get("startTime")) if exp.get("startTime") else None
            stop = float(exp.get("stopTime")) if exp.get("stopTime") else None
        step = _step_size(exp, system)
    return SspSystem(root.get("name"), sources, params, connectors, tuple(connections), start, stop, step)


__all__ = ["read_ssp"]
