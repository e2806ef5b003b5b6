"""Synthetic measurements: a scenario with an effect, sampled as a field campaign would be.

:func:`synthesize` runs the scenario with the effect (a cause of
:mod:`orchestrator.inputs.causes` at given parameters) and turns its virtual sensors into a
measurement file:

1. the acquisition samples at ``rate`` [Hz] (default: the layout's, at most half the
   simulation's output rate so that the comparison's interpolation of the simulation
   stays well below the noise), from an arbitrary trigger: the record's time origin is
   ``trigger`` seconds before its first sample's simulation time (the diagnosis is not
   told and aligns the passages itself);
2. displacement channels are *reconstructed from accelerations*, as in the field: the
   simulated acceleration at the sensor is sampled and integrated twice with the
   layout's high-pass (:func:`track.sensors.displacement_from_acceleration`);
3. noise: independent Gaussian white noise on every channel with standard deviation
   ``noise`` x the channel's standard deviation over the record (default 1 %, a
   well-kept strain-gauge / pressure-cell chain).

:func:`hidden_effect` is the seeded generator of the hidden-effect tests: it draws an
effect (type, sleeper, magnitude) from ranges a crossing survey would call relevant
and returns it to the test — the diagnosis only ever gets the file.

The stages of :func:`synthesize` (:func:`variant_scenario`, :func:`truth_run`,
:func:`acquisition_rate`, :func:`acquisition_times`, :func:`sample_signals`) are also
those of the field-like passages of :mod:`orchestrator.inverse.fieldlike`, which run
another model as the truth and a fuller sensor chain.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from orchestrator.cosim.sensing import SensorRun, simulate_sensors
from orchestrator.inputs.causes import CATALOGUE, DRAWS
from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.measured import write_measured
from orchestrator.inputs.sensor_layout import layout_of
from track.sensors import ANTI_ALIAS_ORDER, ANTI_ALIAS_SHARE, anti_alias, displacement_from_acceleration

DEFAULT_NOISE = 0.01   # noise std / channel std
MAX_RATE_SHARE = 0.5   # sampling rate <= this x the simulation's output rate (module docstring)
TRIGGER_RANGE = (0.02, 0.08)   # s: record time of the first sample (drawn when not given)


@dataclass(frozen=True)
class Effect:
    """A cause at given parameters (what a synthetic measurement hides); ``none``: no effect."""

    cause: str
    sleeper: int | None = None
    parameters: dict = field(default_factory=dict)

    def apply(self, raw: dict) -> dict:
        """A copy of the raw scenario with the effect."""
        if self.cause == "none":
            return copy.deepcopy(raw)
        kind = CATALOGUE[self.cause]
        return kind.apply(raw, self.sleeper, kind.values_of(self.parameters))

    def as_dict(self) -> dict:
        return {"cause": self.cause, "sleeper": self.sleeper, "parameters": dict(self.parameters)}


# ------------------------------------------------------------------------------------------
# The stages of a synthetic measurement (also used by orchestrator.inverse.fieldlike)
# ------------------------------------------------------------------------------------------
def variant_scenario(scenario, raw: dict, label: str):
    """The scenario of a raw mapping derived from ``scenario``'s (relative files resolve as in the nominal)."""
    from orchestrator.inputs.scenario import scenario_from_dict

    base_dir = Path(scenario.source).parent if scenario.source and Path(scenario.source).exists() else Path.cwd()
    return scenario_from_dict(raw, source=label, base_dir=base_dir)


def truth_run(variant, layout) -> SensorRun:
    """The truth's virtual sensors (displacement sensors as their accelerometer's signal, m/s^2).

    Raises
    ------
    RuntimeError
        The run stopped early (a synthetic truth must be complete).
    """
    run = simulate_sensors(variant, layout, reconstruct=False)
    if run.error:
        raise RuntimeError(f"the synthetic run failed: {run.error}")
    return run


def acquisition_rate(t_sim: np.ndarray, rate: float) -> float:
    """The sampling rate [Hz]: ``rate``, capped at :data:`MAX_RATE_SHARE` x the simulation's output rate."""
    sim_rate = round(1.0 / float(np.median(np.diff(t_sim))), 6)
    return min(float(rate), MAX_RATE_SHARE * sim_rate)


def acquisition_times(t_sim: np.ndarray, rate: float, crop: float) -> tuple[np.ndarray, float]:
    """Sample times of the acquisition on the simulation's clock, and its first one, ``t0``.

    The record is the simulated window less ``crop`` seconds at both ends, sampled at ``rate``.
    """
    t0, t1 = t_sim[0] + crop, t_sim[-1] - crop
    return t0 + np.arange(int(np.floor((t1 - t0) * rate)) + 1) / rate, float(t0)


def sample_signals(run: SensorRun, layout, t_acq: np.ndarray, share: float = ANTI_ALIAS_SHARE,
                   order: int = ANTI_ALIAS_ORDER) -> dict:
    """Every sensor's simulated signal at the acquisition times (cubic spline of the output samples), through
    the acquisition's anti-alias filter first (:func:`track.sensors.anti_alias` at the rate of ``t_acq``, corner
    ``share`` x that rate, Butterworth ``order``; the defaults are the diagnosis's comparison filter).

    Displacement sensors stay accelerations [m/s^2] (what their accelerometer measures).
    """
    rate = 1.0 / float(np.median(np.diff(t_acq))) if len(t_acq) > 1 else 0.0
    ids = list(layout.ids)
    band = anti_alias(run.t, np.column_stack([run.signals[sid] for sid in ids]), rate, share, order)
    on = CubicSpline(run.t, band)(t_acq)
    return {sid: on[:, j] for j, sid in enumerate(ids)}


