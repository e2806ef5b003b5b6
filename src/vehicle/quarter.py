r"""Quarter vehicle: one wheelset under a sprung mass, optionally with a flexible wheelset.

The sprung mass stands for the share of bogie frame and car body carried by one
wheelset; it rests on the primary suspension of that wheelset.  Seed 001 (Pålsson
2020) uses "a quarter vehicle model with a flexible wheelset and an axle load of
20 metric tonnes"; ``flexible=True`` (default) adds the wheelset's first symmetric
bending mode.

Rigid quarter vehicle (``flexible=False``): exact equations
-----------------------------------------------------------
These are the equations this module implements; a third-party FMU may re-implement
them for a cross-check.  z up, y to the left (wheel 1 = left, y = +b0; wheel 2 =
right), all coordinates absolute and measured from the configuration in which the
primary springs are unstrained.

Coordinates ``q = [z_s, phi_s, z_w, phi_w]``: sprung-mass bounce [m] and roll [rad],
wheelset bounce [m] and roll [rad]; positive roll lifts the left side.

Primary spring elongations (left/right axle box, lateral position +/- b1)::

    d_L = (z_s + b1 phi_s) - (z_w + b1 phi_w)
    d_R = (z_s - b1 phi_s) - (z_w - b1 phi_w)
    P_L = k1 d_L + c1 d_L'            P_R = k1 d_R + c1 d_R'      (tension +)

Equations of motion (``F_L``, ``F_R`` = contact forces on wheels 1, 2, upward +)::

    m_s z_s''   = -(P_L + P_R) - m_s g
    J_s phi_s'' = -b1 (P_L - P_R)
    m_w z_w''   =  (P_L + P_R) - m_w g + F_L + F_R
    J_w phi_w'' =  b1 (P_L - P_R) + b0 (F_L - F_R)

Outputs (wheel contact points)::

    z_L = z_w + b0 phi_w      z_R = z_w - b0 phi_w      (velocities likewise)

Static state for prescribed wheel positions z0_L, z0_R (zero velocities)::

    z_w = (z0_L + z0_R) / 2,  phi_w = (z0_L - z0_R) / (2 b0),  phi_s = phi_w,
    z_s = z_w - m_s g / (2 k1),   F_L = F_R = (m_s + m_w) g / 2 = axle_load / 2

Numeric defaults (``QuarterParams()``): g = 9.81 m/s^2, axle_load = 196200 N,
m_w = 1500 kg, m_s = axle_load / g - m_w = 18500 kg, J_s = 2.0e4 kg m^2,
J_w = 700 kg m^2, k1 = 1.2e6 N/m and c1 = 2.0e4 N s/m per axle box, b1 = 1.0 m,
b0 = 0.75 m.  (c1 gives the sprung mass about 10 % of critical damping in bounce:
c_crit = 2 sqrt(2 k1 m_s) = 4.2e5 N s/m for the two boxes.)

Flexible wheelset (``flexible=True``)
-------------------------------------
A fifth coordinate ``q_b`` [m], the amplitude of the first symmetric bending mode of
the free-free wheelset, normalised to 1 at the wheel contact points.  Assumed mode
shape (a two-lump idealisation): the wheels and the axle journals (axle boxes) move
together with amplitude 1 (the stub between wheel seat and journal is taken as
rigid); an axle-centre lump of mass ``m_c`` (``axle_centre_mass``) moves with
``psi_c = -(m_w - m_c) / m_c`` so that the mode is mass-orthogonal to bounce (and,
being symmetric, to roll).  Hence gravity does not load ``q_b``, ``z_w`` remains the
wheelset's mass-centre bounce, and::

    modal mass       m_b = (m_w - m_c) m_w / m_c
    modal stiffness  k_b = m_b (2 pi f_b)^2        f_b = bending_frequency
    modal damping    c_b = 2 zeta_b sqrt(k_b m_b)
    wheels:          z_L,R = z_w +/- b0 phi_w + q_b
    axle boxes:      d_L,R = (z_s +/- b1 phi_s) - (z_w +/- b1 phi_w + q_b)
    m_b q_b'' + c_b q_b' + k_b q_b = P_L + P_R + F_L + F_R

Equivalently: wheel/journal ends (mass m_w - m_c) and axle centre (m_c) joined by a
spring ``k_b (m_c / m_w)^2``.  ``f_b`` = 80 Hz is an assumption taken from the
brief of this package ("about 80 Hz free-free bending"); it is of the order of the
first symmetric bending frequencies published for passenger and freight wheelsets
(roughly 70-100 Hz), but no specific measurement was checked here -- set it from a
modal test or an FE model of the actual wheelset.  ``m_c`` = 400 kg (about a quarter
of the wheelset mass at the axle centre) and ``zeta_b`` = 1 % (light structural
damping of a steel wheelset) are assumptions of the same kind.  The static axle bending caused by the outboard journal loads is
not represented (journals move with the wheels): the mode adds the wheelset's dynamic
flexibility, which lowers the effective unsprung mass seen by the rail above f_b.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linear import GRAVITY, LinearVehicle, SuspensionAssembler
from .linear import param_field as _p

QUARTER_DOFS = ("sprung_z", "sprung_roll", "ws_z", "ws_roll")
QUARTER_DOFS_FLEX = QUARTER_DOFS + ("ws_bending",)


@dataclass(frozen=True)
class QuarterParams:
    """Parameters of :func:`quarter_vehicle` (SI units; see the module docstring).

    The sprung mass is not a parameter: ``m_s = axle_load / g - wheelset_mass``
    (property :attr:`sprung_mass`), so the total weight equals the axle load.
    """

    axle_load: float = _p(196200.0, "N", "static axle load = total weight of the model")
    wheelset_mass: float = _p(1500.0, "kg", "wheelset mass including axle boxes (unsprung)")
    sprung_roll_inertia: float = _p(2.0e4, "kg.m2", "roll moment of inertia of the sprung mass")
    wheelset_roll_inertia: float = _p(700.0, "kg.m2", "wheelset roll moment of inertia")
    k1: float = _p(1.2e6, "N/m", "primary vertical stiffness per axle box")
    c1: float = _p(2.0e4, "N.s/m", "primary vertical damping per axle box")
    b0: float = _p(0.75, "m", "lateral semi-distance of the wheel-rail contact points")
    b1: float = _p(1.0, "m", "lateral semi-distance of the primary springs (axle boxes)")
    flexible: bool = _p(True, "-", "include the first symmetric bending mode of the wheelset")
    bending_frequency: float = _p(80.0, "Hz", "free-free first symmetric bending frequency of the wheelset")
    bending_damping_ratio: float = _p(0.01, "-", "modal damping ratio of the wheelset bending mode")
    axle_centre_mass: float = _p(400.0, "kg", "wheelset mass lumped at the axle centre in the bending mode")

    def __post_init__(self):
        for name in ("axle_load", "wheelset_mass", "sprung_roll_inertia", "wheelset_roll_inertia",
                     "k1", "b0", "b1", "bending_frequency", "axle_centre_mass"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"QuarterParams.{name} must be positive and finite, got {value}")
        for name in ("c1", "bending_damping_ratio"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"QuarterParams.{name} must be non-negative and finite, got {value}")
        if self.axle_centre_mass >= self.wheelset_mass:
            raise ValueError("QuarterParams.axle_centre_mass must be smaller than wheelset_mass")
        if self.sprung_mass <= 0:
            raise ValueError(f"axle_load {self.axle_load} N is too small for the wheelset mass")

    @property
    def sprung_mass(self) -> float:
        """Sprung mass [kg]: ``axle_load / g - wheelset_mass``."""
        return self.axle_load / GRAVITY - self.wheelset_mass

    @property
    def bending_modal_mass(self) -> float:
        """Modal mass of the bending mode, normalised to 1 at the wheels [kg]."""
        m_c = self.axle_centre_mass
        return (self.wheelset_mass - m_c) * self.wheelset_mass / m_c


def quarter_vehicle(params: QuarterParams | None = None) -> LinearVehicle:
    """Build the quarter vehicle (4 dofs, or 5 with ``flexible``; 2 wheels)."""
    p = QuarterParams() if params is None else params
    names = QUARTER_DOFS_FLEX if p.flexible else QUARTER_DOFS
    n = len(names)
    e = np.eye(n)
    zs, phis, zw, phiw = e[0], e[1], e[2], e[3]
    bend = e[4] if p.flexible else np.zeros(n)   # moves wheels and journals by 1 per unit

    masses = [p.sprung_mass, p.sprung_roll_inertia, p.wheelset_mass, p.wheelset_roll_inertia]
    f_g = -GRAVITY * np.array([p.sprung_mass, 0.0, p.wheelset_mass, 0.0] + [0.0] * (n - 4))
    susp = SuspensionAssembler(n)
    for y in (p.b1, -p.b1):
        susp.add((zs + y * phis) - (zw + y * phiw + bend), p.k1, p.c1)
    K, C = susp.K, susp.C
    if p.flexible:
        m_b = p.bending_modal_mass
        k_b = m_b * (2 * np.pi * p.bending_frequency) ** 2
        masses.append(m_b)
        K[4, 4] += k_b
        C[4, 4] += 2 * p.bending_damping_ratio * np.sqrt(k_b * m_b)
    W = np.array([zw + p.b0 * phiw + bend, zw - p.b0 * phiw + bend])
    return LinearVehicle(np.diag(masses), C, K, f_g, W, np.zeros(2), names)
