"""The cause registry: every way the real track may differ from the nominal scenario (DESIGN.md §4.5).

One place says, for every cause, its parameters and bounds, its screening grid, how it
enters the scenario (key paths), how a synthetic case draws it, where it lives (global,
per sleeper, or both), its ``--params`` names and the track-FMU parameters it maps onto.
Diagnose, calibrate, the synthetic measurements and the SSP export all ask it; adding a
cause is one :data:`CATALOGUE` entry (plus its draw in :data:`DRAWS`) and its test.

=====================  =======  ===========================================  =====================
cause                  where    parameters (bounds)                          scenario keys
=====================  =======  ===========================================  =====================
``ballast_void``       sleeper  ``gaps``: 6 gap heights along the sleeper,   ``track.ballast.voids``
                                0-4 mm (screened as a uniform gap and the two one-sided wedges)
``ballast_stiffness``  global   ``stiffness_scale`` h1, 0.2-5 (log)           ``track.ballast.stiffness_scale``
``rail_pad_stiffness`` global   ``stiffness_scale`` h2, 0.1-10 (log)          ``track.rail_pad.stiffness_scale``
``rail_pad_stiffness`` sleeper  ``stiffness_scale`` of that sleeper's pads,  ``track.rail_pad.overrides``
                                0.05-20 (log)
``impact_angle``       global   ``impact_angle`` 0-30 mrad                    ``track.crossing.impact_angle``
``rail_pad_damping``   global   ``damping`` 2e3-2e5 N s/m per seat (log)      ``track.rail_pad.damping``
``ballast_damping``    global   ``damping_per_length`` 3e3-3e5 N s/m/m (log)  ``track.ballast.damping_per_length``
``wheelset_mass``      vehicle  ``wheelset_mass`` 800-2500 kg                 ``vehicle.start_values.wheelset_mass``
``primary_stiffness``  vehicle  ``k1`` 5e5-3e6 N/m per axle box (log)         ``vehicle.start_values.k1``
``primary_damping``    vehicle  ``c1`` 3e3-8e4 N s/m per axle box (log)       ``vehicle.start_values.c1``
``speed``              measured ``speed`` 5-120 m/s                           ``vehicle.speed`` (and the duration)
``channel_gain``       channel  ``gain`` 0.5-2 (log): measured = g x true     (the comparison)
``channel_offset``     channel  ``offset`` +-1 channel std                    (the comparison)
``channel_dead``       channel  ``level`` +-1 channel std: reads a constant   (the comparison)
=====================  =======  ===========================================  =====================

Every cause has a :attr:`CauseKind.category`: ``track`` (what a diagnosis may name),
``vehicle`` (the vehicle's parameters, known to +-20 %), ``measurement`` (the speed log)
or ``sensor`` (a channel's fault). :func:`candidates` returns the ``track`` causes only,
so a diagnosis never screens a vehicle or sensor difference as a track cause; the
nuisance fit (:mod:`orchestrator.inverse.nuisance`) fits the others, and calibration's
``--params`` may name any of them. The vehicle bounds are relative to the vehicle
model's default (:class:`VehicleSite`): 0.6-1.6 covers the +-20 % of a vehicle
known from its data sheet with room for the fit to show a larger difference.

A cause is *screened* with one scalar magnitude on a grid (:attr:`CauseKind.grid`,
:meth:`CauseKind.apply_scalar`) and the chosen one is then *fitted* with all its
parameters (:meth:`CauseKind.apply`). Values are stored in the units of the scenario
keys (gaps in m, scales as factors, the angle in rad). The bounds are those of a
plausible track: voids up to 4 mm (seed 000 calibrated 0-2.3 mm), bed and pad stiffness
a factor 5-10 around nominal (DESIGN.md §7 ranges), worn-nose angles up to 30 mrad.

How a cause enters the scenario is a *site* (:class:`KeySite`: one number at a key path;
:class:`SleeperListSite`: the entry of one sleeper in a list such as
``track.ballast.voids``; :class:`VehicleSite`: a vehicle start value; :class:`SpeedSite`:
the speed over the same stretch of track; :class:`ChannelSite`: a sensor fault, which
leaves the scenario alone and acts on one simulated channel in the comparison), so no
code here branches on a cause's name.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from orchestrator.inputs import keypath

N_GAPS = 6          # void gap points along a sleeper (DESIGN.md §4.2)
GAP_MAX = 4e-3      # m
# Screening proxies of a void besides the uniform gap (CauseKind.shapes): a void under one end
# of a sleeper tilts it on the bed, which a uniform gap (the sleeper hanging) does not resemble: a
# one-sided void of 2.3 mm at an instrumented sleeper, screened only as a uniform gap, reduced J
# by 2 % and was never fitted (benchmarks/RESULTS.md, field-like passages, void_sensor). Each
# wedge at two peak magnitudes (with the nominal 0, three points for the dense search): 4 runs a sleeper.
VOID_SHAPES = (((1.0, 0.8, 0.6, 0.4, 0.2, 0.0), (1.0e-3, 2.5e-3)),
               ((0.0, 0.2, 0.4, 0.6, 0.8, 1.0), (1.0e-3, 2.5e-3)))


# ------------------------------------------------------------------------------------ sites
@dataclass(frozen=True)
class KeySite:
    """A cause that is one number at a scenario key path (a global scale, the impact angle)."""

    key: str

    def scenario_key(self, sleeper: int | None) -> str:
        """The key whose whole value carries the cause (what a sweep varies)."""
        return self.key

    def nominal(self, raw: dict, sleeper: int | None, size: int) -> np.ndarray:
        return np.array([keypath.get(raw, self.key)], float)

    def apply(self, raw: dict, sleeper: int | None, values: np.ndarray) -> None:
        keypath.set(raw, self.key, float(values[0]))


@dataclass(frozen=True)
class SleeperListSite:
    """A cause that is one sleeper's entry ``{sleeper: k, <field>: value}`` in a list at ``key``.

    Attributes
    ----------
    key : str
        The list's key path (``track.ballast.voids``).
    field : str
        The entry's value field (``gaps``, ``stiffness_scale``).
    default : float
        The value of a sleeper without an entry (no void: 0; pads: a scale of 1).
    vector : bool
        The field is a list (the 6 gaps) rather than a number.
    drop_at_default : bool
        An entry whose values are all at ``default`` is removed (a void of zero gaps).
    lower_clip : float or None
        Values are clipped from below here before they are written (gaps >= 0).
    """

    key: str
    field: str
    default: float
    vector: bool = False
    drop_at_default: bool = False
    lower_clip: float | None = None

    def scenario_key(self, sleeper: int | None) -> str:
        return self.key

    def nominal(self, raw: dict, sleeper: int | None, size: int) -> np.ndarray:
        for entry in keypath.get(raw, self.key) or []:
            if entry["sleeper"] == sleeper:
                return np.array(entry[self.field] if self.vector else [entry[self.field]], float)
        return np.full(size, self.default)

    def apply(self, raw: dict, sleeper: int | None, values: np.ndarray) -> None:
        entries = [e for e in (keypath.get(raw, self.key) or []) if e["sleeper"] != sleeper]
        if self.lower_clip is not None:
            values = np.clip(values, self.lower_clip, None)
        numbers = [float(v) for v in values]
        if not (self.drop_at_default and all(v == self.default for v in numbers)):
            entries.append({"sleeper": int(sleeper), self.field: numbers if self.vector else numbers[0]})
        keypath.set(raw, self.key, sorted(entries, key=lambda e: e["sleeper"]))


def _vehicle_defaults(fmu: str) -> dict:
    """Field defaults of our vehicle model ``fmu`` (``quarter`` or ``bogie``); {} for a third-party FMU."""
    import dataclasses

    from vehicle.bogie import BogieParams
    from vehicle.quarter import QuarterParams

    cls = {"quarter": QuarterParams, "bogie": BogieParams}.get(fmu)
    return {} if cls is None else {f.name: f.default for f in dataclasses.fields(cls)}


@dataclass(frozen=True)
class VehicleSite:
    """A vehicle parameter: the start value ``vehicle.start_values.<name>`` (our vehicles' parameter names).

    The nominal value is the scenario's start value, else our vehicle model's default
    (:class:`vehicle.quarter.QuarterParams`, :class:`vehicle.bogie.BogieParams` name
    ``wheelset_mass``, ``k1``, ``c1`` alike); a third-party FMU without that start value
    has no known nominal (``ValueError``).
    """

    name: str

    def scenario_key(self, sleeper: int | None) -> str:
        return f"vehicle.start_values.{self.name}"

    def nominal(self, raw: dict, sleeper: int | None, size: int) -> np.ndarray:
        given = keypath.get(raw, self.scenario_key(sleeper))
        if given is None:
            given = _vehicle_defaults(keypath.get(raw, "vehicle.fmu")).get(self.name)
        if given is None:
            raise ValueError(f"vehicle.start_values.{self.name}: not given, and the vehicle FMU's default is unknown")
        return np.array([given], float)

    def apply(self, raw: dict, sleeper: int | None, values: np.ndarray) -> None:
        keypath.set(raw, self.scenario_key(sleeper), float(values[0]), create=True)


@dataclass(frozen=True)
class SpeedSite:
    """The vehicle's speed over the same stretch of track: ``vehicle.speed``, the duration scaled by v0 / v.

    The same rule as :func:`orchestrator.cosim.sensing.variant_for_speed` (a whole number
    of output steps), which this layer cannot import.
    """

    key: str = "vehicle.speed"

    def scenario_key(self, sleeper: int | None) -> str:
        return self.key

    def nominal(self, raw: dict, sleeper: int | None, size: int) -> np.ndarray:
        return np.array([keypath.get(raw, self.key)], float)

    def apply(self, raw: dict, sleeper: int | None, values: np.ndarray) -> None:
        v0, v = float(keypath.get(raw, self.key)), float(values[0])
        sim = raw["simulation"]
        every = max(1, int(round(sim["output_step"] / sim["step"])))
        dur = sim["duration"] * v0 / v
        sim["duration"] = float(np.floor(dur / (every * sim["step"]) + 1e-9) * every * sim["step"])
        keypath.set(raw, self.key, v)


@dataclass(frozen=True)
class ChannelSite:
    """A sensor fault: leaves the scenario alone and acts on one simulated channel in the comparison.

    ``mode``: ``gain`` (measured = g x true), ``offset`` (measured = true + o x the
    channel's spread), ``level`` (a dead channel reads the constant o x its spread).
    The place of such a cause is a sensor id (:attr:`Candidate.channel`), not a sleeper.
    """

    mode: str

    def scenario_key(self, sleeper) -> None:
        """None: a sensor fault has no scenario key."""
        return None

    def nominal(self, raw: dict, sleeper, size: int) -> np.ndarray:
        """A healthy channel: gain 1, no offset; a dead channel has no nominal (it reads 0 x its spread)."""
        return np.array([1.0 if self.mode == "gain" else 0.0])

    def apply(self, raw: dict, sleeper, values: np.ndarray) -> None:
        """The scenario is unchanged (the fault is in the measurement chain)."""

    def on(self, signal: np.ndarray, values, spread: float) -> np.ndarray:
        """What the faulty channel reads when the true signal is ``signal`` (``spread``: the channel's std)."""
        v = float(np.asarray(values, float)[0])
        if self.mode == "gain":
            return v * signal
        if self.mode == "offset":
            return signal + v * spread
        return np.full_like(signal, v * spread)


Site = KeySite | SleeperListSite | VehicleSite | SpeedSite | ChannelSite
CATEGORIES = ("track", "vehicle", "measurement", "sensor")


# ------------------------------------------------------------------------------------ causes
@dataclass(frozen=True)
class Candidate:
    """One cause at one place: what the diagnosis screens, fits and ranks.

    ``channel``: the sensor id of a sensor fault (:class:`ChannelSite`), else ``None``.
    """

    cause: str
    sleeper: int | None = None
    channel: str | None = None

    @property
    def label(self) -> str:
        where = self.channel if self.channel is not None else self.sleeper
        return self.cause if where is None else f"{self.cause}@{where}"


@dataclass(frozen=True)
class CauseKind:
    """A cause of the registry (module docstring).

    Attributes
    ----------
    name : str
    local : bool or None
        Per sleeper (True), global (False) or both (None: the site depends on whether a
        sleeper is given).
    names : tuple of str
        Parameter names (the fitted vector's entries; ``gaps`` expands to 6).
    lower, upper : tuple of float
        Bounds per entry of the fitted vector.
    log : bool
        Fit on a log scale (stiffness factors).
    grid : tuple of float
        Screening magnitudes (the scalar of :meth:`apply_scalar`).
    global_site, local_site : KeySite or SleeperListSite or None
        How the cause enters the scenario without / with a sleeper. A kind made for a
        plain key path (calibration's ``key.path=LO:HI``) with neither gets a
        :class:`KeySite` at its ``name``.
    unit : str
        Unit of the parameters (``m``, ``rad``, ``-``).
    aliases : dict
        ``--params`` item names: ``{"global": "h1"}``, ``{"local": "pad"}``, ...
    fmu_parameters : dict
        Track-FMU parameters the cause maps onto, per scope (the SSP binds them; the
        FMU declares them in :mod:`fmus.track_fmu`, which cannot import this module).
    category : str
        ``track``, ``vehicle``, ``measurement`` or ``sensor`` (module docstring): only
        ``track`` causes are a diagnosis's candidates (:func:`candidates`).
    nuisance : bool
        A track property fitted with the nuisance parameters before any cause and never
        screened as one (the track's damping: known only roughly, its effect broad and
        small, it would soak up any misfit).
    shapes : tuple of (tuple of float, tuple of float)
        Further screening proxies of a vector cause besides the uniform one: (profile of
        peak 1 along the vector, its magnitudes). A void is screened as a uniform gap and
        as the two one-sided wedges (:data:`VOID_SHAPES`); the screening keeps, per
        candidate, the proxy whose best magnitude fits best.
    """

    name: str
    local: bool | None
    names: tuple
    lower: tuple
    upper: tuple
    log: bool
    grid: tuple
    global_site: Site | None = None
    local_site: Site | None = None
    unit: str = "-"
    aliases: dict = field(default_factory=dict)
    fmu_parameters: dict = field(default_factory=dict)
    category: str = "track"
    nuisance: bool = False
    shapes: tuple = ()

    def __post_init__(self):
        if self.category not in CATEGORIES:
            raise ValueError(f"cause {self.name!r}: category {self.category!r} is not one of {', '.join(CATEGORIES)}")

    # ---------------------------------------------------------------- where it lives
    def site(self, sleeper: int | None) -> Site:
        if self.global_site is None and self.local_site is None:
            return KeySite(self.name)
        site = self.global_site if sleeper is None else self.local_site
        if site is None:
            where = "a sleeper" if sleeper is None else "no sleeper"
            raise ValueError(f"cause {self.name!r} needs {where}")
        return site

    def scenario_key(self, sleeper: int | None) -> str:
        """The scenario key whose whole value carries this cause at ``sleeper``."""
        return self.site(sleeper).scenario_key(sleeper)

    @property
    def vector(self) -> bool:
        """The parameters are one vector of a single name (the 6 gaps)."""
        return len(self.names) > 1 and len(set(self.names)) == 1

    # ---------------------------------------------------------------- values
    def nominal(self, raw: dict, sleeper: int | None) -> np.ndarray:
        """The parameter vector the nominal scenario has (the 'no effect' point)."""
        return self.site(sleeper).nominal(raw, sleeper, len(self.names))

    def screen_proxies(self) -> list[tuple[np.ndarray, tuple]]:
        """The screening proxies: (profile of peak 1, magnitudes), the uniform one (:attr:`grid`) first."""
        return [(np.ones(len(self.names)), self.grid)] + [(np.asarray(p, float), g) for p, g in self.shapes]

    def scalar_to_vector(self, value: float, profile: np.ndarray | None = None) -> np.ndarray:
        """The parameter vector of a screening magnitude: ``value`` times ``profile`` (default uniform)."""
        return np.full(len(self.names), value) if profile is None else value * np.asarray(profile, float)

    def apply(self, raw: dict, sleeper: int | None, values) -> dict:
        """A copy of the raw scenario with this cause set to ``values``."""
        raw = copy.deepcopy(raw)
        self.site(sleeper).apply(raw, sleeper, np.asarray(values, float))
        return raw

    def apply_scalar(self, raw: dict, sleeper: int | None, value: float, profile: np.ndarray | None = None) -> dict:
        return self.apply(raw, sleeper, self.scalar_to_vector(value, profile))

    def parameters(self, values) -> dict:
        """JSON-able parameters (``{"gaps": [...]}``, ``{"stiffness_scale": s}``, ...)."""
        values = [float(v) for v in np.asarray(values, float)]
        return {self.names[0]: values if self.vector else values[0]}

    def values_of(self, parameters: dict) -> list[float]:
        """The parameter vector of JSON-able parameters (the inverse of :meth:`parameters`)."""
        v = parameters[self.names[0]]
        return list(v) if self.vector else [v]

    # ---------------------------------------------------------------- the unit cube
    def to_unit(self, values) -> np.ndarray:
        lo, hi, v = (np.asarray(a, float) for a in (self.lower, self.upper, values))
        if self.log:
            return (np.log(v) - np.log(lo)) / (np.log(hi) - np.log(lo))
        return (v - lo) / (hi - lo)

    def from_unit(self, u) -> np.ndarray:
        lo, hi, u = (np.asarray(a, float) for a in (self.lower, self.upper, u))
        u = np.clip(u, 0.0, 1.0)
        if self.log:
            return np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo)))
        return lo + u * (hi - lo)


