"""Receptance of plain track: the pinned-pinned resonance (DESIGN.md §6 rung 2)."""
import numpy as np
from test_elements import ss_timoshenko_frequency

from track.frf import receptance
from track.model import build_track
from track.params import LayoutParams, TrackParams
from track.statics import static_equilibrium


def test_pinned_pinned_peak_mid_span():
    """60E1 on 0.6 m spacing: receptance peak at mid-span near 1033 Hz.

    Reference: the simply supported Timoshenko span of length = spacing (1033.4 Hz).
    Tolerance 3 % (acceptance): the pads are not rigid supports and the rail is
    continuous over them, which shifts the peak by ~1 %; the 2 Hz grid adds 0.1 %.
    """
    lp = LayoutParams(type="plain", sleepers=30, sleeper_spacing=0.6)
    model = build_track(TrackParams(layout=lp))
    st = static_equilibrium(model, [])
    x_mid = model.layout.sleepers[15].x + 0.3
    f = np.arange(700.0, 1400.0, 2.0)
    H = receptance(model, model.point("rail_left", x_mid), f, st.q)
    f_peak = f[np.argmax(np.abs(H))]
    f_pp = ss_timoshenko_frequency(0.6)
    print(f"pinned-pinned: receptance peak {f_peak:.0f} Hz, analytic Timoshenko {f_pp:.1f} Hz")
    assert abs(f_peak / f_pp - 1) < 0.03, (f_peak, f_pp)
    # above a sleeper the same frequency is an anti-resonance: the receptance there is
    # at least 3x smaller than at mid-span (typical ratio ~10)
    H_s = receptance(model, model.point("rail_left", x_mid - 0.3), np.array([f_peak]), st.q)
    assert abs(H_s[0]) < abs(H).max() / 3


def test_receptance_static_limit_matches_static_solution():
    """At 0.5 Hz the receptance equals the static flexibility (linearized at equilibrium).

    Independent route: two static solutions with +-1 kN added to the load (all
    bushings stay closed, so the difference quotient is exact to round-off).
    """
    lp = LayoutParams(type="plain", sleepers=20)
    model = build_track(TrackParams(layout=lp))
    x = model.layout.sleepers[10].x + 0.2
    pm = model.point("rail_left", x)
    st = static_equilibrium(model, [])
    H = receptance(model, pm, np.array([0.5]), st.q)[0]
    s1 = static_equilibrium(model, [(pm, 1e3)])
    s2 = static_equilibrium(model, [(pm, -1e3)])
    flex = (pm.value(s1.q) - pm.value(s2.q)) / 2e3
    assert abs(H.real / flex - 1) < 1e-3  # 0.5 Hz inertia/damping effect is ~1e-5
