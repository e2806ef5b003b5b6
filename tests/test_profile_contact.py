"""Profile-based wheel–rail contact in the track model (issue 15): contact tables in the kernel and the
numpy path, irregularities as contact inputs, the impact angle that emerges at the crossing.

A single wheel is driven here as a rigid mass ``m`` under a constant load ``Q0`` (the primary
suspension's force; its dynamic stiffness is negligible above ~50 Hz), integrated by the test
(semi-implicit Euler, Gauss–Seidel: the wheel with the last force, then the track), so the wheel
is known exactly and its receptance is ``-1 / (m w^2)``.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from orchestrator.inputs.scenario import load_scenario
from track.contact import HERTZ_CONSTANT
from track.cosim import TrackCosim, emergent_impact_angle
from track.frf import receptance
from track.params import ContactParams

ROOT = Path(__file__).resolve().parents[1]
DEFAULT = ROOT / "scenarios" / "crossing_1_12_through_120.yaml"
PLAIN = ROOT / "scenarios" / "plain_track.yaml"
Q0 = 98100.0           # N, static wheel load (20 t axle)
WHEEL_MASS = 800.0     # kg, half a wheelset


def _run_wheel(tc: TrackCosim, x0: float, speed: float, h: float, steps: int) -> dict:
    """Drive one wheel (mass WHEEL_MASS under Q0) over the track; returns t, x, z and the forces."""
    z = v = 0.0
    F = Q0
    out = {k: np.empty(steps) for k in ("t", "x", "z", "F")}
    parts = np.empty((steps, 2))
    for k in range(steps):
        v += h * (F - Q0) / WHEEL_MASS
        z += h * v
        x = x0 + speed * h * (k + 1)
        F = float(tc.do_step(np.array([x]), np.array([z]), np.array([v]))[0])
        out["t"][k], out["x"][k], out["z"][k], out["F"][k] = h * (k + 1), x, z, F
        parts[k] = tc.parts[0]
    out["parts"] = parts
    return out


def test_profile_contact_kernel_and_numpy_path_agree():
    """Consistency check (two code paths of ours): the compiled step and the numpy reference with the
    contact tables (surface heights and Hertz constants per wheel and surface) give the same
    forces over 150 steps through the wing rail; tolerance 1e-6 of the static load (both solve
    to the contact tolerance, the same lookups to round-off)."""
    sc = load_scenario(DEFAULT)
    tp = dataclasses.replace(sc.track, contact=ContactParams(geometry="profiles"))
    forces = []
    for kernel in (True, False):
        tc = TrackCosim(tp, 4, Q0, 1e-4, speed=30.0, kernel=kernel)
        x0 = tc.model.layout.x_tcp - 0.3
        xs = np.array([x0, x0, x0 - 2.5, x0 - 2.5])
        F = [tc.do_step(xs + 30.0 * 1e-4 * k, np.full(4, -1e-5 * k / 150), np.zeros(4)).copy()
             for k in range(150)]
        forces.append(np.array(F))
    assert forces[0][:, 1:].min() > 0.5 * Q0       # the wheels on the plain rail stay loaded
    assert np.abs(forces[0] - forces[1]).max() <= 1e-6 * Q0


def test_table_geometry_at_grid_nodes_equals_the_contact_table():
    """The kernel's lookup (track.contact.table_surface) at the table's own nodes returns the tabulated
    heights and constants (bilinear weights 1/0 up to the round-off of ``(x - x0) / dx``, ~1e-13 of
    a cell: 1e-12 m in height, 1e-9 relative in the constant), and between nodes the same as the
    contact table's own bilinear lookup (ContactTable.lookup, written separately) to 1e-12 m."""
    from track.cosim import contact_tables
    from track.model import build_track

    sc = load_scenario(DEFAULT)
    model = build_track(sc.track)
    crossing, plain = contact_tables(model, ContactParams(geometry="profiles"))
    tab = crossing.table
    rng = np.random.default_rng(1)
    for ix in rng.integers(0, tab.x.size, 20).tolist():
        for iy in range(tab.y.size):
            z1, z2 = crossing.heights(tab.x[ix], tab.y[iy])
            c1, c2 = crossing.constants(tab.x[ix], tab.y[iy])
            for z, c, k in ((z1, c1, 0), (z2, c2, 1)):
                if np.isfinite(tab.data["z"][k, ix, iy]):
                    assert abs(z - tab.data["z"][k, ix, iy]) <= 1e-12
                    assert c == pytest.approx(tab.data["C_vertical"][k, ix, iy], rel=1e-9)
    xs = rng.uniform(tab.x[0], tab.x[-1], 200)
    ys = rng.uniform(tab.y[0], tab.y[-1], 200)
    ref = tab.lookup("z", xs, ys)
    got = np.array([crossing.heights(a, b) for a, b in zip(xs, ys)]).T
    ok = np.isfinite(ref)
    assert np.abs(got[ok] - ref[ok]).max() <= 1e-12


