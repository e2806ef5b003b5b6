"""Tests of the layout generator ``track.layout.build_layout``.

The reference geometry is written out here in closed form, independently of the
root finding and line functions in ``track.layout``:

* diverging line at normal offset d (towards the curve centre), left hand:
  r = R - d, curve for x <= r sin(a): y = R - sqrt(r^2 - x^2); straight beyond:
  y = R - r cos(a) + (x - r sin(a)) / n, with a = atan(1/n);
* curved crossing: L_d (d = -g/2) meets y = g/2 at x_tcp = sqrt(2 R g), crossing
  angle asin(x_tcp / (R + g/2));
* straight crossing: x_tcp = x_e + (g/2 - y_e) n with x_e = (R + g/2) sin(a),
  y_e = R - (R + g/2) cos(a), crossing angle a.
"""
import dataclasses
import math

import numpy as np
import pytest

from track.layout import (
    BEARER_OVERHANG,
    CHECK_HEAD_WIDTH,
    CROSSING_FRONT_SEPARATION,
    CROSSING_REAR_SEPARATION,
    CROSSING_SEAT_MIN_WIDTH,
    FLANGEWAY,
    NOSE_WIDTH_AT_TRANSFER,
    RAIL_HEAD_WIDTH,
    build_layout,
)
from track.params import LayoutParams

G = 1.435
HW = RAIL_HEAD_WIDTH["60E1"] / 2  # half head width: running edge -> rail centreline

# Positions come from brentq (xtol 1e-12) or direct evaluation of the same closed
# forms: 1e-9 m leaves three orders of magnitude of margin over the root tolerance
# plus round-off of x ~ 50 m (eps * 50 ~ 1e-14 m).
TOL_X = 1e-9
# Lateral positions are evaluated in closed form at one x: round-off only (y ~ 2 m).
TOL_Y = 1e-9

CURVED = [("1:12", 500.0), ("1:15", 760.0)]
HANDS = ["left", "right"]


def turnout(crossing="1:12", radius=500.0, **kw) -> LayoutParams:
    return LayoutParams(type="turnout", crossing=crossing, radius=radius, **kw)


def y_div(x, R, n, d, sign=1.0):
    """Closed-form diverging line at offset d (module docstring), world frame."""
    a = math.atan(1.0 / n)
    r = R - d
    if x <= r * math.sin(a):
        y = R - math.sqrt(r * r - x * x)
    else:
        y = R - r * math.cos(a) + (x - r * math.sin(a)) / n
    return sign * y


def nvalue(crossing):
    return float(crossing.split(":")[1])


# ------------------------------------------------------------------ crossing geometry


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("hand", HANDS)
def test_tcp_and_angle_of_curved_crossing(crossing, R, hand):
    """x_tcp = sqrt(2 R g) and theta = asin(x_tcp / (R + g/2)) for a crossing in the curve."""
    lay = build_layout(turnout(crossing, R, hand=hand))
    x_ref = math.sqrt(2 * R * G)
    # 1e-6 m as asked for; brentq converges to 1e-12 m, so this is a loose bound.
    assert abs(lay.x_tcp - x_ref) < 1e-6
    # the TCP really lies in the curve, i.e. before the curve end of L_d
    assert x_ref < (R + G / 2) * math.sin(math.atan(1 / nvalue(crossing)))
    # angle: d(theta)/dx = 1/sqrt(r^2 - x^2) ~ 2e-3 /m, so a 1e-9 m error in x gives
    # ~2e-12 rad; 1e-10 rad covers it with round-off of asin.
    assert abs(lay.crossing_angle - math.asin(x_ref / (R + G / 2))) < 1e-10
    # the curved crossing is flatter than its nominal 1:n
    assert 1 / math.tan(lay.crossing_angle) > nvalue(crossing)


