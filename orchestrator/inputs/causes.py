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
                                0-4 mm (screened with one uniform gap)
``ballast_stiffness``  global   ``stiffness_scale`` h1, 0.2-5 (log)           ``track.ballast.stiffness_scale``
``rail_pad_stiffness`` global   ``stiffness_scale`` h2, 0.1-10 (log)          ``track.rail_pad.stiffness_scale``
``rail_pad_stiffness`` sleeper  ``stiffness_scale`` of that sleeper's pads,  ``track.rail_pad.overrides``
                                0.05-20 (log)
``impact_angle``       global   ``impact_angle`` 0-30 mrad                    ``track.crossing.impact_angle``
=====================  =======  ===========================================  =====================

A cause is *screened* with one scalar magnitude on a grid (:attr:`CauseKind.grid`,
:meth:`CauseKind.apply_scalar`) and the chosen one is then *fitted* with all its
parameters (:meth:`CauseKind.apply`). Values are stored in the units of the scenario
keys (gaps in m, scales as factors, the angle in rad). The bounds are those of a
plausible track: voids up to 4 mm (seed 000 calibrated 0-2.3 mm), bed and pad stiffness
a factor 5-10 around nominal (DESIGN.md §7 ranges), worn-nose angles up to 30 mrad.

How a cause enters the scenario is a *site* (:class:`KeySite`: one number at a key path;
:class:`SleeperListSite`: the entry of one sleeper in a list such as
``track.ballast.voids``), so no code here branches on a cause's name.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from orchestrator.inputs import keypath

N_GAPS = 6          # void gap points along a sleeper (DESIGN.md §4.2)
GAP_MAX = 4e-3      # m


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


# ------------------------------------------------------------------------------------ causes
@dataclass(frozen=True)
class Candidate:
    """One cause at one place: what the diagnosis screens, fits and ranks."""

    cause: str
    sleeper: int | None = None

    @property
    def label(self) -> str:
        return self.cause if self.sleeper is None else f"{self.cause}@{self.sleeper}"


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
    """

    name: str
    local: bool | None
    names: tuple
    lower: tuple
    upper: tuple
    log: bool
    grid: tuple
    global_site: KeySite | SleeperListSite | None = None
    local_site: KeySite | SleeperListSite | None = None
    unit: str = "-"
    aliases: dict = field(default_factory=dict)
    fmu_parameters: dict = field(default_factory=dict)

    # ---------------------------------------------------------------- where it lives
    def site(self, sleeper: int | None) -> KeySite | SleeperListSite:
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

    def scalar_to_vector(self, value: float) -> np.ndarray:
        """The parameter vector of a screening magnitude (a uniform gap for voids)."""
        return np.full(len(self.names), value)

    def apply(self, raw: dict, sleeper: int | None, values) -> dict:
        """A copy of the raw scenario with this cause set to ``values``."""
        raw = copy.deepcopy(raw)
        self.site(sleeper).apply(raw, sleeper, np.asarray(values, float))
        return raw

    def apply_scalar(self, raw: dict, sleeper: int | None, value: float) -> dict:
        return self.apply(raw, sleeper, self.scalar_to_vector(value))

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
              (0.4e-3, 1.0e-3, 2.0e-3, 3.5e-3),
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
)}
"""Cause name -> kind. ``rail_pad_stiffness`` is global and local (``local=None``)."""


def candidates(sensor_sleepers, n_sleepers: int, reach: int = 1) -> list[Candidate]:
    """Every cause at every place the sensors can see.

    Local causes are placed on the sleepers carrying sensors and ``reach`` sleepers
    beyond them on either side ("near the sensors"); global causes once.
    """
    near = sorted({k + d for k in sensor_sleepers for d in range(-reach, reach + 1) if 0 <= k + d < n_sleepers})
    out = []
    for name, kind in CATALOGUE.items():
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


__all__ = ["Candidate", "CauseKind", "CATALOGUE", "candidates", "kind_of", "KeySite", "SleeperListSite", "Draw",
           "DRAWS", "N_GAPS", "GAP_MAX"]