def test_sinusoidal_rail_irregularity_force_amplitude_matches_receptances():
    """Irregularity acceptance (issue 15): a rail irregularity a sin(2 pi x / lambda) at speed V gives a
    contact-force amplitude at V / lambda of a / |alpha_rail + alpha_wheel + alpha_Hertz|.

    alpha_rail: the track's own receptance (track.frf.receptance, the model linearised at the
    static state) averaged over the positions of one sleeper bay the wheel passes; alpha_wheel =
    -1 / (m w^2) (a rigid mass); alpha_Hertz = 1 / k_H with k_H = 1.5 C^(2/3) Q0^(1/3) (the Hertz
    law linearised at the static load). The force amplitude is the least-squares sine at V / lambda
    fitted together with the sleeper-passing harmonics over the last 0.2 s.

    Tolerance 3 % (measured 0.4 %; without the wheel term the prediction is 17 % off): the receptance
    changes by 13 % along the bay (the linear prediction with its bay
    average is first order in that variation) and the Gauss–Seidel coupling lags the wheel by one
    step (w h = 0.06 rad).
    """
    sc = load_scenario(PLAIN)
    V, lam, a, h = 30.0, 0.16, 10e-6, 5e-5
    xr = np.arange(-60.0, 120.0, 0.002)
    zr = a * np.sin(2 * np.pi * xr / lam)
    contact = ContactParams(rail_table=(tuple(xr), tuple(zr), tuple(zr)))
    tp = dataclasses.replace(sc.track, contact=contact)
    tc = TrackCosim(tp, 1, Q0, h, speed=V, kernel=True)
    lay = tc.model.layout
    x0 = lay.sleepers[8].x
    steps = int(round(0.35 / h))
    r = _run_wheel(tc, x0, V, h, steps)
    t, F = r["t"], r["F"]
    sel = t >= t[-1] - 0.2
    f0, fs = V / lam, V / lay.params.sleeper_spacing
    cols = [np.ones(sel.sum())]
    for f in [f0] + [k * fs for k in range(1, 6)]:
        cols += [np.sin(2 * np.pi * f * t[sel]), np.cos(2 * np.pi * f * t[sel])]
    coef = np.linalg.lstsq(np.array(cols).T, F[sel], rcond=None)[0]
    amp = float(np.hypot(coef[1], coef[2]))

    xb = np.linspace(lay.sleepers[12].x, lay.sleepers[13].x, 7)[:-1]
    H = np.mean([receptance(tc.model, tc.model.point(lay.running_body("left", xi), xi), np.array([f0]),
                            tc.static.q)[0] for xi in xb])
    w = 2 * np.pi * f0
    k_h = 1.5 * HERTZ_CONSTANT ** (2 / 3) * Q0 ** (1 / 3)
    pred = a / abs(H - 1.0 / (WHEEL_MASS * w * w) + 1.0 / k_h)
    assert amp == pytest.approx(pred, rel=0.03), (amp, pred)


def _emergent_angle(contact: ContactParams) -> float:
    """The emergent impact angle [rad] of one wheel (mass WHEEL_MASS under Q0) at 33.3 m/s over the
    default 1:12 crossing with ``contact`` (track.cosim.emergent_impact_angle)."""
    sc = load_scenario(DEFAULT)
    tc = TrackCosim(dataclasses.replace(sc.track, contact=contact), 1, Q0, 5e-5, speed=33.3, kernel=True)
    x_tcp = tc.model.layout.x_tcp
    r = _run_wheel(tc, x_tcp - 1.0, 33.3, 5e-5, int(round(1.8 / 33.3 / 5e-5)))
    return emergent_impact_angle(r["x"], r["z"], r["parts"][:, 1], r["parts"][:, 0])["angle"]