def test_tcp_of_straight_crossing():
    """1:9 R190: the curve ends before L_d reaches g/2, so the crossing is straight."""
    R, n = 190.0, 9.0
    lay = build_layout(turnout("1:9", R))
    a = math.atan(1 / n)
    xe = (R + G / 2) * math.sin(a)
    ye = R - (R + G / 2) * math.cos(a)
    assert ye < G / 2  # straight crossing indeed
    assert abs(lay.x_tcp - (xe + (G / 2 - ye) * n)) < TOL_X
    # in the straight part the angle is the end tangent exactly (round-off only)
    assert abs(lay.crossing_angle - a) < 1e-12


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("hand", HANDS)
def test_through_running_edges_at_half_gauge(crossing, R, hand):
    """Both through running edges lie exactly at +-g/2 (plan lines and seats)."""
    lay = build_layout(turnout(crossing, R, hand=hand))
    s = 1.0 if hand == "left" else -1.0
    for name, y_edge in [("stock_through", -G / 2), ("closure_through", G / 2),
                         ("rear_through", G / 2)]:
        # constants evaluated without arithmetic on x: only round-off of g/2
        np.testing.assert_allclose(lay.line(name).y, s * y_edge, rtol=0, atol=1e-15)
        seats_y = np.array([st.y for st in lay.rail(name).seats])
        np.testing.assert_allclose(seats_y - s * np.sign(y_edge) * HW, s * y_edge, rtol=0,
                                   atol=1e-15)


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("hand", HANDS)
def test_diverging_gauge_normal_to_curve(crossing, R, hand):
    """From L_d, a step g along the normal to the route lands on stock_div's edge.

    Checked on the plan lines: the distance from each point of the L_d polylines to the
    stock_div polyline is g. The polylines are chords of step <= 0.1 m: the sag
    h^2 / (8 r) <= 0.01 / (8 * 499) = 2.5e-6 m bounds the error; tolerance 5e-6 m.
    """
    lay = build_layout(turnout(crossing, R, hand=hand))
    sd = lay.line("stock_div")
    P = np.column_stack([sd.x, sd.y])
    for name in ("closure_div", "rear_div"):
        ln = lay.line(name)
        inner = (ln.x > sd.x[0] + 0.5) & (ln.x < sd.x[-1] - 0.5)  # foot of the normal on sd
        for q in np.column_stack([ln.x, ln.y])[inner][::7]:
            a, b = P[:-1], P[1:]
            t = np.clip(np.einsum("ij,ij->i", q - a, b - a) / np.einsum("ij,ij->i", b - a, b - a),
                        0, 1)
            dist = np.min(np.linalg.norm(a + t[:, None] * (b - a) - q, axis=1))
            assert abs(dist - G) < 5e-6
    # the same with the analytic geometry: step g along the normal (exact to round-off)
    geo = lay.geometry()
    for x in np.linspace(lay.rails[0].x_start, lay.rails[0].x_end, 17):
        phi = geo.diverging_heading(x, -G / 2)
        y = geo.diverging_y(x, -G / 2)
        sgn = 1.0 if hand == "left" else -1.0
        qx, qy = x - sgn * G * math.sin(phi), y + sgn * G * math.cos(phi)
        assert abs(geo.diverging_y(qx, G / 2) - qy) < TOL_Y


