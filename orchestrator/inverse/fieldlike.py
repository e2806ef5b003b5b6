"""Field-like synthetic passages: a truth the diagnosis's model does not share, through a real sensor chain.

The hidden-effect tests of :mod:`orchestrator.inverse.synthetic` make their truth with the
very model the diagnosis uses and add white noise after the displacement reconstruction.
Here a *case* (:class:`FieldCase`) hides three things, drawn per seed and per family
(:func:`draw_case`), and :func:`synthesize_case` writes the measured file:

* ``effects``: 0, 1 or 2 track causes of the registry (:mod:`orchestrator.inputs.causes`),
  local ones also on sleepers *without* sensors; void shapes that are not the fit's
  own wedges (asymmetric humps, one-sided convex profiles: :func:`draw_void_gaps`);
  every magnitude continuous and at least :data:`GRID_CLEARANCE` (on the cause's unit
  cube) away from its screening grid;
* ``mismatch`` (:class:`Mismatch`): the truth is another model: vehicle parameters
  (:data:`VEHICLE_MISMATCH`) each within +-20 %, the speed within +-4 %, the track's
  ballast and pad damping x0.6-1.6, a time step 2 or 4 times finer (output step kept);
* the acquisition: the truth's output band-limited by an anti-alias filter, then sampled
  (since 2026-11-29). Its corner and order are drawn per case (:data:`AA_SHARE`,
  :data:`AA_ORDERS`, from a stream of their own so the other draws stay those of before):
  the diagnosis band-limits its model at a fixed 0.4 x the rate, order 4
  (:func:`track.sensors.anti_alias`), and is not told the chain's filter, as it is not
  told a field logger's;
* ``chain`` (:class:`Chain`): white noise, coloured noise (AR(1)), a slow drift (a
  sine below 1 Hz, under the reconstruction's 5 Hz high-pass corner), and in the
  ``faulty`` chain one channel with a gain error and an offset. For displacement
  channels all of it enters the *acceleration* before the reconstruction
  (:func:`track.sensors.displacement_from_acceleration`), as a real chain does.

What that makes of the measurement scenario's channels (measured on one draw, seed 1 of
``null_clean``: 0.7 % white, 2 % coloured, 1.8 % drift): pressure, strain and rail
acceleration channels carry ~3 % of their std; the reconstructed sleeper displacements
5-14 %, since the reconstruction's 1 / (2 pi f)^2 lifts the low-frequency part of the
acceleration noise (the ranges below were halved after that draw). Over a record of
0.14 s a sub-Hz drift is mostly an offset and a slope of each channel. A sensor kind has a
noise floor (:data:`KIND_FLOOR`, :func:`noise_scales`, since 2026-11-28): a channel quieter
than its kind's median carries the median's absolute noise, as a sensor of the same
specification would.

Families (:data:`FAMILIES`; every single-effect family also as ``<name>+mismatch``)::

    family            effects                                      mismatch  chain
    ----------------  -------------------------------------------  --------  ------
    null_clean        none                                         no        field
    null_vehicle      none                                         yes       field
    null_sensor       none                                         no        faulty
    void_sensor       a void on an instrumented sleeper            no        field
    void_off_sensor   a void 1-3 sleepers beyond the instrumented  no        field
    pad_local         one sleeper's pads x0.1-0.3 or x4-8          no        field
    pad_global        all pads x0.3-0.5 or x2.5-5                  no        field
    bed_stiffness     ballast stiffness x0.35-0.6 or x1.8-3        no        field
    worn_nose         impact angle 12-22 mrad (nominal 6)          no        field
    two_void_pad      a void and a soft pad (x0.1-0.3) next to it  no        field
    two_nose_void     a worn nose and a void                       no        field

Solid-truth families (:data:`SLOW_FAMILIES`, not in :data:`FAMILIES`): the truth's
crossing rail is the 3D solid (``track.model: solid``, :attr:`Mismatch.track_model`) —
``null_solid`` (no effect) and ``void_sensor+solid``; the default sensor layout gives all
its channels on the solid (issue 14 item 7). Once slow (the solid's first build), they
now take as long as the others (benchmarks/RESULTS.md, 2026-11-27: 6 passages written in
45 s, diagnosed in 3.7 min); they stay apart so that the default matrix's 51 passages
remain comparable between sessions (``--families`` takes them).

The module draws and writes; it knows no answer. What a diagnosis should answer for a
case (the scoring) lives in ``benchmarks/bench_diagnose_field.py``, out of reach of the
code under test.
"""
from __future__ import annotations

