"""Parameter dataclasses of the track model (SI units throughout).

These are the contracts between the scenario loader (``orchestrator.inputs.scenario``),
the layout generator (``track.layout``) and the model builder (``track.model``).
They hold numbers only, never file paths.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

GRAVITY = 9.81  # m/s^2


@dataclass(frozen=True)
class BeamSection:
    """Cross-section and material of a beam body (constant along the body).

    Attributes
    ----------
    E, G : float
        Young's and shear modulus [Pa].
    A : float
        Cross-section area [m^2].
    I : float
        Second moment of area for vertical bending [m^4].
    rho : float
        Density [kg/m^3]; mass per length is ``rho * A`` [kg/m].
    kappa : float
        Timoshenko shear coefficient [-].
    height : float
        Section height [m]; used for strain at the extreme fibre (gauges).
    width : float
        Section width [m]; for sleepers the bottom width that carries ballast pressure.
    """

    E: float
    G: float
    A: float
    I: float
    rho: float
    kappa: float
    height: float
    width: float

    @property
    def mass_per_length(self) -> float:
        return self.rho * self.A

    def scaled(self, area: float = 1.0, inertia: float = 1.0) -> "BeamSection":
        """Section with area and second moment multiplied by the given factors."""
        return BeamSection(self.E, self.G, self.A * area, self.I * inertia, self.rho,
                           self.kappa, self.height, self.width)


# 60E1 (EN 13674-1): m = 60.21 kg/m, A = 76.70 cm^2, I_y = 3038 cm^4, h = 172 mm, foot 150 mm.
# Shear coefficient 0.34 (lower end of the 0.34-0.40 range in DESIGN.md §7; the value used
# by Knothe & Grassie for UIC60).
RAIL_60E1 = BeamSection(E=210e9, G=81e9, A=76.70e-4, I=3038e-8, rho=60.21 / 76.70e-4,
                        kappa=0.34, height=0.172, width=0.150)

# Concrete turnout bearer / sleeper (DESIGN.md §7): E = 38 GPa, nu = 0.2, 0.28 m wide (bottom),
# 0.22 m high, rectangular: A = b h, I = b h^3 / 12, rho = 2500 kg/m^3 (154 kg/m).
_b, _h = 0.28, 0.22
CONCRETE_BEARER = BeamSection(E=38e9, G=38e9 / (2 * 1.2), A=_b * _h, I=_b * _h ** 3 / 12,
                              rho=2500.0, kappa=5.0 / 6.0, height=_h, width=_b)

# Check rail 33C1 (UIC 33): m = 32.6 kg/m, A = 41.6 cm^2; vertical I taken as 1000 cm^4
# (approximate: the check rail carries no wheel load, only its mass and bending matter).
CHECK_RAIL_33C1 = BeamSection(E=210e9, G=81e9, A=41.6e-4, I=1000e-8, rho=32.6 / 41.6e-4,
                              kappa=0.34, height=0.150, width=0.100)

RAIL_SECTIONS = {"60E1": RAIL_60E1}


@dataclass(frozen=True)
class BeamProfile:
    """A beam section that varies along the body (crossing rail, bearers).

    Properties are interpolated linearly in ``s`` between the stations; each
    element uses the value at its midpoint. A constant section has one station.

    Attributes
    ----------
    base : BeamSection
        Material and reference section.
    s : tuple of float
        Stations along the body axis [m] (increasing); empty for a constant section.
    area_factor, inertia_factor : tuple of float
        Multipliers of ``base.A`` and ``base.I`` at the stations [-].
    """

    base: BeamSection
    s: tuple = ()
    area_factor: tuple = ()
    inertia_factor: tuple = ()

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Area [m^2] and second moment [m^4] at positions ``s`` (shape (n,))."""
        s = np.asarray(s, dtype=float)
        if not self.s:
            return np.full(s.shape, self.base.A), np.full(s.shape, self.base.I)
        fa = np.interp(s, self.s, self.area_factor)
        fi = np.interp(s, self.s, self.inertia_factor)
        return self.base.A * fa, self.base.I * fi