@pytest.mark.parametrize("crossing,R", CURVED)
def test_diverging_end_angle(crossing, R):
    """Behind the curve end, the diverging lines run at atan(1/n)."""
    n = nvalue(crossing)
    lay = build_layout(turnout(crossing, R))
    for name in ("rear_div", "stock_div"):
        ln = lay.line(name)
        assert ln.x[-2] > (R + G / 2) * math.sin(math.atan(1 / n))  # in the straight part
        heading = math.atan2(ln.y[-1] - ln.y[-2], ln.x[-1] - ln.x[-2])
        # slope of a 0.1 m chord from differences of y ~ 2 m: round-off ~ 1e-15/0.1
        assert abs(heading - math.atan(1 / n)) < 1e-12
    # and the heading is continuous at the curve end (tangent transition)
    geo = lay.geometry()
    xe = R * math.sin(math.atan(1 / n))
    assert abs(geo.diverging_heading(xe - 1e-9) - math.atan(1 / n)) < 1e-10  # slope ~ 1/R


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("route", ["through", "diverging"])
def test_right_hand_mirrors_left(crossing, R, route):
    """A right-hand layout is the left-hand one with y -> -y (and sides swapped)."""
    left = build_layout(turnout(crossing, R, hand="left", route=route))
    right = build_layout(turnout(crossing, R, hand="right", route=route))
    assert left.x_tcp == right.x_tcp and left.x_transition == right.x_transition
    for a, b in zip(left.rails, right.rails):
        assert a.name == b.name and (a.x_start, a.x_end) == (b.x_start, b.x_end)
        assert [s.sleeper for s in a.seats] == [s.sleeper for s in b.seats]
        # the construction mirrors with an exact sign flip: equal to round-off
        np.testing.assert_allclose([s.y for s in a.seats], [-s.y for s in b.seats], atol=1e-12)
    for a, b in zip(left.sleepers, right.sleepers):
        assert abs(a.y_start + b.y_end) < 1e-12 and abs(a.y_end + b.y_start) < 1e-12
    swap = {"left": "right", "right": "left"}
    assert right.crossing_side == swap[left.crossing_side]
    for side in ("left", "right"):
        assert [s.body for s in left.running[side]] == [s.body for s in right.running[swap[side]]]


# ------------------------------------------------------------------ seats and sleepers

def centreline(name, x, R, n, sign):
    """Closed-form seat position of a rail body (world frame)."""
    through = {"stock_through": -G / 2 - HW, "closure_through": G / 2 + HW,
               "rear_through": G / 2 + HW,
               "check_through": -G / 2 + FLANGEWAY + CHECK_HEAD_WIDTH / 2}
    div = {"stock_div": G / 2 + HW, "closure_div": -G / 2 - HW, "rear_div": -G / 2 - HW,
           "check_div": G / 2 - FLANGEWAY - CHECK_HEAD_WIDTH / 2}
    if name in through:
        return sign * through[name]
    if name in div:
        return y_div(x, R, n, div[name], sign)
    assert name == "crossing"
    return 0.5 * (sign * G / 2 + y_div(x, R, n, -G / 2, sign))


@pytest.mark.parametrize("crossing,R", CURVED + [("1:9", 190.0)])
@pytest.mark.parametrize("hand", HANDS)
def test_seats_on_analytic_lines(crossing, R, hand):
    """Every seat's y equals the closed-form centreline at its sleeper's x."""
    n, sign = nvalue(crossing), (1.0 if hand == "left" else -1.0)
    lay = build_layout(turnout(crossing, R, hand=hand))
    xs = {sl.index: sl.x for sl in lay.sleepers}
    for r in lay.rails:
        for st in r.seats:
            assert st.x == xs[st.sleeper]
            assert abs(st.y - centreline(r.name, st.x, R, n, sign)) < TOL_Y
            if r.kind == "crossing":
                sep = abs(y_div(st.x, R, n, -G / 2) - G / 2)
                assert abs(st.width - max(sep, CROSSING_SEAT_MIN_WIDTH)) < TOL_Y


