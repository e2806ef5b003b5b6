"""Meshes of the rail section (triangles) and of the rail solid (10-node tetrahedra), by gmsh.

The solid is the section polygon (:mod:`track.solid.section`, plane ``x = 0``)
extruded along ``x`` by the OpenCASCADE kernel, meshed with second-order
tetrahedra. Node ordering of a returned tetrahedron (the scikit-fem order of
:class:`skfem.ElementTetP2`, so :func:`track.solid.fem.assemble` needs no
reordering)::

    0, 1, 2, 3        corners
    4 .. 9            mid-edge nodes of edges (0,1), (1,2), (0,2), (0,3), (1,3), (2,3)

gmsh numbers the mid-edge nodes differently; they are matched to their edges
here by geometry (each mid-edge node is the midpoint of its edge: the solid
has flat faces only and the mesh is made with ``Mesh.SecondOrderLinear``).

gmsh is a process-wide singleton and not thread-safe: mesh from one thread at a
time. If the caller has initialised gmsh already, a temporary model is added and
removed again (mesh options set here stay set).

``gmsh.initialize`` sets SIGPIPE back to its default action (terminate the process)
behind Python's back (Python ignores it, so that a write to a closed pipe raises
``BrokenPipeError``); :func:`_keep_sigpipe` restores what Python had. Without it a process
that had built a solid crossing died silently when a worker of its process pool died
(its pool's feeder thread wrote to the dead worker's pipe): found when CI's run of
tests/test_sweep.py after tests/test_solid.py ended with exit status 141, 2026-11-26.
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from .section import RailSection

TET10 = 11  # gmsh element type: 10-node second-order tetrahedron
TRI3 = 2    # gmsh element type: 3-node triangle

# Local corner pairs of the six tetrahedron edges, scikit-fem order (skfem.refdom.RefTet.edges).
TET_EDGES = np.array([[0, 1], [1, 2], [0, 2], [0, 3], [1, 3], [2, 3]])
MIDNODE_TOL = 1e-6  # relative to the edge length: a mid-edge node this close to the midpoint is "on" it


def _keep_sigpipe(before) -> None:
    """Give SIGPIPE back the disposition ``before`` (Python's, read before gmsh was initialised; module doc)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, before)
    elif before == signal.SIG_IGN:   # signal.signal works in the main thread only; the disposition is per process
        import ctypes
        libc = ctypes.CDLL(None, use_errno=True)
        libc.signal.argtypes, libc.signal.restype = [ctypes.c_int, ctypes.c_void_p], ctypes.c_void_p
        libc.signal(int(signal.SIGPIPE), int(signal.SIG_IGN))


@contextmanager
def _gmsh_model(name: str):
    """A fresh gmsh model, removed afterwards; gmsh is finalised if we initialised it."""
    import gmsh

    own = not gmsh.isInitialized()
    if own:
        # interruptible=False: gmsh would otherwise install a SIGINT handler, which fails
        # outside the main thread (executor / dask workers).
        sigpipe = signal.getsignal(signal.SIGPIPE) if hasattr(signal, "SIGPIPE") else None
        gmsh.initialize(readConfigFiles=False, interruptible=False)
        if sigpipe is not None:
            _keep_sigpipe(sigpipe)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)   # reproducible meshes
        gmsh.model.add(name)
        try:
            yield gmsh
        finally:
            gmsh.model.remove()
    finally:
        if own:
            gmsh.finalize()


def _add_polygon_x0(occ, vertices: np.ndarray, x: float = 0.0) -> int:
    """OCC plane surface of the polygon ``(y, z)`` placed in the plane ``x``; returns its tag."""
    pts = [occ.addPoint(x, float(y), float(z)) for y, z in vertices]
    lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
    return occ.addPlaneSurface([occ.addCurveLoop(lines)])


