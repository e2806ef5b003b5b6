"""Finite-element beam bodies (rails along x, sleepers along y).

A :class:`BeamBody` is the full-order model (``fom``) of one rail or sleeper:
node coordinates, the element data and the assembled sparse ``K`` and ``M``
with dofs ``[w0, th0, w1, th1, ...]``.
"""
from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .elements import deflection_shape, rotation_shape, shear_parameter, timoshenko_matrices
from .params import BeamProfile

DUPLICATE_TOL = 1e-6  # m: mesh points closer than this are one node


def mesh_line(length: float, points: np.ndarray, h_max: float) -> np.ndarray:
    """Nodes on [0, length] that include ``points`` and have spacing <= ``h_max``.

    Parameters
    ----------
    length : float
        Body length [m].
    points : ndarray, shape (k,)
        Positions that must be nodes [m] (seats, bushings, sensor points).
    h_max : float
        Maximum element length [m].

    Returns
    -------
    ndarray, shape (n,)
        Sorted node coordinates, first 0 and last ``length``.
    """
    pts = np.concatenate([[0.0, length], np.clip(np.asarray(points, float), 0.0, length)])
    pts = np.unique(np.round(pts / DUPLICATE_TOL) * DUPLICATE_TOL)
    a, b = pts[:-1], pts[1:]
    n = np.maximum(1, np.ceil((b - a) / h_max - 1e-9).astype(np.int64))   # elements per interval
    # interval i gets a + k (b - a) / n for k = 1 .. n - 1 and b itself: np.linspace(a, b, n + 1)[1:]
    # term by term (same operations, so the same nodes to the bit), for all intervals at once
    i = np.repeat(np.arange(a.size), n)
    k = np.arange(i.size) - np.repeat(np.cumsum(n) - n, n) + 1
    inner = k * ((b - a) / n)[i] + a[i]
    last = k == n[i]
    inner[last] = b[i[last]]
    return np.concatenate([pts[:1], inner])