import zlib
from dataclasses import asdict, dataclass, field, replace
from functools import lru_cache
from typing import Callable

import numpy as np
from scipy.signal import lfilter

from orchestrator.cosim.sensing import variant_for_speed
from orchestrator.inputs import keypath
from orchestrator.inputs.causes import CATALOGUE, DRAWS, N_GAPS
from orchestrator.inputs.measured import write_measured
from orchestrator.inputs.sensor_layout import layout_of
from orchestrator.inverse.synthetic import (TRIGGER_RANGE, Effect, acquisition_rate, acquisition_times,
                                            sample_signals, truth_run, variant_scenario)
from track.sensors import ANTI_ALIAS_ORDER, ANTI_ALIAS_SHARE, displacement_from_acceleration, sleepers_of
from vehicle.bogie import BogieParams
from vehicle.quarter import QuarterParams

GRID_CLEARANCE = 0.02          # min distance of a drawn magnitude from a screening-grid node, on the unit cube
VOID_PEAK = (0.6e-3, 2.5e-3)   # m: peak gap of a drawn void
WEDGE_RESIDUAL_MIN = 0.08      # a void's RMS residual of a straight-line fit over its 6 gaps, / its peak, at least
VEHICLE_RANGE = 0.20           # vehicle parameters x(1 +- this)
SPEED_RANGE = 0.04             # speed x(1 +- this)
DAMPING_RANGE = (0.6, 1.6)     # track damping factors
STEP_DIVISORS = (2, 4)         # the truth's time step = nominal / one of these (output step kept)
WHITE = (0.005, 0.015)         # white noise std / channel std
COLOURED = (0.005, 0.02)       # coloured (AR(1)) noise std / channel std ...
AR_COEFFICIENT = (0.6, 0.9)    # ... and its lag-1 coefficient
DRIFT = (0.003, 0.01)          # drift amplitude / channel std (field chain) ...
FAULTY_DRIFT = (0.01, 0.03)    # ... and in the faulty chain
DRIFT_HZ = (0.1, 1.0)          # drift frequency [Hz], below the reconstruction's high-pass corner (5 Hz)
GAIN_ERROR = ((0.85, 0.95), (1.05, 1.15))   # the faulty channel's gain
OFFSET = (0.02, 0.08)          # the faulty channel's offset / its std (not on displacement channels)
AA_SHARE = (0.35, 0.45)        # the acquisition's anti-alias corner / sampling rate (an analogue filter .. a
                               # sigma-delta converter's pass-band edge)
AA_ORDERS = (2, 4, 6, 8)       # its Butterworth order (run both ways: zero phase)
KIND_FLOOR = 1.0               # a channel's noise scale is at least this share of its sensor kind's median std
READS_NOTHING = 1e-9           # ... of those that read something: std above this x its kind's largest (not round-off)

VEHICLE_MISMATCH = {           # vehicle kind -> (its parameter class, the parameters a case varies)
    "quarter": (QuarterParams, ("wheelset_mass", "k1", "c1")),
    "bogie": (BogieParams, ("wheelset_mass", "k1", "c1", "k2", "c2")),
}
DAMPING_KEYS = {"ballast_damping": "track.ballast.damping_per_length", "pad_damping": "track.rail_pad.damping"}


