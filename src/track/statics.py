"""Static equilibrium of the track with the bi-linear ballast.

Solves ``K q + f_b(q) = f_gravity + sum_k F_k r_k`` (``f_b`` the ballast
reaction, active only where a bushing is compressed) by a semi-smooth Newton
method on the contact set: each iteration solves with the tangent of the current
active set; for a piecewise-linear law it terminates when the set repeats, and the
residual is then at round-off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .model import PointMap, TrackModel

MAX_NEWTON = 60  # a few more than the number of contact-set changes seen in practice (< 10)
REL_TOL = 1e-10  # relative residual at which Newton stops (acceptance asks < 1e-6)


@dataclass
class StaticResult:
    """Static equilibrium.

    Attributes
    ----------
    q : ndarray, shape (n,)
        Generalized displacements [m, rad, modal].
    residual : float
        ||K q + f_b - f|| / ||f|| [-].
    iterations : int
        Newton iterations.
    factorizations : int
    active : ndarray of bool
        Ballast bushings in contact.
    """

    q: np.ndarray
    residual: float
    iterations: int
    factorizations: int
    active: np.ndarray


def load_vector(model: TrackModel, loads) -> np.ndarray:
    """Generalized force of point loads ``[(PointMap, F [N, up +]), ...]``."""
    f = np.zeros(model.n)
    for pm, F in loads:
        np.add.at(f, pm.gidx, F * pm.weights)
    return f


def static_equilibrium(model: TrackModel, loads: list[tuple[PointMap, float]] = (),
                       gravity: bool = True) -> StaticResult:
    """Solve the static equilibrium under self-weight and point loads.

    Parameters
    ----------
    model : TrackModel
    loads : list of (PointMap, float)
        Vertical point loads [N] (up +; a wheel load is negative).
    gravity : bool
        Include the self-weight of rails and sleepers.

    Returns
    -------
    StaticResult
    """
    f = load_vector(model, loads) + (model.f_gravity if gravity else 0.0)
    fnorm = max(np.linalg.norm(f), 1e-30)
    bal = model.ballast
    D = bal.dof
    # start from every bushing in contact with its gap closed: a good guess for a loaded track
    active = np.ones(D.size, bool)
    seen = set()
    q = np.zeros(model.n)
    it = nfact = 0
    res = np.inf
    for it in range(1, MAX_NEWTON + 1):
        kb = np.where(active, bal.k, 0.0)
        A = (model.K + sp.csr_matrix((kb, (D, D)), shape=(model.n, model.n))).tocsc()
        rhs = f.copy()
        np.add.at(rhs, D, -kb * bal.gap)  # an active bushing pushes with k (-u - gap)
        q = spla.spsolve(A, rhs)
        nfact += 1
        new_active = bal.active(q[D])
        r = model.K @ q - f
        np.add.at(r, D, -bal.forces(q[D]))
        res = np.linalg.norm(r) / fnorm
        key = new_active.tobytes()
        if np.array_equal(new_active, active) and res < REL_TOL:
            break
        if key in seen:  # cycling between two sets: fall back to the union (more support)
            new_active |= active
        seen.add(key)
        active = new_active
    return StaticResult(q=q, residual=float(res), iterations=it, factorizations=nfact,
                        active=bal.active(q[D]))
