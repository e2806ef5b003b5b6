"""Linear elasticity of the solid with quadratic tetrahedra (scikit-fem), and node sets.

Dofs: 3 per node, ``[u_x, u_y, u_z]`` of node ``i`` at ``3 i .. 3 i + 2`` (node
``i`` = row ``i`` of ``points``). Frame as in :mod:`track.solid.section`: ``x``
along the rail, ``y`` lateral, ``z`` upward.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .mesh import TET_EDGES, section_mesh
from .section import RailSection

# Local nodes of the four faces of a 10-node tetrahedron (corners, then the mid-edge
# nodes of the face's edges (a,b), (b,c), (a,c)), with TET_EDGES numbering.
_FACES = np.array([[0, 1, 2, 4, 5, 6],
                   [0, 1, 3, 4, 8, 7],
                   [0, 2, 3, 6, 9, 7],
                   [1, 2, 3, 5, 9, 8]])
COORD_TOL = 1e-9  # m: a node within this distance of a plane or line is on it


def lame(E: float, nu: float) -> tuple[float, float]:
    """Lame parameters ``(lambda, mu)`` [Pa] from Young's modulus [Pa] and Poisson's ratio [-]."""
    from skfem.models.elasticity import lame_parameters
    return lame_parameters(E, nu)


def _corner_mesh(points: np.ndarray, tets: np.ndarray):
    """scikit-fem's linear mesh of our 10-node tets and the maps back to our nodes.

    Returns ``(mesh, corners, node_of_edge)``: ``corners`` our node of each mesh vertex,
    ``node_of_edge`` our mid-edge node of each scikit-fem edge (matched through the
    element-to-edge table: local edge k of element e is TET_EDGES[k]).
    """
    import skfem

    corners = np.unique(tets[:, :4])
    renum = np.full(points.shape[0], -1, dtype=np.int64)
    renum[corners] = np.arange(corners.size)
    mesh = skfem.MeshTet1(points[corners].T.copy(), renum[tets[:, :4]].T.astype(np.int32).copy())
    if not np.array_equal(mesh.t, renum[tets[:, :4]].T):
        raise RuntimeError("scikit-fem reordered the tetrahedra corners")
    node_of_edge = np.empty(mesh.edges.shape[1], dtype=np.int64)
    node_of_edge[mesh.t2e.ravel()] = tets[:, 4:].T.ravel()
    return mesh, corners, node_of_edge


def _basis(points: np.ndarray, tets: np.ndarray, intorder: int):
    """scikit-fem vector P2 basis on the corner mesh and the permutation to our dofs.

    Returns ``(basis, P)``: ``P`` (3n, 3n) sparse with ``A_ours = P A_skfem P^T`` and
    ``b_ours = P b_skfem``.
    """
    import skfem

    points = np.asarray(points, dtype=float)
    tets = np.asarray(tets)
    mesh, corners, node_of_edge = _corner_mesh(points, tets)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTetP2()), intorder=intorder)
    n = points.shape[0]
    perm = np.empty(basis.N, dtype=np.int64)                       # skfem dof -> our dof
    comp = np.arange(3)[:, None]
    perm[basis.nodal_dofs] = 3 * corners[None, :] + comp
    perm[basis.edge_dofs] = 3 * node_of_edge[None, :] + comp
    if basis.N != 3 * n or np.unique(perm).size != 3 * n:
        raise ValueError("tets do not use every node exactly once as a corner or mid-edge node")
    P = sp.csr_matrix((np.ones(3 * n), (perm, np.arange(3 * n))), shape=(3 * n, 3 * n))
    return basis, P


def assemble(points: np.ndarray, tets: np.ndarray, E: float, nu: float,
             rho: float, scale=None) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Stiffness and consistent mass of an isotropic linear-elastic solid.

    Quadratic Lagrange tetrahedra (``ElementVector(ElementTetP2)``) on straight-sided
    elements (affine mapping); the quadrature is exact: degree 2 for ``K``
    (products of linear strains), degree 4 for ``M``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Node coordinates [m].
    tets : ndarray of int, shape (m, 10)
        Elements in the node order of :mod:`track.solid.mesh`.
    E : float
        Young's modulus [Pa].
    nu : float
        Poisson's ratio [-].
    rho : float
        Density [kg/m^3].
    scale : callable, optional
        ``scale(x) -> (s_E, s_rho)``: factors on ``E`` and ``rho`` as functions of
        the axial coordinate ``x`` [m] (arrays of the shape of ``x``), evaluated at
        the quadrature points; ``None``: homogeneous. Used to give the solid the
        bending stiffness and mass of a body it stands for (the crossing block,
        :mod:`track.solid.crossing`). With a non-constant factor the quadrature is
        no longer exact; the factors used are piecewise linear and smooth on the
        element scale.

    Returns
    -------
    K, M : scipy.sparse.csr_matrix, shape (3n, 3n)
        [N/m] and [kg], dof ``3 i + c`` = component ``c`` of node ``i``.
    """
    import skfem
    from skfem.helpers import ddot, dot, sym_grad, trace

    basis, P = _basis(points, tets, intorder=2)
    lam, mu = lame(E, nu)

    def s_E(x):
        return 1.0 if scale is None else scale(x[0])[0]

    def s_rho(x):
        return 1.0 if scale is None else scale(x[0])[1]

    @skfem.BilinearForm
    def elasticity(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return s_E(w.x) * (2.0 * mu * ddot(eu, ev) + lam * trace(eu) * trace(ev))

    K = skfem.asm(elasticity, basis)

    @skfem.BilinearForm
    def mass(u, v, w):
        return rho * s_rho(w.x) * dot(u, v)

    M = skfem.asm(mass, skfem.Basis(basis.mesh, basis.elem, intorder=4))   # same dof numbering
    return (P @ K @ P.T).tocsr(), (P @ M @ P.T).tocsr()


def probe_matrix(points: np.ndarray, tets: np.ndarray, X: np.ndarray) -> sp.csr_matrix:
    """Interpolation of a nodal field at arbitrary points inside the mesh.

    Uses the quadratic shape functions (``skfem.CellBasis.probes`` of a scalar
    ``ElementTetP2`` basis) and maps scikit-fem's dof order to our node order as
    :func:`assemble` does.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Node coordinates [m].
    tets : ndarray of int, shape (m, 10)
    X : ndarray, shape (k, 3)
        Points [m]; each must lie in (or on the boundary of) an element.

    Returns
    -------
    scipy.sparse.csr_matrix, shape (k, n)
        ``f(X) = P @ f_nodes`` for a scalar nodal field (e.g. ``u[0::3]``).
    """
    import skfem

    points = np.asarray(points, dtype=float)
    tets = np.asarray(tets)
    mesh, corners, node_of_edge = _corner_mesh(points, tets)
    basis = skfem.Basis(mesh, skfem.ElementTetP2())
    node_of = np.empty(basis.N, dtype=np.int64)                  # skfem dof -> our node
    node_of[basis.nodal_dofs[0]] = corners
    node_of[basis.edge_dofs[0]] = node_of_edge
    Pk = basis.probes(np.asarray(X, dtype=float).T).tocoo()
    return sp.csr_matrix((Pk.data, (Pk.row, node_of[Pk.col])), shape=(Pk.shape[0], points.shape[0]))


LOCATE_TOL = 1e-9   # barycentric: a point this far outside an element (relative) still lies in it


def locate(points: np.ndarray, tets: np.ndarray, X: np.ndarray, tol: float = LOCATE_TOL
           ) -> tuple[np.ndarray, np.ndarray]:
    """The element holding each point and the point's barycentric coordinates there.

    The elements are straight-sided (affine), so the barycentric coordinates of a point
    in element ``e`` with corners ``p0..p3`` solve ``X = p0 + [p1-p0, p2-p0, p3-p0] l``;
    of the elements whose bounding box holds the point, the one with the largest smallest
    coordinate is taken (a point on a face between two elements may take either: the
    field is continuous there).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Node coordinates [m].
    tets : ndarray of int, shape (m, 10)
    X : ndarray, shape (k, 3)
        Points [m].
    tol : float
        A point may lie this far outside its element (barycentric units).

    Returns
    -------
    elements : ndarray of int, shape (k,)
    lam : ndarray, shape (k, 4)
        Barycentric coordinates ``(l0, l1, l2, l3)`` of the corners ``tets[e, :4]``.

    Raises
    ------
    ValueError
        A point in no element (outside the solid).
    """
    P = np.asarray(points, dtype=float)
    C = P[np.asarray(tets)[:, :4]]                                    # (m, 4, 3)
    lo, hi = C.min(axis=1), C.max(axis=1)
    X = np.atleast_2d(np.asarray(X, dtype=float))
    elements, lam = np.empty(X.shape[0], dtype=np.int64), np.empty((X.shape[0], 4))
    for i, x in enumerate(X):
        cand = np.flatnonzero(np.all((lo - 1e-9 <= x) & (x <= hi + 1e-9), axis=1))
        if cand.size:
            J = np.transpose(C[cand, 1:] - C[cand, :1], (0, 2, 1))     # columns p_j - p0
            l123 = np.linalg.solve(J, (x - C[cand, 0])[..., None])[..., 0]
            L = np.column_stack([1.0 - l123.sum(axis=1), l123])
            best = int(np.argmax(L.min(axis=1)))
            if L[best].min() >= -tol:
                elements[i], lam[i] = cand[best], L[best]
                continue
        raise ValueError(f"point {tuple(np.round(x, 6))} m is not inside the solid")
    return elements, lam


def shape_rows(points: np.ndarray, tets: np.ndarray, X: np.ndarray
               ) -> tuple[sp.csr_matrix, list[sp.csr_matrix]]:
    """Values and gradients of a nodal field at points, in the element holding each point.

    Quadratic tetrahedra in barycentric coordinates (node order of :mod:`track.solid.mesh`):
    corner ``i``: ``N = l_i (2 l_i - 1)``, ``grad N = (4 l_i - 1) grad l_i``; mid-edge
    node of edge ``(a, b)``: ``N = 4 l_a l_b``, ``grad N = 4 (l_a grad l_b + l_b grad l_a)``,
    with ``grad l`` constant in an affine element. So the strain of a displacement field at
    a point is that of the finite-element solution itself in the element holding it (a
    field that is linear or quadratic in ``X`` is reproduced exactly).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        [m].
    tets : ndarray of int, shape (m, 10)
    X : ndarray, shape (k, 3)
        Points inside the solid [m] (:func:`locate`).

    Returns
    -------
    N : scipy.sparse.csr_matrix, shape (k, n)
        ``f(X) = N @ f_nodes`` for a scalar nodal field (e.g. ``u[2::3]``).
    G : list of three scipy.sparse.csr_matrix, shape (k, n)
        ``df/dx, df/dy, df/dz`` at ``X`` [1/m]: ``G[0] @ u[0::3]`` is ``eps_xx``.
    """
    tets = np.asarray(tets)
    P = np.asarray(points, dtype=float)
    e, lam = locate(P, tets, X)
    C = P[tets[e, :4]]                                                # (k, 4, 3)
    J = np.transpose(C[:, 1:] - C[:, :1], (0, 2, 1))
    g123 = np.linalg.inv(J)                                           # rows: grad l1, l2, l3
    grad_l = np.concatenate([-g123.sum(axis=1, keepdims=True), g123], axis=1)   # (k, 4, 3)
    a, b = TET_EDGES[:, 0], TET_EDGES[:, 1]
    N = np.concatenate([lam * (2.0 * lam - 1.0), 4.0 * lam[:, a] * lam[:, b]], axis=1)     # (k, 10)
    dN = np.concatenate([(4.0 * lam - 1.0)[..., None] * grad_l,
                         4.0 * (lam[:, a, None] * grad_l[:, b] + lam[:, b, None] * grad_l[:, a])], axis=1)
    k, n = lam.shape[0], P.shape[0]
    rows, cols = np.repeat(np.arange(k), 10), tets[e].ravel()

    def mat(v):
        return sp.csr_matrix((v.ravel(), (rows, cols)), shape=(k, n))

    return mat(N), [mat(dN[..., c]) for c in range(3)]


def assemble_load(points: np.ndarray, tets: np.ndarray, f, intorder: int = 6) -> np.ndarray:
    """Consistent nodal loads of a body-force field.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        [m].
    tets : ndarray of int, shape (m, 10)
    f : callable
        ``f(X)`` with ``X`` of shape (3, ...) [m] returns the force per volume,
        shape (3, ...) [N/m^3].
    intorder : int
        Degree of the quadrature.

    Returns
    -------
    ndarray, shape (3n,)
        [N].
    """
    import skfem
    from skfem.helpers import dot

    basis, P = _basis(points, tets, intorder=intorder)

    @skfem.LinearForm
    def load(v, w):
        return dot(f(w.x), v)

    return P @ skfem.asm(load, basis)


def boundary_nodes(tets: np.ndarray) -> np.ndarray:
    """Nodes on the boundary of the mesh (of the faces that belong to one element), sorted."""
    faces = np.asarray(tets)[:, _FACES].reshape(-1, 6)
    _, inv, count = np.unique(np.sort(faces[:, :3], axis=1), axis=0, return_inverse=True,
                              return_counts=True)
    return np.unique(faces[count[inv.ravel()] == 1])


def nodes_on_plane(points: np.ndarray, axis: int, value: float, tol: float = COORD_TOL) -> np.ndarray:
    """Indices of nodes with ``points[:, axis] == value`` (within ``tol`` [m]), shape (k,)."""
    return np.flatnonzero(np.abs(np.asarray(points)[:, axis] - value) <= tol)


def nodes_on_line(points: np.ndarray, y: float, z: float, tol: float = COORD_TOL) -> np.ndarray:
    """Nodes on the longitudinal line ``(y, z)`` [m], sorted by ``x``, shape (k,).

    The contact path on the running surface is such a line when the section has a
    corner at ``(y_c, top)`` (:meth:`track.solid.section.RailSection.with_points`).
    """
    P = np.asarray(points)
    idx = np.flatnonzero((np.abs(P[:, 1] - y) <= tol) & (np.abs(P[:, 2] - z) <= tol))
    return idx[np.argsort(P[idx, 0])]


def nearest_node(points: np.ndarray, xyz, tol: float | None = None) -> int:
    """Index of the node nearest to ``xyz`` [m]; with ``tol`` [m], raise if farther."""
    d = np.linalg.norm(np.asarray(points) - np.asarray(xyz, dtype=float), axis=1)
    i = int(np.argmin(d))
    if tol is not None and d[i] > tol:
        raise ValueError(f"no node within {tol} m of {tuple(xyz)} (nearest {d[i]:.3g} m)")
    return i


def seat_nodes(points: np.ndarray, x_seat: float, half_length: float, y: float, z: float = 0.0,
               tol: float = COORD_TOL) -> np.ndarray:
    """Nodes of a bushing patch: on the line ``(y, z)`` with ``|x - x_seat| <= half_length``.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    x_seat : float
        Seat centre along the rail [m].
    half_length : float
        Half the patch length along the rail [m]; 0 for the single node at the seat
        centre (a station of the mesh).
    y, z : float
        Line of the bushing on the foot bottom [m] (a corner of the section).

    Returns
    -------
    ndarray of int, shape (k,)
        Sorted by ``x``.
    """
    line = nodes_on_line(points, y, z, tol)
    return line[np.abs(np.asarray(points)[line, 0] - x_seat) <= half_length + tol]


def faces_on_plane(points: np.ndarray, tets: np.ndarray, axis: int, value: float,
                   tol: float = COORD_TOL) -> np.ndarray:
    """The 6-node triangles of the mesh that lie in a plane ``points[:, axis] == value``.

    Works for boundary faces (end surfaces) and interior ones (the cross-section at
    a station); each face is returned once.

    Returns
    -------
    ndarray of int, shape (f, 6)
        Corners then mid-edge nodes (edges (0,1), (1,2), (0,2)).
    """
    tets = np.asarray(tets)
    on = np.abs(np.asarray(points)[:, axis] - value) <= tol
    faces = tets[:, _FACES].reshape(-1, 6)
    faces = faces[on[faces].all(axis=1)]
    _, first = np.unique(np.sort(faces[:, :3], axis=1), axis=0, return_index=True)
    return faces[np.sort(first)]


@dataclass(frozen=True, eq=False)
class SurfaceMoments:
    """Consistent area integrals of the quadratic shape functions over a flat surface.

    With ``u_h(X) = sum_i N_i(X) u_i`` the finite-element field on the surface and
    ``r = X - centroid``, ``int u_h dA = sum_i m0_i u_i`` and
    ``int r (x) u_h dA = sum_i m1_i (x) u_i`` exactly. (The corner values ``m0``
    of quadratic triangles are 0: a uniform traction loads only the mid-edge
    nodes.) Moments are taken about the centroid to avoid cancellation.

    Attributes
    ----------
    nodes : ndarray of int, shape (s,)
        Sorted node indices of the surface.
    m0 : ndarray, shape (s,)
        ``int N_i dA`` [m^2].
    m1 : ndarray, shape (s, 3)
        ``int N_i r dA`` [m^3].
    area : float
        [m^2].
    centroid : ndarray, shape (3,)
        ``int X dA / A`` [m].
    S : ndarray, shape (3, 3)
        ``int r r^T dA`` [m^4].
    """

    nodes: np.ndarray
    m0: np.ndarray
    m1: np.ndarray
    area: float
    centroid: np.ndarray
    S: np.ndarray

    @classmethod
    def from_nodal_weights(cls, points: np.ndarray, nodes: np.ndarray,
                           weights: np.ndarray) -> "SurfaceMoments":
        """Lumped moments of point weights ``w_i`` at the nodes (Abaqus-style weighting).

        Parameters
        ----------
        points : ndarray, shape (n, 3)
            [m].
        nodes : ndarray of int, shape (s,)
        weights : ndarray, shape (s,)
            Non-negative [m^2].
        """
        nodes = np.asarray(nodes)
        w = np.asarray(weights, dtype=float)
        X = np.asarray(points, dtype=float)[nodes]
        c = w @ X / w.sum()
        r = X - c
        return cls(nodes=nodes, m0=w, m1=w[:, None] * r, area=float(w.sum()), centroid=c,
                   S=np.einsum("i,ia,ib->ab", w, r, r))


def surface_moments(points: np.ndarray, faces: np.ndarray) -> SurfaceMoments:
    """Integrate the quadratic shape functions of a set of flat 6-node triangles.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        [m].
    faces : ndarray of int, shape (f, 6)
        Corners then mid-edge nodes of edges (0,1), (1,2), (0,2)
        (:func:`faces_on_plane`).

    Returns
    -------
    SurfaceMoments
    """
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTri

    faces = np.asarray(faces)
    X = np.asarray(points, dtype=float)[faces]                        # (f, 6, 3)
    xi, W = get_quadrature(RefTri, 4)      # exact for N_i * linear (3) and r r^T (2)
    l1, l2 = xi
    l0 = 1.0 - l1 - l2
    N = np.array([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1),
                  4 * l0 * l1, 4 * l1 * l2, 4 * l0 * l2])            # (6, q)
    two_area = np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)   # (f,)
    dA = two_area[:, None] * W[None, :]                                # (f, q)
    Xq = np.einsum("kq,fkd->fqd", N, X)                                # quadrature points (f, q, 3)
    area = float(dA.sum())
    c = np.einsum("fq,fqd->d", dA, Xq) / area
    rq = Xq - c
    nodes, inv = np.unique(faces, return_inverse=True)
    inv = inv.reshape(faces.shape).ravel()
    m0_fk = np.einsum("fq,kq->fk", dA, N)
    m1_fk = np.einsum("fq,kq,fqd->fkd", dA, N, rq)
    m0 = np.bincount(inv, weights=m0_fk.ravel(), minlength=nodes.size)
    m1 = np.stack([np.bincount(inv, weights=m1_fk[..., d].ravel(), minlength=nodes.size)
                   for d in range(3)], axis=1)
    S = np.einsum("fq,fqa,fqb->ab", dA, rq, rq)
    return SurfaceMoments(nodes=nodes, m0=m0, m1=m1, area=area, centroid=c, S=S)


