"""Wheel and rail profiles (:mod:`track.profiles`) against the dimensions their standards give.

S1002 (EN 13715; characteristic dimensions of a new wheel per EN 15313: flange height Sh = 28 mm,
flange thickness Sd = 32.5 mm and flange slope qR = 10.8 mm, measured 10 mm above the taping
circle / 2 mm below the flange tip, the back of the flange 70 mm from the taping line, the flank
at 70 degrees). 60E1 head (EN 13674-1): radii R300 / R80 / R13, 72 mm head width, 1:20 sides.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from track.layout import FLANGEWAY, build_layout
from track.params import LayoutParams
from track.profiles import (
    INCLINATION_1_40,
    RAIL_HEADS,
    S1002_SECTIONS,
    ConicalWheel,
    CrossingSections,
    PlainRail,
    RailHead,
    WheelProfile,
    s1002_mm,
)


def _face_point(w: WheelProfile, height: float) -> float:
    """s [m] on the flange face where F = height (root-finding on the face, between -52 and -30 mm)."""
    return brentq(lambda s: float(w.radius_increment(s)) - height, -0.052, -0.030, xtol=1e-12)


# ------------------------------------------------------------------ S1002
def test_s1002_characteristic_dimensions():
    """Sh = 28 mm, Sd = 32.5 mm, qR = 10.8 mm (EN 15313 for a new S1002), back of the flange at
    -70 mm, flank 70 degrees, F(0) = 0. Tolerances: Sh 1e-6 mm (the tip circle 16 + 12 mm);
    Sd 0.01 mm and qR 0.05 mm (the standard states them to 0.1 mm); flank angle 0.01 degree."""
    w = WheelProfile()
    s = np.linspace(-0.0699, 0.06, 260001)
    F = w.radius_increment(s)
    assert np.nanmax(F) * 1e3 == pytest.approx(28.0, abs=1e-6)
    sd = _face_point(w, 0.010) + 0.070
    assert sd * 1e3 == pytest.approx(32.5, abs=0.01)
    qr = _face_point(w, 0.010) - _face_point(w, 0.026)
    assert qr * 1e3 == pytest.approx(10.8, abs=0.05)
    assert float(w.radius_increment(0.0)) == 0.0
    slope = -S1002_SECTIONS[4][3][1]                       # section E: F = -AE - BE s
    assert math.degrees(math.atan(slope)) == pytest.approx(70.0, abs=0.01)
    # back of the flange: vertical tangent at -70 mm (the circle H ends at its leftmost point)
    a, sign, R, c = S1002_SECTIONS[7][3]
    assert -c - R == pytest.approx(-70.0, abs=1e-9)
    assert np.isnan(w.radius_increment(-0.0701)) and np.isnan(w.radius_increment(0.0601))


def test_s1002_sections_join():
    """The eight sections meet: jumps at the bounds < 2e-4 mm (the coefficients are given to 9-10
    significant digits; the largest jump, 1.2e-4 mm, is at -35 mm where the degree-7 polynomial's
    terms reach 1e4 mm)."""
    for lo, hi, *_ in S1002_SECTIONS[1:]:
        left, right = s1002_mm(np.array([hi - 1e-9, hi + 1e-9]))
        assert abs(left - right) < 2e-4, hi


# ------------------------------------------------------------------ wear parameters
@pytest.mark.parametrize("dt", [-0.005, -0.002, 0.003])
def test_flange_thickness_change(dt):
    """The flange face moves by dt at the measuring height (Sd changes by dt); flange height, the
    back of the flange and the tread (s > -20 mm) stay. Tolerances: 1e-6 m from the vectorised
    bisection (50 halvings of 0.15 m: 1e-16 m) and the face root finding; tread exact."""
    w0, w = WheelProfile(), WheelProfile(flange_thickness_change=dt)
    assert _face_point(w, 0.010) - _face_point(w0, 0.010) == pytest.approx(dt, abs=1e-6)
    s = np.linspace(-0.0699, 0.06, 130001)
    assert np.nanmax(w.radius_increment(s)) == pytest.approx(0.028, abs=1e-8)
    back = np.linspace(-0.0699, -0.067, 50)
    np.testing.assert_allclose(w.radius_increment(back), w0.radius_increment(back), atol=1e-12)
    tread = np.linspace(-0.020, 0.06, 200)
    np.testing.assert_allclose(w.radius_increment(tread), w0.radius_increment(tread), atol=1e-12)


@pytest.mark.parametrize("dh", [-0.002, 0.003])
def test_flange_height_change(dh):
    """The tip rises by dh, the profile below the 10 mm measuring height (tread, Sd) is unchanged."""
    w0, w = WheelProfile(), WheelProfile(flange_height=0.028 + dh)
    s = np.linspace(-0.0699, 0.06, 130001)
    assert np.nanmax(w.radius_increment(s)) == pytest.approx(0.028 + dh, abs=1e-8)
    assert _face_point(w, 0.010) == pytest.approx(_face_point(w0, 0.010), abs=1e-9)
    tread = np.linspace(-0.030, 0.06, 200)
    np.testing.assert_allclose(w.radius_increment(tread), w0.radius_increment(tread), atol=1e-15)


def test_hollow_wear_by_hand():
    """cos^2 band: depth d at the centre, d/2 half-way (cos^2(pi/4) = 1/2), 0 outside the band."""
    d, c, hw = 0.002, 0.005, 0.030
    w0, w = WheelProfile(), WheelProfile(hollow_depth=d, hollow_centre=c, hollow_half_width=hw)
    s = np.array([c, c + hw / 2, c - hw / 2, c + hw, c + 1.5 * hw, -0.04])
    diff = w.radius_increment(s) - w0.radius_increment(s)
    np.testing.assert_allclose(diff, [-d, -d / 2, -d / 2, 0.0, 0.0, 0.0], atol=1e-15)



def test_default_hollow_band_covers_the_running_band_on_an_inclined_rail():
    """Consistency check (the hollow's defaults against our own contact geometry, module docstring of
    track.profiles): the default hollow is centred where the centred new S1002 touches a 60E1 head
    inclined 1:40 (within 0.5 mm: the contact table's lateral step is 0.1 mm, the centre is given
    to 1 mm), and the band (centre +- half width) contains every contact point of the wheelset
    offsets within the flange clearance (+-5 mm: (1435 - 1360 - 2 x 32.5) / 2), with its field-side
    edge inside the tread (false flange: S1002 is defined to +60 mm)."""
    from track.contact_geometry import contact_table
    w = WheelProfile()
    head = dataclasses.replace(RAIL_HEADS["60E1"], inclination=INCLINATION_1_40)
    rail = PlainRail(head=head).rail
    y = np.linspace(-0.005, 0.005, 11)
    s = contact_table(w, {"rail": rail}, [0.0], y, reference=rail).data["s"][0, 0]
    assert s[5] == pytest.approx(w.hollow_centre, abs=5e-4)
    assert w.hollow_centre - w.hollow_half_width < s.min() and s.max() < w.hollow_centre + w.hollow_half_width
    assert w.hollow_centre + w.hollow_half_width < 0.060 - 0.020      # a false flange >= 20 mm wide

def test_bad_wear_parameters():
    with pytest.raises(ValueError, match="flange_height"):
        WheelProfile(flange_height=0.06)
    with pytest.raises(ValueError, match="flange_thickness_change"):
        WheelProfile(flange_thickness_change=-0.01)
    with pytest.raises(ValueError, match="hollow_depth"):
        WheelProfile(hollow_depth=-0.001)


def test_measured_table_and_cone():
    """A measured table is interpolated (PCHIP: exact at the points, C1); a cone of conicity g has
    F = -g s (by hand)."""
    s = np.linspace(-0.06, 0.06, 41)
    F = 1e-3 * s1002_mm(1e3 * s)
    w = WheelProfile(table=(s, F))
    np.testing.assert_allclose(w.radius_increment(s), F, atol=1e-15)
    assert float(w.rolling_radius(0.0)) == pytest.approx(0.46 + F[20], abs=1e-15)
    c = ConicalWheel(conicity=0.025)
    np.testing.assert_allclose(c.height(np.array([-0.01, 0.0, 0.02])), [-2.5e-4, 0.0, 5e-4], atol=1e-18)


# ------------------------------------------------------------------ rail heads
@pytest.mark.parametrize("name, width", [("60E1", 0.072), ("54E1", 0.070)])
def test_rail_head_arcs(name, width):
    """Crown R300, then R80, then R13 (curvature of each piece 1/R), tangent (slope continuous to
    the numerical derivative's accuracy, 1e-5) at the joins, sides at 1:20, head width as given,
    symmetric. Curvatures exact (one radius per piece); the slope check by one-sided finite
    differences of step 1e-9 m, relative 1e-4."""
    h = RAIL_HEADS[name]
    u = np.array([0.0, 0.005, 0.015, 0.030])
    z, k = h.height_and_curvature(u)
    np.testing.assert_allclose(k[[0, 1]], 1 / 0.300)
    assert k[2] == pytest.approx(1 / 0.080) and k[3] == pytest.approx(1 / 0.013)
    np.testing.assert_allclose(h.height(-u), z, atol=1e-15)
    p = h._arcs
    joins = [0.300 * math.sin(p["p"][0]), p["c"][1][0] + 0.080 * math.sin(p["p"][1]), p["end"][0]]
    e = 1e-9       # one-sided differences: their error on the R13 arc near 87 deg ~ e/(R cos^3) ~ 6e-4 * 20
    for uj in joins:
        left = (h.height(uj - e) - h.height(uj - 2 * e)) / e
        right = (h.height(uj + 2 * e) - h.height(uj + e)) / e
        assert float(left) == pytest.approx(float(right), abs=1e-4 * max(1.0, abs(float(left))))
    side = (h.height(0.5 * width - 1e-4) - h.height(0.5 * width - 2e-4)) / 1e-4
    assert float(side) == pytest.approx(-20.0, rel=1e-9)          # 1:20 side
    assert np.isinf(h.height(0.5 * width + 1e-6))
    assert float(h.height(0.5 * width)) == pytest.approx(-h.side_depth, abs=1e-12)


def test_60e1_gauge_point():
    """The R13 corner ends just below the gauge measuring height (14 mm below the crown, EN 13848-1):
    the running edge there is 34.7 mm from the head centre; the layout places the running edge half
    the 72 mm head width (36 mm) from the seat centre line, 1.3 mm apart: within 2 mm."""
    h = RAIL_HEADS["60E1"]
    u14 = brentq(lambda u: float(h.height(u)) + 0.014, 0.02, 0.036)
    assert u14 == pytest.approx(0.036, abs=0.002)


def test_inclined_head():
    """A head inclined 1:40 (normal tilted towards the gauge side -u) has the crown slope 1/40 at the
    centre line, the same curvatures, and its highest point at u = +R300 sin(theta) (the crown arc's
    point whose normal is now vertical)."""
    h = RailHead("60E1", width=0.072, inclination=INCLINATION_1_40)
    e = 1e-6
    slope = (h.height(e) - h.height(-e)) / (2 * e)
    assert float(slope) == pytest.approx(1 / 40, rel=1e-6)
    u = np.linspace(-0.02, 0.02, 4001)
    z, k = h.height_and_curvature(u)
    top = u[np.argmax(z)]
    assert top == pytest.approx(0.300 * math.sin(INCLINATION_1_40), abs=2e-5)   # grid 1e-5 m
    np.testing.assert_allclose(k[np.abs(u) < 0.0099], 1 / 0.300)        # the crown: |v| <= 10 mm upright


# ------------------------------------------------------------------ crossing panel
@pytest.fixture(scope="module")
def layout():
    return build_layout(LayoutParams())


def test_crossing_sections_follow_the_layout(layout):
    """Nose width = the layout's separation of L_t and L_d (where >= the 12 mm tip), growing at the
    heading of the curved L_d (radius R + g/2 = 500.7175 m, a curved crossing: heading asin(x / r)):
    from x_tcp + 0.2 to + 0.3 m by 0.1 tan(asin((x_tcp + 0.25) / r)) (midpoint rule; its error
    0.1^3 / (12 r) ~ 2e-7 m); at the TCP that heading is the layout's crossing angle (1e-12 rad);
    the wing rail's edge is the separation plus the flangeway behind the throat, 0 ahead of it."""
    cs = CrossingSections.from_layout(layout)
    x0 = layout.x_tcp
    r = 500.0 + 1.435 / 2
    assert math.asin(x0 / r) == pytest.approx(layout.crossing_angle, abs=1e-12)
    w1 = float(cs.nose_width(x0 + 0.3)) - float(cs.nose_width(x0 + 0.2))
    assert w1 == pytest.approx(0.1 * math.tan(math.asin((x0 + 0.25) / r)), abs=3e-7)
    assert float(cs.nose_width(x0 + 0.1)) == 0.0              # 7.6 mm: narrower than the tip
    assert float(cs.wing_edge(x0 - 2.0)) == 0.0
    assert float(cs.wing_edge(x0 + 0.3)) == pytest.approx(float(cs.separation(x0 + 0.3)) + FLANGEWAY, abs=1e-15)


def test_nose_section_by_hand(layout):
    """Nose at 30 mm width: the 60E1 head with its gauge corner at eta = 0 cut by the mirrored head
    at eta = 30 mm: a ridge at eta = 15 mm whose height is the head's at u = 15 - 36 = -21 mm (on the
    R80 shoulder arc: centre and radius from the head's own construction, computed here by hand),
    the same at mirrored points, absent outside [0, w] (no design drop); a drop d (1 - w/full_width) and a nose
    wear of 2 mm lower it by those amounts. Tolerances: round-off (1e-12 m), the far edge 1e-7 m
    (the width is 30 mm to the root finding's 1e-13 m; at the vertical side that moves the height by
    20 * 1e-13; kept loose)."""
    cs = CrossingSections.from_layout(layout, tip_drop=0.0)
    x = brentq(lambda x: float(cs.separation(x)) - 0.030, layout.x_tcp, layout.x_tcp + 1.0, xtol=1e-13)
    eta = np.array([-1e-4, 0.0, 0.010, 0.015, 0.020, 0.030, 0.0301])
    z, k = cs.nose(x, eta)
    c2 = RAIL_HEADS["60E1"]._arcs["c"][1]                  # R80 centre (u, z) of the right half
    ridge = c2[1] + math.sqrt(0.080 ** 2 - (0.021 - c2[0]) ** 2)
    assert z[3] == pytest.approx(ridge, abs=1e-12) and k[3] == pytest.approx(1 / 0.080)
    assert z[2] == pytest.approx(z[4], abs=1e-12) and z[1] == pytest.approx(z[5], abs=1e-7)
    assert z[2] < z[3] and z[1] < z[2]
    assert np.isinf(z[0]) and np.isinf(z[6])
    worn = CrossingSections.from_layout(layout, nose_wear_stations=(0.0, 1.0), nose_wear=(0.002, 0.002),
                                        tip_drop=0.003, full_width=0.05)
    assert float(worn.nose(x, 0.015)[0]) == pytest.approx(ridge - 0.002 - 0.003 * (1 - 0.030 / 0.05), abs=1e-12)


def test_wear_shape_functions_are_smooth(layout):
    """Wear through stations is C1 and exact at the stations (PCHIP), constant outside."""
    cs = CrossingSections.from_layout(layout, wing_wear_stations=(0.0, 0.3, 0.8),
                                      wing_wear=(0.0, 0.0015, 0.0005))
    x0 = layout.x_tcp
    ww = cs._wear("wing", np.array([x0, x0 + 0.3, x0 + 0.8, x0 + 5.0, x0 - 1.0]))
    np.testing.assert_allclose(ww, [0.0, 0.0015, 0.0005, 0.0005, 0.0], atol=1e-15)
    x = x0 + np.linspace(0.0, 0.8, 8001)
    d1 = np.diff(cs._wear("wing", x)) / np.diff(x)
    assert np.max(np.abs(np.diff(d1))) < 2e-4          # no slope jumps (C1): slope change per 0.1 mm step


def test_plain_rail_vectorised():
    """Arrays in, arrays out: a (3, 5) grid of (x, eta) gives (3, 5) heights; the head's running edge
    at eta = 0 (centre at half the head width)."""
    r = PlainRail()
    x = np.linspace(0, 1, 3)[:, None]
    eta = np.linspace(0.0, 0.072, 5)[None, :]
    z, k = r.rail(x, eta)
    assert z.shape == (3, 5) and k.shape == (3, 5)
    assert float(z[0, 2]) == 0.0
