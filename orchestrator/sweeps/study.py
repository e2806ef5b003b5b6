"""One run of a parameter study: co-simulation in-process, analysis, arrays on disk.

:func:`run_case` is the default per-run function of :mod:`orchestrator.sweeps.sweep`: it
runs the scenario with the in-process backend (the same model objects as the FMUs,
without building FMUs in every worker), analyses it (:mod:`orchestrator.results.analysis`),
writes the arrays the seed figures need to ``run_dir/arrays.npz`` and returns the
scalars for the sweep table.

A study varies the speed, so the time a vehicle needs to pass the crossing varies: a
run is cut when the front wheelset is ``AFTER_TRANSITION`` behind the crossing
transition (the rail and sleeper responses to the impact have peaked by then), or
where the wheels reach the end of the modelled panel, if either comes before
``simulation.duration`` (``duration_used`` in the scalars says which time was used).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from orchestrator.cosim.master import run_cosim
from orchestrator.cosim.passage import END_MARGIN_SLEEPERS, start_position
from orchestrator.inputs.track_model import track_model
from orchestrator.results.analysis import analyse, profile_scalars
from track.layout import build_layout

AFTER_TRANSITION = 3.0  # m: a study run ends when the front wheelset is this far behind the transfer


def passage_duration(scenario) -> float:
    """The scenario's duration, cut after the crossing passage or at the panel's end [s]."""
    lay = build_layout(scenario.track.layout)
    x0 = start_position(scenario, lay)
    limit = lay.sleepers[-1].x - END_MARGIN_SLEEPERS * lay.params.sleeper_spacing
    if lay.x_transition is not None:
        limit = min(limit, lay.x_transition + AFTER_TRANSITION)
    t_max = (limit - x0) / scenario.vehicle.speed
    h = scenario.simulation.step
    return min(scenario.simulation.duration, np.floor(t_max / h) * h)


def run_case(scenario, run_dir: Path) -> dict[str, float]:
    """Run one case of a study; returns its scalars, writes ``run_dir/arrays.npz``."""
    duration = passage_duration(scenario)
    sim = scenario.simulation
    if duration < sim.duration:
        every = max(1, int(round(sim.output_step / sim.step)))
        duration = max(np.floor(duration / (every * sim.step)) * every * sim.step, every * sim.step)
        scenario = dataclasses.replace(scenario, simulation=dataclasses.replace(sim, duration=float(duration)))
    res = run_cosim(scenario, backend="inprocess", record_states=True)
    if res.error:
        raise RuntimeError(res.error)
    model = track_model(scenario.track)
    an = analyse(model, 0.5 * scenario.vehicle.axle_load, res)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(run_dir / "arrays.npz", t=res.t, Fz=res.Fz, x=res.x, **an.arrays)
    out = {k: float(v) for k, v in an.scalars.items()}
    if scenario.track.contact.geometry == "profiles":      # emergent impact angle, transfer position (issue 15)
        out.update(profile_scalars(scenario.track.contact, model, res))
    out["duration_used"] = float(scenario.simulation.duration)
    return out
