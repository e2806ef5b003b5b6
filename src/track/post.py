"""Post-processing: bending moments, ballast pressure and point displacements.

Everything works on generalized displacements ``q`` (one state, shape (n,), or a
history, shape (nt, n)) through the recovery matrix ``u = T q`` of each body
(seed 001 §4: moments from the nodal displacements and rotations and the FE
section properties; pressure = bushing force / tributary sleeper-bottom area).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .model import TrackModel
from .reduction import residual_flexibility


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
    if b.solid:
        # the solid crossing rail: at its output stations, the section deflection (area mean of
        # u_z, as the distributing coupling defines it) and the section moment from the internal
        # forces (track.solid.crossing); its wheel loads act on retained nodes (no correction)
        qb = np.asarray(q)[..., b.gdofs]
        return BodyResponse(coord=b.coords(), w=qb @ b.fom.W.T, moment=qb @ b.fom.Mom.T)
    u = model.full_field(body, q, loads)
    return BodyResponse(coord=b.coords(), w=u[..., 0::2], moment=b.fom.nodal_moments(u))


def body_response_history(model: TrackModel, body: str, q: np.ndarray, load_x: np.ndarray,
                          load_f: np.ndarray) -> BodyResponse:
    """:func:`body_response` along ``body`` for a history of states and point loads, at once.

    The same quantity as ``body_response(model, body, q[t], loads[t])`` step by step (the
    static correction of the truncated modes is linear in the load: one matrix per body,
    ``track.reduction.residual_flexibility``, the correction of a unit load on each dof),
    without a point map per load and step.

    Parameters
    ----------
    q : ndarray, shape (nt, n)
        Generalized displacements.
    load_x : ndarray, shape (nt, m)
        Track coordinate [m] of each point load on ``body``; NaN where the load is on
        another body at that step.
    load_f : ndarray, shape (nt, m)
        Point loads [N], up + (a wheel's contact force enters as ``-Fz``).
    """
    b = model.body(body)
    if b.solid:    # its wheel loads act on retained nodes: no correction (body_response)
        return body_response(model, body, q)
    q = np.asarray(q)
    u = q[:, b.gdofs] @ b.rom.T.T
    on = np.isfinite(load_x)
    if on.any():
        t, i = np.nonzero(on)
        e, w = b.fom.shape_rows(b.local(load_x[t, i]))
        # G (nt, ndof): each step's loads on the full dofs (F times the shape weights of its element)
        G = sp.csr_matrix(((load_f[t, i][:, None] * w).ravel(),
                           (np.repeat(t, 4), (2 * e[:, None] + np.arange(4)).ravel())), shape=(len(q), b.fom.ndof))
        u += G @ residual_flexibility(b.rom)   # symmetric (ndof, ndof), once per body: column j, a unit load on j
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


def strain(model: TrackModel, body: str, coord: float, z: float, q: np.ndarray,
           gauge_length: float = 0.1) -> np.ndarray:
    """Longitudinal engineering strain of a gauge on a body, for state(s) ``q``.

    The gauge of length ``L = gauge_length`` is centred at ``coord`` along the body,
    at height ``z`` above the body's neutral axis (positive up). Its strain is the
    change of its length over ``L`` (seed 000 eq. 1, read as ``eps = u / L``; the
    printed ``(L + u) / L`` is the stretch):

    * beam bodies (rails along x, sleepers along y): the section rotations ``theta``
      (= dw/ds in the Euler-Bernoulli limit) at both gauge ends, from the recovered
      full field, give ``eps = -z (theta(c + L/2) - theta(c - L/2)) / L``, which is
      ``-z M / (E I)`` for a constant moment M (sagging +);
    * the solid crossing rail: the axial displacements of the two surface points at
      that height (on the +y side of the section, the centroid height at the gauge centre
      as neutral axis, both ends at one height),
      ``eps = (u_x(c + L/2) - u_x(c - L/2)) / L``.

    Parameters
    ----------
    model : TrackModel
    body : str
    coord : float
        Gauge centre: x for rails, y for sleepers [m].
    z : float
        Height of the gauge above the neutral axis [m].
    q : ndarray, shape (n,) or (nt, n)
        Generalized displacements.
    gauge_length : float
        [m], > 0; the gauge must lie on the body.

    Returns
    -------
    ndarray, shape () or (nt,)
        Strain [-], tension +.
    """
    return np.asarray(q) @ strain_row(model, body, coord, z, gauge_length)


def strain_row(model: TrackModel, body: str, coord: float, z: float, gauge_length: float = 0.1) -> np.ndarray:
    """The gauge of :func:`strain` as a row on the generalized coordinates, shape (n,).

    ``strain(model, body, coord, z, q) == q @ strain_row(model, body, coord, z)``; the
    virtual strain gauges (:mod:`track.sensors`) use the row directly.
    """
    b = model.body(body)
    L = float(gauge_length)
    c = np.asarray(b.coords())
    if not L > 0.0:
        raise ValueError(f"gauge_length: must be > 0, got {gauge_length!r}")
    lo, hi = coord - 0.5 * L, coord + 0.5 * L
    s0, s1 = (b.origin + b.fom.contact_s[[0, -1]]) if b.solid else (c[0], c[-1])
    if lo < s0 - 1e-9 or hi > s1 + 1e-9:
        raise ValueError(f"gauge {lo:.3f}..{hi:.3f} m is not on {body} ({s0:.3f}..{s1:.3f} m)")
    row = np.zeros(model.n)
    if b.solid:
        row[b.gdofs] = b.fom.gauge_row(b.local(coord), z, L)          # both ends at one height
        return row
    th = []
    for s in (lo, hi):
        e, N = b.fom.rotation_row(b.local(s))
        th.append(N @ b.rom.T[2 * e:2 * e + 4, :])
    row[b.gdofs] = -z * (th[1] - th[0]) / L
    return row