@dataclass(frozen=True)
class LayoutParams:
    """Parameters of the track layout (``track.layout`` in the scenario YAML).

    Attributes
    ----------
    type : str
        ``"plain"`` (straight track) or ``"turnout"`` (crossing panel).
    crossing : str
        Crossing ratio ``"1:n"`` (tan of the crossing angle = 1/n).
    radius : float
        Turnout (diverging route) radius [m].
    sleeper_spacing : float
        Centre distance of sleepers [m].
    sleepers : int
        Number of modelled sleepers, indexed 0..N-1 in increasing track coordinate.
    route : str
        ``"through"`` or ``"diverging"``: the route the vehicle runs on.
    hand : str
        ``"left"`` or ``"right"``: side to which the diverging route turns.
    gauge : float
        Track gauge between running edges [m].
    rail : str
        Rail profile name (key of ``RAIL_SECTIONS``).
    transition_sleeper : int or None
        Index of the sleeper under the crossing transition (wheel transfer from
        wing rail to nose); ``None`` -> ``sleepers // 2 + 1``.
    sleeper_length : float
        Length of a plain-line sleeper [m] (turnout bearers grow to span their rails).
    """

    type: str = "turnout"
    crossing: str = "1:12"
    radius: float = 500.0
    sleeper_spacing: float = 0.6
    sleepers: int = 40
    route: str = "through"
    hand: str = "left"
    gauge: float = 1.435
    rail: str = "60E1"
    transition_sleeper: int | None = None
    sleeper_length: float = 2.6

    @property
    def crossing_n(self) -> float:
        return float(self.crossing.split(":")[1])


@dataclass(frozen=True)
class PadOverride:
    """Local rail-pad stiffness scale at one sleeper (all rail seats on it)."""

    sleeper: int
    stiffness_scale: float


@dataclass(frozen=True)
class RailPadParams:
    """Rail pads as Kelvin bushings per rail seat.

    Attributes
    ----------
    stiffness : float
        Vertical stiffness per rail seat [N/m].
    damping : float
        Viscous damping per rail seat [N s/m].
    stiffness_scale : float
        Global scale h2 [-].
    overrides : tuple of PadOverride
        Per-sleeper scale factors (multiply h2).
    two_bushings : bool
        Model the wide crossing-rail seat with two bushings (half stiffness each)
        across the seat instead of one at its centre.
    """

    stiffness: float = 1.2e8
    damping: float = 2.0e4
    stiffness_scale: float = 1.0
    overrides: tuple = ()
    two_bushings: bool = False


@dataclass(frozen=True)
class VoidSpec:
    """Ballast void under one sleeper: gaps at 6 equidistant points from end to end [m]."""

    sleeper: int
    gaps: tuple


@dataclass(frozen=True)
class BallastParams:
    """Bi-linear (compression-only) ballast bushings along each sleeper.

    Attributes
    ----------
    stiffness_per_length : float
        Bed stiffness per metre of sleeper [N/m/m].
    damping_per_length : float
        Bed damping per metre of sleeper [N s/m/m].
    stiffness_scale : float
        Global scale h1 [-].
    voids : tuple of VoidSpec
        Void gaps per sleeper.
    spacing : float
        Maximum lateral distance between ballast bushings along a sleeper [m].
    """

    stiffness_per_length: float = 4.0e7
    damping_per_length: float = 3.0e4
    stiffness_scale: float = 1.0
    voids: tuple = ()
    spacing: float = 0.4


@dataclass(frozen=True)
class ReductionParams:
    """Craig–Bampton settings.

    Attributes
    ----------
    f_cut : float
        Cut-off frequency of the model [Hz]: reduced eigenfrequencies below it
        are within 1 % of the full model (tests/test_reduction.py). 1500 Hz covers
        the pinned-pinned resonance (~1030 Hz) and the P1 impact force; raise it for
        receptances to higher frequencies.
    mode_factor : float
        Fixed-interface modes are kept up to ``mode_factor * f_cut`` (3: the
        smallest factor of 2, 2.5, 3 that met the 1 % bound on the assembled crossing panel).
    element_length : float
        Maximum FE element length for rails and sleepers [m] (also the spacing of
        the output stations along the solid crossing rail).
    solid_mesh_size : float
        Mesh size of the solid crossing rail (``model: solid``), gmsh ``MeshSizeMax`` [m].
    """

    f_cut: float = 1500.0
    mode_factor: float = 3.0
    element_length: float = 0.1
    solid_mesh_size: float = 0.06


