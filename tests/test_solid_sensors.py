"""Virtual sensors on the 3D solid crossing rail (``track.model: solid``; issue 14 item 7).

Sleeper sensors (pressure, accelerations, strains) are the beam model's on both track
models; crossing-rail sensors read the solid's recovered field ``u = T q`` at a point of
its surface (track.solid.crossing.SolidCrossing.gauge_points): accelerometers its ``u_z``,
strain gauges its axial displacements at the gauge ends (the exact mean of the quadratic
tetrahedra's ``eps_xx`` along the gauge). Heights ``z`` on the solid are above the
untrimmed rail section's neutral axis (track.sensors.SOLID_DATUM).

Layers: shape functions and gradients reproduce quadratic fields (exactness) -> a solid
cantilever against eps = -M z / (E I) (verification) -> the default layout on the solid
model and a short run writing every channel -> solid against beam strains and
displacements (consistency checks).
"""
from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest
from conftest import DEFAULT_SCENARIO, PLAIN_SCENARIO

from orchestrator.cli import main
from orchestrator.inputs.scenario import load_scenario
from orchestrator.inputs.sensor_layout import load_layout, resolve
from orchestrator.inputs.track_model import track_model
from track.cache import cache_dir_from_env
from track.sensors import Sensor, compile_sensors, displacement_row, solid_strain_row
from track.solid.body import SolidRailParams
from track.solid.crossing import solid_crossing
from track.solid.fem import locate, probe_matrix, shape_rows
from track.solid.section import rail_60e1_like

F_TIP = 1.0e4            # N: cantilever tip load
CANTILEVER = 1.2         # m: 7 section heights, so gauges 0.45-0.75 m are > 2.5 heights from both ends
Q_WHEEL = 1.0e5          # N: static wheel load of the beam-vs-solid comparisons


@pytest.fixture(scope="module")
def models():
    """Beam and solid models of the default scenario (the solid body is cached by content, in-process
    and on disk, $TURNOUT_CACHE: tests/test_solid_track.py and the run below reuse it)."""
    sc = load_scenario(DEFAULT_SCENARIO)
    return sc, track_model(sc.track), track_model(replace(sc.track, model="solid"))


@pytest.fixture(scope="module")
def cantilever():
    """A 1.2 m prismatic 60E1-like solid (h = 0.06 m as the crossing), clamped at x = 0 through its
    end coupling and loaded by F_TIP (up) on the coupling at x = L; the reduced static solution
    (Craig–Bampton is exact in statics for loads on retained coordinates)."""
    p = SolidRailParams(length=CANTILEVER, seats=(), h=0.06, f_modes=1.0, axial_free_end=True)
    sc = solid_crossing(p, cache_dir_from_env(os.environ))       # built once, then from the cache
    free = np.setdiff1d(np.arange(sc.nr), sc.end_q[0])
    f = np.zeros(sc.nr)
    f[sc.end_q[1, 0]] = F_TIP
    q = np.zeros(sc.nr)
    q[free] = np.linalg.solve(sc.K[np.ix_(free, free)], f[free])
    return p, sc, q


# ----------------------------------------------------------------------------- (1) exactness

def test_shape_rows_reproduce_a_quadratic_field_and_its_gradient(models):
    """Quadratic tetrahedra hold every quadratic field exactly: values and gradients at points
    anywhere in the crossing's mesh equal the analytic ones to round-off (1e-9 relative), and the
    values equal scikit-fem's own interpolation (probe_matrix, an independent code path)."""
    _, _, solid = models
    fom = solid.body("crossing").fom
    P = fom.points
    rng = np.random.default_rng(14)
    e = rng.integers(0, fom.tets.shape[0], 40)
    w = rng.dirichlet(np.ones(4), size=e.size)                      # random points inside random elements
    X = np.einsum("kc,kcd->kd", w, P[fom.tets[e, :4]])

    def field(Y):
        return 1e-3 * (1.0 + 2.0 * Y[:, 0] - Y[:, 1] + 3.0 * Y[:, 2] ** 2 + 5.0 * Y[:, 0] * Y[:, 2])

    N, G = shape_rows(P, fom.tets, X)
    grad = 1e-3 * np.column_stack([2.0 + 5.0 * X[:, 2], -np.ones(len(X)), 6.0 * X[:, 2] + 5.0 * X[:, 0]])
    u = field(P)
    assert np.allclose(N @ u, field(X), rtol=1e-9, atol=0)
    for c in range(3):
        assert np.allclose(G[c] @ u, grad[:, c], rtol=1e-9, atol=1e-12)
    assert abs(N - probe_matrix(P, fom.tets, X)).max() < 1e-12
    assert np.array_equal(locate(P, fom.tets, X)[0], e)
    with pytest.raises(ValueError, match="not inside the solid"):
        locate(P, fom.tets, [[0.5, 0.5, 0.5]])