NEW = ContactParams(geometry="profiles")
WORN_NOSE = ContactParams(geometry="profiles", crossing=(("nose_wear_stations", (0.0, 0.3, 0.6)),
                                                        ("nose_wear", (0.002, 0.002, 0.0))))
HOLLOW = ContactParams(geometry="profiles", wheel=(("hollow_depth", 0.002),))


def test_emergent_impact_angle_new_crossing_and_nose_wear():
    """Acceptance (d) of issue 15, the part that holds (README "Wheel–rail profiles"): for the nominal
    1:12 crossing and a new S1002 wheel the impact angle emerging from the wheel's path lies in the
    range of a new crossing, and 2 mm of nose wear (over 0.3 m behind the theoretical point,
    vanishing at 0.6 m) makes it grow.

    Range: the only published figure found (seed 001: B. Pålsson, "A parameterized turnout model
    for simulation of dynamic vehicle-turnout interaction with an application to crossing geometry
    assessment", Lecture Notes in Mechanical Engineering, Springer 2020, pp. 351-358,
    doi:10.1007/978-3-030-38077-9_41, §5 "Demonstration case", before its Fig. 2) takes 6 mrad as a typical impact
    angle of a nominal crossing of its type (60E1-R760-1:15), 12 mrad as worn and 18 as severely
    worn. No published range of impact angles for new crossings of about 1:12 was found with the
    search tools at hand (README "Wheel–rail profiles"), so the band 3-12 mrad (half the nominal
    value up to the worn one) is this test's, argued from that single value, not a literature
    range. Measured: 7.4 mrad new (above the seed's nominal 6, below its worn 12), 11.1 mrad worn.
    The kinematic angle of the same tables (track.contact_geometry.transfer, rigid track) is 17.5
    mrad: the dynamic wheel does not follow the nose's rise (README)."""
    new = _emergent_angle(NEW)
    worn = _emergent_angle(WORN_NOSE)
    assert 0.003 <= new <= 0.012, new
    assert worn > new + 0.001, (new, worn)     # 1 mrad: beyond the fit's scatter between runs (~0.1 mrad)


@pytest.mark.xfail(strict=True, reason="issue 15 (d) does not hold for hollow wheels in this model: at the transfer "
                                       "the nose contact (s = -22 mm, by the flange root) lies outside the hollow, so "
                                       "the false flange changes little (7.75 vs 7.4 mrad); a hollow reaching "
                                       "the nose delays the transfer to where the nose rises more gently (6.3 mrad). "
                                       "test_hollow_wheel_at_the_transfer, README 'Wheel–rail profiles'")
def test_emergent_impact_angle_grows_with_a_hollow_worn_wheel():
    """Acceptance (d) of issue 15 for wheels: a hollow-worn S1002 (2 mm deep, the default band of
    track.profiles: centred on the running band of a 1:40 rail, +5 mm, reaching from the flange root
    to 35 mm, a false flange 35-60 mm) gives a larger emergent angle than a new one (by more than
    1 mrad, as for the nose wear). Fails (strict xfail): why is test_hollow_wheel_at_the_transfer."""
    assert _emergent_angle(HOLLOW) > _emergent_angle(NEW) + 0.001