# ------------------------------------------------------------------------------------------ the case
@dataclass(frozen=True)
class Mismatch:
    """How the truth's model differs from the nominal scenario (all factors 1: not at all).

    Attributes
    ----------
    vehicle : dict
        Vehicle parameter -> factor on its nominal value (``vehicle.start_values``, else the
        parameter class's default).
    speed : float
        Factor on the speed (same stretch of track: :func:`orchestrator.cosim.sensing.variant_for_speed`).
    ballast_damping, pad_damping : float
        Factors on ``track.ballast.damping_per_length`` and ``track.rail_pad.damping``.
    step_divisor : int
        The truth's time step is the nominal's divided by this (the output step is kept).
    track_model : str or None
        ``track.model`` of the truth (None: the nominal's).
    """

    vehicle: dict = field(default_factory=dict)
    speed: float = 1.0
    ballast_damping: float = 1.0
    pad_damping: float = 1.0
    step_divisor: int = 1
    track_model: str | None = None

    def apply(self, raw: dict) -> dict:
        """A copy of the raw scenario as the truth's model."""
        raw = Effect("none").apply(raw)
        veh = raw["vehicle"]
        if self.vehicle:
            cls, _ = VEHICLE_MISMATCH[veh["fmu"]]
            start = dict(veh.get("start_values") or {})
            for name, factor in self.vehicle.items():
                start[name] = float(start.get(name, cls.__dataclass_fields__[name].default)) * factor
            veh["start_values"] = start
        for name, key in DAMPING_KEYS.items():
            keypath.set(raw, key, float(keypath.get(raw, key)) * getattr(self, name))
        raw["simulation"]["step"] = float(raw["simulation"]["step"]) / self.step_divisor
        if self.track_model:
            raw["track"]["model"] = self.track_model
        if self.speed != 1.0:
            raw = variant_for_speed(raw, float(veh["speed"]) * self.speed)
        return raw


@dataclass(frozen=True)
class Chain:
    """The sensor chain of a case (module docstring); shares are of each channel's std.

    Attributes
    ----------
    seed : int
        Seed of every channel's disturbance (:func:`disturbance`).
    trigger : float
        Record time of the first sample [s].
    white, coloured : float
        White and AR(1) noise std / channel std.
    ar : float
        AR(1) coefficient of the coloured noise.
    drift : float
        Amplitude of the drift (a sine of a per-channel frequency in :data:`DRIFT_HZ`) / channel std.
    gain_channel : str or None
        The channel with a gain error (and an offset), if any.
    gain : float
        Its gain.
    offset : float
        Its offset / its std (0 on displacement channels: the reconstruction removes it).
    aa_share, aa_order : float, int
        The acquisition's anti-alias filter: corner / sampling rate and Butterworth order
        (:func:`track.sensors.anti_alias`; the defaults are the diagnosis's, the draws
        :data:`AA_SHARE`, :data:`AA_ORDERS`).
    kind_floor : float
        The noise floor of a sensor kind: a channel's noise and drift scale with its own std,
        but not below this share of the median std of the channels of its kind
        (:func:`noise_scales`). 0: each channel's own std (every passage written before
        2026-11-28 12:30; their ``case.json`` has no such key).
    """

    seed: int
    trigger: float
    white: float
    coloured: float
    ar: float
    drift: float
    gain_channel: str | None = None
    gain: float = 1.0
    offset: float = 0.0
    kind_floor: float = 0.0
    aa_share: float = ANTI_ALIAS_SHARE
    aa_order: int = ANTI_ALIAS_ORDER


@dataclass(frozen=True)
class FieldCase:
    """The hidden truth of one passage: family, seed, effects, model mismatch, sensor chain."""

    family: str
    seed: int
    effects: tuple = ()
    mismatch: Mismatch = field(default_factory=Mismatch)
    chain: Chain | None = None

    def truth_raw(self, raw: dict) -> dict:
        """The truth's raw scenario: the nominal with the effects, as the mismatched model."""
        for e in self.effects:
            raw = e.apply(raw)
        return self.mismatch.apply(raw)

    def as_dict(self) -> dict:
        """JSON-able dict (effects as :meth:`Effect.as_dict`)."""
        return {"family": self.family, "seed": self.seed, "effects": [e.as_dict() for e in self.effects],
                "mismatch": asdict(self.mismatch), "chain": asdict(self.chain) if self.chain else None}

    @classmethod
    def from_dict(cls, d: dict) -> "FieldCase":
        """The case of an :meth:`as_dict` dict (e.g. a benchmark's ``case.json``)."""
        return cls(d["family"], int(d["seed"]),
                   tuple(Effect(e["cause"], e["sleeper"], dict(e["parameters"])) for e in d["effects"]),
                   Mismatch(**d["mismatch"]), Chain(**d["chain"]) if d.get("chain") else None)


# ------------------------------------------------------------------------------------------ the sensor chain
def ar1(rng: np.random.Generator, n: int, phi: float, std: float) -> np.ndarray:
    """A stationary AR(1) series e_k = phi e_(k-1) + w_k of standard deviation ``std`` (from its first sample)."""
    w = rng.normal(0.0, std * np.sqrt(1.0 - phi ** 2), n)
    e0 = rng.normal(0.0, std)              # the stationary distribution: no start-up transient
    return lfilter([1.0], [1.0, -phi], w, zi=[phi * e0])[0]