@pytest.mark.parametrize("crossing,R", CURVED)
def test_sleepers_span_seats_and_grow(crossing, R):
    """Bearers reach 0.5 m beyond their outermost seats, in 0.1 m steps, and lengthen
    towards the crossing (the diverging stock rail moves away from the through route)."""
    p = turnout(crossing, R)
    lay = build_layout(p)
    ys = {sl.index: [] for sl in lay.sleepers}
    for r in lay.rails:
        for st in r.seats:
            ys[st.sleeper].append(st.y)
    lengths = np.array([sl.length for sl in lay.sleepers])
    for sl in lay.sleepers:
        lo = min(min(ys[sl.index]) - BEARER_OVERHANG, -p.sleeper_length / 2)
        hi = max(max(ys[sl.index]) + BEARER_OVERHANG, p.sleeper_length / 2)
        # 1e-12 m: the rounding is computed in floating point from the seat positions
        assert sl.y_start <= lo + 1e-12 and sl.y_end >= hi - 1e-12
        # multiple of 0.1 m, up to round-off of the sum of ~50 steps
        assert abs(sl.length / 0.1 - round(sl.length / 0.1)) < 1e-9
        # rounding adds less than one step to the needed span
        assert sl.length < hi - lo + 0.1 + 1e-9
    assert np.all(np.diff(lengths) >= -1e-9)  # non-decreasing up to round-off
    assert lengths[-1] > lengths[0] + 1.0  # stock_div moves out by > 0.5 m over 24 m


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("hand", HANDS)
def test_long_panels_end_their_bearers_where_two_sleepers_fit(crossing, R, hand):
    """Far behind the crossing each track gets its own sleeper: a position is split exactly where two
    sleepers of ``sleeper_length``, centred on the through centreline (y = 0) and on the diverging one
    (closed form y_div(x, d = 0)), no longer overlap, i.e. y_div >= sleeper_length; the pieces are those
    two sleepers, every seat lies on one with at least BEARER_OVERHANG to its ends, and the bearers
    ahead of the split stay under 5.2 m (two sleepers' length plus the rounding step)."""
    p = turnout(crossing, R, hand=hand, sleepers=120, transition_sleeper=25)
    lay = build_layout(p)
    sign, n, half = (1.0 if hand == "left" else -1.0), nvalue(crossing), p.sleeper_length / 2
    seats = {sl.index: [] for sl in lay.sleepers}
    for r in lay.rails:
        for st in r.seats:
            seats[st.sleeper].append(sign * st.y)          # canonical frame (left hand)
    split = []
    for sl in lay.sleepers:
        yd = y_div(sl.x, R, n, 0.0)
        # no position within 1 mm of the boundary here (checked: the nearest is 4.4 mm off), so the
        # comparison of the two computations of y_div cannot flip on round-off
        assert abs(yd - 2 * half) > 1e-3
        if yd < 2 * half:
            # unsplit: from -half to the diverging stock rail's seat (yd + g/2 + hw) plus the overhang,
            # < 3 half + 1.2535 m = 5.15 m, rounded up to the 0.1 m step: <= two sleepers' length
            assert sl.gap == () and sl.length <= 4 * half + 1e-9
            continue
        split.append(sl.index)
        pieces = sorted(tuple(sorted((sign * a, sign * b))) for a, b in sl.pieces)
        ref = [(-half, half), (yd - half, yd + half)]
        assert np.allclose(pieces, ref, atol=TOL_Y, rtol=0), (sl.index, pieces, ref)
        for y in seats[sl.index]:
            assert any(a + BEARER_OVERHANG - TOL_Y <= y <= b - BEARER_OVERHANG + TOL_Y for a, b in pieces), y
    assert split and split == list(range(split[0], p.sleepers))     # from the first split to the panel end
    assert split[0] > p.transition_sleeper + 10                        # well behind the crossing


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("t", [None, 15, 25])
def test_transition_sleeper_at_transfer_point(crossing, R, t):
    """The transition sleeper sits where the nose (L_d - L_t) is 20 mm wide."""
    p = turnout(crossing, R, transition_sleeper=t)
    lay = build_layout(p)
    j = p.sleepers // 2 + 1 if t is None else t
    sl = lay.sleepers[j]
    assert sl.index == j
    assert abs(sl.x - lay.x_transition) < TOL_X  # x_0 + j h reproduces it to round-off
    n = nvalue(crossing)
    assert abs(y_div(lay.x_transition, R, n, -G / 2) - G / 2 - NOSE_WIDTH_AT_TRANSFER) < TOL_Y
    assert lay.x_transition > lay.x_tcp
    spacing = np.diff([s.x for s in lay.sleepers])
    np.testing.assert_allclose(spacing, p.sleeper_spacing, rtol=0, atol=1e-12)