@dataclass(frozen=True)
class ContactParams:
    """Wheel–rail contact geometry: the dip model or tables from wheel and rail profiles, and the
    irregularities (``track.crossing.geometry``, ``track.crossing.profiles``, ``track.irregularity``,
    ``vehicle.wheel_profile``, ``vehicle.lateral_offset``, ``vehicle.wheel_flat``, ``vehicle.wheel_polygon``).

    Attributes
    ----------
    geometry : str
        ``dip`` (:class:`track.contact.CrossingGeometry`, one Hertz constant) or ``profiles``
        (contact tables of the wheel profile on the rail sections, :mod:`track.contact_geometry`).
    wheel : tuple of (str, float)
        :class:`track.profiles.WheelProfile` parameters (empty: new S1002).
    wheel_table : tuple of 2 tuples, optional
        Measured wheel profile ``(s, F)`` [m] (replaces S1002 and ``wheel``).
    lateral_offset : float
        Wheelset lateral offset [m], positive towards the field side of the wheel that passes the
        crossing nose (constant along the track, unless ``lateral_offset_table``).
    lateral_offset_table : tuple of 2 tuples
        ``(x, y)`` [m]: the offset over the track coordinate (linear, held beyond the ends).
    crossing : tuple of (str, value)
        :class:`track.profiles.CrossingSections` parameters (tip_drop, full_width, wear stations...).
    rail_psd : tuple of 2 tuples
        One-sided PSD ``(wavenumber [1/m], G [m^3])`` of a vertical rail irregularity (empty: none).
    rail_psd_seed : int
        Seed of the left rail's realisation (the right rail: seed + 1).
    rail_psd_band : tuple of 2 float
        Wavelength band ``(shortest, longest)`` [m] the realisation is limited to.
    rail_table : tuple of 3 tuples
        Measured irregularity ``(x, z_left, z_right)`` [m] (replaces the PSD).
    wheel_flat : tuple of (str, value)
        :class:`track.irregularity.WheelFlat` parameters on the leading wheelset (empty: none).
    wheel_polygon : tuple of (str, value)
        :class:`track.irregularity.WheelPolygon` parameters on the leading wheelset (empty: none).
    """

    geometry: str = "dip"
    wheel: tuple = ()
    wheel_table: tuple | None = None
    lateral_offset: float = 0.0
    lateral_offset_table: tuple = ()
    crossing: tuple = ()
    rail_psd: tuple = ()
    rail_psd_seed: int = 0
    rail_psd_band: tuple = (0.01, 50.0)
    rail_table: tuple = ()
    wheel_flat: tuple = ()
    wheel_polygon: tuple = ()

    @property
    def irregular(self) -> bool:
        """Whether any irregularity (rail or wheel) is given."""
        return bool(self.rail_psd or self.rail_table or self.wheel_flat or self.wheel_polygon)


def _tuples(v):
    """Lists (from JSON) -> tuples, recursively."""
    return tuple(_tuples(x) for x in v) if isinstance(v, (list, tuple)) else v


@dataclass(frozen=True)
class TrackParams:
    """Everything the track model builder needs (the ``track:`` section)."""

    model: str = "beam"
    layout: LayoutParams = field(default_factory=LayoutParams)
    rail_pad: RailPadParams = field(default_factory=RailPadParams)
    ballast: BallastParams = field(default_factory=BallastParams)
    reduction: ReductionParams = field(default_factory=ReductionParams)
    impact_angle: float = 0.006  # crossing.impact_angle [rad]
    dipped_joint: float = 0.0  # plain track only: total angle of a dipped joint mid-panel, both rails [rad]
    structural_damping: float = 0.0  # stiffness-proportional Rayleigh beta of the bodies [s]
    contact: ContactParams = field(default_factory=ContactParams)  # contact geometry, irregularities


def track_params_from_dict(data: dict) -> TrackParams:
    """Rebuild a :class:`TrackParams` from ``dataclasses.asdict(params)`` (e.g. read back from JSON).

    The inverse of ``dataclasses.asdict`` for this dataclass tree: nested mappings
    become the frozen dataclasses again and lists become tuples (pad overrides, voids
    and their gaps), so ``track_params_from_dict(asdict(p)) == p``. Missing keys take
    the dataclass defaults; unknown keys raise ``TypeError``.

    Parameters
    ----------
    data : dict
        Plain data with the field names of :class:`TrackParams` (SI units).

    Returns
    -------
    TrackParams
    """
    d = dict(data)
    if "layout" in d:
        d["layout"] = LayoutParams(**d["layout"])
    if "rail_pad" in d:
        pad = dict(d["rail_pad"])
        pad["overrides"] = tuple(PadOverride(**o) for o in pad.get("overrides", ()))
        d["rail_pad"] = RailPadParams(**pad)
    if "ballast" in d:
        bal = dict(d["ballast"])
        bal["voids"] = tuple(VoidSpec(int(v["sleeper"]), tuple(float(g) for g in v["gaps"]))
                             for v in bal.get("voids", ()))
        d["ballast"] = BallastParams(**bal)
    if "reduction" in d:
        d["reduction"] = ReductionParams(**d["reduction"])
    if "contact" in d:
        c = {k: (_tuples(v) if isinstance(v, (list, tuple)) else v) for k, v in d["contact"].items()}
        d["contact"] = ContactParams(**c)
    return TrackParams(**d)