CATALOGUE: dict[str, CauseKind] = {k.name: k for k in (
    CauseKind("ballast_void", True, ("gaps",) * N_GAPS, (0.0,) * N_GAPS, (GAP_MAX,) * N_GAPS, False,
              (0.4e-3, 1.0e-3, 2.0e-3, 3.5e-3), shapes=VOID_SHAPES,
              local_site=SleeperListSite("track.ballast.voids", "gaps", 0.0, vector=True, drop_at_default=True,
                                         lower_clip=0.0),
              unit="m", aliases={"local": "gaps"},
              fmu_parameters={"local": ("void_sleeper",) + tuple(f"void_gap_{i + 1}" for i in range(N_GAPS))}),
    CauseKind("ballast_stiffness", False, ("stiffness_scale",), (0.2,), (5.0,), True, (0.3, 0.55, 1.8, 3.3),
              global_site=KeySite("track.ballast.stiffness_scale"), aliases={"global": "h1"},
              fmu_parameters={"global": ("h1",)}),
    CauseKind("rail_pad_stiffness", None, ("stiffness_scale",), (0.05,), (20.0,), True, (0.1, 0.3, 3.0, 10.0),
              global_site=KeySite("track.rail_pad.stiffness_scale"),
              local_site=SleeperListSite("track.rail_pad.overrides", "stiffness_scale", 1.0),
              aliases={"global": "h2", "local": "pad"}, fmu_parameters={"global": ("h2",)}),
    CauseKind("impact_angle", False, ("impact_angle",), (0.0,), (0.03,), False, (0.0, 0.012, 0.02, 0.03),
              global_site=KeySite("track.crossing.impact_angle"), unit="rad", aliases={"global": "angle"},
              fmu_parameters={"global": ("impact_angle",)}),
    # track damping: measured pad damping is 1e4-1e5 N s/m per seat, ballast of the same order per
    # metre (inputs.schema's plausible ranges); a decade either side of the defaults
    CauseKind("rail_pad_damping", False, ("damping",), (2e3,), (2e5,), True, (5e3, 1e4, 4e4, 8e4),
              global_site=KeySite("track.rail_pad.damping"), unit="N s/m", aliases={"global": "c_pad"},
              nuisance=True),
    CauseKind("ballast_damping", False, ("damping_per_length",), (3e3,), (3e5,), True, (7.5e3, 1.5e4, 6e4, 1.2e5),
              global_site=KeySite("track.ballast.damping_per_length"), unit="N s/m2", aliases={"global": "c_bed"},
              nuisance=True),
    # the vehicle (module docstring): our models' parameter names, as start values
    CauseKind("wheelset_mass", False, ("wheelset_mass",), (800.0,), (2500.0,), False, (1200.0, 1350.0, 1650.0, 1800.0),
              global_site=VehicleSite("wheelset_mass"), unit="kg", aliases={"global": "m_w"}, category="vehicle"),
    CauseKind("primary_stiffness", False, ("k1",), (5e5,), (3e6,), True, (0.8e6, 1.0e6, 1.45e6, 1.8e6),
              global_site=VehicleSite("k1"), unit="N/m", aliases={"global": "k1"}, category="vehicle"),
    CauseKind("primary_damping", False, ("c1",), (3e3,), (8e4,), True, (5e3, 1e4, 4e4, 6e4),
              global_site=VehicleSite("c1"), unit="N s/m", aliases={"global": "c1"}, category="vehicle"),
    CauseKind("speed", False, ("speed",), (5.0,), (120.0,), False, (),
              global_site=SpeedSite(), unit="m/s", aliases={"global": "speed"}, category="measurement"),
    # sensor faults: at a channel (Candidate.channel); gain 0.5-2 covers a mis-set amplifier or
    # a gauge factor off by a factor 2, offsets and a dead channel's level are in channel spreads
    CauseKind("channel_gain", True, ("gain",), (0.5,), (2.0,), True, (),
              local_site=ChannelSite("gain"), category="sensor"),
    CauseKind("channel_offset", True, ("offset",), (-1.0,), (1.0,), False, (),
              local_site=ChannelSite("offset"), category="sensor"),
    CauseKind("channel_dead", True, ("level",), (-1.0,), (1.0,), False, (),
              local_site=ChannelSite("level"), category="sensor"),
)}
"""Cause name -> kind. ``rail_pad_stiffness`` is global and local (``local=None``)."""


