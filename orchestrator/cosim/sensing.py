"""Run a scenario and read its virtual sensors (the simulated side of every comparison).

:func:`simulate_sensors` runs the co-simulation in-process (the same model objects as
the FMUs; :mod:`orchestrator.cosim.master`), records the columns of the track states that
the layout's sensors read (:func:`sensor_columns`) at the output step and reads the
sensors from them (:func:`read_sensors`, :mod:`track.sensors`). :func:`sensors_job` is the
top-level (picklable) form that diagnosis sends to worker processes: it takes the
scenario by value (:class:`orchestrator.cosim.portable.PortableScenario`).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from orchestrator.cosim.portable import PortableScenario
from orchestrator.inputs.sensor_layout import SensorLayout, layout_of, resolve
from track.cosim import state_rows
from track.sensors import CompiledSensors, compile_sensors, displacement_from_acceleration, sensor_signals

SENSOR_BLOCK = 128        # output steps per block of virtual-sensor reading (bounds its temporaries: q, v, a
                          # at full width, 1.8 MB each for 1741 dofs; 500 made the run's peak memory 45 MB higher)


@dataclass
class SensorRun:
    """Simulated sensor signals of one run.

    Attributes
    ----------
    t : ndarray, shape (nt,)
        [s].
    signals : dict
        Sensor id -> signal (nt,), SI units.
    error : str or None
        Why the run stopped early (the signals then end there).
    """

    t: np.ndarray
    signals: dict
    error: str | None = None


def sensor_columns(model, compiled: CompiledSensors) -> dict:
    """The columns of the track states that the sensors read (a ``record_columns`` request).

    Strain rows read q, accelerometers a, pressure cells the ballast bushings under them
    (their sleeper node's q and v).

    Returns
    -------
    dict
        ``{"q": ..., "v": ..., "a": ...}``, sorted column indices (ndarray of int).
    """
    bushings = np.flatnonzero(np.any(compiled.Pb != 0.0, axis=0))
    D = np.unique(model.ballast.dof[bushings])
    return {"q": np.union1d(np.flatnonzero(np.any(compiled.Cq != 0.0, axis=0)), D), "v": D,
            "a": np.flatnonzero(np.any(compiled.Ca != 0.0, axis=0))}


def read_sensors(model, compiled: CompiledSensors, record: dict, dt: float, highpass: float,
                 reconstruct: bool = True) -> dict:
    """The sensors' signals from a track record (all columns, or those of :func:`sensor_columns`).

    Read in blocks of :data:`SENSOR_BLOCK` output steps (a record of some columns as it is:
    ``sensor_signals(columns=...)``; one of all columns as full-width rows); displacement
    sensors are then reconstructed from their accelerometer's whole signal
    (:func:`track.sensors.displacement_from_acceleration`),
    as :func:`track.sensors.sensor_signals` does in one go.

    Parameters
    ----------
    model : TrackModel
    compiled : track.sensors.CompiledSensors
    record : dict
        ``t`` and ``q``, ``v``, ``a`` (``track.cosim.Record.arrays``).
    dt : float
        Output step [s].
    highpass : float
        Corner of the displacement reconstruction [Hz].
    reconstruct : bool
        ``False``: displacement sensors give their accelerometer's signal [m/s^2].

    Returns
    -------
    dict
        Sensor id -> signal (nt,), SI units.
    """
    n, nt = model.n, len(record["t"])
    columns = {k: record.get(f"{k}_columns") for k in ("q", "v", "a")}
    some = all(c is not None for c in columns.values())   # a record of some columns: read as they are
    blocks = []
    for b in range(0, nt, SENSOR_BLOCK):
        rows = slice(b, b + SENSOR_BLOCK)
        q, v, a = (record[k][rows] if some else state_rows(record, k, n, rows) for k in ("q", "v", "a"))
        blocks.append(sensor_signals(model, compiled, q, v, a, dt, highpass, reconstruct=False,
                                     columns=columns if some else None))
    out = {}
    for s in compiled.sensors:
        sig = np.concatenate([blk[s.id] for blk in blocks]) if blocks else np.empty(0)
        out[s.id] = displacement_from_acceleration(sig, dt, highpass) \
            if reconstruct and s.type == "displacement" else sig
    return out


def simulate_sensors(scenario, layout: SensorLayout | None = None, reconstruct: bool = True) -> SensorRun:
    """Co-simulate ``scenario`` in-process and read its sensors at every output step.

    The track records only what the sensors read (:func:`sensor_columns`).  With
    ``reconstruct=False`` displacement sensors give their accelerometer's signal
    [m/s^2]: :func:`orchestrator.inverse.objective.compare` and the synthetic measurements
    reconstruct the displacement on the measured time base, the window the
    measurement's own reconstruction used.
    """
    from orchestrator.cosim.master import run_cosim
    from orchestrator.inputs.track_model import track_model

    layout = layout_of(scenario) if layout is None else layout
    model = track_model(scenario.track)   # the bodies are cached: the run's own build reuses them
    compiled = compile_sensors(model, resolve(layout, model))
    res = run_cosim(scenario, backend="inprocess", record_states=True,
                    record_columns=sensor_columns(model, compiled))
    rec = res.track_record
    t = np.asarray(rec["t"], float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else scenario.simulation.output_step
    sig = read_sensors(model, compiled, rec, dt, layout.displacement_highpass, reconstruct)
    return SensorRun(t, sig, res.error)


def variant_for_speed(raw: dict, speed: float) -> dict:
    """A raw scenario at another speed [m/s], over the same stretch of track (duration scaled)."""
    raw = copy.deepcopy(raw)
    v0 = float(raw["vehicle"]["speed"])
    raw["vehicle"]["speed"] = float(speed)
    sim = raw["simulation"]
    every = max(1, int(round(sim["output_step"] / sim["step"])))
    dur = sim["duration"] * v0 / speed
    sim["duration"] = float(np.floor(dur / (every * sim["step"]) + 1e-9) * every * sim["step"])
    return raw


def sensors_job(scenario: PortableScenario, reconstruct: bool = False) -> SensorRun:
    """:func:`simulate_sensors` of a scenario sent by value (what diagnosis runs in its workers).

    The scenario comes with its files (its sensor layout, a vehicle FMU:
    :class:`orchestrator.cosim.portable.PortableScenario`) and the signals go back by value,
    so the worker needs no access to the client's files.
    """
    return simulate_sensors(scenario.scenario(), reconstruct=reconstruct)


__all__ = ["variant_for_speed", "SensorRun", "read_sensors", "sensor_columns", "simulate_sensors", "sensors_job"]