def disturbance(chain: Chain, index: int, n: int, dt: float, scale: float) -> np.ndarray:
    """White + coloured noise + drift of channel number ``index`` (n samples at ``dt``), in units of ``scale``.

    Seeded by ``(chain.seed, index)``: a channel's disturbance does not depend on the others.
    """
    rng = np.random.default_rng([chain.seed, index])
    white = rng.normal(0.0, chain.white * scale, n)
    coloured = ar1(rng, n, chain.ar, chain.coloured * scale)
    f, phase = rng.uniform(*DRIFT_HZ), rng.uniform(0.0, 2.0 * np.pi)
    return white + coloured + chain.drift * scale * np.sin(2.0 * np.pi * f * dt * np.arange(n) + phase)


def noise_scales(sampled: dict, types: dict, chain: Chain) -> dict:
    """Channel id -> the scale of its disturbance (:func:`disturbance`): the channel's std, but at
    least ``chain.kind_floor`` times the median std of the channels of its sensor type that read
    something (std above :data:`READS_NOTHING` times the kind's largest).

    Why a floor: sensors of one kind share an amplifier and a noise specification, so a quiet
    channel (a pressure cell under a sleeper that hardly loads it, a cell reading nothing)
    carries the same absolute noise as its neighbours, not a share of its own small signal.
    Scaling by each channel's own std alone made the quietest channels the cleanest: in the
    field matrix the transition bearer's pressure cell A6 (std ~2 kPa against 13-39 kPa
    for A1-A5) had 1/13 of the others' absolute noise, and a cell reading round-off none.
    Why only the channels that read something: a cell reading nothing says nothing of its
    amplifier's noise. Until 2026-11-29 (session 38) the median took them in, so under a sleeper
    hanging over a void, where four or five of the six cells read nothing, the median and so the
    floor were zero and those cells noise-free (void_sensor+mismatch 7606 and 7707 of issue 14's
    field matrix: exact zeros, a signature of infinite ratio to the noise), and where two read
    nothing it was low (two_void_pad 7101: 3.6 times below the median of the cells that read).
    """
    std = {sid: float(np.std(x)) for sid, x in sampled.items()}
    if chain.kind_floor <= 0.0:
        return std
    by_kind: dict = {}
    for sid, s in std.items():
        by_kind.setdefault(types[sid], []).append(s)
    level = {}
    for kind, stds in by_kind.items():
        reading = [s for s in stds if s > READS_NOTHING * max(stds)]
        level[kind] = float(np.median(reading)) if reading else 0.0
    return {sid: max(s, chain.kind_floor * level[types[sid]]) for sid, s in std.items()}


def apply_chain(sampled: dict, types: dict, dt: float, highpass: float, chain: Chain) -> dict:
    """The measured channels of the sampled true signals through the chain (module docstring).

    Parameters
    ----------
    sampled : dict
        Channel id -> the true signal at the acquisition times; displacement channels as
        their accelerometer's acceleration [m/s^2].
    types : dict
        Channel id -> sensor type.
    dt : float
        Sampling interval [s].
    highpass : float
        Corner of the displacement reconstruction [Hz].
    chain : Chain

    Returns
    -------
    dict
        Channel id -> measured signal (displacements reconstructed after the disturbance).
    """
    out, scales = {}, noise_scales(sampled, types, chain)
    for index, (sid, x) in enumerate(sampled.items()):
        y = gain_and_reconstruct(sid, x + disturbance(chain, index, len(x), dt, scales[sid]), types, dt, highpass,
                                 chain)
        if sid == chain.gain_channel and types[sid] != "displacement":
            y = y + chain.offset * float(np.std(x))
        out[sid] = y
    return out


def gain_and_reconstruct(sid: str, y: np.ndarray, types: dict, dt: float, highpass: float,
                         chain: Chain | None) -> np.ndarray:
    """Channel ``sid``'s signal ``y`` past the chain's amplifier and reconstruction: times the gain
    error on the faulty channel, a displacement rebuilt from its accelerometer's signal."""
    if chain is not None and sid == chain.gain_channel:
        y = chain.gain * y
    return displacement_from_acceleration(y, dt, highpass) if types[sid] == "displacement" else y


