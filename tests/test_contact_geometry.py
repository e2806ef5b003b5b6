"""Contact geometry tables (:mod:`track.contact_geometry`): closed forms of issue 15's acceptance
(a) a conical wheel on a wing rail diverging from its path at 1:N drops with slope gamma/N,
(c) a cylindrical wheel on the 60E1 head contacts at the crown; the Hertz constant of that contact
against an independent quadrature; and the crossing transfer of the default panel.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from test_crossing_geometry import hertz_by_quadrature

from track.contact_geometry import ContactTable, contact_table, crossing_table, taping_line_offset, transfer
from track.hertz import equivalent_modulus
from track.layout import NOSE_WIDTH_AT_TRANSFER, build_layout
from track.params import LayoutParams
from track.profiles import INCLINATION_1_40, ConicalWheel, CrossingSections, PlainRail, RailHead, WheelProfile


def _diverging_wing(N: float, x0: float = 0.0) -> CrossingSections:
    """A straight wing rail whose running edge leaves the wheel's path at 1:N from x0 (no nose)."""
    return CrossingSections(x_tcp=x0, separation=lambda x: (np.asarray(x, dtype=float) - x0) / N,
                            flangeway=0.0, wing_end=1e9, tip_width=1e9)


@pytest.mark.parametrize("gamma, N", [(0.05, 10.0), (1 / 40, 12.0), (1 / 15, 15.0)])
def test_cone_on_diverging_wing_drops_with_gamma_over_N(gamma, N):
    """Acceptance (a). A cone F(s) = -gamma s on a rail head that moves outward by (x - x0)/N: the
    contact point moves with the head (the same point of the head, where its slope is gamma) and
    the wheel's radius there falls by gamma (x - x0)/N: z(x) = z(x0) - gamma (x - x0)/N exactly,
    for every lateral offset. Checked by a straight-line fit over 1 m. Tolerances: slope 1e-7
    relative, residual 1e-9 m: the parabolic refinement of the sampled maximum (0.1 mm samples)
    leaves O(d_eta^3 d''') ~ 1e-12 m on the R80 shoulder arc where the contact sits."""
    x = np.linspace(0.0, 1.0, 101)
    y = np.array([-0.004, 0.0, 0.004])
    tab = contact_table(ConicalWheel(conicity=gamma, half_width=0.25), {"wing": _diverging_wing(N).wing}, x, y)
    for j in range(y.size):
        z = tab.data["z"][0, :, j]
        slope, icpt = np.polyfit(x, z, 1)
        assert slope == pytest.approx(-gamma / N, rel=1e-7)
        assert np.max(np.abs(z - (slope * x + icpt))) < 1e-9
        # the contact follows the head: eta moves by (x - x0)/N (1e-6 m: the refinement's position error)
        eta = tab.data["eta"][0, :, j]
        np.testing.assert_allclose(eta - eta[0], x / N, atol=1e-6)