# ----------------------------------------------------------------------------- (2) verification

@pytest.mark.parametrize("z", [-0.07, -0.03, 0.03, 0.06])
def test_solid_gauge_strain_of_a_cantilever_is_minus_m_z_over_ei(cantilever, z):
    """Cantilever of the rail section under a tip load: M(x) = F (L - x) (sagging +), and in
    Saint-Venant's flexure solution sigma_xx = -M z / I with sigma_yy = sigma_zz = 0, so on the
    surface eps_xx = -M z / (E I) exactly (I of the polygon in closed form, z above its centroid).

    Gauges of 0.1 m at 0.45, 0.6, 0.75 m (> 2.5 section heights from the clamp and the load,
    where the end effects have decayed): tolerance 1 % (measured <= 0.4 %: the quadratic
    elements' discretisation error at h = 0.06 m). Point strains from the displacement gradient
    in one element (strain_rows) are linear per element and jump between elements: 2 %
    (measured <= 0.65 %; on an element face, where either side may be taken, the jump reached
    5 % on the web in a mesh with a station plane there)."""
    p, sc, q = cantilever
    E, I = p.E, rail_60e1_like().properties.I_y
    L = 0.1
    for x in (0.45, 0.6, 0.75):
        ref = -z * F_TIP * (CANTILEVER - x) / (E * I)
        R = sc.axial_rows(np.array([x - 0.5 * L, x + 0.5 * L]), z, datum="rail")
        gauge = float((R[1] - R[0]) @ q / L)
        point = float(sc.strain_rows(np.array([x]), z, datum="rail")[0] @ q)
        print(f"\nx = {x} m, z = {z:+.2f} m: eps_ref {ref * 1e6:.2f} ue, gauge {gauge / ref - 1:+.2%}, "
              f"point {point / ref - 1:+.2%}")
        assert gauge == pytest.approx(ref, rel=0.01)
        assert point == pytest.approx(ref, rel=0.02)


def test_a_gauge_inside_one_element_reads_the_strain_at_its_centre(cantilever):
    """Consistency check of the two strain readings: along a line in one quadratic element u_x is
    quadratic, and a quadratic's chord slope is its slope at the midpoint, so a gauge whose ends
    lie in one element reads the element's eps_xx at its centre (round-off: 1e-6 relative, the
    difference of two displacements over a 1 mm gauge)."""
    _, sc, q = cantilever
    L = 1e-3
    checked = 0
    for x in np.linspace(0.4, 0.8, 81):
        ends = np.array([x - 0.5 * L, x + 0.5 * L])
        if len(set(locate(sc.points, sc.tets, sc.gauge_points(ends, -0.07, datum="rail"))[0])) != 1:
            continue                        # the gauge straddles two elements
        R = sc.axial_rows(ends, -0.07, datum="rail")
        chord = float((R[1] - R[0]) @ q / L)
        point = float(sc.strain_rows(np.array([x]), -0.07, datum="rail")[0] @ q)
        assert chord == pytest.approx(point, rel=1e-6)
        checked += 1
    assert checked >= 10


# ----------------------------------------------------------------------------- (3) the default layout

def test_default_layout_resolves_every_channel_on_the_solid(models):
    """Every sensor of the default layout resolves on ``track.model: solid``, at the beam model's
    positions: sleeper sensors on the same sleepers and lateral positions (``seat:crossing`` is the
    block's seat whichever part of the block carries it), E and F on the solid; every row is
    non-zero (a sensor that reads nothing would be a silently dead channel)."""
    _, beam, solid = models
    layout = load_layout()
    on_beam, on_solid = resolve(layout, beam), resolve(layout, solid)
    assert [s.id for s in on_solid] == layout.ids
    for a, b in zip(on_beam, on_solid):
        assert (b.type, b.coord, b.z) == pytest.approx((a.type, a.coord, a.z), abs=1e-12)
        assert b.body == a.body or (b.group in "EF" and b.body == "crossing")
    assert all(solid.body(s.body).solid for s in on_solid if s.group in "EF")
    cs = compile_sensors(solid, on_solid)
    reads = np.any(cs.Cq != 0, axis=1) | np.any(cs.Ca != 0, axis=1) | np.any(cs.Pb != 0, axis=1)
    assert reads.all(), [s.id for s, r in zip(on_solid, reads) if not r]


