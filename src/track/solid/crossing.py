"""The solid crossing rail as one reduced body of the track model (``track.model: solid``).

What is modelled
----------------
The part of the cast crossing block around the wheel transfer, from half a
sleeper spacing ahead of the sleeper before the transition sleeper to half a
spacing behind the one after it (``SOLID_SPANS`` = 3 spacings, clipped to the
block), is a 3D solid (:mod:`track.solid.body`): the 60E1-like section whose head
is trimmed to the crossing nose (half-width ``(x - x_TCP) / 2n``, blunt tip
``NOSE_TIP_WIDTH``, above ``NOSE_CUT_HEIGHT``), meshed with second-order
tetrahedra. The rest of the block stays a beam on both sides
(``crossing_front``, ``crossing_rear``); the solid's end surfaces are tied to
their end nodes by distributing couplings (``w``, ``theta`` shared; lateral,
torsion and yaw of the end surfaces held, as the vertical-plane beams hold
them, and the axial motion at the front end: held at both ends, the solid,
whose centroid is lower along the trimmed nose, arched between them in bending
and its gauges read an axial strain the beam model does not have). Each rail seat under the solid is two bushings (half the pad
each) from the foot bottom at ``y = -b, +b`` to the bearer at ``seat y -+ b``.

The beam model's block carries the wing rails as well (2-3 rails' worth of
section, :func:`track.layout._crossing_profile`); they are not meshed. The
solid stands for the whole block by scaling its Young's modulus and density
along ``x`` by ``I_block(x) / I_solid(x)`` and ``A_block(x) / A_solid(x)``
(``A_solid``, ``I_solid`` of the trimmed section at ``x``): beam and solid then
have the same bending stiffness and mass per length everywhere, and their
differences are the 3D ones (local deformation under the wheel on the thin
nose, shear and warping, the two-bushing seats), which is the comparison of
seed 000 (Fig. 6). The wheel runs on the contact path, a node line on the
running surface at ``y = 0``; its load is shared linearly between the two
path nodes around it (retained coordinates, so no residual flexibility term).

Outputs recovered from the solid (:class:`SolidCrossing`): the section
deflection (distributing-coupling average) and the section bending moment at
every mesh station (``track.reduction.element_length`` apart), from the
internal nodal forces of the elements left of the station plane; at any surface
point (sensors, :meth:`SolidCrossing.gauge_points`) the axial displacement (gauge
strains), the vertical displacement (accelerometers) and ``eps_xx`` from the
quadratic tetrahedra's displacement gradient, each a row on the reduced coordinates.

Cost and cache
--------------
Meshing, assembly and reduction take ~10 s (1:12, 0.6 m spacing, h = 0.06 m).
The reduced body is kept in-process and, when the caller passes a folder, on
disk, keyed by every parameter that changes it (geometry, mesh size, cut-off), so
parameter studies on bushings and ballast build it once. This module never chooses
the folder: the edges do (the orchestrator and the track FMU pass
:func:`track.cache.cache_dir_from_env` of their environment: ``$TURNOUT_CACHE``, default
``~/.cache/turnout``; ``TURNOUT_CACHE=off`` disables the disk cache).
"""
from __future__ import annotations

import hashlib
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..params import RAIL_60E1, BeamProfile
from .body import SolidRailParams, solid_rail
from .coupling import surface_coupling
from .fem import COORD_TOL, assemble, faces_on_plane, shape_rows, surface_moments
from .mesh import CrossingGeometry
from .section import RailSection, polygon_properties, rail_60e1_like

SOLID_SPANS = 3               # sleeper spacings covered by the solid, centred on the transition sleeper
NOSE_TIP_WIDTH = 0.012        # m, blunt nose tip (typical 10-15 mm)
NOSE_CUT_HEIGHT = 0.1328      # m above the foot: the head above it is trimmed to the nose (head fillet top)
SOLID_MODE_FACTOR = 4.0       # fixed-interface modes up to 4 f_cut (3 f_cut gave 1.1 % errors, test_solid.py)
BUSHING_OFFSET = 0.05         # m, lateral position +-b of the two bushings of a seat on the foot bottom
DEFAULT_MESH_SIZE = 0.06      # m: < 0.3 % against Timoshenko for the prismatic rail (test_solid.py)
GAUGE_INSET = 1e-6            # m: gauge points are moved this far inside the surface (element search)
CACHE_VERSION = "solid-crossing-1"
_CACHE: dict = {}