# ------------------------------------------------------------------------------------------ drawing effects
def _off_grid(rng: np.random.Generator, cause: str, draw: Callable[[np.random.Generator], float]) -> float:
    """A magnitude of ``draw`` at least :data:`GRID_CLEARANCE` (unit cube) from ``cause``'s screening grid."""
    kind = CATALOGUE[cause]
    nodes = np.array([float(kind.to_unit([g])[0]) for g in kind.grid])
    for _ in range(1000):
        value = float(draw(rng))
        if np.min(np.abs(nodes - float(kind.to_unit([value])[0]))) >= GRID_CLEARANCE:
            return value
    raise RuntimeError(f"no {cause} magnitude off its screening grid in 1000 draws")


def _registry_scalar(label: str) -> Callable[[np.random.Generator], float]:
    """The scalar magnitude of the registry's synthetic draw ``label`` (:data:`orchestrator.inputs.causes.DRAWS`)."""
    d = next(d for d in DRAWS if d.label == label)
    return lambda rng: CATALOGUE[d.cause].values_of(d.parameters(rng))[0]


def wedge_residual(gaps) -> float:
    """RMS residual of a straight-line fit of the gaps over their positions, / their peak (0 for a wedge)."""
    gaps = np.asarray(gaps, float)
    s = np.linspace(0.0, 1.0, gaps.size)
    a = np.vstack([np.ones_like(s), s]).T
    r = gaps - a @ np.linalg.lstsq(a, gaps, rcond=None)[0]
    return float(np.sqrt(np.mean(r ** 2)) / np.max(gaps))


def _void_shape(rng: np.random.Generator) -> np.ndarray:
    """A void profile over the 6 points, peak 1: an asymmetric hump or a one-sided convex profile."""
    s = np.linspace(0.0, 1.0, N_GAPS)
    if rng.random() < 0.5:    # a hump with its own width either side of its crest
        c, left, right = rng.uniform(0.15, 0.85), rng.uniform(0.25, 0.7), rng.uniform(0.25, 0.7)
        w = np.where(s < c, left, right)
        shape = np.clip(1.0 - ((s - c) / w) ** 2, 0.0, None)
    else:                     # deepest at one end, dying away convexly
        end, length, power = rng.integers(2), rng.uniform(0.4, 0.9), rng.uniform(1.6, 3.0)
        shape = np.clip(1.0 - np.abs(s - end) / length, 0.0, None) ** power
    return shape / shape.max()


def draw_void_gaps(rng: np.random.Generator) -> list[float]:
    """Six gaps [m]: a shape of :func:`_void_shape` that is no wedge (:data:`WEDGE_RESIDUAL_MIN`),
    its peak in :data:`VOID_PEAK` and off the screening grid."""
    for _ in range(1000):
        shape = _void_shape(rng)
        if wedge_residual(shape) >= WEDGE_RESIDUAL_MIN:
            break
    else:
        raise RuntimeError("no void shape away from a wedge in 1000 draws")
    peak = _off_grid(rng, "ballast_void", lambda r: r.uniform(*VOID_PEAK))
    return [float(g) for g in peak * shape]


def _void_on(sleeper: int, rng: np.random.Generator) -> Effect:
    return Effect("ballast_void", sleeper, {"gaps": draw_void_gaps(rng)})


def _pad_on(sleeper: int, scale: float) -> Effect:
    return Effect("rail_pad_stiffness", sleeper, {"stiffness_scale": scale})


def _global(cause: str, label: str) -> Callable:
    name = CATALOGUE[cause].names[0]
    return lambda rng, sleepers, drawn: Effect(cause, None, {name: _off_grid(rng, cause, _registry_scalar(label))})


def _beyond(rng: np.random.Generator, sleepers) -> int:
    """A sleeper 1-3 beyond the instrumented ones, either side."""
    d = int(rng.integers(1, 4))
    return min(sleepers) - d if rng.random() < 0.5 else max(sleepers) + d


def _next_to(rng: np.random.Generator, sleepers, k: int) -> int:
    """A neighbour of sleeper ``k``, an instrumented one where there is one."""
    near = [j for j in (k - 1, k + 1) if j in sleepers] or [k - 1, k + 1]
    return int(rng.choice(near))


