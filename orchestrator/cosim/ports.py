"""Checks of a vehicle FMU against the ports and start values the scenario gives it (DESIGN.md §4.4).

Run when the FMU is loaded, before it is instantiated: a port mapped onto the wrong
kind of variable otherwise crashes the FMU or runs with wrong results and no message
(an ``Fz`` written into an output, a wheel ``z`` read from a parameter, a wheel left
unmapped whose force input keeps its start value). Each problem is a
:class:`~orchestrator.inputs.errors.UserInputError` naming the scenario key, the FMU
and the variable:

* every ``x``, ``z``, ``vz`` is a Real **output** and every ``Fz`` a Real **input** of
  the FMU (FMI 2.0 ``causality``);
* **count**: every continuous Real input of the FMU is some wheel's ``Fz`` (one
  ``ports`` entry per wheel; an input left out would keep its start value);
* **start values** name a parameter or input of the FMU and have its type (a
  string for a Real is refused here, not by a ``ValueError`` in the middle of a run).

The FMU itself must be a readable FMI 2.0 co-simulation FMU (:func:`read_fmu_description`).
"""
from __future__ import annotations

import math
import numbers
from pathlib import Path
from typing import Any, Mapping, Sequence

from orchestrator.inputs.errors import UserInputError, did_you_mean
from orchestrator.inputs.specs import PortMap

__all__ = ["read_fmu_description", "fmu_variables", "check_ports", "check_start_values", "check_vehicle_fmu"]

OUTPUT_PORTS = ("x", "z", "vz")  # the vehicle FMU's outputs per wheel (DESIGN.md §4.4)
INPUT_PORTS = ("Fz",)  # its input per wheel


def read_fmu_description(path: str | Path, what: str = "FMU"):
    """FMPy's model description of the FMI 2.0 co-simulation FMU at ``path``.

    Raises
    ------
    UserInputError
        Not a file, not a zip archive (empty, random bytes), no ``modelDescription.xml``,
        bad XML, another FMI version or no co-simulation interface.
    """
    from fmpy import read_model_description

    path = Path(path)
    if not path.is_file():
        raise UserInputError(f"{what} {path}: file not found")
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # zipfile.BadZipFile, KeyError (no modelDescription.xml), XML errors, ...
        reason = str(exc).strip() or type(exc).__name__
        raise UserInputError(f"{what} {path}: not a readable FMU (an FMU is a zip archive with a "
                             f"modelDescription.xml; {reason})") from None
    if md.fmiVersion != "2.0" or md.coSimulation is None:
        raise UserInputError(f"{what} {path}: needs to be an FMI 2.0 co-simulation FMU "
                             f"(fmiVersion {md.fmiVersion}, co-simulation: {md.coSimulation is not None})")
    return md


def fmu_variables(md) -> dict[str, Any]:
    """Model variables by name (FMPy ``ScalarVariable`` objects: ``type``, ``causality``, ``variability``)."""
    return {v.name: v for v in md.modelVariables}


def check_ports(variables: Mapping[str, Any], ports: Sequence[PortMap], fmu: str) -> None:
    """Each port's variable exists with the right causality, and the ports cover every force input.

    Parameters
    ----------
    variables : mapping of str to variable
        The FMU's variables by name; each has ``type``, ``causality`` and ``variability``.
    ports : sequence of PortMap
        One per wheel.
    fmu : str
        The FMU's name for messages.
    """
    for i, port in enumerate(ports):
        for attr in OUTPUT_PORTS + INPUT_PORTS:
            name = getattr(port, attr)
            key = f"vehicle.ports[{i}].{attr}"
            var = variables.get(name)
            if var is None:
                raise UserInputError(f"{key}: {fmu} has no variable {name!r}{did_you_mean(name, variables)}")
            wanted = "input" if attr in INPUT_PORTS else "output"
            if var.causality != wanted or var.type != "Real":
                role = "the contact force the track sets" if wanted == "input" else "a wheel signal the track reads"
                raise UserInputError(f"{key}: {name!r} of {fmu} is a {var.type} {var.causality}, but {attr} is "
                                     f"{role}: it must be a Real {wanted}")
    mapped = {p.Fz for p in ports}
    unmapped = [v.name for v in variables.values()
                if v.causality == "input" and v.type == "Real" and v.variability == "continuous"
                and v.name not in mapped]
    if unmapped:
        n_inputs = len(unmapped) + len(mapped)
        raise UserInputError(f"vehicle.ports: {fmu} has {n_inputs} Real inputs but the ports map {len(mapped)} "
                             f"as wheel forces; {unmapped[0]!r} would keep its start value. Give one ports entry "
                             f"per wheel (wheelset by wheelset, left then right)")


def check_start_values(variables: Mapping[str, Any], values: Mapping[str, Any], fmu: str,
                       key: str = "vehicle.start_values") -> None:
    """Each start value names a parameter or input of the FMU and fits its type."""
    for name, value in values.items():
        var = variables.get(name)
        where = f"{key}.{name}"
        if var is None:
            raise UserInputError(f"{where}: {fmu} has no variable {name!r}{did_you_mean(name, variables)}")
        if var.causality not in ("parameter", "input") or var.variability == "constant":
            raise UserInputError(f"{where}: {name!r} of {fmu} is a {var.variability} {var.causality}; only "
                                 "parameters and inputs take start values")
        if var.type == "Boolean":
            ok = isinstance(value, bool)
        elif var.type == "String":
            ok = isinstance(value, str)
        elif var.type in ("Integer", "Enumeration"):
            ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
        else:  # Real
            ok = isinstance(value, numbers.Real) and not isinstance(value, bool) and math.isfinite(value)
        if not ok:
            raise UserInputError(f"{where}: {name!r} of {fmu} is {var.type}, got {value!r}")


def check_vehicle_fmu(path: str | Path, ports: Sequence[PortMap], start_values: Mapping[str, Any]):
    """Read the vehicle FMU and check ``ports`` and ``start_values`` against it; returns its model description."""
    md = read_fmu_description(path, "vehicle.fmu:")
    variables = fmu_variables(md)
    fmu = Path(path).name
    check_ports(variables, ports, fmu)
    check_start_values(variables, start_values, fmu)
    return md