@dataclass
class SolidCrossing:
    """Reduced solid crossing body and the rows that recover its outputs.

    Coordinates along the solid are local, ``s = x - x_start`` [m]. Reduced
    coordinates ``q`` (nr,): see :class:`track.solid.body.SolidRail`.

    Attributes
    ----------
    params : SolidRailParams
    K, M : ndarray, shape (nr, nr)
        Reduced stiffness [N/m ...] and mass [kg ...].
    T : ndarray, shape (3 n, nr)
        Full solid displacements ``u = T q`` [m].
    points : ndarray, shape (n, 3)
    tets : ndarray of int, shape (m, 10)
    end_q : ndarray of int, shape (2, 2)
        ``q`` positions of ``(w, theta)`` of the beam nodes at ``s = 0`` and ``s = length``.
    seat_s : ndarray, shape (ns,)
    seat_q : ndarray of int, shape (ns, 2)
        ``q`` positions of the bushing nodes at ``y = -b, +b`` of each seat.
    contact_s : ndarray, shape (k,)
    contact_q : ndarray of int, shape (k,)
    station_s : ndarray, shape (m,)
        Stations of the section outputs [m].
    W : ndarray, shape (m, nr)
        Section deflection (area mean of ``u_z``) [m per unit q].
    Mom : ndarray, shape (m, nr)
        Section bending moment about the section centroid, sagging + [N m per unit q].
    weight : ndarray, shape (nr,)
        ``T^T M e_z``: generalized force of a unit upward acceleration field [N / (m/s^2)].
    mode_freqs : ndarray
        Fixed-interface frequencies [Hz].
    fom_dofs : int
        Dofs of the meshed solid (3 per node).
    t_mesh, t_reduction : float
        One-time cost [s] of mesh + assembly + tie + Craig–Bampton, and of the output
        rows (section deflections and moments).
    """

    params: SolidRailParams
    K: np.ndarray
    M: np.ndarray
    T: np.ndarray
    points: np.ndarray
    tets: np.ndarray
    end_q: np.ndarray
    seat_s: np.ndarray
    seat_q: np.ndarray
    contact_s: np.ndarray
    contact_q: np.ndarray
    station_s: np.ndarray
    W: np.ndarray
    Mom: np.ndarray
    weight: np.ndarray
    mode_freqs: np.ndarray
    fom_dofs: int
    t_mesh: float
    t_reduction: float
    from_cache: str = ""       # "", "memory" or "disk"

    @property
    def nr(self) -> int:
        return self.K.shape[0]

    @property
    def length(self) -> float:
        return float(self.params.length)

    def path_row(self, s: float) -> tuple[int, np.ndarray]:
        """Contact-path segment and linear weights at ``s`` [m] (clipped to the path).

        Returns
        -------
        e : int
            Segment: between path nodes ``e`` and ``e + 1``.
        w : ndarray, shape (2,)
        """
        cs = self.contact_s
        e = int(np.clip(np.searchsorted(cs, s, side="right") - 1, 0, cs.size - 2))
        t = float(np.clip((s - cs[e]) / (cs[e + 1] - cs[e]), 0.0, 1.0))
        return e, np.array([1.0 - t, t])

    def segment_rows(self, e: int) -> np.ndarray:
        """Unit rows (2, nr) of the ``q`` of path nodes ``e``, ``e + 1`` (where a wheel load acts)."""
        R = np.zeros((2, self.nr))
        R[0, self.contact_q[e]] = R[1, self.contact_q[e + 1]] = 1.0
        return R

    @property
    def section(self) -> RailSection:
        """The untrimmed cross-section."""
        return self.params.section if self.params.section is not None else rail_60e1_like()

    def centroid_height(self, s: float) -> float:
        """Height of the centroid of the section at ``s`` [m] (lower where the head is trimmed) [m]."""
        cg = self.params.crossing
        if cg is None:
            return float(self.section.properties.centroid[1])
        return trimmed_section_properties(self.section, cg.cut_height, float(cg.half_width(s)))[2]

    def gauge_points(self, s: np.ndarray, z: float, datum: str = "section") -> np.ndarray:
        """Surface points of sensors on the solid, shape (k, 3) [m].

        A sensor at ``s`` [m] along the solid, ``z`` [m] above a datum height ``z_d``, sits
        on the section's outer surface at the height ``z_d + z``, on the ``+y`` side: the
        surface point reached from the rail's centre plane going outward at that height
        (the foot edge, the web, the head or the nose flank). It is moved ``GAUGE_INSET``
        into the solid, so that the element holding it is found
        (:func:`track.solid.fem.locate`).

        Parameters
        ----------
        s : array_like, shape (k,)
            [m] along the solid.
        z : float
            Height above the datum [m], up +.
        datum : str
            ``"section"``: the neutral axis of the (nose-trimmed) section at ``s``, its
            centroid (:meth:`centroid_height`): a lever arm as on a beam
            (:func:`track.post.strain`). ``"rail"``: the neutral axis of the untrimmed rail
            section (60E1: 81.5 mm above the foot), the same height all along the solid:
            a place on the rail, as a field layout gives it (a foot gauge stays on the foot
            where the trimmed nose lowers the section's neutral axis).

        Raises
        ------
        ValueError
            The height is outside the section (below the foot, above the running surface).
        """
        s = np.atleast_1d(np.asarray(s, dtype=float))
        return self.surface_points(s, self.datum_heights(s, datum) + z)

    def surface_points(self, s: np.ndarray, heights: np.ndarray) -> np.ndarray:
        """The ``+y`` surface points at ``s`` [m] and ``heights`` [m] above the foot, moved
        ``GAUGE_INSET`` inside, shape (k, 3) (see :meth:`gauge_points`)."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        h = np.broadcast_to(np.asarray(heights, dtype=float), s.shape)
        y = np.array([_half_width(self.section, hi, self.params.crossing, si) for si, hi in zip(s, h)])
        return np.column_stack([s, y - GAUGE_INSET, h])

    def gauge_row(self, s: float, z: float, length: float, datum: str = "section") -> np.ndarray:
        """Row (nr,) of the strain of a gauge of ``length`` [m] centred at ``s`` [m] (seed 000 eq. 1).

        ``(u_x(s + L/2) - u_x(s - L/2)) / L`` between two surface points at one height, ``z``
        above the datum *at the gauge centre* (a straight gauge glued along the rail: where
        the section's centroid moves along the nose taper, ends that followed it would add
        the section rotation times their height difference). It is the exact mean of the
        tetrahedra's ``eps_xx`` along the gauge, and their ``eps_xx`` at the centre when the
        gauge lies in one element (:meth:`axial_rows`, :meth:`strain_rows`).
        """
        L = float(length)
        h = self.datum_heights(np.array([s]), datum)[0] + z
        N, _ = self._field_rows(self.surface_points(np.array([s - 0.5 * L, s + 0.5 * L]), h))
        R = N @ self.T[0::3]
        return (R[1] - R[0]) / L

    def datum_heights(self, s: np.ndarray, datum: str = "section") -> np.ndarray:
        """Heights [m] above the foot of the datum of :meth:`gauge_points` at ``s`` [m]."""
        s = np.atleast_1d(np.asarray(s, dtype=float))
        if datum == "section":
            return np.array([self.centroid_height(si) for si in s])
        if datum == "rail":
            return np.full(s.shape, float(self.section.properties.centroid[1]))
        raise ValueError(f"datum: 'section' or 'rail', got {datum!r}")

    def _field_rows(self, X: np.ndarray):
        """Shape-function values and gradients at points (:func:`track.solid.fem.shape_rows`)."""
        return shape_rows(self.points, self.tets, X)

    def axial_rows(self, s: np.ndarray, z: float, datum: str = "section") -> np.ndarray:
        """Rows (k, nr) of the axial displacement ``u_x`` [m] at the :meth:`gauge_points`.

        ``(u_x(c + L/2) - u_x(c - L/2)) / L`` is a gauge of length ``L`` centred at ``c``
        (:func:`track.post.strain_row`, :func:`track.sensors.compile_sensors`): the exact
        mean of the elements' ``eps_xx`` along the gauge line (``u`` is continuous), and,
        when the gauge lies in one element, the element's ``eps_xx`` at the gauge centre
        (``u_x`` is quadratic along the line, and a quadratic's chord slope is its slope at
        the midpoint): :meth:`strain_rows`.
        """
        N, _ = self._field_rows(self.gauge_points(s, z, datum))
        return N @ self.T[0::3]

    def vertical_rows(self, s: np.ndarray, z: float = 0.0, datum: str = "section") -> np.ndarray:
        """Rows (k, nr) of the vertical displacement ``u_z`` [m] at the :meth:`gauge_points`.

        What an accelerometer on the solid reads (times the accelerations ``a`` instead of
        ``q``); ``z = 0``: on the web at the neutral axis, where the section's vertical
        motion is read without the local deformation under the wheel.
        """
        N, _ = self._field_rows(self.gauge_points(s, z, datum))
        return N @ self.T[2::3]

    def strain_rows(self, s: np.ndarray, z: float, datum: str = "section") -> np.ndarray:
        """Rows (k, nr) of the longitudinal strain ``eps_xx = du_x/dx`` [-] at the :meth:`gauge_points`.

        From the displacement gradient of the quadratic tetrahedra in the element holding
        each point (:func:`track.solid.fem.shape_rows`): a point gauge.
        """
        _, G = self._field_rows(self.gauge_points(s, z, datum))
        return G[0] @ self.T[0::3]


# ----------------------------------------------------------------------------- geometry helpers
def _clip(poly: list, inside, cut) -> list:
    """Sutherland–Hodgman clip of a polygon by one half-plane."""
    out = []
    for i in range(len(poly)):
        a, c = poly[i - 1], poly[i]
        if inside(c):
            if not inside(a):
                out.append(cut(a, c))
            out.append(c)
        elif inside(a):
            out.append(cut(a, c))
    return out


def _raw_moments(P: np.ndarray) -> np.ndarray:
    """``(int dA, int z dA, int z^2 dA)`` of a polygon ``(y, z)`` (0 if degenerate)."""
    if len(P) < 3:
        return np.zeros(3)
    y, z = P[:, 0], P[:, 1]
    y1, z1 = np.roll(y, -1), np.roll(z, -1)
    cr = y * z1 - y1 * z
    A = 0.5 * cr.sum()
    Sz = (cr * (z + z1)).sum() / 6.0
    Izz = (cr * (z * z + z * z1 + z1 * z1)).sum() / 12.0
    return np.array([A, Sz, Izz])


def trimmed_section_properties(section: RailSection, cut_height: float, b: float
                               ) -> tuple[float, float, float]:
    """Area [m^2], vertical second moment about the centroid [m^4] and centroid height [m]
    of a section whose part above ``cut_height`` with ``|y| > b`` is removed (the crossing
    nose at half-width ``b``)."""
    full = _raw_moments(section.vertices)
    removed = np.zeros(3)
    for sgn in (1.0, -1.0):
        P = _clip([tuple(v) for v in section.vertices], lambda p: p[1] >= cut_height,
                  lambda a, c: (a[0] + (c[0] - a[0]) * (cut_height - a[1]) / (c[1] - a[1]), cut_height))
        P = _clip(P, lambda p, s=sgn: s * p[0] >= b,
                  lambda a, c, s=sgn: (s * b, a[1] + (c[1] - a[1]) * (s * b - a[0]) / (c[0] - a[0])))
        removed += _raw_moments(np.array(P, dtype=float).reshape(-1, 2))
    A, Sz, Izz = full - removed
    zc = Sz / A
    return float(A), float(Izz - A * zc * zc), float(zc)


def _half_width(section: RailSection, z: float, crossing: CrossingGeometry | None, s: float) -> float:
    """Half-width [m] of the (trimmed) section at height ``z`` [m] and axial position ``s``."""
    V = section.vertices
    ys = []
    for (ya, za), (yb, zb) in zip(V, np.roll(V, -1, axis=0)):
        if (za - z) * (zb - z) <= 0.0 and za != zb:
            ys.append(ya + (yb - ya) * (z - za) / (zb - za))
    if not ys:
        raise ValueError(f"height {z:.4f} m is outside the rail section")
    w = max(ys)
    if crossing is not None and z >= crossing.cut_height:
        w = min(w, float(crossing.half_width(s)))
    return w


# ----------------------------------------------------------------------------- parameters from a layout
def solid_extent(lay, spacing: float) -> tuple[float, float]:
    """Track coordinates ``(x_a, x_b)`` [m] of the solid: ``SOLID_SPANS`` spacings centred on
    the transition, clipped to the crossing block."""
    block = lay.rail("crossing")
    half = 0.5 * SOLID_SPANS * spacing
    return max(block.x_start, lay.x_transition - half), min(block.x_end, lay.x_transition + half)


def solid_params(lay, profile: BeamProfile, x_origin: float, x_a: float, x_b: float, seats_x,
                 mesh_size: float, f_cut: float, station_step: float) -> SolidRailParams:
    """:class:`SolidRailParams` of the solid part ``[x_a, x_b]`` of the crossing block.

    Parameters
    ----------
    lay : track.layout.Layout
    profile : BeamProfile
        Profile of the beam block (body coordinate ``x - x_origin``).
    x_origin : float
        Start of the beam block [m].
    x_a, x_b : float
        Extent of the solid [m].
    seats_x : sequence of float
        Seat positions under the solid [m].
    mesh_size : float
        gmsh ``MeshSizeMax`` [m].
    f_cut : float
        Model cut-off [Hz].
    station_step : float
        Maximum distance between output stations [m].
    """
    length = x_b - x_a
    n = 1.0 / np.tan(lay.crossing_angle)
    section = rail_60e1_like()
    cg = CrossingGeometry(crossing_n=round(float(n), 9), x_point=round(lay.x_tcp - x_a, 9),
                          tip_width=NOSE_TIP_WIDTH, cut_height=NOSE_CUT_HEIGHT)
    k = max(1, int(np.ceil(length / station_step - 1e-9)))
    stations = tuple(round(float(v), 9) for v in np.linspace(0.0, length, k + 1)[1:-1])
    seats = tuple(round(float(x - x_a), 9) for x in seats_x)
    stations = tuple(s for s in stations if min((abs(s - t) for t in seats), default=1.0) > 0.02)
    # material table: block stiffness and mass over the trimmed solid section
    xs = np.unique(np.concatenate([np.linspace(0.0, length, 61),
                                   [x for x in np.asarray(profile.s, float) - (x_a - x_origin) if 0 < x < length]]))
    A_b, I_b = profile.at(xs + (x_a - x_origin))
    base = profile.base
    AI = np.array([trimmed_section_properties(section, cg.cut_height, float(cg.half_width(x)))[:2] for x in xs])
    sE = (base.E * np.asarray(I_b)) / (RAIL_60E1.E * AI[:, 1])
    sR = (base.rho * np.asarray(A_b)) / (RAIL_60E1.rho * AI[:, 0])
    material = (tuple(np.round(xs, 9)), tuple(np.round(sE, 9)), tuple(np.round(sR, 9)))
    return SolidRailParams(length=round(length, 9), seats=seats, h=mesh_size, bushing_offset=BUSHING_OFFSET,
                           crossing=cg, f_modes=SOLID_MODE_FACTOR * f_cut, stations=stations, material=material,
                           axial_free_end=True)


# ----------------------------------------------------------------------------- build + cache
def _key(p: SolidRailParams) -> str:
    fields = (CACHE_VERSION, p.length, p.seats, p.h, p.bushing_offset, p.contact_y,
              None if p.section is None else p.section.vertices.round(12).tolist(), repr(p.crossing),
              p.E, p.nu, p.rho, p.f_modes, p.stations, p.material, p.axial_free_end)
    return hashlib.sha1(repr(fields).encode()).hexdigest()


_ARRAYS = ("K", "M", "T", "points", "tets", "end_q", "seat_s", "seat_q", "contact_s", "contact_q",
           "station_s", "W", "Mom", "weight", "mode_freqs")


def _save(sc: SolidCrossing, path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez(tmp, **{k: getattr(sc, k) for k in _ARRAYS},
                 scalars=np.array([sc.fom_dofs, sc.t_mesh, sc.t_reduction]))
        os.replace(tmp, path)
    except OSError:
        pass        # a read-only or full cache folder costs a rebuild next time, nothing else


def _load(p: SolidRailParams, path: Path) -> SolidCrossing | None:
    try:
        with np.load(path) as z:
            d = {k: z[k] for k in _ARRAYS}
            fom, tm, tr = z["scalars"]
    except (OSError, KeyError, ValueError):
        return None
    return SolidCrossing(params=p, fom_dofs=int(fom), t_mesh=float(tm), t_reduction=float(tr),
                         from_cache="disk", **d)


def clear_solid_cache() -> None:
    """Forget the in-process solid bodies (the disk cache stays)."""
    _CACHE.clear()


def solid_crossing(p: SolidRailParams, cache_dir: Path | None = None) -> SolidCrossing:
    """The reduced solid body of ``p``: from memory, from disk, or built (and cached).

    Parameters
    ----------
    p : SolidRailParams
    cache_dir : Path, optional
        Folder of the on-disk cache (:func:`track.cache.cache_dir_from_env`); None: in memory only.

    Returns
    -------
    SolidCrossing
    """
    key = _key(p)
    sc = _CACHE.get(key)
    if sc is not None:
        return replace(sc, from_cache="memory")
    path = None if cache_dir is None else Path(cache_dir) / f"solid-{key}.npz"
    if path is not None and path.exists():
        sc = _load(p, path)
    if sc is None:
        sc = build_solid_crossing(p)
        if path is not None:
            _save(sc, path)
    _CACHE[key] = sc
    return sc


def build_solid_crossing(p: SolidRailParams) -> SolidCrossing:
    """Mesh, assemble and reduce the solid and build its output rows (no cache)."""
    t0 = time.perf_counter()
    sr = solid_rail(p)
    t1 = time.perf_counter()
    T = np.asarray(sr.tied.T @ sr.rom.T)                                  # (3n, nr)
    e_z = np.zeros(sr.M.shape[0])
    e_z[2::3] = 1.0
    weight = T.T @ (sr.M @ e_z)
    station_s = np.unique(np.round(np.concatenate([[0.0, p.length], p.seats, p.stations]), 9))
    W = np.empty((station_s.size, sr.rom.nr))
    Mom = np.empty((station_s.size, sr.rom.nr))
    for k, s in enumerate(station_s):
        cpl = surface_coupling(sr.points, sr.tets, s)
        W[k] = cpl.rows(("w",))[0] @ T[cpl.dofs]
        Mom[k] = _moment_row(sr.points, sr.tets, p, s) @ T
    t2 = time.perf_counter()
    return SolidCrossing(params=p, K=sr.rom.K, M=sr.rom.M, T=T, points=sr.points, tets=sr.tets,
                         end_q=sr.end_q, seat_s=np.asarray(p.seats, float), seat_q=sr.seat_q,
                         contact_s=sr.contact_x, contact_q=sr.contact_q, station_s=station_s, W=W, Mom=Mom,
                         weight=weight, mode_freqs=sr.rom.mode_freqs, fom_dofs=3 * sr.points.shape[0],
                         t_mesh=t1 - t0, t_reduction=t2 - t1)


def _moment_row(points: np.ndarray, tets: np.ndarray, p: SolidRailParams, s: float) -> np.ndarray:
    """Row (3n,) of the bending moment at the station plane ``x = s`` (sagging +).

    The elements on one side of the plane that touch it are assembled alone; their
    internal nodal forces at the plane nodes are the forces the other side exerts on
    them (external loads at plane nodes are vertical and do not enter). About the
    centroid of the plane section, sagging +: ``M = -sum (z_i - z_c) F_x,i`` with
    ``F`` the force on the left part (``K_left u``), or ``+sum (z_i - z_c) (K_right u)_x``
    at the start face.
    """
    X = points[tets][..., 0]                                               # (m, 10)
    left = s > COORD_TOL
    side = (X.max(axis=1) <= s + COORD_TOL) if left else (X.min(axis=1) >= s - COORD_TOL)
    touch = (np.abs(X - s) <= COORD_TOL).any(axis=1)
    sub = tets[side & touch]
    nodes, inv = np.unique(sub, return_inverse=True)
    K, _ = assemble(points[nodes], inv.reshape(sub.shape), p.E, p.nu, p.rho,
                    scale=None if p.material is None else p.scale)
    plane = np.flatnonzero(np.abs(points[nodes, 0] - s) <= COORD_TOL)
    zc = surface_moments(points, faces_on_plane(points, tets, 0, s)).centroid[2]
    lever = points[nodes[plane], 2] - zc
    Fx = K[3 * plane]                                                      # rows of F_x at the plane nodes
    r_sub = np.asarray((sp.diags(lever) @ Fx).sum(axis=0)).ravel() * (-1.0 if left else 1.0)
    row = np.zeros(3 * points.shape[0])
    row[(3 * nodes[:, None] + np.arange(3)).ravel()] = r_sub
    return row


__all__ = ["SolidCrossing", "solid_crossing", "build_solid_crossing", "solid_params", "solid_extent",
           "trimmed_section_properties", "clear_solid_cache", "SOLID_SPANS"]
