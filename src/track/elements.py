"""Two-node Timoshenko beam element for bending in one plane.

Degrees of freedom per element: ``[w1, th1, w2, th2]`` with ``w`` the deflection
(upward +) [m] and ``th`` the cross-section rotation [rad], positive in the sense of
``dw/ds`` (so that ``th = dw/ds`` in the Euler-Bernoulli limit).

The element uses the interdependent interpolation of Friedman & Kosmatka (1993),
"An improved two-node Timoshenko beam finite element", Computers & Structures
47(3): shape functions that solve the homogeneous static Timoshenko equations, so
the stiffness matrix is exact for nodal loads and the element is free of shear
locking. Mass: consistent translational + rotary inertia from the same shape
functions. Bending moment sign: positive = sagging (tension at the foot),
``M = E I dth/ds``.
"""
from __future__ import annotations

import numpy as np


def shear_parameter(L: float, E: float, G: float, A: float, I: float, kappa: float) -> float:
    """Phi = 12 E I / (kappa G A L^2) [-] of an element of length ``L`` [m]."""
    return 12.0 * E * I / (kappa * G * A * L * L)


def timoshenko_matrices(L, E: float, G: float, A, I, rho: float,
                        kappa: float) -> tuple[np.ndarray, np.ndarray]:
    """Stiffness and mass matrix of one element, or of many at once.

    Parameters
    ----------
    L : float or ndarray
        Element length [m].
    E, G : float
        Young's and shear modulus [Pa].
    A, I : float or ndarray
        Area [m^2] and second moment of area [m^4].
    rho : float
        Density [kg/m^3].
    kappa : float
        Shear coefficient [-].

    Returns
    -------
    K, M : ndarray, shape (..., 4, 4)
        Stiffness [N/m, N, N m] and mass [kg, kg m, kg m^2] matrices; ``...`` is the broadcast
        shape of ``L``, ``A``, ``I`` (none for scalars).
    """
    L, A, I = (np.asarray(v, dtype=float) for v in (L, A, I))
    phi = shear_parameter(L, E, G, A, I, kappa)
    p1 = 1.0 + phi
    L2 = L * L
    K = (E * I / (p1 * _cube(L)))[..., None, None] * _matrix([
        [12.0, 6 * L, -12.0, 6 * L],
        [6 * L, (4 + phi) * L2, -6 * L, (2 - phi) * L2],
        [-12.0, -6 * L, 12.0, -6 * L],
        [6 * L, (2 - phi) * L2, -6 * L, (4 + phi) * L2],
    ], phi.shape)
    f2 = phi * phi
    a = 70 * f2 + 147 * phi + 78
    b = (35 * f2 + 77 * phi + 44) * L / 4
    c = 35 * f2 + 63 * phi + 27
    d = (35 * f2 + 63 * phi + 26) * L / 4
    e = (7 * f2 + 14 * phi + 8) * L2 / 4
    f = (7 * f2 + 14 * phi + 6) * L2 / 4
    M_t = (rho * A * L / (210 * p1 * p1))[..., None, None] * _matrix([
        [a, b, c, -d],
        [b, e, d, -f],
        [c, d, a, -b],
        [-d, -f, -b, e],
    ], phi.shape)
    g = (15 * phi - 3) * L
    r1 = (10 * f2 + 5 * phi + 4) * L2
    r2 = (5 * f2 - 5 * phi - 1) * L2
    M_r = (rho * I / (30 * p1 * p1 * L))[..., None, None] * _matrix([
        [36.0, -g, -36.0, -g],
        [-g, r1, g, r2],
        [-36.0, g, 36.0, g],
        [-g, r2, g, r1],
    ], phi.shape)
    return K, M_t + M_r


def _cube(L: np.ndarray) -> np.ndarray:
    """``L ** 3`` by the C library's pow, element by element: numpy's vectorised power differs from it
    in the last bit for ~5 % of values, and the elements' matrices stay those of one element at a time."""
    return np.array([v ** 3 for v in L.ravel().tolist()]).reshape(L.shape)


def _matrix(rows, shape: tuple) -> np.ndarray:
    """A (..., 4, 4) array from 4 x 4 entries, each a scalar or an array of ``shape``."""
    out = np.empty(shape + (4, 4))
    for i, row in enumerate(rows):
        for j, value in enumerate(row):
            out[..., i, j] = value
    return out


def deflection_shape(xi, L: float, phi: float) -> np.ndarray:
    """Interdependent-interpolation shape functions of the deflection.

    Parameters
    ----------
    xi : float or ndarray, shape (m,)
        Local coordinate s/L in [0, 1].
    L : float
        Element length [m].
    phi : float
        Shear parameter of the element (:func:`shear_parameter`).

    Returns
    -------
    N : ndarray, shape (4,) for a scalar ``xi``, else (m, 4)
        ``w(xi) = N @ [w1, th1, w2, th2]``. The scalar path avoids numpy's per-call
        overhead: the time stepper calls it for every wheel at every step.
    """
    x2 = xi * xi
    x3 = x2 * xi
    c = 1.0 / (1.0 + phi)
    N = (c * (2 * x3 - 3 * x2 - phi * xi + 1 + phi),
         c * L * (x3 - (2 + phi / 2) * x2 + (1 + phi / 2) * xi),
         c * (-2 * x3 + 3 * x2 + phi * xi),
         c * L * (x3 - (1 - phi / 2) * x2 - (phi / 2) * xi))
    return np.stack(N, axis=-1) if np.ndim(xi) else np.array(N)


def rotation_shape(xi, L: float, phi: float) -> np.ndarray:
    """Interdependent-interpolation shape functions of the section rotation.

    The companions of :func:`deflection_shape` (Friedman & Kosmatka 1993): for
    ``phi = 0`` they are its derivatives ``dN/ds``.

    Parameters
    ----------
    xi : float or ndarray, shape (m,)
        Local coordinate s/L in [0, 1].
    L : float
        Element length [m].
    phi : float
        Shear parameter of the element.

    Returns
    -------
    N : ndarray, shape (4,) or (m, 4)
        ``th(xi) = N @ [w1, th1, w2, th2]`` [rad].
    """
    xi = np.asarray(xi, dtype=float)
    c = 1.0 / (1.0 + phi)
    a = 6.0 * c / L * (xi * xi - xi)
    N = (a, c * (3 * xi * xi - (4 + phi) * xi + 1 + phi), -a, c * (3 * xi * xi - (2 - phi) * xi))
    return np.stack(N, axis=-1)
