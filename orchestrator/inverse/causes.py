"""The catalogue of model extensions a diagnosis can name (DESIGN.md §4.5).

Each cause is a way the real track may differ from the nominal scenario, with its
parameters, their bounds and how they enter the scenario:

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
"""
from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

N_GAPS = 6          # void gap points along a sleeper (DESIGN.md §4.2)
GAP_MAX = 4e-3      # m


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
    """A cause of the catalogue (module docstring).

    Attributes
    ----------
    name : str
    local : bool
        Per sleeper (True) or global.
    names : tuple of str
        Parameter names (the fitted vector's entries; ``gaps`` expands to 6).
    lower, upper : tuple of float
        Bounds per entry of the fitted vector.
    log : bool
        Fit on a log scale (stiffness factors).
    grid : tuple of float
        Screening magnitudes (the scalar of :meth:`apply_scalar`).
    """

    name: str
    local: bool
    names: tuple
    lower: tuple
    upper: tuple
    log: bool
    grid: tuple

    # ---------------------------------------------------------------- values
    def nominal(self, raw: dict, sleeper: int | None) -> np.ndarray:
        """The parameter vector the nominal scenario has (the 'no effect' point)."""
        t = raw["track"]
        if self.name == "ballast_void":
            for v in t["ballast"].get("voids") or []:
                if v["sleeper"] == sleeper:
                    return np.array(v["gaps"], float)
            return np.zeros(N_GAPS)
        if self.name == "ballast_stiffness":
            return np.array([t["ballast"]["stiffness_scale"]], float)
        if self.name == "rail_pad_stiffness" and sleeper is None:
            return np.array([t["rail_pad"]["stiffness_scale"]], float)
        if self.name == "rail_pad_stiffness":
            for o in t["rail_pad"].get("overrides") or []:
                if o["sleeper"] == sleeper:
                    return np.array([o["stiffness_scale"]], float)
            return np.array([1.0])
        return np.array([t["crossing"]["impact_angle"]], float)

    def scalar_to_vector(self, value: float) -> np.ndarray:
        """The parameter vector of a screening magnitude (a uniform gap for voids)."""
        return np.full(N_GAPS, value) if self.name == "ballast_void" else np.array([value])

    def apply(self, raw: dict, sleeper: int | None, values) -> dict:
        """A copy of the raw scenario with this cause set to ``values``."""
        raw = copy.deepcopy(raw)
        t = raw["track"]
        values = np.asarray(values, float)
        if self.name == "ballast_void":
            voids = [v for v in (t["ballast"].get("voids") or []) if v["sleeper"] != sleeper]
            gaps = [float(g) for g in np.clip(values, 0.0, None)]
            if any(g > 0 for g in gaps):
                voids.append({"sleeper": int(sleeper), "gaps": gaps})
            t["ballast"]["voids"] = sorted(voids, key=lambda v: v["sleeper"])
        elif self.name == "ballast_stiffness":
            t["ballast"]["stiffness_scale"] = float(values[0])
        elif self.name == "rail_pad_stiffness" and sleeper is None:
            t["rail_pad"]["stiffness_scale"] = float(values[0])
        elif self.name == "rail_pad_stiffness":
            over = [o for o in (t["rail_pad"].get("overrides") or []) if o["sleeper"] != sleeper]
            over.append({"sleeper": int(sleeper), "stiffness_scale": float(values[0])})
            t["rail_pad"]["overrides"] = sorted(over, key=lambda o: o["sleeper"])
        else:
            t["crossing"]["impact_angle"] = float(values[0])
        return raw

    def apply_scalar(self, raw: dict, sleeper: int | None, value: float) -> dict:
        return self.apply(raw, sleeper, self.scalar_to_vector(value))

    def parameters(self, values) -> dict:
        """JSON-able parameters (``{"gaps": [...]}``, ``{"stiffness_scale": s}``, ...)."""
        values = [float(v) for v in np.asarray(values, float)]
        if self.name == "ballast_void":
            return {"gaps": values}
        return {self.names[0]: values[0]}

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


CATALOGUE = {
    "ballast_void": CauseKind("ballast_void", True, ("gaps",) * N_GAPS, (0.0,) * N_GAPS, (GAP_MAX,) * N_GAPS,
                              False, (0.4e-3, 1.0e-3, 2.0e-3, 3.5e-3)),
    "ballast_stiffness": CauseKind("ballast_stiffness", False, ("stiffness_scale",), (0.2,), (5.0,), True,
                                   (0.3, 0.55, 1.8, 3.3)),
    "rail_pad_stiffness": CauseKind("rail_pad_stiffness", None, ("stiffness_scale",), (0.05,), (20.0,), True,
                                    (0.1, 0.3, 3.0, 10.0)),
    "impact_angle": CauseKind("impact_angle", False, ("impact_angle",), (0.0,), (0.03,), False,
                              (0.0, 0.012, 0.02, 0.03)),
}
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


__all__ = ["Candidate", "CauseKind", "CATALOGUE", "candidates", "kind_of", "N_GAPS", "GAP_MAX"]