def synthesize(scenario, effect: Effect, out_file, *, noise: float = DEFAULT_NOISE, seed: int = 0,
               trigger: float | None = None, rate: float | None = None, crop: float = 0.01) -> dict:
    """Write a synthetic measurement of ``scenario`` with ``effect`` (module docstring).

    Parameters
    ----------
    scenario : Scenario
        The nominal scenario (its sensor layout is used).
    effect : Effect
    out_file : path-like
        ``.csv``, ``.h5`` or ``.mat``.
    noise : float
        Noise std as a share of each channel's std.
    seed : int
        Seed of the noise and of the trigger time.
    trigger : float, optional
        Record time of the first sample [s]; default drawn from :data:`TRIGGER_RANGE`.
    rate : float, optional
        Sampling rate [Hz]; default the layout's, capped at half the simulation's output rate.
    crop : float
        Time cut from both ends of the simulated window [s] (a record is a window of the passage).

    Returns
    -------
    dict
        What was hidden: effect, trigger, rate, noise, seed (for the test, not the diagnosis).
    """
    rng = np.random.default_rng(seed)
    layout = layout_of(scenario)
    run = truth_run(variant_scenario(scenario, effect.apply(scenario.raw), f"<{effect.cause}>"), layout)
    rate = acquisition_rate(run.t, layout.rate if rate is None else rate)
    trigger = float(rng.uniform(*TRIGGER_RANGE) if trigger is None else trigger)
    t_acq, t0 = acquisition_times(run.t, rate, crop)
    sampled = sample_signals(run, layout, t_acq)
    channels = {}
    for sid in layout.ids:
        x = sampled[sid]
        if layout.types[sid] == "displacement":   # x is the accelerometer's signal
            x = displacement_from_acceleration(x, 1.0 / rate, layout.displacement_highpass)
        channels[sid] = x + rng.normal(0.0, noise * float(np.std(x)), size=x.shape)
    write_measured(out_file, t_acq - t0 + trigger, channels)
    return {"effect": effect.as_dict(), "trigger": trigger, "time_offset": trigger - t0, "rate": rate,
            "noise": noise, "seed": seed, "file": str(out_file)}


def synthesize_file(scenario_path, out_file, overrides=(), speed: float | None = None, noise: float | None = None,
                    seed: int = 0) -> dict:
    """:func:`synthesize` for the command line: the effect given as scenario overrides."""
    from orchestrator.cosim.sensing import variant_for_speed
    from orchestrator.inputs.scenario import load_scenario, scenario_from_dict

    scenario = load_scenario(scenario_path, overrides=list(overrides))
    if speed is not None:
        if not speed > 0:
            raise UserInputError(f"--speed must be > 0 m/s, got {speed!r}")
        scenario = scenario_from_dict(variant_for_speed(scenario.raw, speed), source=str(scenario_path),
                                      base_dir=Path(scenario_path).parent)
    if noise is not None and not 0.0 <= noise < 1.0:
        raise UserInputError(f"--noise must be a share in [0, 1), got {noise!r}")
    return synthesize(scenario, Effect("none"), out_file, noise=DEFAULT_NOISE if noise is None else noise, seed=seed)


# ------------------------------------------------------------------------------------------
# The hidden-effect generator
# ------------------------------------------------------------------------------------------
HIDDEN_KINDS = tuple(d.label for d in DRAWS)   # the registry's synthetic draws (causes.DRAWS)


def hidden_effect(seed: int, kind: str | None = None, sleepers=None) -> Effect:
    """A random effect (seeded), as the hidden-effect tests use.

    Parameters
    ----------
    seed : int
    kind : str, optional
        One of :data:`HIDDEN_KINDS` or ``none``; default drawn.
    sleepers : sequence of int
        Where local effects may be (the sleepers carrying sensors).

    Ranges (relevant to a survey, inside the catalogue's bounds): a void of 0.6-2 mm
    peak, shaped as a random hump or a one-sided wedge over the 6 points; bed stiffness
    x0.35-0.6 or x1.8-3; pads of one sleeper x0.1-0.3 (a worn or missing pad) or x4-8;
    global pads x0.3-0.5 or x2.5-5; impact angle 12-22 mrad (a worn nose; nominal 6).
    """
    rng = np.random.default_rng(seed)
    kind = kind or str(rng.choice(HIDDEN_KINDS))
    if kind == "none":
        return Effect("none")
    for d in DRAWS:
        if d.label == kind:
            sleeper, parameters = d.draw(rng, sleepers)
            return Effect(d.cause, sleeper, parameters)
    raise ValueError(f"unknown effect kind {kind!r} (one of {', '.join(HIDDEN_KINDS)}, none)")


__all__ = ["Effect", "synthesize", "variant_scenario", "truth_run", "acquisition_rate", "acquisition_times",
           "sample_signals", "synthesize_file", "hidden_effect", "HIDDEN_KINDS", "DEFAULT_NOISE"]