@dataclass
class BeamBody:
    """Full-order FE model of one beam body.

    Attributes
    ----------
    name : str
    s : ndarray, shape (n,)
        Node coordinates along the body axis [m].
    profile : BeamProfile
    K, M : scipy.sparse.csr_matrix, shape (2n, 2n)
    Ke : ndarray, shape (n-1, 4, 4)
        Element stiffness matrices (for moment recovery).
    phi : ndarray, shape (n-1,)
        Element shear parameters (for the deflection shape functions).
    empty : tuple
        ``(s0, s1)`` spans with no material [m] (:func:`beam_body`); ``()`` for most beams.
    """

    name: str
    s: np.ndarray
    profile: BeamProfile
    K: sp.csr_matrix
    M: sp.csr_matrix
    Ke: np.ndarray
    phi: np.ndarray
    empty: tuple = ()

    @property
    def ndof(self) -> int:
        return 2 * self.s.size

    def node(self, s: float) -> int:
        """Index of the node at coordinate ``s`` [m] (must be a node)."""
        sl = self._s_list                   # the nearer of the two nodes around s (the first on a tie)
        j = min(max(bisect_right(sl, s), 1), len(sl) - 1)
        i = j - 1 if abs(sl[j - 1] - s) <= abs(sl[j] - s) else j
        if abs(sl[i] - s) > 1e-5:
            raise ValueError(f"{self.name}: no node at s = {s:.6f} m")
        return i

    def shape_row(self, s: float) -> tuple[int, np.ndarray]:
        """Deflection at ``s`` as weights on the dofs of one element.

        Returns
        -------
        e : int
            Element index; its dofs are ``2e .. 2e+3``.
        weights : ndarray, shape (4,)
            ``w(s) = weights @ u[2e:2e+4]``.
        """
        sl = self._s_list
        e = min(max(bisect_right(sl, s) - 1, 0), len(sl) - 2)
        L = sl[e + 1] - sl[e]
        xi = min(max((s - sl[e]) / L, 0.0), 1.0)
        return e, deflection_shape(xi, L, self._phi_list[e])

    def shape_rows(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`shape_row` for an array of coordinates ``s`` [m], shape (k,): elements (k,) and
        weights (k, 4)."""
        s = np.asarray(s, dtype=float)
        e = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, self.s.size - 2)
        L = self.s[e + 1] - self.s[e]
        xi = np.clip((s - self.s[e]) / L, 0.0, 1.0)
        return e, deflection_shape(xi, L, self.phi[e]).reshape(s.size, 4)

    def rotation_row(self, s: float) -> tuple[int, np.ndarray]:
        """Section rotation at ``s`` [m] as weights on the dofs of one element.

        Returns ``(e, weights)`` with ``theta(s) = weights @ u[2e:2e+4]`` [rad]
        (:func:`track.elements.rotation_shape`).
        """
        sl = self._s_list
        e = min(max(bisect_right(sl, s) - 1, 0), len(sl) - 2)
        L = sl[e + 1] - sl[e]
        xi = min(max((s - sl[e]) / L, 0.0), 1.0)
        return e, rotation_shape(xi, L, self._phi_list[e])

    def __post_init__(self):
        self._s_list = self.s.tolist()
        self._phi_list = self.phi.tolist()

    def element_moments(self, u: np.ndarray) -> np.ndarray:
        """Bending moments at both ends of every element [N m], shape (..., n-1, 2).

        Parameters
        ----------
        u : ndarray, shape (..., 2n)
            Full displacement vector(s).
        """
        n = self.s.size
        idx = 2 * np.arange(n - 1)[:, None] + np.arange(4)[None, :]
        ue = np.asarray(u)[..., idx]                      # (..., n-1, 4)
        f = np.einsum("eij,...ej->...ei", self.Ke, ue)
        return np.stack([-f[..., 1], f[..., 3]], axis=-1)

    def nodal_moments(self, u: np.ndarray) -> np.ndarray:
        """Bending moment at the nodes [N m], shape (..., n): mean of adjacent element ends."""
        me = self.element_moments(u)
        n = self.s.size
        out = np.zeros(me.shape[:-2] + (n,))
        cnt = np.zeros(n)
        out[..., :-1] += me[..., 0]
        out[..., 1:] += me[..., 1]
        cnt[:-1] += 1
        cnt[1:] += 1
        return out / cnt


_BODIES: dict = {}      # (name, nodes, profile) -> BeamBody: the FE models built in this process
_BODIES_MAX = 512       # a 64-sleeper panel has ~90 bodies; a run of a study or a calibration rebuilds
                        # the same ones (only pads and ballast change): 0.11 s of a 0.40 s run, measured


def beam_body(name: str, s: np.ndarray, profile: BeamProfile, empty: tuple = ()) -> BeamBody:
    """Assemble the FE model of a beam with nodes ``s`` [m] and section ``profile``.

    ``empty``: ``(s0, s1)`` spans [m] with no material (the gap between the two sleepers of a
    split position, ``track.layout.SleeperBody.gap``): an element whose midpoint lies in one has
    zero stiffness and mass, so the beam is two pieces with the element indices of one. The
    same inputs give the same (shared, not to be modified) :class:`BeamBody` again.
    """
    s = np.asarray(s, dtype=float)
    key = (name, s.tobytes(), profile, tuple(empty))
    body = _BODIES.get(key)
    if body is None:
        if len(_BODIES) >= _BODIES_MAX:
            _BODIES.pop(next(iter(_BODIES)))
        body = _BODIES[key] = _assemble_beam(name, s, profile, tuple(empty))
    return body


def _assemble_beam(name: str, s: np.ndarray, profile: BeamProfile, empty: tuple = ()) -> BeamBody:
    base = profile.base
    mid = 0.5 * (s[:-1] + s[1:])
    A, I = profile.at(mid)
    ne = s.size - 1
    void = np.zeros(ne, bool)
    for s0, s1 in empty:
        void |= (mid > s0) & (mid < s1)
    L = np.diff(s)
    Ke, Me = timoshenko_matrices(L, base.E, base.G, A, I, base.rho, base.kappa)
    phi = shear_parameter(L, base.E, base.G, A, I, base.kappa)
    Ke[void], Me[void], phi[void] = 0.0, 0.0, 0.0   # the gap of a split position: no material
    idx = 2 * np.arange(ne)[:, None] + np.arange(4)[None, :]
    rows = np.repeat(idx, 4, axis=1).ravel()
    cols = np.tile(idx, (1, 4)).ravel()
    n = 2 * s.size
    K = sp.csr_matrix((Ke.ravel(), (rows, cols)), shape=(n, n))
    M = sp.csr_matrix((Me.ravel(), (rows, cols)), shape=(n, n))
    return BeamBody(name=name, s=s, profile=profile, K=K, M=M, Ke=Ke, phi=phi, empty=empty)


__all__ = ["BeamBody", "beam_body", "mesh_line"]