def test_cylinder_on_60e1_contacts_at_the_crown():
    """Acceptance (c). A cylinder on the upright 60E1 head touches its highest point, the crown
    centre (half the head width outside the running edge), whatever the wheelset's lateral offset;
    z = 0 there (the head's top is the reference); rolling radius r0; A = 1/(2 r0); lateral relative
    curvature B = 1/(2 R300) of the arc, taken (track.contact_geometry.PATCH_HALF_WIDTH) from the
    least-squares parabola through the gap over +-h, h = 3.5 mm: for the arc
    z = -u^2/(2R) - u^4/(8R^3) - ... that is B = (1 + 3 h^2 / (14 R^2)) / (2R) (the u^4 term's
    projection on {1, u^2} over a uniform window: 6 h^2 / 7), 2.9e-5 above 1/(2R). Tolerances: eta
    1e-9 m (the crown is symmetric about the sample at its top, the refinement exact there), A
    round-off, B 2e-6 relative (the 71 samples' sums against the integrals: O(1/71) of the 2.9e-5
    correction; the u^6 term, (h/R)^4 = 2e-8), C the same propagated (C ~ B^(<1))."""
    y = np.linspace(-0.006, 0.006, 7)
    cyl = ConicalWheel(conicity=0.0)
    tab = contact_table(cyl, {"rail": PlainRail().rail}, [0.0], y, reference=PlainRail().rail)
    np.testing.assert_allclose(tab.data["eta"][0, 0], 0.036, atol=1e-9)
    np.testing.assert_allclose(tab.data["z"][0, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(tab.data["radius"][0, 0], 0.46, rtol=1e-15)
    R, h = 0.3, 0.0035
    B = (1 + 3 * h * h / (14 * R * R)) / (2 * R)
    np.testing.assert_allclose(tab.data["B"][0, 0], B, rtol=2e-6)
    np.testing.assert_allclose(tab.data["A"][0, 0], 1 / 0.92, rtol=1e-12)
    # Hertz constant of the contact against Hertz's integrals by quadrature (independent route)
    ref = hertz_by_quadrature(1 / 0.92, B, 1e5, equivalent_modulus())["C"]
    np.testing.assert_allclose(tab.data["C"][0, 0], ref, rtol=2e-6)


def test_cylinder_on_inclined_head():
    """A cylinder on the 60E1 head inclined 1:40 touches where the crown's normal is vertical:
    u = R300 sin(theta) = 7.50 mm outside the head centre (closed form); 1e-8 m (refinement)."""
    head = RailHead("60E1", width=0.072, inclination=INCLINATION_1_40)
    rail = PlainRail(head=head).rail
    tab = contact_table(ConicalWheel(0.0), {"rail": rail}, [0.0], [0.0, 0.002], reference=rail)
    np.testing.assert_allclose(tab.data["eta"][0, 0], 0.036 + 0.300 * math.sin(INCLINATION_1_40), atol=1e-8)


def test_s1002_on_plain_rail_is_the_reference():
    """Consistency check: the centred S1002 wheel on the plain 60E1 rail is the reference (z = 0);
    with the wheelset offset the contact moves on the wheel, and the rolling radius is r0 + F(s)
    at the contact's s (the wheel's own function). Taping line 32.5 mm outside the running edge."""
    w = WheelProfile()
    assert taping_line_offset(1.435) == pytest.approx(0.0325, abs=1e-15)
    tab = contact_table(w, {"rail": PlainRail().rail}, [0.0, 1.0], [-0.004, 0.0, 0.004])
    assert tab.data["z"][0, 0, 1] == pytest.approx(0.0, abs=1e-15)
    s = tab.data["s"][0, 0]
    np.testing.assert_allclose(tab.data["radius"][0, 0], 0.46 + w.radius_increment(s), rtol=1e-15)
    assert s[2] < s[1] < s[0]          # wheelset outward: the contact moves towards the flange


def test_lookup_is_bilinear():
    """lookup() returns the grid values at grid points and the bilinear mean at cell centres."""
    x, y = np.array([0.0, 1.0, 2.0]), np.array([-1.0, 1.0])
    z = np.arange(6, dtype=float).reshape(1, 3, 2) ** 2
    tab = ContactTable(x=x, y=y, surfaces=("rail",), data={"z": z}, z_ref=0.0)
    assert tab.lookup("z", 1.0, 1.0)[0] == z[0, 1, 1]
    assert tab.lookup("z", 0.5, 0.0)[0] == pytest.approx(z[0, :2, :].mean())
    assert tab.lookup("z", 9.0, 9.0)[0] == z[0, 2, 1]           # clipped to the grid


@pytest.fixture(scope="module")
def panel():
    lay = build_layout(LayoutParams())
    x = np.arange(lay.x_tcp - 0.2, lay.x_tcp + 0.8, 0.0025)
    return lay, x


def test_default_crossing_transfers_at_the_design_width(panel):
    """The nose-top design lowering (track.profiles.CrossingSections defaults) was chosen so that the
    centred new S1002 wheel transfers at the layout's 20 mm nose width: regression check of that
    design point (0.3 mm: the table's x step of 2.5 mm times the nose's growth 1:13). The wheel
    falls on the wing rail before (the 1:15 field-side section of S1002 on the flaring wing:
    about gamma/N = (1/15)/13.2 = 5.1 mrad) and rises on the nose after."""
    lay, x = panel
    cs = CrossingSections.from_layout(lay)
    tr = transfer(crossing_table(WheelProfile(), cs, x, [0.0]))
    assert not tr["tip_impact"]
    assert float(cs.separation(tr["x"])) == pytest.approx(NOSE_WIDTH_AT_TRANSFER, abs=3e-4)
    assert tr["slope_wing"] == pytest.approx(-(1 / 15) / (1 / math.tan(lay.crossing_angle)), rel=0.05)
    assert tr["slope_nose"] > 0 and tr["eta_nose"] < tr["eta_wing"]


def test_nose_height_loss_moves_the_transfer(panel):
    """Consistency check (two paths of ours): a uniform nose height loss d lowers the nose's z by d
    exactly (the contact point does not move under a vertical shift), so the worn table's transfer
    is where the new table's z_nose - d meets z_wing; later and deeper than the new one."""
    lay, x = panel
    new = crossing_table(WheelProfile(), CrossingSections.from_layout(lay), x, [0.0])
    d = 0.001
    worn = crossing_table(WheelProfile(), CrossingSections.from_layout(lay, nose_wear_stations=(0.0,),
                                                                       nose_wear=(d,)), x, [0.0])
    fin = np.isfinite(new.data["z"][1, :, 0])
    np.testing.assert_allclose(worn.data["z"][1, fin, 0], new.data["z"][1, fin, 0] - d, atol=1e-15)
    shifted = ContactTable(new.x, new.y, new.surfaces,
                           {"z": np.stack([new.data["z"][0], new.data["z"][1] - d]), "eta": new.data["eta"]}, 0.0)
    t_new, t_worn, t_pred = transfer(new), transfer(worn), transfer(shifted)
    assert t_worn["x"] == pytest.approx(t_pred["x"], abs=1e-12)
    assert t_worn["x"] > t_new["x"]
    zw = new.data["z"][0, :, 0]
    assert np.interp(t_worn["x"], x, zw) < np.interp(t_new["x"], x, zw)     # the wheel falls further


def test_bad_grid():
    with pytest.raises(ValueError, match="evenly spaced"):
        contact_table(ConicalWheel(), {"rail": PlainRail().rail}, [0.0, 0.1, 0.3], [0.0])


def test_equivalent_lateral_curvature_of_a_ridge():
    """The lateral relative curvature B is that of the least-squares parabola through the gap over the
    patch's half width h (track.contact_geometry.PATCH_HALF_WIDTH, 3.5 mm): for a flat wheel on a
    ridge of slopes +-p (a kink, where a point curvature is undefined) the projection of -p |u| on
    {1, u^2} over a uniform window gives B = 15 p / (16 h). Tolerance 2 %: the window is centred on
    the sample nearest the ridge (here 0.03 mm off it, O(d_eta / (2 h)) = 1.4 %) and its 71 samples'
    sums approximate the integrals to O(1/71)."""
    p, h = 0.2, 0.0035
    e0 = taping_line_offset() + 3e-5

    def ridge(x, eta):
        z = -p * np.abs(np.asarray(eta, dtype=float) - e0) + 0.0 * np.asarray(x, dtype=float)
        return z, np.zeros(z.shape)

    tab = contact_table(ConicalWheel(conicity=0.0), {"ridge": ridge}, [0.0], [0.0], reference=ridge)
    assert tab.data["eta"][0, 0, 0] == pytest.approx(e0, abs=5e-5)          # at the ridge (one sample)
    assert tab.data["B"][0, 0, 0] == pytest.approx(15 * p / (16 * h), rel=0.02)


def test_nose_hertz_constant_is_continuous_along_the_crossing(panel):
    """The nose's Hertz constant changes smoothly as the contact moves along the default crossing
    (new S1002, offsets -3 .. +3 mm, from the transfer to 0.3 m behind it): by under 5 % between
    table nodes 5 mm apart (measured 1.5 %; the nose widens 0.42 mm per step). With the point
    curvature of the heads' arcs it jumped x2.4 (B 32.6 -> 0.5 1/m) 0.305 m behind the theoretical
    point, where the narrow nose's ridge crossed the R13 / R80 tangent points of its two heads, and
    the peak wheel force of the profile runs sat on that step (README "Wheel–rail profiles")."""
    lay = panel[0]
    x = lay.x_tcp + np.arange(0.24, 0.56, 0.005)
    y = np.array([-0.003, 0.0, 0.003])
    tab = crossing_table(WheelProfile(), CrossingSections.from_layout(lay), x, y)
    c = tab.data["C_vertical"][1]
    assert np.isfinite(c).all()
    assert np.max(np.abs(np.diff(np.log(c), axis=0))) < np.log(1.05)