@pytest.mark.parametrize("crossing,R", CURVED)
@pytest.mark.parametrize("route", ["through", "diverging"])
def test_bodies_joints_and_running(crossing, R, route):
    """Every body has >= 2 seats, joints sit at the crossing-block ends, and each wheel
    side's running segments cover (-inf, inf) without gaps or overlaps."""
    n = nvalue(crossing)
    lay = build_layout(turnout(crossing, R, route=route))
    names = {r.name for r in lay.rails}
    assert names == {"stock_through", "stock_div", "closure_through", "closure_div", "crossing",
                     "rear_through", "rear_div", "check_through", "check_div"}
    for r in lay.rails:
        assert len(r.seats) >= 2
        assert all(r.x_start <= st.x < r.x_end for st in r.seats)
    # each sleeper is seated once per body it lies under (no double seat at a joint)
    for a, b in [("closure_through", "crossing"), ("crossing", "rear_through")]:
        assert not {s.sleeper for s in lay.rail(a).seats} & {s.sleeper for s in lay.rail(b).seats}
    cf, cr = lay.joints
    assert set(cf.ends) == {("closure_through", "end"), ("closure_div", "end"), ("crossing", "start")}
    assert set(cr.ends) == {("crossing", "end"), ("rear_through", "start"), ("rear_div", "start")}
    assert cf.x < lay.x_tcp < cr.x
    assert abs(G / 2 - y_div(cf.x, R, n, -G / 2) - CROSSING_FRONT_SEPARATION) < TOL_Y
    assert abs(y_div(cr.x, R, n, -G / 2) - G / 2 - CROSSING_REAR_SEPARATION) < TOL_Y
    for name, end in cf.ends + cr.ends:
        r = lay.rail(name)
        assert (r.x_end if end == "end" else r.x_start) == (cf.x if (name, end) in cf.ends else cr.x)
    for side, segs in lay.running.items():
        assert segs[0].x0 == -math.inf and segs[-1].x1 == math.inf
        assert all(a.x1 == b.x0 for a, b in zip(segs[:-1], segs[1:]))
        for seg in segs:
            assert seg.body in names
    leg = "through" if route == "through" else "div"
    side = lay.crossing_side
    assert side == ("left" if route == "through" else "right")  # left-hand turnout
    assert [s.body for s in lay.running[side]] == [f"closure_{leg}", "crossing", f"rear_{leg}"]
    other = "right" if side == "left" else "left"
    assert [s.body for s in lay.running[other]] == [f"stock_{leg}"]
    assert lay.running_body(side, lay.x_tcp) == "crossing"


def test_crossing_profile_stations():
    """Cast-crossing section: 2x at x_cf and TCP, 3x from TCP + 0.5 m to TCP + 1.8 m,
    2x at x_cr (stations in body coordinates)."""
    lay = build_layout(turnout())
    cr = lay.rail("crossing")
    s = np.array([lay.x_tcp, lay.x_tcp + 0.5, lay.x_tcp + 1.8, cr.x_start, cr.x_end]) - cr.x_start
    A, I = cr.profile.at(s)
    base = cr.profile.base
    # interpolation at the stations returns the station values: round-off only
    np.testing.assert_allclose(A / base.A, [2, 3, 3, 2, 2], rtol=1e-12)
    np.testing.assert_allclose(I / base.I, [2, 3, 3, 2, 2], rtol=1e-12)


def test_plan_lines_wings_and_nose():
    """Wing rails keep a flangeway beside the other route behind the throat; the nose
    V closes at the TCP."""
    lay = build_layout(turnout())
    geo = lay.geometry()
    wt, wd, nose = lay.line("wing_through"), lay.line("wing_div"), lay.line("nose")
    behind = wt.x > lay.x_tcp
    yd = geo.diverging_y(wt.x[behind], -G / 2)
    np.testing.assert_allclose(wt.y[behind] - yd, FLANGEWAY, atol=1e-12)  # round-off
    np.testing.assert_allclose(wd.y[behind], G / 2 - FLANGEWAY, atol=1e-12)
    assert wt.x[0] == lay.joints[0].x and nose.x[0] == lay.x_tcp
    assert abs(nose.y[0] - G / 2) < 1e-12 and abs(nose.y[-1] - G / 2) < 1e-12
    assert {ln.kind for ln in lay.lines} == {"stock", "closure", "wing", "nose", "check", "rail"}


