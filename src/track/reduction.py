"""Craig–Bampton reduction of one body: ``reduce`` and ``reconstruct``.

The full-order model (``fom``: K, M over n dofs) is split into retained boundary
dofs B (interface: rail seats, bushing nodes, joints) and interior dofs I. The
reduced coordinates are ``q = [u_B, eta]``: the physical boundary displacements
and the amplitudes of the fixed-interface normal modes, and

    u = T q,   T = [[I, 0], [Psi, Phi]]   (rows reordered to the fom's dof order)

with the constraint modes ``Psi = -K_II^{-1} K_IB`` and the fixed-interface modes
``K_II Phi = M_II Phi Omega^2`` (mass-normalised). Reduced matrices
``K_r = T^T K T``, ``M_r = T^T M T``.

Loads between retained nodes (a wheel between two rail seats) are represented only
through the kept fixed-interface modes, which misses the static part of the
truncated ones: the displacement under the load is a little stiff and the bending
moment under it clearly low. :func:`static_correction` adds that part back
(mode-acceleration / residual-flexibility correction, exact in statics):

    u_I += (K_II^{-1} - Phi Omega^{-2} Phi^T) f_I

Cut-off: fixed-interface modes are kept up to ``f_modes`` [Hz]. The model's
cut-off f_cut is chosen so that ``f_modes = mode_factor * f_cut`` (default 3):
with the constraint modes exact in statics, eigenfrequencies of the reduced body
below f_cut are then within 1 % of the full model (verified in
tests/test_reduction.py, which also shows the convergence as modes are added).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as la
import scipy.sparse as sp


@dataclass
class ReducedBody:
    """Reduced-order model (``rom``) of one body.

    Attributes
    ----------
    K, M : ndarray, shape (nr, nr)
        Reduced stiffness and mass, ``nr = nb + nm``.
    T : ndarray, shape (n, nr)
        Recovery matrix: full dofs ``u = T @ q``.
    boundary : ndarray of int, shape (nb,)
        Full-model dof index of each retained boundary coordinate (``q[:nb]``).
    mode_freqs : ndarray, shape (nm,)
        Fixed-interface mode frequencies [Hz].
    """

    K: np.ndarray
    M: np.ndarray
    T: np.ndarray
    boundary: np.ndarray
    mode_freqs: np.ndarray
    interior: np.ndarray = None
    modes_I: np.ndarray = None
    K_II_factor: tuple = None
    # element -> its 4x4 block of the residual flexibility [m/N] (track.model.Body.residual_block): kept
    # with the reduced body, which a process reuses across builds (the variants of a diagnosis), not with
    # the Body of one build (2376 blocks of 4200 were computed again in six void variants' runs, 8 ms a run)
    residual_blocks: dict = field(default_factory=dict, repr=False, compare=False)
    # the compiled step's element data of the body (track.kernel.element_rows), kept here for the same reason
    kernel_rows: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def nb(self) -> int:
        return self.boundary.size

    @property
    def nr(self) -> int:
        return self.K.shape[0]


def craig_bampton(K, M, boundary: np.ndarray, f_modes: float | None = None,
                  n_modes: int | None = None) -> ReducedBody:
    """Reduce a body by Craig–Bampton.

    Parameters
    ----------
    K, M : array_like or sparse, shape (n, n)
        Full stiffness and mass matrices.
    boundary : array_like of int, shape (nb,)
        Retained dofs (their order is the order of ``q[:nb]``).
    f_modes : float, optional
        Keep fixed-interface modes with frequency <= ``f_modes`` [Hz].
    n_modes : int, optional
        Keep exactly this many fixed-interface modes (overrides ``f_modes``).

    Returns
    -------
    ReducedBody
    """
    K = K.toarray() if sp.issparse(K) else np.asarray(K, dtype=float)
    M = M.toarray() if sp.issparse(M) else np.asarray(M, dtype=float)
    n = K.shape[0]
    B = np.asarray(boundary, dtype=int)
    if np.unique(B).size != B.size:
        raise ValueError("boundary dofs must be unique")
    mask = np.ones(n, bool)
    mask[B] = False
    I = np.flatnonzero(mask)
    K_II = K[np.ix_(I, I)]
    M_II = M[np.ix_(I, I)]
    K_II_factor = la.cho_factor(K_II)
    Psi = -la.cho_solve(K_II_factor, K[np.ix_(I, B)])
    if n_modes is not None:
        nm = min(int(n_modes), I.size)
        w2, Phi = la.eigh(K_II, M_II, subset_by_index=(0, nm - 1)) if nm > 0 else (np.zeros(0), np.zeros((I.size, 0)))
    elif f_modes is not None and I.size > 0:
        w2max = (2 * np.pi * f_modes) ** 2
        w2, Phi = la.eigh(K_II, M_II, subset_by_value=(-np.inf, w2max))
    else:
        w2, Phi = np.zeros(0), np.zeros((I.size, 0))
    nb, nm = B.size, w2.size
    T = np.zeros((n, nb + nm))
    T[B, np.arange(nb)] = 1.0
    T[np.ix_(I, np.arange(nb))] = Psi
    T[np.ix_(I, nb + np.arange(nm))] = Phi
    Kr = T.T @ K @ T
    Mr = T.T @ M @ T
    Kr = 0.5 * (Kr + Kr.T)
    Mr = 0.5 * (Mr + Mr.T)
    return ReducedBody(K=Kr, M=Mr, T=T, boundary=B, mode_freqs=np.sqrt(np.maximum(w2, 0)) / (2 * np.pi),
                       interior=I, modes_I=Phi, K_II_factor=K_II_factor)


def residual_flexibility(rom: ReducedBody) -> np.ndarray:
    """The full residual flexibility matrix ``R`` (n, n) [m/N], computed once per body.

    ``R[i, j]`` is the static correction displacement at dof i for a unit load at dof j
    (:func:`static_correction`); rows and columns of boundary dofs are zero.
    """
    R = getattr(rom, "_R", None)
    if R is None:
        n = rom.T.shape[0]
        R = np.zeros((n, n))
        I = rom.interior
        if I is not None and I.size:
            w2 = (2 * np.pi * rom.mode_freqs) ** 2
            RI = la.cho_solve(rom.K_II_factor, np.eye(I.size)) - (rom.modes_I / w2) @ rom.modes_I.T
            R[np.ix_(I, I)] = 0.5 * (RI + RI.T)
        rom._R = R
    return R


def element_residual(rom: ReducedBody, dofs: np.ndarray) -> np.ndarray:
    """Block of the residual flexibility for loads on ``dofs`` (e.g. one element's 4 dofs).

    ``R[i, j]`` is the static correction displacement at ``dofs[i]`` for a unit load
    at ``dofs[j]`` (see :func:`static_correction`); shape (k, k) [m/N].
    """
    return residual_flexibility(rom)[np.ix_(dofs, dofs)]


def reconstruct(rom: ReducedBody, q: np.ndarray) -> np.ndarray:
    """Full displacement field(s) ``u = T q``; ``q`` shape (..., nr) -> (..., n)."""
    return np.asarray(q) @ rom.T.T


def static_correction(rom: ReducedBody, f: np.ndarray) -> np.ndarray:
    """Static displacement that the truncated modes miss for loads ``f`` on the full dofs.

    Parameters
    ----------
    rom : ReducedBody
    f : ndarray, shape (n,) or (n, k)
        Loads on the full-model dofs [N, N m]; loads on boundary dofs need no correction.

    Returns
    -------
    ndarray, shape like ``f``
        ``u_corr`` (zero at boundary dofs): add to ``T q`` for the full field.
    """
    f = np.asarray(f, dtype=float)
    u = np.zeros_like(f)
    I = rom.interior
    if I is None or I.size == 0:
        return u
    fI = f[I]
    w2 = (2 * np.pi * rom.mode_freqs) ** 2
    eta = (rom.modes_I.T @ fI) / (w2[:, None] if fI.ndim == 2 else w2)
    u[I] = la.cho_solve(rom.K_II_factor, fI) - rom.modes_I @ eta
    return u