def test_hollow_wheel_at_the_transfer():
    """Why a hollow wheel does not raise the impact angle here (the xfail above), on the kinematic
    tables of the default 1:12 crossing (track.contact_geometry.transfer, centred wheelset).

    The field mechanism ("false flange"): the wing rail, diverging, touches the wheel further and
    further towards the field side, ends on the unworn tread beyond the hollow, which holds the wheel
    up by about the hollow depth, and the wheel then drops onto the nose inside the hollow. Here:

    (a) the wing contact at the transfer is on the false flange (s > centre + half width, where the
        hollow is exactly 0) for the new and the hollow wheel alike (s ~ +52 mm, S1002's 1:15
        field-side chamfer);
    (b) the nose contact is at the flange root (s ~ -22 mm: a 22 mm wide nose under the taping line
        32.5 mm outside the running edge), where the cos^2 band is under 3 % of its depth: the
        wheel does not land in the hollow, the transfer moves by under 5 mm (one table step) and
        the kinematic angle does not grow (the emergent one, 7.75 vs 7.4 mrad, differs by the
        wheel's path on the hollow's field-side flank before the transfer);
    (c) a hollow that does reach the nose contact (the same band centred on the running point of
        the *upright* 60E1 of this model's plain line, s = -9.6 mm) shows the false flange's
        geometric effect, a later transfer (> 50 mm), but the nose rises more gently there (its
        design lowering and its ridge flatten as it widens) and the wing-side fall is already the
        chamfer's, so the kinematic angle falls instead (12.8 vs 17.5 mrad; emergent 6.3 vs 7.4).

    Tolerances: 5 mm = one x step of the table; 3 % of the depth is cos^2(0.5 pi 0.9) = 2.4 % rounded
    up (the contact within the outer tenth of the band)."""
    from orchestrator.inputs.scenario import load_scenario as load
    from track.contact_geometry import crossing_table, taping_line_offset, transfer
    from track.layout import build_layout
    from track.profiles import CrossingSections, WheelProfile

    lay = build_layout(load(DEFAULT).track.layout)
    sec = CrossingSections.from_layout(lay)
    x = lay.x_tcp + np.arange(-0.2, 0.7, 0.005)
    new, hollow = WheelProfile(), WheelProfile(hollow_depth=0.002)
    upright = WheelProfile(hollow_depth=0.002, hollow_centre=-0.0096)
    tr = {k: transfer(crossing_table(w, sec, x, [0.0])) for k, w in
          (("new", new), ("hollow", hollow), ("upright", upright))}
    eta_tl = taping_line_offset()
    for k in ("new", "hollow"):
        assert tr[k]["eta_wing"] - eta_tl > hollow.hollow_centre + hollow.hollow_half_width     # (a)
        s_nose = tr[k]["eta_nose"] - eta_tl
        assert s_nose < hollow.hollow_centre - 0.9 * hollow.hollow_half_width                   # (b)
    depth = hollow.radius_increment(s_nose) - new.radius_increment(s_nose)
    assert -0.03 * hollow.hollow_depth < depth <= 0.0
    assert abs(tr["hollow"]["x"] - tr["new"]["x"]) <= 0.005
    assert tr["hollow"]["angle"] <= tr["new"]["angle"] + 1e-4
    assert tr["upright"]["x"] > tr["new"]["x"] + 0.05                                            # (c)
    assert tr["upright"]["slope_nose"] < tr["new"]["slope_nose"]


def test_wheel_polygon_and_rail_sinusoid_are_the_same_contact_input():
    """Consistency check (two inputs of ours): a wheel polygon of order n and amplitude a and a rail
    irregularity a cos(2 pi x / lambda) with lambda = 2 pi r0 / n (the polygon's wavelength along the
    track, in phase) give the same contact forces: both raise the contact by the same r(x)
    (track.irregularity.Irregularities). Tolerance: the rail table is sampled every dx = 0.2 mm, its
    linear interpolation is off the cosine by up to a k^2 dx^2 / 8 (1.9e-10 m), which the Hertz
    stiffness at the static load k_H = 1.5 C^(2/3) Q0^(1/3) turns into a force (0.26 N); 1.5x that."""
    sc = load_scenario(PLAIN)
    n, a, r0, h, V = 20, 20e-6, 0.46, 5e-5, 30.0
    lam = 2 * np.pi * r0 / n
    xr = np.arange(-60.0, 120.0, 0.0002)
    forces = []
    for contact in (ContactParams(wheel_polygon=(("order", n), ("amplitude", a), ("radius", r0))),
                    ContactParams(rail_table=(tuple(xr), tuple(a * np.cos(2 * np.pi * xr / lam)),
                                              tuple(a * np.cos(2 * np.pi * xr / lam))))):
        tc = TrackCosim(dataclasses.replace(sc.track, contact=contact), 1, Q0, h, speed=V, kernel=True)
        forces.append(_run_wheel(tc, tc.model.layout.sleepers[8].x, V, h, 600)["F"])
    assert np.ptp(forces[0]) > 0.05 * Q0          # the input does excite the wheel
    k_h = 1.5 * HERTZ_CONSTANT ** (2 / 3) * Q0 ** (1 / 3)
    interp = a * (2 * np.pi / lam) ** 2 * 0.0002 ** 2 / 8
    assert np.abs(forces[0] - forces[1]).max() <= 1.5 * k_h * interp