def candidates(sensor_sleepers, n_sleepers: int, reach: int = 1, categories=("track",)) -> list[Candidate]:
    """Every cause of the given categories (default: the track's) at every place the sensors can see.

    Local causes are placed on the sleepers carrying sensors and ``reach`` sleepers
    beyond them on either side ("near the sensors"); global causes once. Sensor faults
    live at a channel, not a sleeper, and nuisance kinds (:attr:`CauseKind.nuisance`)
    are fitted before any cause: neither is ever a candidate here.
    """
    near = sorted({k + d for k in sensor_sleepers for d in range(-reach, reach + 1) if 0 <= k + d < n_sleepers})
    out = []
    for name, kind in CATALOGUE.items():
        if kind.category not in categories or kind.category == "sensor" or kind.nuisance:
            continue
        if kind.local in (False, None):
            out.append(Candidate(name))
        if kind.local in (True, None):
            out.extend(Candidate(name, k) for k in near)
    return out


def kind_of(c: Candidate) -> CauseKind:
    return CATALOGUE[c.cause]


# ------------------------------------------------------------------------------------ synthetic draws
def _pick(rng: np.random.Generator, low: tuple, high: tuple) -> float:
    """A magnitude from one of two ranges (softer or stiffer than nominal), each with probability 1/2."""
    return float(rng.uniform(*(low if rng.random() < 0.5 else high)))


