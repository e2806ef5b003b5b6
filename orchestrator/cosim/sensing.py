"""Run a scenario and read its virtual sensors (the simulated side of every comparison).

:func:`simulate_sensors` runs the co-simulation in-process (the same model objects as
the FMUs; :mod:`orchestrator.cosim.master`), records the track states at the output step and
reads the layout's sensors from them (:mod:`track.sensors`). :func:`sensors_job` is the
top-level (picklable) form that diagnosis sends to worker processes: it takes the
scenario by value (:class:`orchestrator.cosim.portable.PortableScenario`).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from track.sensors import compile_sensors, sensor_signals

from orchestrator.cosim.portable import PortableScenario
from orchestrator.inputs.sensor_layout import SensorLayout, layout_of, resolve

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


def simulate_sensors(scenario, layout: SensorLayout | None = None, reconstruct: bool = True) -> SensorRun:
    """Co-simulate ``scenario`` in-process and read its sensors at every output step.

    With ``reconstruct=False`` displacement sensors give their accelerometer's signal
    [m/s^2]: :func:`orchestrator.inverse.objective.compare` and the synthetic measurements
    reconstruct the displacement on the measured time base, the window the
    measurement's own reconstruction used.
    """
    from orchestrator.cosim.master import run_cosim

    layout = layout_of(scenario) if layout is None else layout
    res = run_cosim(scenario, backend="inprocess", record_states=True)
    model = res.track_model
    compiled = compile_sensors(model, resolve(layout, model))
    rec = res.track_record
    t = np.asarray(rec["t"], float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else scenario.simulation.output_step
    sig = sensor_signals(model, compiled, rec["q"], rec["v"], rec["a"], dt,
                         layout.displacement_highpass, reconstruct)
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


__all__ = ["variant_for_speed", "SensorRun", "simulate_sensors", "sensors_job"]