@pytest.mark.parametrize("override, key", [
    ("track.crossing.geometry=wedge", "track.crossing.geometry"),
    ("vehicle.lateral_offset=0.05", "vehicle.lateral_offset"),
    ("track.crossing.profiles.nose_wear=[0.001]", "track.crossing.profiles.nose_wear"),
    ("vehicle.wheel_flat.length=0.04", "vehicle.wheel_flat.depth"),
    ("vehicle.lateral_offset_table.x=[1.0,0.5]", "vehicle.lateral_offset_table.x"),
    ("track.irregularity.psd=[1e-7]", "track.irregularity.psd"),
])
def test_contact_keys_bad_input_names_the_key(override, key):
    """Bad contact keys are one clear error naming the key (README "Scenario YAML")."""
    from orchestrator.inputs.errors import ScenarioError
    with pytest.raises(ScenarioError) as exc:
        load_scenario(ROOT / "scenarios" / "profiles.yaml", [override])
    assert exc.value.key == key, str(exc.value)


def test_profiles_scenario_keys_reach_the_contact_parameters(tmp_path):
    """scenarios/profiles.yaml and a measured wheel profile / rail irregularity file end up in
    track.params.ContactParams (the files read, their columns in SI units)."""
    wheel = tmp_path / "wheel.csv"
    wheel.write_text("s,F\n-0.06,0.02\n0.0,0.0\n0.06,-0.002\n", encoding="utf-8")
    rail = tmp_path / "rail.csv"
    rail.write_text("0.0,0.0,0.0\n10.0,1e-4,-1e-4\n", encoding="utf-8")
    sc = load_scenario(ROOT / "scenarios" / "profiles.yaml",
                       [f"vehicle.wheel_profile.file={wheel}", f"track.irregularity.file={rail}",
                        "vehicle.lateral_offset=0.002", "vehicle.wheel_polygon.amplitude=1e-5"])
    c = sc.track.contact
    assert c.geometry == "profiles" and c.lateral_offset == 0.002
    assert c.wheel_table == ((-0.06, 0.0, 0.06), (0.02, 0.0, -0.002))
    assert c.rail_table == ((0.0, 10.0), (0.0, 1e-4), (0.0, -1e-4))
    assert dict(c.wheel_polygon)["amplitude"] == 1e-5 and c.irregular
    assert dict(c.crossing)["tip_drop"] == 0.004


def test_emergent_impact_angle_of_a_kinked_path():
    """track.cosim.emergent_impact_angle on a path of two straight lines (slopes -5 and +3 mrad) kinked at
    the transfer (where the nose force first exceeds the wing rail's): the angle is their difference,
    8 mrad, to round-off (a straight line is fitted exactly by least squares)."""
    x = np.linspace(10.0, 11.0, 2001)
    xt = 10.4
    z = np.where(x < xt, -0.005 * (x - xt), 0.003 * (x - xt))
    wing = np.where(x < xt, 1e5, 0.0)
    nose = np.where(x < xt, 0.0, 1e5)
    em = emergent_impact_angle(x, z, nose, wing)
    assert em["x_transfer"] == pytest.approx(xt, abs=1e-3)          # the first sample past the kink
    assert em["angle"] == pytest.approx(0.008, abs=1e-12)
    assert em["slope_before"] == pytest.approx(-0.005, abs=1e-12)


def test_profile_study_figure_from_sweep_rows(tmp_path):
    """orchestrator.studies.figures.profile_study_figure draws the study from sweep.csv-like rows (values
    as text, as csv.DictReader gives them) and writes a PNG; a row without a key of the study is an
    error, not a silent gap."""
    from orchestrator.studies.figures import PROFILE_STUDY, profile_study_figure
    from orchestrator.sweeps.plan import expand_grid
    rows = [{**{k: str(v) for k, v in case.items()}, "delta_Q": "1e5", "impact_angle_emergent": "0.008",
             "transfer_behind_tcp": "0.26"} for case in expand_grid(PROFILE_STUDY)]
    out = profile_study_figure(rows, tmp_path / "study.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(KeyError):
        profile_study_figure([{k: v for k, v in rows[0].items() if k != "vehicle.speed"}], tmp_path / "bad.png")
