"""Elliptic Hertz contact (:mod:`track.hertz`) against closed forms and an independent quadrature.

References: Johnson, *Contact Mechanics*, Cambridge 1985: sphere on a plane eqs. (4.22)-(4.23);
elliptic contact §4.2 eqs. (4.36)-(4.41). The independent reference for the elliptic cases is
:func:`test_crossing_geometry.hertz_by_quadrature`: Hertz's potential integrals by numerical
quadrature, no elliptic integrals (the code under test uses ``ellipkm1``/``ellipe``).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_crossing_geometry import hertz_by_quadrature

from track.hertz import axis_ratio, equivalent_modulus, hertz_constant, hertz_patch, relative_curvatures

E, NU = 210e9, 0.3
E_STAR = E / (2.0 * (1.0 - NU * NU))   # two equal steels, by hand (Johnson eq. (4.28))


def test_equivalent_modulus_by_hand():
    """E* of two steels 210 GPa / 0.3 = 115.38 GPa; steel on an aluminium (70 GPa, 0.33) disc by hand."""
    assert equivalent_modulus() == pytest.approx(E_STAR, rel=1e-15)
    assert equivalent_modulus(210e9, 0.3, 70e9, 0.33) == pytest.approx(
        1.0 / (0.91 / 210e9 + (1 - 0.33 ** 2) / 70e9), rel=1e-15)


@pytest.mark.parametrize("R, P", [(0.46, 100e3), (0.01, 10.0), (2.0, 1e6)])
def test_sphere_on_plane_closed_form(R, P):
    """Sphere of radius R on a plane: A = B = 1/(2R); a = b = (3PR/(4E*))^(1/3), p0 = 3P/(2 pi a^2),
    delta = a^2/R, C = (4/3) E* sqrt(R) (Johnson eqs. (4.22)-(4.23)). Tolerance 1e-9 relative: the
    circle is reached through the near-circle series of the shape equation (error < 1e-9 by its
    O(e^4) remainder), the rest is round-off."""
    p = hertz_patch(1 / (2 * R), 1 / (2 * R), P, E_STAR)
    a = (3 * P * R / (4 * E_STAR)) ** (1 / 3)
    assert float(p.a) == pytest.approx(a, rel=1e-9)
    assert float(p.b) == pytest.approx(a, rel=1e-9)
    assert float(p.p0) == pytest.approx(3 * P / (2 * math.pi * a * a), rel=1e-9)
    assert float(p.delta) == pytest.approx(a * a / R, rel=1e-9)
    assert float(p.C) == pytest.approx(4 / 3 * E_STAR * math.sqrt(R), rel=1e-9)
    assert float(p.e) == pytest.approx(0.0, abs=1e-4)   # e = sqrt(4/3 (B/A - 1)) ~ 0 (series)


def test_equal_crossed_cylinders_are_a_sphere_on_a_plane():
    """Two cylinders of equal radius R crossed at right angles: A = B = 1/(2R), the circle of a
    sphere R on a plane (Johnson §4.2, the classic example). Closed form, tolerance 1e-9 as above."""
    R, P = 0.3, 50e3
    # cylinder 1 (axis along y): curvature 1/R along x; cylinder 2 (axis along x): 1/R along y
    A, B = relative_curvatures(R, 0.0, 1 / R)
    p = hertz_patch(A, B, P, E_STAR)
    a = (3 * P * R / (4 * E_STAR)) ** (1 / 3)
    assert float(p.a) == pytest.approx(a, rel=1e-9) and float(p.b) == pytest.approx(a, rel=1e-9)
    assert float(p.C) == pytest.approx(4 / 3 * E_STAR * math.sqrt(R), rel=1e-9)


@pytest.mark.parametrize("R1, R2", [(0.46, 0.30), (0.46, 0.08), (0.46, 0.013), (0.30, 0.46), (0.5, 0.0005)])
def test_crossed_cylinders_against_quadrature(R1, R2):
    """Two crossed cylinders of radii R1 (axis along y: curvature along x) and R2 (axis along x):
    A = 1/(2 R1), B = 1/(2 R2); wheel 0.46 m on the 60E1 head radii R300, R80, R13, the swapped
    case, and a slender ellipse (B/A = 1000). Against Hertz's integrals by quadrature (independent
    route, see module docstring). Tolerance 1e-7 relative: the quadrature's rel. 1e-12 and its
    root finding on the axis ratio (xtol 1e-14) leave < 1e-9; 1e-7 leaves margin for the slender case."""
    P = 80e3
    A, B = 1 / (2 * R1), 1 / (2 * R2)
    p = hertz_patch(A, B, P, E_STAR)
    ref = hertz_by_quadrature(A, B, P, E_STAR)          # a >= b there; ours: a along x
    major, minor = max(float(p.a), float(p.b)), min(float(p.a), float(p.b))
    assert major == pytest.approx(ref["a"], rel=1e-7)
    assert minor == pytest.approx(ref["b"], rel=1e-7)
    assert float(p.p0) == pytest.approx(ref["p0"], rel=1e-7)
    assert float(p.delta) == pytest.approx(ref["delta"], rel=1e-7)
    assert float(p.C) == pytest.approx(ref["C"], rel=1e-7)
    # the major axis lies along the direction of smaller relative curvature
    assert (float(p.a) >= float(p.b)) == (A <= B)


@pytest.mark.parametrize("ratio", [1.5, 2.0, 3.0, 5.0])
def test_axis_ratio_against_johnsons_approximation(ratio):
    """Johnson (1985, §4.2) approximates the axis ratio by b/a ~ (A/B)^(2/3) for moderate ratios.
    Exact (ours) and approximation differ by 0.02 % at B/A = 1.5 rising to 1.2 % at 5 (computed);
    tolerance 1.5 %: the approximation's own error at B/A = 5, plus margin."""
    assert float(axis_ratio(ratio)) == pytest.approx(ratio ** (-2 / 3), rel=0.015)


