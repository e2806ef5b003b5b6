"""Bogie with half car-body mass (vertical dynamics: bounce, pitch, roll).

Bodies and coordinates (9 dofs, in this order)::

    0 carbody_z    car body (half) bounce [m]      1 carbody_roll  [rad]
    2 frame_z      bogie frame bounce [m]          3 frame_pitch   [rad]
    4 frame_roll   [rad]
    5 ws1_z, 6 ws1_roll   front wheelset bounce [m], roll [rad]
    7 ws2_z, 8 ws2_roll   rear wheelset

Sign conventions: z up, y to the left, x forward (driving direction).  A point at
lateral position y and longitudinal position s (relative to the body centre) of a
body moves by ``z + y * roll + s * pitch``: positive roll lifts the left side,
positive pitch lifts the front.  Wheelset j sits at ``s = +a`` (front, j = 1) and
``s = -a`` (rear), ``a = wheelbase / 2``.  Wheels: 1 = front left, 2 = front right,
3 = rear left, 4 = rear right, contact points at ``y = +/- b0``.

Suspension (Kelvin elements, elongation = upper point minus lower point):

* primary, one per axle box (4): between the frame at ``(s = +/-a, y = +/-b1)`` and
  the wheelset at ``y = +/-b1``; stiffness ``k1``, damping ``c1`` each;
* secondary, one per bogie side (2): between the car body at ``y = +/-b2`` and the
  frame at ``(s = 0, y = +/-b2)``; ``k2``, ``c2`` each.

The car body carries half the car's mass and has bounce and roll only: its pitch
involves the other bogie and is outside this model.  Gravity acts on every mass.

Default values (``BogieParams``) describe a 20 t axle-load vehicle.  Typical
ranges (cf. Iwnicki (ed.), *Handbook of Railway Vehicle Dynamics*, CRC Press 2006,
chapters on suspension components and vehicle design; values vary widely between
passenger and freight designs):

* primary vertical stiffness 0.5-2 MN/m per axle box, damping 5-30 kN s/m per box;
* secondary vertical stiffness 0.3-1 MN/m per side (air springs at the low end),
  damping 10-40 kN s/m per side;
* bogie frame 2.5-3.5 t, pitch inertia 1.5-3 t m^2; wheelset 1.3-1.8 t incl. axle boxes.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .linear import GRAVITY, LinearVehicle, SuspensionAssembler
from .linear import param_field as _p

BOGIE_DOFS = ("carbody_z", "carbody_roll", "frame_z", "frame_pitch", "frame_roll",
              "ws1_z", "ws1_roll", "ws2_z", "ws2_roll")


@dataclass(frozen=True)
class BogieParams:
    """Parameters of :func:`bogie` (SI units; see the module docstring for geometry).

    The car-body (half) mass is not a parameter: it is set so that the total weight
    of the model is ``2 * axle_load`` (property :attr:`carbody_mass`).
    """

    axle_load: float = _p(196200.0, "N", "static axle load; total weight of the model is 2 x axle_load")
    wheelbase: float = _p(2.5, "m", "distance between the two wheelsets")
    wheel_radius: float = _p(0.46, "m", "nominal wheel rolling radius (contact geometry; not used by the vertical dynamics)")
    b0: float = _p(0.75, "m", "lateral semi-distance of the wheel-rail contact points")
    b1: float = _p(1.0, "m", "lateral semi-distance of the primary springs (axle boxes)")
    b2: float = _p(1.0, "m", "lateral semi-distance of the secondary springs")
    frame_mass: float = _p(3000.0, "kg", "bogie frame mass")
    frame_pitch_inertia: float = _p(2000.0, "kg.m2", "bogie frame pitch moment of inertia")
    frame_roll_inertia: float = _p(1600.0, "kg.m2", "bogie frame roll moment of inertia")
    wheelset_mass: float = _p(1500.0, "kg", "wheelset mass including axle boxes (unsprung)")
    wheelset_roll_inertia: float = _p(700.0, "kg.m2", "wheelset roll moment of inertia")
    carbody_roll_inertia: float = _p(4.0e4, "kg.m2", "roll moment of inertia of the half car body")
    k1: float = _p(1.2e6, "N/m", "primary vertical stiffness per axle box")
    c1: float = _p(1.0e4, "N.s/m", "primary vertical damping per axle box")
    k2: float = _p(0.6e6, "N/m", "secondary vertical stiffness per bogie side")
    c2: float = _p(2.0e4, "N.s/m", "secondary vertical damping per bogie side")

    def __post_init__(self):
        for name in ("axle_load", "wheelbase", "wheel_radius", "b0", "b1", "b2", "frame_mass",
                     "frame_pitch_inertia", "frame_roll_inertia", "wheelset_mass",
                     "wheelset_roll_inertia", "carbody_roll_inertia", "k1", "k2"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"BogieParams.{name} must be positive and finite, got {value}")
        for name in ("c1", "c2"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"BogieParams.{name} must be non-negative and finite, got {value}")
        if self.carbody_mass <= 0:
            raise ValueError(f"axle_load {self.axle_load} N is too small for the frame and wheelset "
                             f"masses (car-body share {self.carbody_mass:.1f} kg)")

    @property
    def carbody_mass(self) -> float:
        """Half car-body mass [kg]: ``2 axle_load / g - frame - 2 wheelsets``."""
        return 2.0 * self.axle_load / GRAVITY - self.frame_mass - 2.0 * self.wheelset_mass


def bogie(params: BogieParams | None = None) -> LinearVehicle:
    """Build the bogie model (9 dofs, 4 wheels); see the module docstring."""
    p = BogieParams() if params is None else params
    n = len(BOGIE_DOFS)
    e = np.eye(n)
    i = {name: k for k, name in enumerate(BOGIE_DOFS)}
    a = 0.5 * p.wheelbase

    M = np.diag([p.carbody_mass, p.carbody_roll_inertia, p.frame_mass, p.frame_pitch_inertia,
                 p.frame_roll_inertia, p.wheelset_mass, p.wheelset_roll_inertia,
                 p.wheelset_mass, p.wheelset_roll_inertia])
    f_g = -GRAVITY * np.array([p.carbody_mass, 0, p.frame_mass, 0, 0, p.wheelset_mass, 0,
                               p.wheelset_mass, 0])

    susp = SuspensionAssembler(n)
    for ws, s in (("ws1", a), ("ws2", -a)):
        for y in (p.b1, -p.b1):
            frame_point = e[i["frame_z"]] + s * e[i["frame_pitch"]] + y * e[i["frame_roll"]]
            axle_box = e[i[f"{ws}_z"]] + y * e[i[f"{ws}_roll"]]
            susp.add(frame_point - axle_box, p.k1, p.c1)
    for y in (p.b2, -p.b2):
        body_point = e[i["carbody_z"]] + y * e[i["carbody_roll"]]
        frame_point = e[i["frame_z"]] + y * e[i["frame_roll"]]
        susp.add(body_point - frame_point, p.k2, p.c2)

    W = np.array([e[i[f"{ws}_z"]] + y * e[i[f"{ws}_roll"]]
                  for ws in ("ws1", "ws2") for y in (p.b0, -p.b0)])
    offsets = np.array([0.0, 0.0, -p.wheelbase, -p.wheelbase])
    return LinearVehicle(M, susp.C, susp.K, f_g, W, offsets, BOGIE_DOFS)


def bounce_pitch_frequencies(params: BogieParams | None = None) -> tuple[float, float]:
    """Analytic bounce and pitch frequencies [Hz] of the bogie frame.

    The frame moves on its four primary springs with the wheelsets held fixed and
    the car body held fixed, so each secondary spring acts as a spring to ground
    under the frame centre (it adds bounce stiffness, no pitch stiffness because it
    sits at ``s = 0``).  The two dofs are uncoupled for this symmetric layout::

        f_bounce = sqrt((4 k1 + 2 k2) / m_frame) / 2 pi
        f_pitch  = sqrt(4 k1 a^2 / J_pitch) / 2 pi,     a = wheelbase / 2

    Returns
    -------
    (f_bounce, f_pitch) : tuple of float
    """
    p = BogieParams() if params is None else params
    a = 0.5 * p.wheelbase
    f_bounce = np.sqrt((4 * p.k1 + 2 * p.k2) / p.frame_mass) / (2 * np.pi)
    f_pitch = np.sqrt(4 * p.k1 * a * a / p.frame_pitch_inertia) / (2 * np.pi)
    return float(f_bounce), float(f_pitch)