# ------------------------------------------------------------------ plain track

def test_plain_layout():
    p = LayoutParams(type="plain", sleeper_spacing=0.65, sleepers=12)
    lay = build_layout(p)
    assert [r.name for r in lay.rails] == ["rail_left", "rail_right"]
    assert lay.x_tcp is None and lay.crossing_side is None and lay.crossing_angle is None
    assert lay.x_transition is None and lay.joints == ()
    for r, sgn in zip(lay.rails, (1, -1)):
        assert r.kind == "rail"
        # x_j = j * h, computed from an integer counter: round-off only
        assert abs(r.x_start + 0.325) < 1e-12 and abs(r.x_end - (11 * 0.65 + 0.325)) < 1e-12
        assert [s.sleeper for s in r.seats] == list(range(12))
        np.testing.assert_allclose([s.y for s in r.seats], sgn * (G / 2 + HW), atol=1e-15)
    for j, sl in enumerate(lay.sleepers):
        assert abs(sl.x - 0.65 * j) < 1e-12
        assert (sl.y_start, sl.y_end) == (-1.3, 1.3)
    assert [s.body for s in lay.running["left"]] == ["rail_left"]
    assert [s.body for s in lay.running["right"]] == ["rail_right"]


# ------------------------------------------------------------------ bad parameters

@pytest.mark.parametrize("change,name", [
    (dict(type="slab"), "type"),
    (dict(crossing="12"), "crossing"),
    (dict(crossing="1:1"), "crossing"),
    (dict(crossing="1:x"), "crossing"),
    (dict(crossing="2:12"), "crossing"),
    (dict(radius=0.0), "radius"),
    (dict(radius=-500.0), "radius"),
    (dict(sleeper_spacing=0.0), "sleeper_spacing"),
    (dict(sleeper_spacing=-0.6), "sleeper_spacing"),
    (dict(sleepers=3), "sleepers"),
    (dict(sleepers=10.5), "sleepers"),
    (dict(transition_sleeper=40), "transition_sleeper"),
    (dict(transition_sleeper=-1), "transition_sleeper"),
    (dict(route="straight"), "route"),
    (dict(hand="up"), "hand"),
    (dict(rail="49E1"), "rail"),
    (dict(gauge=0.0), "gauge"),
    (dict(sleeper_length=-1.0), "sleeper_length"),
    (dict(sleepers=200, transition_sleeper=150), "sleepers"),  # panel starts before x = 0
    (dict(transition_sleeper=1), "transition_sleeper"),  # closure rails get < 2 seats
    (dict(sleepers=40, transition_sleeper=39), "transition_sleeper"),  # rear rails < 2 seats
])
def test_bad_parameters(change, name):
    with pytest.raises(ValueError, match=name):
        build_layout(dataclasses.replace(turnout(), **change))


# ------------------------------------------------------------------ plot

@pytest.mark.parametrize("kw", [dict(), dict(hand="right", route="diverging")])
def test_plot_layout(tmp_path, kw):
    """The plan view draws one rectangle per sleeper and one line per plan line."""
    import matplotlib
    matplotlib.use("Agg")
    from orchestrator.results.plots_layout import plot_layout

    lay = build_layout(turnout(**kw))
    fig = plot_layout(lay)
    ax = fig.axes[0]
    assert len(ax.patches) == len(lay.sleepers)
    xlo, xhi = ax.get_xlim()
    assert xlo <= lay.sleepers[0].x and xhi >= lay.sleepers[-1].x
    fig.savefig(tmp_path / "layout.png")
    assert (tmp_path / "layout.png").stat().st_size > 0
    import matplotlib.pyplot as plt
    plt.close(fig)