def _draw_void(rng: np.random.Generator) -> dict:
    """A void of 0.6-2 mm peak, shaped as a random hump or a one-sided wedge over the 6 points."""
    peak = rng.uniform(0.6e-3, 2.0e-3)
    s = np.linspace(0.0, 1.0, N_GAPS)
    if rng.random() < 0.5:
        c, w = rng.uniform(0.3, 0.7), rng.uniform(0.25, 0.5)
        shape = np.clip(1.0 - ((s - c) / w) ** 2, 0.0, None)
    else:
        shape = s if rng.random() < 0.5 else s[::-1]
    return {"gaps": [float(round(g, 6)) for g in peak * shape / shape.max()]}


@dataclass(frozen=True)
class Draw:
    """How a synthetic case draws one cause at one scope (:func:`orchestrator.inverse.synthetic.hidden_effect`).

    Attributes
    ----------
    label : str
        The hidden-effect kind (``rail_pad_stiffness_local`` for the local pads).
    cause : str
    local : bool
        Drawn at one of the given sleepers.
    parameters : callable
        ``parameters(rng) -> dict``, the cause's JSON-able parameters.
    sleeper_first : bool
        A local cause's sleeper is drawn before its parameters (else after): the order
        the seeded draws were first made in, kept so that a seed gives the same case.
    """

    label: str
    cause: str
    local: bool
    parameters: Callable[[np.random.Generator], dict]
    sleeper_first: bool = False

    def draw(self, rng: np.random.Generator, sleepers) -> tuple[int | None, dict]:
        """(sleeper or None, parameters) of one draw."""
        if not self.local:
            return None, self.parameters(rng)
        if self.sleeper_first:
            sleeper = int(rng.choice(sleepers))
            return sleeper, self.parameters(rng)
        parameters = self.parameters(rng)
        return int(rng.choice(sleepers)), parameters