EFFECT_DRAWS: dict[str, Callable] = {     # name -> (rng, instrumented sleepers, effects drawn so far) -> Effect
    "void_sensor": lambda rng, sleepers, drawn: _void_on(int(rng.choice(sleepers)), rng),
    "void_off": lambda rng, sleepers, drawn: _void_on(_beyond(rng, sleepers), rng),
    "pad_local": lambda rng, sleepers, drawn: _pad_on(
        int(rng.choice(sleepers)), _off_grid(rng, "rail_pad_stiffness", _registry_scalar("rail_pad_stiffness_local"))),
    "pad_soft_next": lambda rng, sleepers, drawn: _pad_on(      # a worn or missing pad next to a void
        _next_to(rng, sleepers, drawn[-1].sleeper),
        _off_grid(rng, "rail_pad_stiffness", lambda r: r.uniform(0.1, 0.3))),
    "pad_global": _global("rail_pad_stiffness", "rail_pad_stiffness"),
    "bed": _global("ballast_stiffness", "ballast_stiffness"),
    "nose": _global("impact_angle", "impact_angle"),
}


# ------------------------------------------------------------------------------------------ families
@dataclass(frozen=True)
class Family:
    """A family of cases: which effects (:data:`EFFECT_DRAWS`), with a model mismatch or not, which chain."""

    effects: tuple = ()
    mismatch: bool = False
    chain: str = "field"      # field | faulty
    solid: bool = False       # the truth's crossing rail is the 3D solid


_SINGLE = {"void_sensor": Family(("void_sensor",)), "void_off_sensor": Family(("void_off",)),
           "pad_local": Family(("pad_local",)), "pad_global": Family(("pad_global",)),
           "bed_stiffness": Family(("bed",)), "worn_nose": Family(("nose",))}
FAMILIES: dict[str, Family] = {
    "null_clean": Family(), "null_vehicle": Family(mismatch=True), "null_sensor": Family(chain="faulty"),
    **_SINGLE,
    "two_void_pad": Family(("void_sensor", "pad_soft_next")), "two_nose_void": Family(("nose", "void_sensor")),
    **{f"{name}+mismatch": replace(f, mismatch=True) for name, f in _SINGLE.items()},
}
"""Family name -> :class:`Family` (the table of the module docstring)."""
SLOW_FAMILIES: dict[str, Family] = {"null_solid": Family(solid=True),
                                    "void_sensor+solid": Family(("void_sensor",), solid=True)}
"""Families whose truth is the solid crossing rail (module docstring)."""


def draw_mismatch(rng: np.random.Generator, vehicle_kind: str) -> Mismatch:
    """Vehicle parameters, speed, track damping and time step of another model (module docstring)."""
    _, names = VEHICLE_MISMATCH[vehicle_kind]
    return Mismatch({n: float(rng.uniform(1.0 - VEHICLE_RANGE, 1.0 + VEHICLE_RANGE)) for n in names},
                    float(rng.uniform(1.0 - SPEED_RANGE, 1.0 + SPEED_RANGE)),
                    float(rng.uniform(*DAMPING_RANGE)), float(rng.uniform(*DAMPING_RANGE)),
                    int(rng.choice(STEP_DIVISORS)))


def draw_chain(rng: np.random.Generator, seed: int, channels, faulty: bool) -> Chain:
    """A field chain; ``faulty``: stronger drift and one channel off in gain (and offset)."""
    chain = Chain(seed, float(rng.uniform(*TRIGGER_RANGE)), float(rng.uniform(*WHITE)), float(rng.uniform(*COLOURED)),
                  float(rng.uniform(*AR_COEFFICIENT)), float(rng.uniform(*(FAULTY_DRIFT if faulty else DRIFT))),
                  kind_floor=KIND_FLOOR)
    aa = np.random.default_rng([seed, 0xAA])   # its own stream: the draws above and below stay as they were
    chain = replace(chain, aa_share=float(aa.uniform(*AA_SHARE)), aa_order=int(aa.choice(AA_ORDERS)))
    if not faulty:
        return chain
    gain = float(rng.uniform(*GAIN_ERROR[int(rng.integers(2))]))
    return replace(chain, gain_channel=str(rng.choice(list(channels))), gain=gain, offset=float(rng.uniform(*OFFSET)))