def test_load_scaling():
    """Hertz scaling: a, b, p0 ~ P^(1/3), delta ~ P^(2/3), C independent of P (Johnson eqs. (4.40)).
    Tolerance 1e-12: exact powers, round-off only."""
    A, B = 1 / 0.92, 1 / 0.6
    p1, p8 = hertz_patch(A, B, 10e3), hertz_patch(A, B, 80e3)
    assert float(p8.a / p1.a) == pytest.approx(2.0, rel=1e-12)
    assert float(p8.b / p1.b) == pytest.approx(2.0, rel=1e-12)
    assert float(p8.p0 / p1.p0) == pytest.approx(2.0, rel=1e-12)
    assert float(p8.delta / p1.delta) == pytest.approx(4.0, rel=1e-12)
    assert float(p8.C) == pytest.approx(float(p1.C), rel=1e-12)


def test_consistency_of_the_outputs():
    """Consistency check (relations between outputs of the same code): total load of the Hertz
    pressure (2/3) pi a b p0 = P, and C delta^1.5 = P, over an array of curvature pairs; the
    stiffness constant equals hertz_constant; swapping A and B swaps a and b."""
    A = np.array([0.5, 1.087, 1.087, 20.0])
    B = np.array([0.5, 1.667, 38.5, 1.0])
    P = 75e3
    p = hertz_patch(A, B, P)
    np.testing.assert_allclose(2 / 3 * np.pi * p.a * p.b * p.p0, P, rtol=1e-12)
    np.testing.assert_allclose(p.C * p.delta ** 1.5, P, rtol=1e-12)
    np.testing.assert_allclose(hertz_constant(A, B), p.C, rtol=1e-14)
    q = hertz_patch(B, A, P)
    np.testing.assert_allclose(q.a, p.b, rtol=1e-14)
    np.testing.assert_allclose(q.b, p.a, rtol=1e-14)


def test_non_hertzian_is_nan():
    """A hollow tread tighter than the head (B <= 0) or a zero curvature sum has no Hertz solution:
    NaN, not a number that looks valid."""
    A, B = relative_curvatures(0.46, -1 / 0.25, 1 / 0.30)     # hollow R250 wheel on the R300 crown
    assert float(B) < 0
    p = hertz_patch(A, B, 1e5)
    assert np.isnan(float(p.C)) and np.isnan(float(p.a))
    assert np.isnan(float(hertz_constant(0.0, 1.0)))


def test_relative_curvatures_by_hand():
    """Wheel r = 0.46 m, contact angle 0.2 rad, hollow tread R1000 (-1/1 m), rail R80 flank:
    A = cos(0.2)/(2*0.46), B = (-1 + 12.5)/2 (Meusnier for the wheel's parallel circle)."""
    A, B = relative_curvatures(0.46, -1.0, 1 / 0.08, 0.0, 0.2)
    assert float(A) == pytest.approx(math.cos(0.2) / 0.92, rel=1e-15)
    assert float(B) == pytest.approx(5.75, rel=1e-15)