def body_force(M: sp.spmatrix, g) -> np.ndarray:
    """Consistent nodal loads of a uniform acceleration field ``g`` [m/s^2] (e.g. gravity).

    Parameters
    ----------
    M : sparse, shape (3n, 3n)
        Consistent mass [kg].
    g : array_like, shape (3,)
        Body acceleration ``(g_x, g_y, g_z)`` [m/s^2]; gravity is ``(0, 0, -9.81)``.

    Returns
    -------
    ndarray, shape (3n,)
        Nodal forces [N].
    """
    n = M.shape[0] // 3
    return M @ np.tile(np.asarray(g, dtype=float), n)


def strain_energy(K: sp.spmatrix, u: np.ndarray) -> float:
    """``u^T K u / 2`` [J] for displacements ``u`` [m], shape (3n,)."""
    return 0.5 * float(u @ (K @ u))


def shear_coefficient(section: RailSection, h: float = 0.004) -> float:
    """Timoshenko shear coefficient for vertical shear, by 2D finite elements.

    Energy definition with the Saint-Venant flexure shear stresses for
    Poisson's ratio 0: under a shear force ``V`` (along ``z``) the shear stresses
    are ``tau = (V / I_y) grad g`` with

        laplace(g) = z - z_c  in the section,   dg/dn = 0 on its boundary,

    and ``kappa`` is defined by ``int |tau|^2 dA = V^2 / (kappa A)``, i.e.
    ``kappa = I_y^2 / (A int |grad g|^2 dA)``. For a rectangle this gives 5/6.
    Solved with quadratic triangles (scikit-fem) on a gmsh mesh of size ``h``.

    Poisson's ratio enters the exact flexure solution only through a small
    correction (Cowper 1966 gives 0.833 -> 0.850 for a rectangle at nu = 0.3,
    2 %). Shear is 6 % of the mid-span deflection of a 2 m simply supported
    60E1 rail (25 % at 1 m), so 2 % in kappa moves that deflection by ~0.1 %
    (0.5 % at 1 m).

    Parameters
    ----------
    section : RailSection
    h : float
        Mesh size [m].

    Returns
    -------
    float
        kappa [-].
    """
    import skfem
    from skfem.helpers import dot, grad

    pts, tris = section_mesh(section.vertices, h)
    props = section.properties
    mesh = skfem.MeshTri(pts.T.copy(), tris.T.copy())
    basis = skfem.Basis(mesh, skfem.ElementTriP2())
    zc = props.centroid[1]

    @skfem.BilinearForm
    def laplace(u, v, w):
        return dot(grad(u), grad(v))

    @skfem.LinearForm
    def load(v, w):
        return -(w.x[1] - zc) * v

    K = laplace.assemble(basis)
    b = load.assemble(basis)
    # Pure Neumann problem, compatible load (int (z - z_c) dA = 0): fix g at one dof.
    g = skfem.solve(*skfem.condense(K, b, D=np.array([0])))
    energy = float(g @ (K @ g))
    return props.I_y ** 2 / (props.A * energy)


__all__ = ["shear_coefficient", "assemble", "assemble_load", "probe_matrix", "locate", "shape_rows", "boundary_nodes", "lame", "nodes_on_plane", "nodes_on_line", "nearest_node", "seat_nodes",
           "faces_on_plane", "SurfaceMoments",
           "surface_moments", "body_force", "strain_energy", "TET_EDGES"]
