"""Receptance (frequency response) of the track linearized about a static state.

``H(f) = r^T (K_t - w^2 M + i w C_t)^{-1} r`` [m/N] for a unit vertical force at
the material point ``r`` (direct receptance), with the ballast tangent (stiffness
and damping of bushings in contact) taken at the static equilibrium.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse.linalg as spla

from .model import PointMap, TrackModel


def receptance(model: TrackModel, point: PointMap, freqs: np.ndarray, q_static: np.ndarray,
               response: PointMap | None = None) -> np.ndarray:
    """Receptance at ``freqs``.

    Parameters
    ----------
    model : TrackModel
    point : PointMap
        Excitation point (unit vertical force).
    freqs : ndarray, shape (nf,)
        Frequencies [Hz].
    q_static : ndarray, shape (n,)
        Linearization state (static equilibrium).
    response : PointMap, optional
        Response point (default: the excitation point, direct receptance).

    Returns
    -------
    ndarray of complex, shape (nf,)
        Displacement per unit force [m/N].
    """
    K, C = model.tangent(q_static)
    M = model.M
    resp = point if response is None else response
    f = np.zeros(model.n, dtype=complex)
    f[point.gidx] += point.weights
    out = np.empty(len(freqs), dtype=complex)
    for k, fr in enumerate(np.asarray(freqs, float)):
        w = 2 * np.pi * fr
        A = (K - (w * w) * M + (1j * w) * C).tocsc()
        x = spla.spsolve(A, f)
        out[k] = resp.weights @ x[resp.gidx]
    return out