@pytest.mark.parametrize("entry, words", [
    ({"id": "X", "type": "strain", "group": "F", "rail": "crossing", "x": "T-0.3", "z": -0.09},
     "outside the rail section"),
    ({"id": "X", "type": "strain", "group": "F", "rail": "crossing", "x": "T+0.88", "z": -0.07},
     "crosses an end of crossing"),
    ({"id": "X", "type": "acceleration", "group": "E", "rail": "crossing", "x": "T+40"}, "is off crossing"),
])
def test_a_sensor_off_the_solid_is_one_clear_error(models, entry, words):
    """A gauge below the foot, or across the joint between the solid and a beam part of the block,
    cannot be read from one body: a one-line UserInputError naming the sensor."""
    from orchestrator.inputs.errors import UserInputError
    from orchestrator.inputs.sensor_layout import layout_from_dict

    _, _, solid = models
    with pytest.raises(UserInputError, match=words) as err:
        resolve(layout_from_dict({"sensors": [entry]}, "lay.yaml"), solid)
    assert "(X)" in str(err.value) and "\n" not in str(err.value)


def test_a_short_solid_run_writes_every_channel(models, tmp_path, capsys):
    """``turnout run`` with ``track.model: solid`` (quarter vehicle, 10 ms over the nose): sensors.csv
    has a finite column for every sensor of the default layout, and nothing is said about sensors
    that do not fit."""
    _, beam, _ = models
    x0 = beam.layout.x_transition - 0.15            # the wheel crosses the transition 4.5 ms in
    out = tmp_path / "solid"
    rc = main(["run", str(DEFAULT_SCENARIO), "--out", str(out), "--no-progress", "--backend", "inprocess",
               "--set", "track.model=solid", "--set", "vehicle.fmu=quarter", "--set", "simulation.duration=0.01",
               "--set", f"simulation.x_start={x0:.4f}"])
    assert rc == 0
    err = capsys.readouterr().err
    assert "does not fit" not in err, err
    csv = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True)
    ids = load_layout().ids
    assert set(ids) <= set(csv.dtype.names)
    for sid in ids:
        assert np.all(np.isfinite(csv[sid])) and np.any(csv[sid] != 0.0), sid


def test_a_default_layout_that_does_not_fit_is_named_not_dropped_silently(tmp_path, capsys):
    """On a plain track (no crossing rail) the default layout does not fit: the run writes no
    layout channels and the command line says so in one warning line naming the sensors."""
    out = tmp_path / "plain"
    rc = main(["run", str(PLAIN_SCENARIO), "--out", str(out), "--no-progress", "--backend", "inprocess",
               "--set", "vehicle.fmu=quarter", "--set", "simulation.duration=0.002"])
    assert rc == 0
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "sensor layout" in ln]
    assert len(lines) == 1 and lines[0].startswith("turnout: warning: the default sensor layout does not fit")
    assert "E1, E2, F1, F2 do not" in lines[0] and "Traceback" not in lines[0]
    names = np.genfromtxt(out / "sensors.csv", delimiter=",", names=True).dtype.names
    assert not set(load_layout().ids) & set(names)


# ----------------------------------------------------------------------------- (4) consistency with the beam

def _static(model, x: float) -> np.ndarray:
    """Static state under one wheel load Q_WHEEL on the running rail at ``x`` (no self-weight)."""
    from track.statics import static_equilibrium

    side = model.layout.crossing_side
    return static_equilibrium(model, [(model.rail_point(side, x), -Q_WHEEL)], gravity=False).q


def _gauge(model, x: float, z: float, L: float = 0.1) -> np.ndarray:
    s = Sensor("g", "strain", "F", "crossing", x, z, L)
    return compile_sensors(model, [s]).Cq[0]


def _levers(solid, x: float, z: float) -> float:
    """(z_gauge - z_c) / z: the gauge's lever about the solid's own neutral axis (the trimmed
    section's centroid z_c) over its lever on the beam (z above the rail's neutral axis)."""
    f = solid.body("crossing").fom
    s = np.array([x - solid.body("crossing").origin])
    zr, zc = f.datum_heights(s, "rail")[0], f.datum_heights(s, "section")[0]
    return float((zr + z - zc) / z)