@lru_cache(maxsize=None)
def _measurement_setup() -> tuple[tuple[int, ...], tuple[str, ...], str]:
    """Instrumented sleepers, channel ids and vehicle kind of the bundled measurement scenario."""
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario

    sc = load_scenario(bundled_scenario("measurement/crossing_quarter_120.yaml"))
    return tuple(instrumented_sleepers(sc)), tuple(layout_of(sc).ids), sc.vehicle.fmu


def instrumented_sleepers(scenario) -> list[int]:
    """Indices of the sleepers carrying sensors of the scenario's layout, sorted."""
    from orchestrator.inputs.sensor_layout import resolve
    from orchestrator.inputs.track_model import track_model

    sensors = resolve(layout_of(scenario), track_model(scenario.track))
    return sleepers_of(sensors)


def draw_case(seed: int, family: str, sleepers=None, channels=None, vehicle_kind: str | None = None) -> FieldCase:
    """The hidden truth of one passage of ``family`` (:data:`FAMILIES`), seeded.

    Parameters
    ----------
    seed : int
    family : str
    sleepers, channels : sequence, optional
        The instrumented sleepers and the channel ids; default those of the bundled
        measurement scenario (``scenarios/measurement/crossing_quarter_120.yaml``).
    vehicle_kind : str, optional
        ``quarter`` or ``bogie`` (which parameters a mismatch varies); default that scenario's.
    """
    fam = FAMILIES.get(family) or SLOW_FAMILIES.get(family)
    if fam is None:
        raise ValueError(f"unknown family {family!r} (one of {', '.join({**FAMILIES, **SLOW_FAMILIES})})")
    if sleepers is None or channels is None or vehicle_kind is None:
        d_sleepers, d_channels, d_kind = _measurement_setup()
        sleepers, channels = sleepers or d_sleepers, channels or d_channels
        vehicle_kind = vehicle_kind or d_kind
    rng = np.random.default_rng([seed, zlib.crc32(family.encode())])
    effects: list[Effect] = []
    for name in fam.effects:
        effects.append(EFFECT_DRAWS[name](rng, list(sleepers), effects))
    mismatch = draw_mismatch(rng, vehicle_kind) if fam.mismatch else Mismatch()
    if fam.solid:
        mismatch = replace(mismatch, track_model="solid")
    return FieldCase(family, seed, tuple(effects), mismatch, draw_chain(rng, seed, channels, fam.chain == "faulty"))


# ------------------------------------------------------------------------------------------ the measured file
def synthesize_case(scenario, case: FieldCase, out_file, crop: float = 0.01) -> dict:
    """Run the case's truth and write its measured file through the case's chain.

    Parameters
    ----------
    scenario : Scenario
        The nominal scenario (its sensor layout and output step make the acquisition).
    case : FieldCase
    out_file : path-like
        ``.csv``, ``.h5`` or ``.mat``.
    crop : float
        Time cut from both ends of the simulated window [s].

    Returns
    -------
    dict
        The case (:meth:`FieldCase.as_dict`), the sampling rate, the record's time offset
        to the truth's clock, the file (for the benchmark, never for the diagnosis).
    """
    layout = layout_of(scenario)
    run = truth_run(variant_scenario(scenario, case.truth_raw(scenario.raw), f"<{case.family}>"), layout)
    rate = acquisition_rate(run.t, layout.rate)
    t_acq, t0 = acquisition_times(run.t, rate, crop)
    sampled = sample_signals(run, layout, t_acq, case.chain.aa_share, case.chain.aa_order)
    channels = apply_chain(sampled, layout.types, 1.0 / rate,
                           layout.displacement_highpass, case.chain)
    write_measured(out_file, t_acq - t0 + case.chain.trigger, channels)
    return {"case": case.as_dict(), "rate": rate, "time_offset": case.chain.trigger - t0, "file": str(out_file)}


__all__ = ["FieldCase", "Mismatch", "Chain", "Family", "FAMILIES", "SLOW_FAMILIES", "EFFECT_DRAWS", "draw_case",
           "draw_mismatch", "draw_chain", "draw_void_gaps", "wedge_residual", "ar1", "disturbance", "noise_scales",
           "apply_chain", "instrumented_sleepers", "synthesize_case", "gain_and_reconstruct", "GRID_CLEARANCE",
           "WEDGE_RESIDUAL_MIN", "DRIFT_HZ", "KIND_FLOOR", "AA_SHARE", "AA_ORDERS"]
