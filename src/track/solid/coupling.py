"""Distributing coupling of a surface of the solid to one reference node (a beam node).

In the sense of Abaqus ``*COUPLING, *DISTRIBUTING``: the motion of the reference
node is the weighted least-squares rigid-body fit to the displacements of the
coupling nodes, and loads on the reference node are spread over the coupling
nodes in proportion to the weights (forces) and linearly over the surface
(moments). The surface may deform freely otherwise (warping, Poisson
contraction): it is not made rigid.

Reference motion ``a = [u_x, u_y, u_z, phi_x, phi_y, phi_z]`` (translation [m] and
small rotation [rad] about the axes) minimises

    int |u_h - (u_r + phi x r)|^2 dA,   r = X - X_ref,

over the surface, ``u_h`` the quadratic finite-element field (Abaqus minimises
a nodal-weighted sum instead; see :func:`distributing_coupling` for why the
integral is used here), so ``a = C u_s`` with a (6, 3 s) matrix ``C``. A rigid
motion of the surface is returned exactly; if ``X_ref`` is the area centroid of
the surface (the beam node at the end-surface centroid) the translation is the
area average of the surface displacement.

The beam of :mod:`track.elements` carries ``(w, theta)`` per node: ``w = u_z`` and
``theta = -phi_y`` (``theta`` is positive in the sense of ``dw/dx``; a section
turning with the slope moves its top fibre by ``u_x = -z theta``).

Tying a surface to its reference node (:func:`tie`) eliminates, per tied
component, one surface dof in favour of the reference dof (master-slave
elimination of ``C_k u_s = q_k``): exact, penalty-free, and it keeps ``K`` and
``M`` symmetric and sparse apart from a dense block over the tied surface.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp

from .fem import SurfaceMoments, faces_on_plane, surface_moments

# Row of the reference motion a = [ux, uy, uz, phix, phiy, phiz] and its sign, per named component.
COMPONENTS = {
    "ux": (0, 1.0), "uy": (1, 1.0), "uz": (2, 1.0),
    "rx": (3, 1.0), "ry": (4, 1.0), "rz": (5, 1.0),
    "w": (2, 1.0),          # beam deflection (upward +)
    "theta": (4, -1.0),     # beam rotation, positive as dw/dx
}
BEAM = ("w", "theta")


def _skew(r: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``[r]x`` (``[r]x v = r x v``), shape (..., 3, 3)."""
    S = np.zeros(r.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -r[..., 2], r[..., 1]
    S[..., 1, 0], S[..., 1, 2] = r[..., 2], -r[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -r[..., 1], r[..., 0]
    return S


@dataclass(frozen=True, eq=False)
class DistributingCoupling:
    """A surface node set coupled to a reference point.

    Attributes
    ----------
    nodes : ndarray of int, shape (s,)
        Coupling nodes (solid node indices).
    weights : ndarray, shape (s,)
        ``int N_i dA / A`` [-] (sum 1): ``u_r = weights @ u_i`` for the translations
        when the reference point is the centroid.
    ref_point : ndarray, shape (3,)
        Reference point ``X_ref`` [m].
    C : ndarray, shape (6, 3 s)
        ``[u_x, u_y, u_z, phi_x, phi_y, phi_z] = C @ u_s`` with
        ``u_s = u[3 nodes + c]`` flattened node by node.
    """

    nodes: np.ndarray
    weights: np.ndarray
    ref_point: np.ndarray
    C: np.ndarray

    @property
    def dofs(self) -> np.ndarray:
        """Solid dofs of the coupling nodes, shape (3 s,), in the column order of ``C``."""
        return (3 * self.nodes[:, None] + np.arange(3)).ravel()

    def rows(self, components=BEAM) -> np.ndarray:
        """Rows of ``C`` for named components (keys of :data:`COMPONENTS`), shape (k, 3 s)."""
        return np.array([COMPONENTS[c][1] * self.C[COMPONENTS[c][0]] for c in components])

    def motion(self, u: np.ndarray, components=BEAM) -> np.ndarray:
        """Reference motion of a full solid displacement ``u`` (3n,) [m]; shape (k,).

        Default components ``(w, theta)`` [m, rad].
        """
        return self.rows(components) @ np.asarray(u)[self.dofs]

    def matrix(self, n_dofs: int, components=BEAM) -> sp.csr_matrix:
        """The coupling as a sparse (k, n_dofs) matrix on the full solid dof vector."""
        R = self.rows(components)
        k = R.shape[0]
        return sp.csr_matrix((R.ravel(), (np.repeat(np.arange(k), self.dofs.size),
                                          np.tile(self.dofs, k))), shape=(k, n_dofs))


def distributing_coupling(moments: SurfaceMoments, ref_point=None) -> DistributingCoupling:
    """Build the coupling matrix of a surface from its shape-function moments.

    The rigid fit minimises ``int |u_h - (u_r + phi x r)|^2 dA`` over the surface
    (the continuous form of the weighted least squares of the module docstring):
    with ``G(r) = [I, -[r]x]``,

        (int G^T G dA) a = sum_i (int G^T N_i dA) u_i,

    both sides exact for the quadratic field ``u_h`` (:class:`SurfaceMoments`).
    Then a rigid motion is returned exactly, ``u_r`` is the area mean of ``u_h``
    when the reference point is the area centroid, and a reference force is
    spread as the consistent nodal loads of a uniform traction (a moment: of a
    linear one). Nodal weights as in Abaqus are the special case
    :meth:`SurfaceMoments.from_nodal_weights`; they act on a quadratic mesh like
    point loads at element scale, and the static deflection of a rail
    supported through them converged at order 0.8 instead of 2.

    Parameters
    ----------
    moments : SurfaceMoments
        Of the coupled surface (:func:`track.solid.fem.surface_moments`).
    ref_point : array_like, shape (3,), optional
        Reference point [m]; default the area centroid of the surface.

    Returns
    -------
    DistributingCoupling
    """
    A = moments.area
    X_ref = moments.centroid if ref_point is None else np.asarray(ref_point, dtype=float)
    d = moments.centroid - X_ref                                         # int r dA / A
    S_r = moments.S + A * np.outer(d, d)                                 # int r r^T dA (parallel axes)
    N = np.block([[A * np.eye(3), -_skew(A * d)], [_skew(A * d), np.trace(S_r) * np.eye(3) - S_r]])
    r1 = moments.m1 + moments.m0[:, None] * d                           # int N_i r dA, (s, 3)
    B = np.concatenate([moments.m0[:, None, None] * np.eye(3), _skew(r1)], axis=1)   # (s, 6, 3)
    C = la.solve(N, B.transpose(1, 0, 2).reshape(6, -1), assume_a="pos")
    return DistributingCoupling(nodes=moments.nodes, weights=moments.m0 / A, ref_point=X_ref, C=C)


def surface_coupling(points: np.ndarray, tets: np.ndarray, x: float,
                     ref_point=None) -> DistributingCoupling:
    """Distributing coupling of the cross-section of the solid at ``x`` [m].

    The nodes of the mesh faces in the plane ``x`` (an end surface, or an
    interior station plane), with consistent area moments; the reference point
    defaults to the area centroid of the section, where the beam node sits.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    tets : ndarray of int, shape (m, 10)
    x : float
        [m].
    ref_point : array_like, shape (3,), optional
        [m].

    Returns
    -------
    DistributingCoupling
    """
    faces = faces_on_plane(points, tets, 0, x)
    if faces.size == 0:
        raise ValueError(f"no mesh faces in the plane x = {x} m (add it to the mesh stations)")
    return distributing_coupling(surface_moments(points, faces), ref_point)


def rigid_motion(points: np.ndarray, a, ref_point) -> np.ndarray:
    """Displacements of a small rigid-body motion, ``u_i = u_r + phi x (X_i - X_ref)``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        [m].
    a : array_like, shape (6,)
        ``[u_x, u_y, u_z, phi_x, phi_y, phi_z]`` [m, rad] at ``ref_point``.
    ref_point : array_like, shape (3,)
        [m].

    Returns
    -------
    ndarray, shape (3 n,)
        [m], node by node.
    """
    a = np.asarray(a, dtype=float)
    r = np.asarray(points, dtype=float) - np.asarray(ref_point, dtype=float)
    return (a[:3] + np.cross(a[3:], r)).ravel()


@dataclass
class TiedBody:
    """A solid whose coupled surfaces are tied to reference dofs.

    The tied dof vector is ``v = [u_f; q]``: the solid dofs that stay
    independent (``free``, in increasing order) followed by the reference dofs
    ``q`` (coupling by coupling, component by component). ``u = T @ v``.

    Attributes
    ----------
    K, M : scipy.sparse.csr_matrix, shape (N, N)
        ``T^T K T`` [N/m ...], ``T^T M T`` [kg ...].
    T : scipy.sparse.csr_matrix, shape (n, N)
        Recovery of the full solid displacements.
    free : ndarray of int, shape (N - nq,)
        Solid dof of each independent coordinate ``v[:N - nq]``.
    ref_dofs : list of ndarray of int
        Per coupling, the positions of its reference dofs in ``v``.
    components : list of tuple of str
        Per coupling, the names of its reference dofs.
    """

    K: sp.csr_matrix
    M: sp.csr_matrix
    T: sp.csr_matrix
    free: np.ndarray
    ref_dofs: list
    components: list

    def dof_of(self, solid_dof: int) -> int:
        """Position in ``v`` of an independent solid dof (raises if it was eliminated)."""
        i = int(np.searchsorted(self.free, solid_dof))
        if i >= self.free.size or self.free[i] != solid_dof:
            raise ValueError(f"solid dof {solid_dof} was eliminated by a tie")
        return i


def tie(K: sp.spmatrix, M: sp.spmatrix, couplings, components=BEAM,
        keep=()) -> TiedBody:
    """Tie coupled surfaces to reference dofs by master-slave elimination.

    For each coupling and its ``k`` components, the constraint ``R u_s = q`` (``R`` =
    ``coupling.rows(components)``) is solved for ``k`` master dofs of the surface,
    chosen by pivoted QR of ``R`` (best conditioned), ``u_m = R_m^{-1} (q - R_f u_f)``.

    Parameters
    ----------
    K, M : sparse, shape (n, n)
        Solid stiffness and mass.
    couplings : sequence of DistributingCoupling
        Surfaces to tie; their node sets must be disjoint.
    components : tuple of str, or sequence of them (one per coupling)
        Reference dofs of each coupling (keys of :data:`COMPONENTS`); default
        ``("w", "theta")``, the dofs of a vertical-bending beam node.
    keep : sequence of int
        Solid dofs that must stay independent (not chosen as masters), e.g. dofs
        retained for bushings on the tied surface.

    Returns
    -------
    TiedBody
    """
    n = K.shape[0]
    couplings = list(couplings)
    if components and isinstance(components[0], str):
        components = [tuple(components)] * len(couplings)
    keep = set(int(d) for d in keep)
    masters, rows_T, cols_T, vals_T = [], [], [], []
    n_ref = sum(len(c) for c in components)
    seen = set()
    for cpl, comps in zip(couplings, components):
        dofs = cpl.dofs
        if seen & set(dofs.tolist()):
            raise ValueError("coupled surfaces overlap")
        seen |= set(dofs.tolist())
        R = cpl.rows(comps)
        allowed = np.array([d not in keep for d in dofs])
        _, _, piv = la.qr(R[:, allowed], pivoting=True, mode="economic")
        m_local = np.flatnonzero(allowed)[piv[: R.shape[0]]]
        masters.append((dofs, R, m_local))
    master_dofs = np.concatenate([d[m] for d, _, m in masters]) if masters else np.zeros(0, int)
    is_master = np.zeros(n, bool)
    is_master[master_dofs] = True
    free = np.flatnonzero(~is_master)
    col_of = np.full(n, -1, dtype=np.int64)
    col_of[free] = np.arange(free.size)
    # independent dofs map to themselves
    rows_T.append(free)
    cols_T.append(np.arange(free.size))
    vals_T.append(np.ones(free.size))
    ref_dofs, q0 = [], free.size
    for (dofs, R, m_local), comps in zip(masters, components):
        k = R.shape[0]
        f_local = np.setdiff1d(np.arange(dofs.size), m_local)
        Rm_inv = la.inv(R[:, m_local])
        A_f = -Rm_inv @ R[:, f_local]          # u_m = A_f u_f + A_q q
        A_q = Rm_inv
        q_cols = q0 + np.arange(k)
        for j, md in enumerate(dofs[m_local]):
            rows_T.append(np.full(f_local.size + k, md))
            cols_T.append(np.concatenate([col_of[dofs[f_local]], q_cols]))
            vals_T.append(np.concatenate([A_f[j], A_q[j]]))
        ref_dofs.append(q_cols)
        q0 += k
    N = free.size + n_ref
    T = sp.csr_matrix((np.concatenate(vals_T), (np.concatenate(rows_T), np.concatenate(cols_T))),
                      shape=(n, N))
    Kt = (T.T @ K @ T).tocsr()
    Mt = (T.T @ M @ T).tocsr()
    return TiedBody(K=0.5 * (Kt + Kt.T), M=0.5 * (Mt + Mt.T), T=T, free=free, ref_dofs=ref_dofs,
                    components=[tuple(c) for c in components])


__all__ = ["COMPONENTS", "BEAM", "DistributingCoupling", "distributing_coupling", "surface_coupling",
           "rigid_motion", "TiedBody", "tie"]