@pytest.mark.parametrize("dx_load", [0.0, 1.0])
def test_consistency_f1_strains_agree_with_the_beam(models, dx_load):
    """Consistency check, beam vs solid, at the default layout's F1 (T-0.3), under the same static
    wheel load (100 kN at T, on the nose, and at T+1.0, on the block behind the solid).

    Why F1: it is mid-span between two seats (the solid's seats are point bushings on the foot,
    whose local stresses reach the foot gauges within ~0.15 m of a seat), 0.6 m from the solid's
    end coupling and 0.2 m ahead of the nose tip, where the solid's section is prismatic (the
    head trimmed to the 12 mm strip): no taper, no shear lag. Its neutral axis is lower than the
    rail's (52.4 instead of 81.5 mm above the foot: the wing rails are not meshed, their
    stiffness is in the solid's E), so a gauge at its place on the rail (foot z = -0.07 m, head
    z = +0.07 m above the rail's neutral axis) has the lever (z_gauge - z_c), not z: with the
    same curvature the solid reads the beam's strain times (z_gauge - z_c) / z (0.58 at the foot,
    1.42 at the head). Tolerance 5 %: the section moments of the two models agree within 1-2 %
    (test_solid_track.py) and the solid adds shear and the two-bushing seats; measured 0.3-2.1 %
    (printed). The curvature itself, (eps_head - eps_foot) / (z_head - z_foot), is the same
    for both to 3 % (no lever involved)."""
    _, beam, solid = models
    T = beam.layout.x_transition
    x = T - 0.3
    q_b, q_s = _static(beam, T + dx_load), _static(solid, T + dx_load)
    eps = {}
    for z in (-0.07, 0.07):
        e_b, e_s = _gauge(beam, x, z) @ q_b, _gauge(solid, x, z) @ q_s
        lever = _levers(solid, x, z)
        eps[z] = e_b, e_s
        print(f"\nF1 (T-0.3), z = {z:+.2f} m, load at T{dx_load:+.1f}: beam {e_b * 1e6:.2f} ue, solid "
              f"{e_s * 1e6:.2f} ue (solid / beam {e_s / e_b:.3f}, lever ratio {lever:.3f}: {e_s / (lever * e_b) - 1:+.2%})")
        assert abs(lever - 1.0) > 0.3                               # the neutral axis is lower there
        assert e_s == pytest.approx(lever * e_b, rel=0.05)
    kappa_b, kappa_s = (eps[0.07][i] - eps[-0.07][i] for i in (0, 1))
    assert abs(kappa_b) > 1e-6 and kappa_s == pytest.approx(kappa_b, rel=0.03)


def test_consistency_f2_on_the_nose_taper(models):
    """Consistency check at F2 (T+0.3, mid-span, on the tapering nose 0.4 m behind its tip; wheel
    load on the nose at T): the trimmed section's centroid moves up along the taper (70.4 mm at
    F2), and a gauge at its place on the rail reads the beam's strain times (z_gauge - z_c) / z.
    Tolerance 5 % as at F1 (measured ~2.5 %: the taper adds a little shear lag; printed)."""
    _, beam, solid = models
    T = beam.layout.x_transition
    x = T + 0.3
    q_b, q_s = _static(beam, T), _static(solid, T)
    for z in (-0.07, 0.07):
        e_b, e_s = _gauge(beam, x, z) @ q_b, _gauge(solid, x, z) @ q_s
        lever = _levers(solid, x, z)
        print(f"\nF2 (T+0.3), z = {z:+.2f} m, load at T: beam {e_b * 1e6:.2f} ue, solid {e_s * 1e6:.2f} ue "
              f"(solid / beam {e_s / e_b:.3f}, lever ratio {lever:.3f}: {e_s / (lever * e_b) - 1:+.2%})")
        assert abs(e_b) > 1e-5
        assert e_s == pytest.approx(lever * e_b, rel=0.05)


def test_consistency_solid_accelerometers_read_the_beam_deflection(models):
    """Consistency check: the E accelerometers' rows (u_z of the web at the rail's neutral axis) on
    the static state under the wheel at T read the beam model's rail deflection at the same x
    within 3 % (same stiffness and supports; the solid adds shear and the two-bushing seats; the
    receptance below 250 Hz agrees within 4 %, test_solid_track.py)."""
    sc, beam, solid = models
    T = beam.layout.x_transition
    q_b, q_s = _static(beam, T), _static(solid, T)
    for e in resolve(load_layout(), solid):
        if e.group != "E":
            continue
        w_b = displacement_row(beam, "crossing", e.coord) @ q_b
        w_s = displacement_row(solid, e.body, e.coord, e.z) @ q_s
        print(f"\n{e.id} at T{e.coord - T:+.2f}: beam {w_b * 1e3:.4f} mm, solid {w_s * 1e3:.4f} mm "
              f"({w_s / w_b - 1:+.2%})")
        assert w_s == pytest.approx(w_b, rel=0.03)
    # a strain row of the solid is the solid_strain_row of track.sensors (one code path for sensors)
    row = solid_strain_row(solid, "crossing", T - 0.3, -0.07)
    assert np.array_equal(row, _gauge(solid, T - 0.3, -0.07))
