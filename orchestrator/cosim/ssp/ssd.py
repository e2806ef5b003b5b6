"""The SSP format as this package writes and reads it: file and namespace names, the
system's data (:class:`Connection`, :class:`Component`, :class:`SspSystem`) and the time
unit of libcosim (whole nanoseconds, :func:`step_ns`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Mapping
from xml.etree import ElementTree as ET

from orchestrator.inputs.errors import UserInputError

SSD_FILE = "SystemStructure.ssd"
NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd",
}
OSP_ANNOTATION = "com.opensimulationplatform"   # libcosim's: the step of its fixed-step algorithm
OMS_ANNOTATION = "org.openmodelica"             # OMSimulator's: the system's kind and master algorithm
VEHICLE, TRACK = "vehicle", "track"
NS_PER_S = 1_000_000_000

for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


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
    """What :func:`orchestrator.cosim.ssp.reader.read_ssp` finds in an SSP file.

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
        The OSP ``baseStepSize`` annotation, else OMSimulator's ``FixedStepMaster`` ``stepSize``.
    """

    name: str
    sources: Dict[str, str]
    parameters: Dict[str, Dict[str, Any]]
    connectors: Dict[str, Dict[str, tuple]]
    connections: tuple
    start_time: float | None
    stop_time: float | None
    step_size: float | None


def qname(prefix: str, tag: str) -> str:
    """``{namespace}tag`` of ``prefix`` (a key of :data:`NS`), for ElementTree."""
    return f"{{{NS[prefix]}}}{tag}"


def step_ns(step: float) -> int:
    """The step [s] in whole nanoseconds (libcosim's time unit); :class:`UserInputError` if it is not."""
    ns = round(step * NS_PER_S)
    if ns <= 0 or abs(ns - step * NS_PER_S) > 1e-6 * max(1, ns):
        raise UserInputError(f"step {step!r} s is not a whole number of nanoseconds (libcosim's time unit)")
    return int(ns)


__all__ = ["SSD_FILE", "NS", "OSP_ANNOTATION", "OMS_ANNOTATION", "VEHICLE", "TRACK", "NS_PER_S", "Connection",
           "Component", "SspSystem", "qname", "step_ns"]
