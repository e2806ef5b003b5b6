"""Post-processing: bending moments, ballast pressure and point displacements.

Everything works on generalized displacements ``q`` (one state, shape (n,), or a
history, shape (nt, n)) through the recovery matrix ``u = T q`` of each body
(seed 001 §4: moments from the nodal displacements and rotations and the FE
section properties; pressure = bushing force / tributary sleeper-bottom area).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import TrackModel


@dataclass
class BodyResponse:
    """Deflection and bending moment along one body.

    Attributes
    ----------
    coord : ndarray, shape (nn,)
        Track coordinate of the nodes: x for rails, y for sleepers [m].
    w : ndarray, shape (..., nn)
        Vertical displacement [m].
    moment : ndarray, shape (..., nn)
        Bending moment [N m], sagging +.
    """

    coord: np.ndarray
    w: np.ndarray
    moment: np.ndarray


def body_response(model: TrackModel, body: str, q: np.ndarray, loads=()) -> BodyResponse:
    """Deflection and bending moment along ``body`` for state(s) ``q``.

    ``loads`` are the point loads ``[(PointMap, F), ...]`` acting at that instant (the
    wheel forces); those on ``body`` add the static correction of the truncated modes,
    without which the moment under a wheel between two seats is clearly low.
    """
    b = model.body(body)
    u = model.full_field(body, q, loads)
    return BodyResponse(coord=b.coords(), w=u[..., 0::2], moment=b.fom.nodal_moments(u))


def all_moments(model: TrackModel, q: np.ndarray, loads=()) -> dict[str, BodyResponse]:
    """:func:`body_response` of every body, keyed by body name."""
    return {b.name: body_response(model, b.name, q, loads) for b in model.bodies}


def ballast_forces(model: TrackModel, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """Force of every ballast bushing on its sleeper [N] (up +), shape (..., nb)."""
    D = model.ballast.dof
    return model.ballast.forces(np.asarray(q)[..., D], None if v is None else np.asarray(v)[..., D])


def ballast_pressure(model: TrackModel, q: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """Sleeper-ballast contact pressure of every bushing [Pa], shape (..., nb)."""
    return ballast_forces(model, q, v) / model.ballast.area


def sleeper_pressure(model: TrackModel, sleeper: int, q: np.ndarray,
                     v: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Lateral positions [m] and contact pressure [Pa] of the bushings under one sleeper."""
    sel = model.ballast.sleeper == sleeper
    return model.ballast.y[sel], ballast_pressure(model, q, v)[..., sel]


def displacement(model: TrackModel, body: str, coord: float, q: np.ndarray) -> np.ndarray:
    """Vertical displacement [m] at a point (track coordinate x or y) for state(s) q."""
    pm = model.point(body, coord)
    return np.asarray(q)[..., pm.gidx] @ pm.weights