DRAWS: tuple[Draw, ...] = (
    # Ranges a crossing survey would call relevant, inside the catalogue's bounds. The order
    # is that of a random kind's draw: append new causes at the end (seeded draws stay the same).
    Draw("ballast_void", "ballast_void", True, _draw_void),
    Draw("ballast_stiffness", "ballast_stiffness", False,
         lambda rng: {"stiffness_scale": _pick(rng, (0.35, 0.6), (1.8, 3.0))}),
    Draw("rail_pad_stiffness_local", "rail_pad_stiffness", True,     # a worn or missing pad, or a stiff one
         lambda rng: {"stiffness_scale": _pick(rng, (0.1, 0.3), (4.0, 8.0))}, sleeper_first=True),
    Draw("impact_angle", "impact_angle", False,                      # a worn nose (nominal 6 mrad)
         lambda rng: {"impact_angle": float(rng.uniform(0.012, 0.022))}),
    Draw("rail_pad_stiffness", "rail_pad_stiffness", False,
         lambda rng: {"stiffness_scale": _pick(rng, (0.3, 0.5), (2.5, 5.0))}),
)


__all__ = ["Candidate", "CauseKind", "CATALOGUE", "CATEGORIES", "candidates", "kind_of", "KeySite", "SleeperListSite",
           "VehicleSite", "SpeedSite", "ChannelSite", "Draw", "DRAWS", "N_GAPS", "GAP_MAX"]
