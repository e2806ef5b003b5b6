"""The co-simulation system as an SSP file for other FMI tools (``turnout export-ssp``).

An SSP (System Structure and Parameterization, SSP 1.0) file is a zip archive::

    SystemStructure.ssd     the system: components, connectors, connections, default experiment
    resources/vehicle.fmu   the vehicle FMU (ours: bogie / quarter, or the scenario's third-party FMU)
    resources/track.fmu     the track FMU, built from the scenario's track
    resources/vehicle.ssv   parameter values of the vehicle (ssv:ParameterSet)
    resources/track.ssv     parameter values of the track

Modules, along the way a file is made and used:

- :mod:`~orchestrator.cosim.ssp.ssd`: the format's names and data (:class:`Connection`,
  :class:`Component`, :class:`SspSystem`);
- :mod:`~orchestrator.cosim.ssp.system`: the scenario's system (components, parameter
  values, connections; the system and its parameters are described there) and
  :func:`export_ssp`;
- :mod:`~orchestrator.cosim.ssp.writer`: :func:`write_ssp`, the generic writer
  (components, parameter values, connections);
- :mod:`~orchestrator.cosim.ssp.reader`: :func:`read_ssp` reads back the subset of SSP
  the writer writes (plus inline parameter values);
- :mod:`~orchestrator.cosim.ssp.runners`: :func:`run_ssp_libcosim` and
  :func:`run_ssp_fmpy` run an exported file and return time series (what libcosim and
  FMPy do with such a file is described there).
"""
from orchestrator.cosim.ssp.reader import read_ssp
from orchestrator.cosim.ssp.runners import run_ssp_fmpy, run_ssp_libcosim
from orchestrator.cosim.ssp.ssd import NS, SSD_FILE, Component, Connection, SspSystem
from orchestrator.cosim.ssp.system import (
                                           default_x_start,
                                           export_ssp,
                                           system_connections,
                                           track_parameters,
                                           vehicle_parameters,
)
from orchestrator.cosim.ssp.writer import write_ssp

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
