"""The solid crossing rail as a reduced body for the track model.

Mesh -> K, M -> distributing couplings of both end surfaces to beam nodes ->
retained dofs -> sparse Craig–Bampton. The retained (boundary) coordinates of
the reduced body are

* at each end surface the beam-node dofs ``(w, theta)`` [m, rad] of the
  coupling (:mod:`track.solid.coupling`), to be shared with the adjacent beam
  rail's end node; the other four motions of the end surface (axial, lateral,
  torsion, yaw) are held at zero, as the vertical-plane beam model does for
  the rails (without this the solid would have free rigid motions that no
  bushing restrains). With ``axial_free_end`` the axial motion of the end
  surface at ``x = length`` is left free: the solid is then axially
  determinate, as the beams (which have no axial dof) are; holding both ends
  made a bending solid with a varying centroid height (the trimmed nose) arch
  between them, with an axial strain the beam model does not have;
* per rail seat two bushing nodes on the foot bottom at ``y = -b, +b``
  (vertical dof ``u_z``), for the two-bushing wide seat of the seed's 3D model;
* the vertical dofs of the nodes on the contact path (a longitudinal line on
  the running surface at ``y = contact_y``), where the wheel load is applied
  and the rail surface position is read.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..params import RAIL_60E1
from .coupling import TiedBody, surface_coupling, tie
from .fem import assemble, nodes_on_line, seat_nodes
from .mesh import CrossingGeometry, rail_solid_mesh
from .reduction import SparseReducedBody, craig_bampton_sparse
from .section import RailSection, rail_60e1_like

END_COMPONENTS = ("ux", "uy", "w", "rx", "theta", "rz")
END_HELD = ("ux", "uy", "rx", "rz")   # held at zero; (w, theta) are the beam node's dofs


@dataclass(frozen=True, eq=False)
class SolidRailParams:
    """Parameters of a solid crossing rail body (SI units).

    Attributes
    ----------
    length : float
        Length of the solid along the track [m]; its ends tie to beam nodes.
    seats : tuple of float
        Rail-seat centres along the solid [m] (0 < x < length).
    h : float
        Mesh size [m] (gmsh ``MeshSizeMax``); 0.06 m gave < 0.3 % against a
        Timoshenko beam for the prismatic rail (tests/test_solid.py).
    bushing_offset : float
        Lateral position ``b`` of the two bushings of a seat, ``y = -b, +b`` [m].
    contact_y : float
        Lateral position of the contact path on the running surface [m].
    section : RailSection or None
        Cross-section; ``None`` -> :func:`track.solid.section.rail_60e1_like`.
    crossing : CrossingGeometry or None
        Nose taper; ``None`` -> prismatic rail.
    E : float
        Young's modulus [Pa].
    nu : float
        Poisson's ratio [-] (E / 2G - 1 of 60E1: 0.296).
    rho : float
        Density [kg/m^3].
    f_modes : float
        Fixed-interface modes kept up to this frequency [Hz]; 4 x the model
        cut-off keeps the reduced frequencies below the cut-off within 1 %
        (3 x was not enough for the solid, see tests/test_solid.py).
    axial_free_end : bool
        Leave the axial motion of the end surface at ``x = length`` free (see the
        module docstring); False holds it as at ``x = 0``.
    stations : tuple of float
        Further axial positions with a full cross-section plane of nodes [m]
        (sections where moments and section deflections are recovered).
    material : tuple or None
        ``(x, s_E, s_rho)``, three equal-length tuples: factors on ``E`` and
        ``rho`` tabulated along the solid, linear in between (``None``: 1).
    """

    length: float
    seats: tuple
    h: float = 0.06
    bushing_offset: float = 0.05
    contact_y: float = 0.0
    section: RailSection | None = None
    crossing: CrossingGeometry | None = None
    E: float = RAIL_60E1.E
    nu: float = RAIL_60E1.E / (2.0 * RAIL_60E1.G) - 1.0
    rho: float = RAIL_60E1.rho
    f_modes: float = 6000.0
    stations: tuple = ()
    material: tuple | None = None
    axial_free_end: bool = False

    def scale(self, x: np.ndarray) -> tuple:
        """Factors ``(s_E, s_rho)`` on ``E`` and ``rho`` at axial positions ``x`` [m]."""
        if self.material is None:
            return 1.0, 1.0
        xs, sE, sr = (np.asarray(v, dtype=float) for v in self.material)
        return np.interp(x, xs, sE), np.interp(x, xs, sr)


@dataclass
class SolidRail:
    """Full and reduced model of a solid rail, with the meaning of each retained coordinate.

    Attributes
    ----------
    points : ndarray, shape (n, 3)
        Node coordinates [m].
    tets : ndarray of int, shape (m, 10)
    K, M : scipy.sparse.csr_matrix, shape (3n, 3n)
        Full solid matrices.
    tied : TiedBody
        The solid with its ends tied (held end components removed); ``u = tied.T @ v``.
    rom : SparseReducedBody
        Reduced body over ``v``; ``q[:nb]`` are the retained coordinates below.
    end_q : ndarray of int, shape (2, 2)
        Positions in ``q`` of ``(w, theta)`` of the beam node at ``x = 0`` and ``x = length``.
    seat_q : ndarray of int, shape (n_seats, 2)
        Positions in ``q`` of ``u_z`` of the bushing nodes at ``y = -b, +b`` of each seat.
    contact_x : ndarray, shape (k,)
        ``x`` of the contact-path nodes [m], increasing.
    contact_q : ndarray of int, shape (k,)
        Positions in ``q`` of their ``u_z``.
    """

    points: np.ndarray
    tets: np.ndarray
    K: sp.csr_matrix
    M: sp.csr_matrix
    tied: TiedBody
    rom: SparseReducedBody
    end_q: np.ndarray
    seat_q: np.ndarray
    contact_x: np.ndarray
    contact_q: np.ndarray

    def displacements(self, q: np.ndarray) -> np.ndarray:
        """Full solid displacements ``(n, 3)`` [m] from reduced coordinates ``q`` (nr,)."""
        return (self.tied.T @ (self.rom.T @ np.asarray(q))).reshape(-1, 3)


def solid_rail(p: SolidRailParams) -> SolidRail:
    """Build and reduce a solid rail body.

    Parameters
    ----------
    p : SolidRailParams

    Returns
    -------
    SolidRail
    """
    section = p.section if p.section is not None else rail_60e1_like()
    b, top = p.bushing_offset, section.top
    section = section.with_points([[-b, 0.0], [b, 0.0], [p.contact_y, top]])
    points, tets = rail_solid_mesh(p.length, section, p.h, stations=tuple(p.seats) + tuple(p.stations),
                                   crossing=p.crossing)
    K, M = assemble(points, tets, p.E, p.nu, p.rho, scale=None if p.material is None else p.scale)

    seat_nodes_ = np.array([[_one(seat_nodes(points, x, 0.0, y)) for y in (-b, b)] for x in p.seats],
                           dtype=np.int64).reshape(-1, 2)
    path = nodes_on_line(points, p.contact_y, top)
    retained_solid = np.concatenate([3 * seat_nodes_.ravel() + 2, 3 * path + 2])
    ends = [surface_coupling(points, tets, 0.0), surface_coupling(points, tets, p.length)]
    full = tie(K, M, ends, components=END_COMPONENTS, keep=retained_solid)

    # hold the end components that no beam dof carries
    held_at = [END_HELD, tuple(c for c in END_HELD if not (p.axial_free_end and c == "ux"))]
    held = np.concatenate([r[[END_COMPONENTS.index(c) for c in h]] for r, h in zip(full.ref_dofs, held_at)])
    keep = np.setdiff1d(np.arange(full.K.shape[0]), held)
    new_of = np.full(full.K.shape[0], -1, dtype=np.int64)
    new_of[keep] = np.arange(keep.size)
    beam = [END_COMPONENTS.index("w"), END_COMPONENTS.index("theta")]
    tied = TiedBody(K=full.K[keep][:, keep].tocsr(), M=full.M[keep][:, keep].tocsr(),
                    T=full.T[:, keep].tocsr(), free=full.free,
                    ref_dofs=[new_of[r[beam]] for r in full.ref_dofs],
                    components=[("w", "theta")] * 2)

    end_v = np.array(tied.ref_dofs)                                          # (2, 2)
    seat_v = np.array([[tied.dof_of(d) for d in 3 * s + 2] for s in seat_nodes_], dtype=np.int64)
    path_v = np.array([tied.dof_of(3 * i + 2) for i in path], dtype=np.int64)
    boundary = np.concatenate([end_v.ravel(), seat_v.ravel(), path_v])
    rom = craig_bampton_sparse(tied.K, tied.M, boundary, f_modes=p.f_modes)
    q_of = np.full(tied.K.shape[0], -1, dtype=np.int64)
    q_of[boundary] = np.arange(boundary.size)
    return SolidRail(points=points, tets=tets, K=K, M=M, tied=tied, rom=rom, end_q=q_of[end_v],
                     seat_q=q_of[seat_v].reshape(-1, 2), contact_x=points[path, 0],
                     contact_q=q_of[path_v])


def _one(idx: np.ndarray) -> int:
    if idx.size != 1:
        raise ValueError(f"expected one bushing node, found {idx.size} (is the seat a mesh station?)")
    return int(idx[0])


__all__ = ["SolidRailParams", "SolidRail", "solid_rail", "END_COMPONENTS", "END_HELD"]
