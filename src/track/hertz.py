"""Elliptic Hertz contact from the principal curvatures at the contact point.

Two bodies touching at a point, with the gap between their surfaces near it

    h(x, y) = A x^2 + B y^2,   A = (k1x + k2x) / 2,   B = (k1y + k2y) / 2,

(``k`` the principal curvatures of each body along the rolling direction x and across it, y,
convex positive, the axes of both bodies aligned as they are for a wheel on a rail without yaw),
pressed together by a load P, touch on an ellipse of semi-axes ``a`` (along x) and ``b``
(along y) with the Hertz pressure ``p0 sqrt(1 - x^2/a^2 - y^2/b^2)``. With ``e`` the eccentricity
of the ellipse (``e^2 = 1 - (minor/major)^2``) and ``K(e)``, ``E(e)`` the complete elliptic
integrals of the first and second kind, Johnson (*Contact Mechanics*, 1985, §4.2, eqs. (4.39),
(4.40)) gives, for ``A <= B`` (major axis along x, ``a >= b``):

    B / A = ((a/b)^2 E(e) - K(e)) / (K(e) - E(e))            (shape: solved for e)
    a^3 = 3 P (K(e) - E(e)) / (2 pi e^2 A E*),  b = a sqrt(1 - e^2)
    p0 = 3 P / (2 pi a b),   delta = p0 b K(e) / E*          (approach of distant points)
    1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2

so ``P = C delta^(3/2)`` with the load-independent normal stiffness constant

    C = (2 pi / 3) E* sqrt((K - E) / A) / (e K^(3/2)),

which for ``A = B = 1/(2R)`` is the sphere's ``(4/3) E* sqrt(R)``. ``A > B`` is the same with the
axes swapped. The shape equation is solved by bisection on ``log(b/a)`` with ``K`` from
``scipy.special.ellipkm1`` (accurate for slender ellipses), vectorised over arrays of curvatures.
No approximation is made beyond Hertz's (half-spaces, small patch, frictionless, elastic).
Where ``A <= 0`` or ``B <= 0`` (conformal or saddle contact, e.g. a hollow-worn tread tighter than
the rail head) the Hertz solution does not exist and every output is NaN.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ellipe, ellipkm1

E_STEEL = 210e9     # Pa, Young's modulus of wheel and rail steel (DESIGN.md §7)
NU_STEEL = 0.3      # -, Poisson's ratio of steel
_BISECT_STEPS = 64  # halvings of the log(b/a) bracket [-LOG_K_MIN, 0]: 34 / 2^64 ~ 2e-18, round-off
_LOG_K_MIN = -34.0  # b/a >= 1.7e-15: beyond any curvature ratio met (B/A up to ~1e20)
_NEAR_ONE = 1e-9    # B/A - 1 below this: the circle (the shape equation's 0/0 limit), error < 1e-9


def equivalent_modulus(E1: float = E_STEEL, nu1: float = NU_STEEL, E2: float = E_STEEL,
                       nu2: float = NU_STEEL) -> float:
    """Contact modulus ``E* = 1 / ((1 - nu1^2)/E1 + (1 - nu2^2)/E2)`` [Pa] (Johnson eq. (4.28))."""
    return 1.0 / ((1.0 - nu1 ** 2) / E1 + (1.0 - nu2 ** 2) / E2)


@dataclass(frozen=True)
class HertzPatch:
    """Hertz contact of given curvatures (arrays broadcast from the inputs).

    Attributes
    ----------
    a, b : ndarray
        Semi-axes along the rolling direction x and across it [m] (at the given load).
    p0 : ndarray
        Peak pressure [Pa].
    delta : ndarray
        Normal approach [m].
    C : ndarray
        Normal stiffness constant of ``P = C delta^1.5`` [N/m^1.5] (load independent).
    e : ndarray
        Eccentricity of the ellipse [-].
    """

    a: np.ndarray
    b: np.ndarray
    p0: np.ndarray
    delta: np.ndarray
    C: np.ndarray
    e: np.ndarray


def _shape_ratio(logk: np.ndarray) -> np.ndarray:
    """``B/A`` of a patch with axis ratio ``k = b/a = exp(logk) <= 1`` (module docstring)."""
    k2 = np.exp(2.0 * logk)
    K = ellipkm1(k2)                 # K at m = 1 - k^2, accurate for small k
    E = ellipe(1.0 - k2)
    return (E / k2 - K) / (K - E)


def axis_ratio(ratio) -> np.ndarray:
    """Minor/major axis ratio ``k = sqrt(1 - e^2)`` of the Hertz ellipse for the curvature ratio
    ``ratio = max(A, B) / min(A, B) >= 1`` (array in, array out).

    Bisection on ``log k`` in ``[-34, 0]`` (the ratio is monotone in k); near the circle
    (``ratio - 1 < 1e-9``) the series ``ratio = 1 + 3 e^2 / 4 + O(e^4)`` of the shape equation.
    """
    r = np.asarray(ratio, dtype=float)
    lo = np.full(r.shape, _LOG_K_MIN)
    hi = np.zeros(r.shape)
    for _ in range(_BISECT_STEPS):
        mid = 0.5 * (lo + hi)
        big = _shape_ratio(mid) > r          # too slender: the answer is rounder (larger k)
        lo = np.where(big, mid, lo)
        hi = np.where(big, hi, mid)
    k = np.exp(0.5 * (lo + hi))
    near = r - 1.0 < _NEAR_ONE
    series = np.sqrt(np.clip(1.0 - (r - 1.0) / 0.75, 0.0, 1.0))
    return np.where(near, series, k)


def _k_minus_e_over_e2(k: np.ndarray) -> np.ndarray:
    """``(K(e) - E(e)) / e^2`` with ``e^2 = 1 - k^2``; the series ``pi/4 (1 + 3 e^2 / 8)`` near the
    circle (e^2 < 1e-6: remainder O(e^4) < 1e-12 relative)."""
    k2 = k * k
    m = 1.0 - k2
    small = m < 1e-6
    msafe = np.where(small, 0.5, m)
    direct = (ellipkm1(k2) - ellipe(msafe)) / msafe
    return np.where(small, 0.25 * np.pi * (1.0 + 0.375 * m), direct)


def hertz_patch(A, B, P, E_star: float | None = None) -> HertzPatch:
    """Semi-axes, peak pressure, approach and stiffness constant of a Hertz contact.

    Parameters
    ----------
    A, B : array_like
        Relative curvatures along the rolling direction x and across it [1/m]
        (:func:`relative_curvatures`); must be > 0 (else NaN outputs).
    P : array_like
        Normal load [N] (> 0).
    E_star : float, optional
        Contact modulus [Pa]; default two steels (:func:`equivalent_modulus`).

    Returns
    -------
    HertzPatch
        Arrays of the broadcast shape of ``A, B, P``.
    """
    Es = equivalent_modulus() if E_star is None else float(E_star)
    A, B, P = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (A, B, P)))
    ok = (A > 0) & (B > 0) & np.isfinite(A) & np.isfinite(B)
    As, Bs = np.where(ok, A, 1.0), np.where(ok, B, 1.0)
    lo_c, hi_c = np.minimum(As, Bs), np.maximum(As, Bs)      # major axis along the smaller curvature
    k = axis_ratio(hi_c / lo_c)
    e2 = 1.0 - k * k
    kme = _k_minus_e_over_e2(k)                                  # (K - E) / e^2
    K = ellipkm1(k * k)
    major = (3.0 * P * kme / (2.0 * np.pi * lo_c * Es)) ** (1.0 / 3.0)
    minor = k * major
    p0 = 3.0 * P / (2.0 * np.pi * major * minor)
    delta = p0 * minor * K / Es
    C = (2.0 * np.pi / 3.0) * Es * np.sqrt(kme / lo_c) / K ** 1.5   # sqrt((K-E)/A)/e = sqrt(kme/A)
    a = np.where(As <= Bs, major, minor)
    b = np.where(As <= Bs, minor, major)
    nan = np.nan
    return HertzPatch(a=np.where(ok, a, nan), b=np.where(ok, b, nan), p0=np.where(ok, p0, nan),
                      delta=np.where(ok, delta, nan), C=np.where(ok, C, nan),
                      e=np.where(ok, np.sqrt(e2), nan))


def hertz_constant(A, B, E_star: float | None = None) -> np.ndarray:
    """Normal stiffness constant ``C`` of ``P = C delta^1.5`` [N/m^1.5] for relative curvatures
    ``A``, ``B`` [1/m] (load independent; :func:`hertz_patch`)."""
    return hertz_patch(A, B, 1.0, E_star).C


def relative_curvatures(wheel_radius, wheel_lateral_curvature=0.0, rail_lateral_curvature=0.0,
                        rail_longitudinal_curvature=0.0, contact_angle=0.0) -> tuple[np.ndarray, np.ndarray]:
    """Relative curvatures ``A`` (rolling direction) and ``B`` (lateral) of a wheel on a rail [1/m].

    Parameters
    ----------
    wheel_radius : array_like
        Rolling radius at the contact point [m].
    wheel_lateral_curvature : array_like
        Curvature of the wheel profile across the tread at the contact point [1/m]: convex
        (bulging towards the rail) positive, hollow (concave, worn) negative; 0 for a cone.
    rail_lateral_curvature : array_like
        Curvature of the rail head profile at the contact point [1/m], convex positive
        (60E1 crown: 1/0.3).
    rail_longitudinal_curvature : array_like
        Curvature of the rail along x [1/m] (0 for a straight rail; a vertical irregularity's
        curvature otherwise), convex positive.
    contact_angle : array_like
        Angle of the common normal to the vertical at the contact point [rad] (0 on a tread;
        up to ~1.2 on a flange).

    Returns
    -------
    A, B : ndarray
        ``A = (cos(gamma)/r + k_rail_x) / 2``, ``B = (k_wheel_y + k_rail_y) / 2`` [1/m]. The wheel is
        a surface of revolution: its principal curvatures are the profile's own (meridian, exact)
        and ``cos(gamma) / r`` along the parallel circle (Meusnier: the circle's curvature 1/r
        projected on the surface normal). The lateral curvatures are those of the profiles in the
        y-z section, which is the contact-normal section's to first order in the small yaw.
    """
    r = np.asarray(wheel_radius, dtype=float)
    A = 0.5 * (np.cos(np.asarray(contact_angle, dtype=float)) / r
               + np.asarray(rail_longitudinal_curvature, dtype=float))
    B = 0.5 * (np.asarray(wheel_lateral_curvature, dtype=float) + np.asarray(rail_lateral_curvature, dtype=float))
    return np.broadcast_arrays(A, B)
