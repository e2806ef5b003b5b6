"""Bi-linear ballast with voids: law, static equilibrium, residual."""
import numpy as np

from track.ballast import Ballast
from track.model import build_track
from track.params import BallastParams, LayoutParams, TrackParams, VoidSpec
from track.post import ballast_forces
from track.statics import static_equilibrium


def test_law_compression_only_with_gap():
    b = Ballast(dof=np.zeros(1, int), k=np.array([1e7]), c=np.array([1e4]), gap=np.array([1e-3]),
                sleeper=np.zeros(1, int), y=np.zeros(1), area=np.array([0.1]))
    u = np.array([[0.0], [-0.5e-3], [-1e-3], [-1.5e-3], [+1e-3]])
    F = b.forces(u)[:, 0]
    assert np.array_equal(F, [0, 0, 0, 1e7 * 0.5e-3, 0])
    # the damper cannot pull: a fast upward velocity while in contact gives zero, not tension
    assert b.forces(np.array([-1.2e-3]), np.array([1.0]))[0] == 0.0
    assert b.pressure(np.array([-2e-3]))[0] == 1e7 * 1e-3 / 0.1


def test_void_sleeper_carries_no_ballast_force_until_it_has_moved_by_the_gap():
    """Sleeper 10 of a plain track has a uniform 1 mm void; the axle load over it grows.

    Until the sleeper has moved down 1 mm at a bushing, that bushing's force is
    exactly zero; beyond, it is k (|u| - 1 mm). Equilibrium residual < 1e-6.
    """
    gap = 1e-3
    lp = LayoutParams(type="plain", sleepers=21)
    tp = TrackParams(layout=lp, ballast=BallastParams(voids=(VoidSpec(10, (gap,) * 6),)))
    model = build_track(tp)
    x = model.layout.sleepers[10].x
    sel = model.ballast.sleeper == 10
    D = model.ballast.dof[sel]
    seen_open = seen_closed = False
    for Q in np.linspace(0, 250e3, 11):
        st = static_equilibrium(model, [(model.point("rail_left", x), -Q), (model.point("rail_right", x), -Q)])
        assert st.residual < 1e-6
        u = st.q[D]
        F = ballast_forces(model, st.q)[sel]
        open_ = u > -gap
        assert np.all(F[open_] == 0.0)
        assert np.allclose(F[~open_], model.ballast.k[sel][~open_] * (-u[~open_] - gap), rtol=1e-12)
        seen_open |= open_.all()
        seen_closed |= (~open_).any()
    assert seen_open and seen_closed  # the load range crosses the gap


def test_void_distribution_interpolated_from_six_points():
    gaps = (0.0, 0.4e-3, 0.9e-3, 0.9e-3, 0.4e-3, 0.0)
    lp = LayoutParams(type="plain", sleepers=6)
    model = build_track(TrackParams(layout=lp, ballast=BallastParams(voids=(VoidSpec(3, gaps),))))
    sl = model.layout.sleepers[3]
    sel = model.ballast.sleeper == 3
    y = model.ballast.y[sel]
    expect = np.interp(y, np.linspace(sl.y_start, sl.y_end, 6), gaps)
    assert np.allclose(model.ballast.gap[sel], expect, rtol=0, atol=1e-15)
    assert np.all(model.ballast.gap[~sel] == 0.0)


def test_hanging_sleeper_equilibrium():
    """A 3 mm void under sleeper 5: under self-weight only it hangs from the rails.

    Its ballast force is zero and the sleeper sits above the gap; residual < 1e-6.
    """
    lp = LayoutParams(type="plain", sleepers=11)
    model = build_track(TrackParams(layout=lp, ballast=BallastParams(voids=(VoidSpec(5, (3e-3,) * 6),))))
    st = static_equilibrium(model, [])
    sel = model.ballast.sleeper == 5
    assert st.residual < 1e-6
    assert np.all(ballast_forces(model, st.q)[sel] == 0.0)
    assert np.all(st.q[model.ballast.dof[sel]] > -3e-3)
    assert np.all(st.q[model.ballast.dof[sel]] < 0.0)  # it does sag with the rails


def test_the_two_sleepers_of_a_split_position_each_stand_on_their_own_ballast():
    """A 64-sleeper panel behind a 1:12 crossing (transition sleeper 25) splits its last positions into
    one sleeper per track (track.layout._bearer). In the static equilibrium under self-weight each of
    the two carries its own weight and its rails' pad forces to its own ballast: the vertical balance
    holds piece by piece (nothing crosses the gap), no ballast bushing and no FE node lies in the gap.
    Tolerance 1e-8 of the piece's weight: the static solve's residual is 1e-10 of the whole load vector
    (~100 sleepers' and rails' weight), which is ~100x one piece's."""
    from track.params import GRAVITY
    model = build_track(TrackParams(layout=LayoutParams(type="turnout", sleepers=64, transition_sleeper=25)))
    q = static_equilibrium(model).q
    fb = ballast_forces(model, q)
    pads = model.pads
    split = [sl for sl in model.layout.sleepers if sl.gap]
    assert len(split) >= 5
    for sl in split:
        body = model.sleeper(sl.index)
        g0, g1 = sl.gap
        nodes_y = body.origin + body.fom.s
        assert not ((nodes_y > g0 + 1e-9) & (nodes_y < g1 - 1e-9)).any()
        on = model.ballast.sleeper == sl.index
        assert not ((model.ballast.y[on] > g0) & (model.ballast.y[on] < g1)).any()
        base = sl.profile.base
        for a, b in sl.pieces:
            bal = on & (model.ballast.y > a) & (model.ballast.y < b)
            mine = (pads.sleeper == sl.index) & (pads.y > a) & (pads.y < b)
            f_pad = np.sum(pads.k[mine] * (q[pads.i[mine]] - q[pads.j[mine]]))   # on the sleeper, up +
            weight = base.rho * base.A * (b - a) * GRAVITY
            assert mine.sum() == 2 and bal.sum() >= 2
            assert abs(fb[bal].sum() + f_pad - weight) < 1e-8 * weight, (sl.index, a, b)