def section_mesh(vertices: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Linear triangle mesh of a polygon (for 2D section analyses).

    Parameters
    ----------
    vertices : ndarray, shape (k, 2)
        Polygon corners ``(y, z)`` [m], counter-clockwise.
    h : float
        Target element size [m].

    Returns
    -------
    points : ndarray, shape (n, 2)
        Node coordinates ``(y, z)`` [m].
    triangles : ndarray of int, shape (m, 3)
        Node indices of each triangle.
    """
    with _gmsh_model("section") as gmsh:
        occ = gmsh.model.occ
        pts = [occ.addPoint(float(y), float(z), 0.0) for y, z in vertices]
        lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
        occ.addPlaneSurface([occ.addCurveLoop(lines)])
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
        gmsh.model.mesh.generate(2)
        tags, xyz, _ = gmsh.model.mesh.getNodes()
        _, conn = gmsh.model.mesh.getElementsByType(TRI3)
    points, cells = _compact(tags, xyz.reshape(-1, 3), conn.reshape(-1, 3))
    return points[:, :2].copy(), cells


def _compact(tags, xyz, conn):
    """Keep the nodes that elements use, numbered 0..n-1 in gmsh tag order."""
    tags = np.asarray(tags, dtype=np.int64)
    used = np.unique(conn)
    lookup = np.full(tags.max() + 1, -1, dtype=np.int64)
    lookup[tags] = np.arange(tags.size)
    points = xyz[lookup[used]]
    renum = np.full(tags.max() + 1, -1, dtype=np.int64)
    renum[used] = np.arange(used.size)
    return points, renum[conn]


@dataclass(frozen=True)
class CrossingGeometry:
    """Plan-view shape of a crossing nose cut from the rail head (API for the crossing variant).

    The head of the extruded rail (everything above ``cut_height``) is trimmed to
    the half-width ``b(x) = max(tip_width / 2, (x - x_point) / (2 n))`` [m], the
    two running edges diverging at the crossing angle ``atan(1 / n)`` from the
    theoretical point ``x_point``; from the ``x`` where ``b`` reaches half the head
    width the section is the full rail.

    Attributes
    ----------
    crossing_n : float
        Crossing ratio 1:n, given as n [-] (tan of the crossing angle = 1/n).
    x_point : float
        Theoretical point of the crossing along the solid's axis [m] (may be < 0).
    tip_width : float
        Width of the blunt nose tip [m].
    cut_height : float
        Height above which the head is trimmed [m] (e.g. the fishing surface at the head side).
    """

    crossing_n: float
    x_point: float
    tip_width: float
    cut_height: float

    def half_width(self, x: np.ndarray) -> np.ndarray:
        """Nose half-width ``b(x)`` [m] at axial positions ``x`` [m], before clipping to the head."""
        x = np.asarray(x, dtype=float)
        return np.maximum(0.5 * self.tip_width, (x - self.x_point) / (2.0 * self.crossing_n))


def rail_solid_mesh(length: float, section: RailSection, h: float, stations=(),
                    crossing: CrossingGeometry | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Second-order tetrahedral mesh of a rail extruded along ``x``.

    Parameters
    ----------
    length : float
        Solid length [m]; the solid spans ``0 <= x <= length``.
    section : RailSection
        Cross-section polygon in ``(y, z)`` [m]. Its corners become longitudinal
        node lines (use :meth:`RailSection.with_points` for bushing and contact lines).
    h : float
        Target element size [m] (gmsh ``Mesh.MeshSizeMax``).
    stations : sequence of float
        Axial positions [m] where the mesh has a full cross-section plane of nodes
        (rail seats, sensor sections, the mid-span of a test).
    crossing : CrossingGeometry, optional
        Trim the head to a crossing nose; ``None``: prismatic rail.

    Returns
    -------
    points : ndarray, shape (n, 3)
        Node coordinates ``(x, y, z)`` [m].
    tets : ndarray of int, shape (m, 10)
        Node indices, corners then mid-edge nodes in the order of the module docstring.
    """
    xs = np.unique(np.concatenate([[0.0, length], np.asarray(stations, dtype=float)]))
    if xs[0] < 0.0 or xs[-1] > length:
        raise ValueError("stations must lie in [0, length]")
    with _gmsh_model("rail_solid") as gmsh:
        occ = gmsh.model.occ
        top = (2, _add_polygon_x0(occ, section.vertices))
        volumes = []
        for a, b in zip(xs[:-1], xs[1:]):
            out = occ.extrude([top], b - a, 0.0, 0.0)
            top = out[0]                                   # the far face: the next segment's base
            volumes.append(out[1])
        if crossing is not None:
            volumes = _trim_nose(occ, volumes, section, length, crossing)
        occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMax", h)
        gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
        gmsh.option.setNumber("Mesh.SecondOrderLinear", 1)   # flat faces: mid-edge nodes at midpoints
        gmsh.model.mesh.generate(3)
        gmsh.model.mesh.setOrder(2)
        tags, xyz, _ = gmsh.model.mesh.getNodes()
        _, conn = gmsh.model.mesh.getElementsByType(TET10)
    points, tets = _compact(tags, xyz.reshape(-1, 3), conn.reshape(-1, 10))
    return points, order_tet10(points, tets)


def _trim_nose(occ, volumes, section: RailSection, length: float, crossing: CrossingGeometry):
    """Cut the head outside ``|y| <= b(x)`` from the extruded segments; keep them conformal."""
    V = section.vertices
    bh = float(np.abs(V[V[:, 1] >= crossing.cut_height - 1e-9, 0]).max())   # head half-width
    x_full = crossing.x_point + 2.0 * crossing.crossing_n * bh     # b(x_full) = half the rail width
    x_tipend = crossing.x_point + crossing.crossing_n * crossing.tip_width
    if x_full <= 0.0:
        return volumes
    z0, z1 = crossing.cut_height, section.top + 0.01
    pad = 0.01
    tools = []
    for sgn in (1.0, -1.0):
        # plan-view polygon of the removed part on one side, extruded over the head height
        xa, xb = -pad, min(x_full, length + pad)
        xk = [xa] + [x for x in (x_tipend,) if xa < x < xb] + [xb]     # kink of b(x) at the tip
        plan = [(x, float(crossing.half_width(x))) for x in xk] + [(xb, bh + pad), (xa, bh + pad)]
        pts = [occ.addPoint(x, sgn * y, z0) for x, y in plan]
        lines = [occ.addLine(pts[i], pts[(i + 1) % len(pts)]) for i in range(len(pts))]
        surf = occ.addPlaneSurface([occ.addCurveLoop(lines)])
        tools += [d for d in occ.extrude([(2, surf)], 0.0, 0.0, z1 - z0) if d[0] == 3]
    out, _ = occ.cut(volumes, tools)
    out, _ = occ.fragment(out, [])            # glue the segments again (shared faces)
    return [d for d in out if d[0] == 3]


def order_tet10(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Reorder the mid-edge nodes of straight-sided 10-node tetrahedra to :data:`TET_EDGES`.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        Node coordinates [m].
    tets : ndarray of int, shape (m, 10)
        Corners first, mid-edge nodes in any order.

    Returns
    -------
    ndarray of int, shape (m, 10)
        Same elements, mid-edge node ``4 + k`` on edge ``TET_EDGES[k]``.

    Raises
    ------
    ValueError
        If a mid-edge node is not at the midpoint of exactly one edge (curved element).
    """
    tets = np.asarray(tets)
    X = points[tets]                                               # (m, 10, 3)
    mid = 0.5 * (X[:, TET_EDGES[:, 0]] + X[:, TET_EDGES[:, 1]])   # (m, 6, 3)
    edge_len = np.linalg.norm(X[:, TET_EDGES[:, 0]] - X[:, TET_EDGES[:, 1]], axis=2)
    d = np.linalg.norm(mid[:, :, None, :] - X[:, None, 4:, :], axis=3)   # (m, 6 edges, 6 nodes)
    pick = np.argmin(d, axis=2)
    ok = np.take_along_axis(d, pick[:, :, None], 2)[:, :, 0] <= MIDNODE_TOL * edge_len
    if not ok.all() or not np.all(np.sort(pick, axis=1) == np.arange(6)):
        raise ValueError("mid-edge nodes are not at their edge midpoints (curved or invalid elements)")
    return np.concatenate([tets[:, :4], np.take_along_axis(tets[:, 4:], pick, 1)], axis=1)


# The 8 children of a tetrahedron split at its mid-edge nodes (local numbering of a
# 10-node tet: corners 0-3, mid-edge nodes 4-9 on TET_EDGES): 4 corner tetrahedra, and the
# inner octahedron cut into 4 along one of its three diagonals (4-9, 5-7 or 6-8), each
# written as the diagonal plus consecutive vertices of the 4-cycle around it.
_CORNER_CHILDREN = np.array([[0, 4, 6, 7], [4, 1, 5, 8], [6, 5, 2, 9], [7, 8, 9, 3]])
_DIAGONALS = np.array([[4, 9], [5, 7], [6, 8]])
_OCTA_CHILDREN = np.array([
    [[4, 9, 5, 6], [4, 9, 6, 7], [4, 9, 7, 8], [4, 9, 8, 5]],
    [[5, 7, 4, 6], [5, 7, 6, 9], [5, 7, 9, 8], [5, 7, 8, 4]],
    [[6, 8, 4, 5], [6, 8, 5, 9], [6, 8, 9, 7], [6, 8, 7, 4]],
])


def refine(points: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Uniform refinement of a straight-sided 10-node mesh: every element into 8.

    The parent's mid-edge nodes become corners of the children, so the meshes of
    a sequence are nested and the element size halves exactly (for convergence
    studies). The inner octahedron is cut along its shortest diagonal, which
    keeps the element shapes from degrading over levels (a fixed diagonal did:
    the first refinement of a rail mesh then hardly reduced the error). Children
    keep positive orientation.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
        [m].
    tets : ndarray of int, shape (m, 10)
        Node order of this module.

    Returns
    -------
    points : ndarray, shape (n', 3)
        The old nodes followed by the new mid-edge nodes [m].
    tets : ndarray of int, shape (8 m, 10)
    """
    points = np.asarray(points, dtype=float)
    tets = np.asarray(tets)
    # shortest diagonal of the inner octahedron: keeps the children shape-regular over levels
    d = points[tets[:, _DIAGONALS[:, 0]]] - points[tets[:, _DIAGONALS[:, 1]]]   # (m, 3, 3)
    choice = np.argmin(np.einsum("mkd,mkd->mk", d, d), axis=1)
    local = np.concatenate([np.broadcast_to(_CORNER_CHILDREN, (tets.shape[0], 4, 4)),
                            _OCTA_CHILDREN[choice]], axis=1)                     # (m, 8, 4)
    kids = np.take_along_axis(tets[:, None, :], local.reshape(tets.shape[0], -1)[:, None, :],
                              axis=2).reshape(-1, 4)
    flip = tet_volumes(points, kids) < 0.0
    kids[flip] = kids[flip][:, [1, 0, 2, 3]]
    edges = np.sort(kids[:, TET_EDGES].reshape(-1, 2), axis=1)
    uniq, inv = np.unique(edges, axis=0, return_inverse=True)
    mids = points.shape[0] + inv.reshape(-1, 6)
    new_points = np.concatenate([points, 0.5 * (points[uniq[:, 0]] + points[uniq[:, 1]])])
    return new_points, np.concatenate([kids, mids], axis=1)


def tet_volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Volume of each (straight-sided) tetrahedron [m^3], shape (m,); negative if inverted."""
    X = points[np.asarray(tets)[:, :4]]
    e = X[:, 1:] - X[:, :1]
    return np.einsum("ij,ij->i", e[:, 0], np.cross(e[:, 1], e[:, 2])) / 6.0


__all__ = ["CrossingGeometry", "section_mesh", "rail_solid_mesh", "order_tet10", "refine", "tet_volumes",
           "TET_EDGES"]
