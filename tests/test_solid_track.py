"""The 3D solid crossing rail inside the track model (``track.model: solid``, seed 000).

Beam and solid describe the same crossing block (the solid carries the block's
bending stiffness and mass, track.solid.crossing), so what differs is 3D: the
wheel load on a node of the thin nose, shear and warping of the section, two
bushings per seat. Seed 000 finds the receptances equal below ~250 Hz.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import DEFAULT_SCENARIO

from orchestrator.cosim.master import run_cosim
from orchestrator.inputs.scenario import load_scenario, scenario_from_dict
from track.frf import receptance
from track.layout import build_layout
from track.model import build_track
from track.params import LayoutParams, TrackParams
from track.post import ballast_forces, body_response, strain
from track.statics import static_equilibrium

F_AGREE = 250.0      # Hz: seed 000 §5.3, "very good agreement below 250 Hz"


@pytest.fixture(scope="module")
def models():
    """Beam and solid models of the default scenario (1:12, R500, 0.6 m, through route)."""
    sc = load_scenario(DEFAULT_SCENARIO)
    beam = build_track(sc.track)
    solid = build_track(replace(sc.track, model="solid"))
    return beam, solid


def test_solid_replaces_the_block_around_the_nose(models):
    beam, solid = models
    lay = solid.layout
    parts = [r for r in lay.rails if r.kind == "crossing"]
    assert [r.name for r in parts] == ["crossing_front", "crossing", "crossing_rear"]
    blk = beam.layout.rail("crossing")
    assert parts[0].x_start == blk.x_start and parts[-1].x_end == blk.x_end
    assert parts[1].x_start < lay.x_transition < parts[1].x_end
    assert solid.body("crossing").solid and not beam.body("crossing").solid
    # every seat of the block is still supported, those under the solid by two bushings
    assert sum(len(r.seats) for r in parts) == len(blk.seats)
    n_solid = sum(1 for r in solid.pads.rail if r == "crossing")
    assert n_solid == 2 * len(parts[1].seats)
    # cost in dofs: the seed's 3D model added 13 % (798 -> 904)
    print(f"\ndofs reduced: beam {beam.n}, solid {solid.n} (+{solid.n - beam.n}); "
          f"full: beam {beam.stats.fom_dofs}, solid {solid.stats.fom_dofs}")
    assert beam.n < solid.n < 1.2 * beam.n


def test_solid_ends_move_with_the_beam_nodes(models):
    """The distributing couplings give the beam node the end surface's mean deflection: in a
    static state the section deflection of the solid's end stations is the shared joint
    coordinate, and the solid's weight hangs on the same track as the beam's."""
    beam, solid = models
    st = static_equilibrium(solid, [(solid.rail_point("left", solid.layout.x_transition), -98.1e3)])
    b = solid.body("crossing")
    r = body_response(solid, "crossing", st.q)
    for k, (end, node) in enumerate((("start", 0), ("end", -1))):
        front = solid.body("crossing_front" if end == "start" else "crossing_rear")
        w_beam = st.q[front.gdofs] @ front.rom.T[2 * (front.fom.s.size - 1 if end == "start" else 0)]
        # round-off: the coupling row and the tie are the same linear map
        assert r.w[node] == pytest.approx(w_beam, rel=1e-9, abs=1e-15)
        assert st.q[b.gdofs[b.fom.end_q[k, 0]]] == pytest.approx(w_beam, rel=1e-12)
    # the solid carries the block's mass per length (scaled density): under self-weight the
    # ballast carries the same total in both models, within the material table's linear
    # interpolation (61 points on 1.8 m) of a ratio of section areas: 1e-4 of the panel weight
    W = [ballast_forces(m, static_equilibrium(m, []).q).sum() for m in (beam, solid)]
    assert W[1] == pytest.approx(W[0], rel=1e-4)


def test_receptance_at_the_nose_agrees_with_the_beam_below_250_hz(models):
    """Seed 000 Fig. 6: direct receptance at the crossing nose (the transition point).

    Tolerance 10 % below 250 Hz (the issue's acceptance); measured ~4 %: same bending
    stiffness and mass, differences from the two-bushing seats (the bearer is loaded at
    two points) and the local compliance of the nose under a nodal load. Above ~500 Hz
    the solid is more flexible locally and the curves part (as in the seed)."""
    beam, solid = models
    f = np.concatenate([np.linspace(5.0, F_AGREE, 50), [800.0, 1500.0]])
    x = beam.layout.x_transition
    side = beam.layout.crossing_side
    H = [receptance(m, m.rail_point(side, x), f, static_equilibrium(m, []).q) for m in (beam, solid)]
    err = np.abs(np.abs(H[1]) / np.abs(H[0]) - 1)
    low = f <= F_AGREE
    print(f"\nreceptance |solid / beam - 1| below {F_AGREE:.0f} Hz: max {err[low].max() * 100:.2f} % "
          f"(at {f[low][np.argmax(err[low])]:.0f} Hz); at 800, 1500 Hz: {np.round(err[~low] * 100, 1)} %")
    assert err[low].max() < 0.10
    # and they do part above: at 1500 Hz the difference is several times the low-frequency one
    assert err[-1] > 2 * err[low].max()


def test_beam_strain_is_minus_z_m_over_ei():
    """Static plain track, wheel load 100 kN over a sleeper. Inside one rail element without
    loads the moment is linear, so a gauge there measures the moment at its centre:
    eps = -z M / (E I). The interdependent-interpolation rotations are exact in statics and
    M is interpolated linearly between the element's end moments: round-off tolerance 1e-8."""
    model = build_track(TrackParams(layout=LayoutParams(type="plain", sleepers=12)))
    x_load = model.layout.sleepers[6].x
    st = static_equilibrium(model, [(model.rail_point("left", x_load), -1.0e5)], gravity=False)
    b = model.body("rail_left")
    xs = b.coords()
    e = int(np.searchsorted(xs, x_load + 0.25)) - 1                 # an element between two seats
    xc, L = 0.5 * (xs[e] + xs[e + 1]), 0.5 * (xs[e + 1] - xs[e])
    u = model.full_field("rail_left", st.q)
    m_ends = b.fom.element_moments(u)[e]
    M = 0.5 * (m_ends[0] + m_ends[1])
    base = b.fom.profile.base
    z = -0.0809                                                     # foot bottom below the neutral axis [m]
    eps = strain(model, "rail_left", xc, z, st.q, gauge_length=L)
    assert abs(M) > 1e3                                             # a real bending state
    assert eps == pytest.approx(-z * M / (base.E * base.I), rel=1e-8)
    # a history of states gives a history of strains
    assert np.allclose(strain(model, "rail_left", xc, z, np.stack([st.q, 2 * st.q]), L), [eps, 2 * eps],
                       rtol=1e-12)


def test_solid_strain_and_moment_match_the_beam(models):
    """Static wheel load 100 kN mid-span between the last two seats under the solid (behind
    the nose tip); gauges 40 mm above and below the neutral axis 0.15 m either side of the
    load (mid-way to the seats), and the section moments at the solid's stations, against
    the beam model.

    Tolerances: section moments 5 % of the peak (same stiffness distribution; the solid's
    seats are two bushings and its sections shear and warp: measured 0.9 %); the bending
    part of the strain, (eps(+z) - eps(-z)) / 2, 5 % (measured 0.7-1.8 %); one gauge alone
    25 %: in the tapering nose the head lags in carrying stress (shear lag), so the solid's
    neutral axis is not quite the trimmed section's centroid and each gauge also reads a
    membrane part (measured 2-7 % with both gauge ends at one height; 10-20 % before, when
    the ends followed the centroid up the taper) -- the local effect the 3D model is there for."""
    beam, solid = models
    b = solid.body("crossing")
    x_load = b.origin + 0.5 * (b.fom.seat_s[-1] + b.fom.seat_s[-2])
    q = {}
    for name, m in (("beam", beam), ("solid", solid)):
        q[name] = static_equilibrium(m, [(m.point("crossing", x_load), -1.0e5)], gravity=False).q
    z = 0.04
    for x_gauge in (x_load - 0.15, x_load + 0.15):
        eps = {name: np.array([float(strain(m, "crossing", x_gauge, zz, q[name])) for zz in (-z, z)])
               for name, m in (("beam", beam), ("solid", solid))}
        bend = {k: 0.5 * (v[0] - v[1]) for k, v in eps.items()}
        print(f"\ngauge at {x_gauge:.3f} m, z = -+{z} m: beam {eps['beam']}, solid {eps['solid']}; "
              f"bending part {(bend['solid'] / bend['beam'] - 1) * 100:+.1f} %")
        assert abs(bend["beam"]) > 1e-5
        assert bend["solid"] == pytest.approx(bend["beam"], rel=0.05)
        assert np.allclose(eps["solid"], eps["beam"], rtol=0.25)
    r_s = body_response(solid, "crossing", q["solid"])
    # the beam's moment under the load needs the static correction of the truncated modes
    r_b = body_response(beam, "crossing", q["beam"], [(beam.point("crossing", x_load), -1.0e5)])
    M_b = np.interp(r_s.coord, r_b.coord, r_b.moment)
    dM = np.abs(r_s.moment - M_b) / np.abs(M_b).max()
    print(f"section moments: max |solid - beam| / max |M| = {dM.max() * 100:.1f} %")
    assert dM.max() < 0.05


def _short_run(model: str, backend: str = "inprocess", **kw):
    base = load_scenario(DEFAULT_SCENARIO)
    x0 = build_layout(base.track.layout).x_transition - 1.5
    raw = {**base.raw}
    raw["track"] = {**raw["track"], "model": model}
    raw["vehicle"] = {"fmu": "quarter", "speed": 33.333}
    raw["simulation"] = {**raw["simulation"], "duration": 2.5 / 33.333, "x_start": x0}
    return run_cosim(scenario_from_dict(raw), backend=backend, record_states=False, **kw)


def test_cosimulation_over_the_crossing_beam_vs_solid():
    """Quarter vehicle over the crossing at 120 km/h: peak contact force beam vs solid.

    Tolerance 10 %: the models share stiffness and mass but the solid adds the nose's local
    compliance under the wheel and the two-bushing seats; the peak (P1-type, ~1 kHz content)
    lies where the receptances begin to part. Measured +3.4 %."""
    a, b = _short_run("beam"), _short_run("solid")
    assert a.error is None and b.error is None
    pa, pb = a.Fz[1:, 0].max(), b.Fz[1:, 0].max()
    print(f"\npeak contact force: beam {pa / 1e3:.1f} kN, solid {pb / 1e3:.1f} kN ({(pb / pa - 1) * 100:+.1f} %)")
    assert pb == pytest.approx(pa, rel=0.10)
    # the wheel load is static away from the crossing: both start at Q0 = 98.1 kN
    assert b.Fz[1, 0] == pytest.approx(a.Fz[1, 0], rel=0.01)


def test_track_fmu_with_the_solid_crossing(tmp_path):
    """The same run through the track FMU (FMPy) equals the in-process run to round-off
    (1e-6 relative: same code, the FMU only adds the FMI variable copies)."""
    a = _short_run("solid", backend="fmu", work_dir=tmp_path)
    b = _short_run("solid")
    assert a.error is None
    assert np.allclose(a.Fz, b.Fz, rtol=1e-6, atol=1e-3)
