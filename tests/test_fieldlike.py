"""The field-like truth generator (:mod:`orchestrator.inverse.fieldlike`), checked against references of its own.

What a field-like case must be, and the reference each check uses:

- coloured noise: the lag-1 autocorrelation of a long draw is the AR(1) coefficient,
  and its Welch spectrum has the closed-form AR(1) shape
  S(f) ~ 1 / |1 - phi exp(-i 2 pi f dt)|^2;
- drift: its periodogram peak lies below the reconstruction's high-pass corner, and
  (almost) none of its energy above it;
- the gain error: a straight-line fit (numpy.polyfit) of each output channel against its
  input, noise off, has slope 1 and no intercept on every channel but one;
- displacement channels: the noise enters the *acceleration* before the reconstruction
  (compared with a double integration written here, in the frequency domain with the
  zero-phase Butterworth gain |H|^2 = 1 / (1 + (f_c / f)^(2 n)));
- void shapes: a straight-line fit over the six positions leaves a clear residual
  (a wedge or a uniform gap leaves none), peaks off the screening grid;
- seeds reproduce their cases; a mismatched truth is another run (its impact comes later
  or earlier by the speed factor: the time a wheel needs to reach a sleeper is distance / speed).
"""
from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import welch

from orchestrator.inputs.causes import CATALOGUE
from orchestrator.inverse.fieldlike import (DRIFT_HZ, FAMILIES, GRID_CLEARANCE, WEDGE_RESIDUAL_MIN, Chain, Mismatch,
                                            apply_chain, disturbance, draw_case, draw_void_gaps, wedge_residual)

SLEEPERS = [19, 20, 21, 22, 23]       # the default layout's instrumented sleepers (T-2 .. T+2, T = 21)
CHANNELS = [f"A{i}" for i in range(1, 7)] + [f"B{i}" for i in range(1, 6)] + [f"C{i}" for i in range(1, 6)] + \
    ["D1", "D2", "E1", "E2", "F1", "F2"]
TYPES = {c: {"A": "pressure", "B": "displacement", "C": "displacement", "D": "strain", "E": "acceleration",
             "F": "strain"}[c[0]] for c in CHANNELS}
RATE = 2500.0                          # Hz: the acquisition rate of the measurement scenario
HIGHPASS, ORDER = 5.0, 2               # the default layout's reconstruction corner [Hz] and Butterworth order


def _chain(**kw) -> Chain:
    base = dict(seed=3, trigger=0.05, white=0.0, coloured=0.0, ar=0.8, drift=0.0)
    return Chain(**{**base, **kw})


def _reconstruct_by_hand(acc: np.ndarray, dt: float) -> np.ndarray:
    """Double integration X = -A / (2 pi f)^2 with the zero-phase Butterworth high-pass, written here."""
    n = acc.size
    f = np.fft.rfftfreq(n, dt)
    A = np.fft.rfft(acc)
    X = np.zeros_like(A)
    f1 = f[1:]
    X[1:] = -A[1:] / (2 * np.pi * f1) ** 2 / (1.0 + (HIGHPASS / f1) ** (2 * ORDER))
    return np.fft.irfft(X, n=n)


@pytest.mark.parametrize("phi", [0.6, 0.85])
def test_coloured_noise_is_ar1_with_its_coefficient_and_spectrum(phi):
    n, std = 2 ** 18, 0.02
    e = disturbance(_chain(coloured=std, ar=phi), 0, n, 1.0 / RATE, 1.0)
    # lag-1 autocorrelation: its standard error is sqrt((1 - phi^2) / n) ~ 0.0015; 5 of them
    r1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert r1 == pytest.approx(phi, abs=5 * np.sqrt((1 - phi ** 2) / n))
    # std: the variance estimate of an AR(1) series has relative SE sqrt(2 (1 + phi^2) / (n (1 - phi^2))) < 1 %; 5 %
    assert np.std(e) == pytest.approx(std, rel=0.05)
    # spectrum shape: Welch with 1024-sample segments (~500 averages, ~5 % scatter per bin), averaged over
    # 8 bands of ~64 bins (<1 % scatter) against the closed form; 5 % for the band means
    f, p = welch(e, fs=RATE, nperseg=1024)
    shape = 1.0 / np.abs(1.0 - phi * np.exp(-2j * np.pi * f / RATE)) ** 2
    bands = np.array_split(np.arange(1, f.size), 8)
    ratio = np.array([p[b].mean() / shape[b].mean() for b in bands])
    assert np.allclose(ratio / ratio.mean(), 1.0, atol=0.05), ratio / ratio.mean()


def test_drift_lies_below_the_reconstruction_corner():
    n = int(200 * RATE)                 # 200 s: the sub-Hz sine resolved to 5 mHz
    for index in range(len(CHANNELS)):
        d = disturbance(_chain(drift=0.03), index, n, 1.0 / RATE, 1.0)
        f = np.fft.rfftfreq(n, 1.0 / RATE)
        power = np.abs(np.fft.rfft(d)) ** 2
        assert f[np.argmax(power)] < HIGHPASS
        # leakage of a sine cut at a non-integer number of periods: well under 1e-3 of the power above f_c
        assert power[f > HIGHPASS].sum() < 1e-3 * power.sum()
        assert np.std(d) == pytest.approx(0.03 / np.sqrt(2), rel=0.02)  # a sine of amplitude a: std a / sqrt 2


def _signals(n: int, dt: float) -> dict:
    t = np.arange(n) * dt
    rng = np.random.default_rng(0)
    return {c: sum(rng.uniform(0.5, 2) * np.sin(2 * np.pi * rng.uniform(10, 200) * t + rng.uniform(0, 6))
                   for _ in range(3)) + (5.0 if TYPES[c] != "displacement" else 0.0) for c in CHANNELS}


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_the_faulty_chain_puts_a_gain_error_on_exactly_one_channel(seed):
    case = draw_case(seed, "null_sensor", SLEEPERS, CHANNELS, "quarter")
    assert not draw_case(seed, "null_clean", SLEEPERS, CHANNELS, "quarter").chain.gain_channel
    chain = replace(case.chain, white=0.0, coloured=0.0, drift=0.0)
    dt = 1.0 / RATE
    x = _signals(350, dt)
    y = apply_chain(x, TYPES, dt, HIGHPASS, chain)
    off = []
    for c in CHANNELS:
        ref = _reconstruct_by_hand(x[c], dt) if TYPES[c] == "displacement" else x[c]
        slope, intercept = np.polyfit(ref, y[c], 1)
        if abs(slope - 1.0) > 1e-9 or abs(intercept) > 1e-9 * np.std(ref):   # float round-off only
            off.append((c, slope, intercept / np.std(x[c])))
    assert len(off) == 1 and off[0][0] == chain.gain_channel, off
    assert 0.85 <= off[0][1] <= 0.95 or 1.05 <= off[0][1] <= 1.15
    if TYPES[chain.gain_channel] != "displacement":
        assert off[0][2] == pytest.approx(chain.offset, rel=1e-9)


def test_noise_enters_displacement_channels_before_the_reconstruction():
    """Consistency check of the order of the chain: the output is the hand-made reconstruction of
    (acceleration + disturbance), not the reconstruction plus a disturbance."""
    dt, n = 1.0 / RATE, 350
    acc = _signals(n, dt)["B1"]
    chain = _chain(white=0.01, coloured=0.02, ar=0.7, drift=0.02)
    y = apply_chain({"B1": acc}, {"B1": "displacement"}, dt, HIGHPASS, chain)["B1"]
    d = disturbance(chain, 0, n, dt, float(np.std(acc)))
    before = _reconstruct_by_hand(acc + d, dt)
    assert np.allclose(y, before, rtol=0, atol=1e-9 * np.std(before))      # FFT round-off
    after = _reconstruct_by_hand(acc, dt) + d                                # noise added after: not this
    assert np.std(y - after) > 0.5 * np.std(d)   # the disturbance as such would stay in the output


def test_a_quiet_channel_carries_its_sensor_kinds_noise_floor():
    """A channel's noise does not fall below its sensor kind's: three pressure cells with stds 40, 20
    and 2 (a cell under a sleeper that hardly loads it) and one reading nothing; then a sleeper
    hanging over a void, one cell reading 30 and three nothing. Reference: the noise each output
    carries (output minus input, exact: no displacement channel here) against a scale computed here
    from the inputs' stds — the median of the cells that read something, 20 and 30 — times the
    white share, measured on a long record. Tolerance 5 %: the std of n = 2^16 Gaussian samples has
    a relative standard error 1/sqrt(2n) = 0.28 %; 5 % is far from that and from the ratios the
    floor makes on the quiet cells (10x, infinite). The loud cells keep their own scale (40 >= 20).
    Draws write this floor; the chain before it (kind_floor 0) scaled by each channel's own std, so
    the cell reading nothing stayed noise-free; until session 38 the median took in the cells
    reading nothing, so the hanging sleeper's (a median of 0) stayed noise-free too."""
    n, dt, white = 2 ** 16, 1.0 / RATE, 0.01
    t = np.arange(n) * dt
    types = {c: "pressure" for c in ("A1", "A2", "A3", "A4")}
    for stds, median in (({"A1": 40.0, "A2": 20.0, "A3": 2.0, "A4": 0.0}, 20.0),
                         ({"A1": 30.0, "A2": 0.0, "A3": 0.0, "A4": 0.0}, 30.0)):
        x = {c: s * np.sqrt(2.0) * np.sin(2 * np.pi * 37.0 * t) for c, s in stds.items()}
        floor = np.median([np.std(v) for v in x.values() if np.std(v) > 0.0])   # from the signals themselves
        # rel 1e-3: the record holds 969.9 periods, not a whole number, so the sampled sines' stds are off
        # their amplitudes / sqrt(2) by the unfinished period's share, ~1e-4
        assert floor == pytest.approx(median, rel=1e-3)
        own = {c: float(np.std(v)) for c, v in x.items()}
        for kind_floor, expect in ((1.0, {c: max(s, floor) for c, s in own.items()}), (0.0, own)):
            y = apply_chain(x, types, dt, HIGHPASS, _chain(white=white, kind_floor=kind_floor))
            for c, scale in expect.items():
                got = np.std(y[c] - x[c])
                assert got == pytest.approx(white * scale, rel=0.05, abs=1e-12), (stds, kind_floor, c, got)
    assert draw_case(1, "null_clean", SLEEPERS, CHANNELS, "quarter").chain.kind_floor > 0.0   # drawn chains have one


def test_void_shapes_are_not_wedges_and_magnitudes_avoid_the_grid():
    # the residual measure itself: a wedge and a uniform gap leave none (what the fit's wedge stage covers)
    assert wedge_residual(np.linspace(0.0, 2e-3, 6)) < 1e-12 and wedge_residual(np.full(6, 1e-3)) < 1e-12
    rng = np.random.default_rng(11)
    grid = np.array(CATALOGUE["ballast_void"].grid)
    s = np.linspace(0.0, 1.0, 6)
    for _ in range(300):
        gaps = np.array(draw_void_gaps(rng))
        line = np.polyval(np.polyfit(s, gaps, 1), s)
        assert np.sqrt(np.mean((gaps - line) ** 2)) >= WEDGE_RESIDUAL_MIN * gaps.max() - 1e-15
        assert 0.6e-3 <= gaps.max() <= 2.5e-3 and gaps.min() >= 0.0
        assert np.min(np.abs(grid - gaps.max())) >= GRID_CLEARANCE * 4e-3 - 1e-15   # unit cube of 0-4 mm


@pytest.mark.parametrize("family, cause", [("pad_local", "rail_pad_stiffness"), ("pad_global", "rail_pad_stiffness"),
                                           ("bed_stiffness", "ballast_stiffness"), ("worn_nose", "impact_angle")])
def test_scalar_magnitudes_are_continuous_and_off_the_grid(family, cause):
    kind = CATALOGUE[cause]
    lo, hi = kind.lower[0], kind.upper[0]
    values = []
    for seed in range(200):
        v = next(iter(draw_case(seed, family, SLEEPERS, CHANNELS, "quarter").effects[0].parameters.values()))
        dist = np.abs(np.log(np.array(kind.grid)) - np.log(v)) / np.log(hi / lo) if kind.log \
            else np.abs(np.array(kind.grid) - v) / (hi - lo)
        assert dist.min() >= GRID_CLEARANCE - 1e-12, (v, kind.grid)
        values.append(v)
    assert len(set(values)) == len(values)        # continuous: no two seeds on the same value


def test_where_the_effects_are():
    for seed in range(50):
        on = draw_case(seed, "void_sensor", SLEEPERS, CHANNELS, "quarter").effects[0].sleeper
        off = draw_case(seed, "void_off_sensor", SLEEPERS, CHANNELS, "quarter").effects[0].sleeper
        void, pad = draw_case(seed, "two_void_pad", SLEEPERS, CHANNELS, "quarter").effects
        assert on in SLEEPERS
        assert off not in SLEEPERS and 1 <= min(abs(off - 19), abs(off - 23)) <= 3
        assert abs(void.sleeper - pad.sleeper) == 1 and 0.1 <= pad.parameters["stiffness_scale"] <= 0.3
        assert {e.cause for e in draw_case(seed, "two_nose_void", SLEEPERS, CHANNELS, "quarter").effects} == \
            {"impact_angle", "ballast_void"}


def test_seeds_reproduce_their_cases():
    for family in FAMILIES:
        a, b = (draw_case(5, family, SLEEPERS, CHANNELS, "quarter") for _ in range(2))
        assert a == b and a.as_dict() == b.as_dict()
        assert draw_case(6, family, SLEEPERS, CHANNELS, "quarter").as_dict() != a.as_dict()
        assert (family.endswith("+mismatch") or family == "null_vehicle") == (a.mismatch != Mismatch())
    c = draw_case(5, "null_clean", SLEEPERS, CHANNELS, "quarter").chain
    assert np.array_equal(disturbance(c, 2, 100, 1e-3, 1.0), disturbance(c, 2, 100, 1e-3, 1.0))
    assert not np.array_equal(disturbance(c, 2, 100, 1e-3, 1.0), disturbance(c, 3, 100, 1e-3, 1.0))


def test_mismatch_changes_the_model_as_drawn():
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario
    from vehicle.quarter import QuarterParams

    raw = load_scenario(bundled_scenario("measurement/crossing_quarter_120.yaml")).raw
    m = Mismatch({"wheelset_mass": 1.1, "k1": 0.9, "c1": 1.2}, 1.03, 0.7, 1.5, 4)
    out = m.apply(raw)
    p = QuarterParams()
    assert out["vehicle"]["start_values"] == pytest.approx({"wheelset_mass": 1.1 * p.wheelset_mass,
                                                            "k1": 0.9 * p.k1, "c1": 1.2 * p.c1})
    assert out["vehicle"]["speed"] == pytest.approx(1.03 * raw["vehicle"]["speed"])
    ballast = raw["track"]["ballast"]["damping_per_length"]
    assert out["track"]["ballast"]["damping_per_length"] == pytest.approx(0.7 * ballast)
    assert out["track"]["rail_pad"]["damping"] == pytest.approx(1.5 * raw["track"]["rail_pad"]["damping"])
    assert out["simulation"]["step"] == pytest.approx(raw["simulation"]["step"] / 4)
    assert out["simulation"]["output_step"] == raw["simulation"]["output_step"]
    # the same stretch of track: duration x 1/speed factor, to a whole output step
    assert out["simulation"]["duration"] == pytest.approx(raw["simulation"]["duration"] / 1.03,
                                                          abs=raw["simulation"]["output_step"])
    assert raw["vehicle"].get("start_values", {}) == {}    # the nominal is untouched


def test_a_mismatched_truth_is_another_run(tmp_path):
    """The truth of a mismatch case is a different run from the nominal one: the wheel reaches the
    instrumented sleepers after distance / speed, so the pressure peak under the transition sleeper
    comes earlier by the speed factor (to an output step: 0.2 ms of ~90 ms)."""
    from orchestrator.inputs.measured import read_measured
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario
    from orchestrator.inputs.sensor_layout import layout_of
    from orchestrator.inverse.fieldlike import synthesize_case
    from orchestrator.inverse.synthetic import truth_run, variant_scenario

    sc = load_scenario(bundled_scenario("measurement/crossing_quarter_120.yaml"))
    layout = layout_of(sc)
    nominal = truth_run(sc, layout)
    speedy = Mismatch(speed=1.04)
    fast = truth_run(variant_scenario(sc, speedy.apply(sc.raw), "<fast>"), layout)
    t_nom, t_fast = (r.t[np.argmax(np.abs(r.signals["A3"]))] - r.t[0] for r in (nominal, fast))
    dt = sc.simulation.output_step
    assert t_fast == pytest.approx(t_nom / 1.04, abs=2 * dt)
    assert abs(t_fast - t_nom) > 10 * dt                     # a shift the comparison must see

    case = draw_case(1, "null_vehicle", SLEEPERS, CHANNELS, "quarter")
    info = synthesize_case(sc, case, tmp_path / "p.csv")
    data = read_measured(tmp_path / "p.csv", layout.types)
    t = data.t
    assert t[0] == pytest.approx(case.chain.trigger) and np.allclose(np.diff(t), 1.0 / info["rate"])
    truth = truth_run(variant_scenario(sc, case.truth_raw(sc.raw), "<truth>"), layout)
    k = min(truth.t.size, nominal.t.size)
    assert not np.allclose(truth.signals["A3"][:k], nominal.signals["A3"][:k], rtol=0.01)


@pytest.mark.slow
def test_the_solid_crossing_rail_serves_as_truth(tmp_path):
    """Slow family ``null_solid``: the truth's crossing rail is the 3D solid. Every channel of the
    default layout is measured (none dropped, all finite), and the crossing rail's foot strain is
    another model's: it differs from the beam's peak by more than the 5 % a re-run of one model
    could not explain (a re-run is bit-identical)."""
    from orchestrator.inputs.measured import read_measured
    from orchestrator.inputs.scenario import bundled_scenario, load_scenario
    from orchestrator.inputs.sensor_layout import layout_of
    from orchestrator.inverse.fieldlike import synthesize_case
    from orchestrator.inverse.synthetic import truth_run, variant_scenario

    sc = load_scenario(bundled_scenario("measurement/crossing_quarter_120.yaml"))
    layout = layout_of(sc)
    case = draw_case(1, "null_solid", SLEEPERS, CHANNELS, "quarter")
    assert case.mismatch.track_model == "solid" and not case.effects
    synthesize_case(sc, case, tmp_path / "p.csv")
    data = read_measured(tmp_path / "p.csv", layout.types)
    assert set(data.channels) == set(layout.ids)
    assert all(np.all(np.isfinite(v)) for v in data.channels.values())
    solid = truth_run(variant_scenario(sc, case.truth_raw(sc.raw), "<solid>"), layout)
    beam = truth_run(sc, layout)
    peak = {k: np.max(np.abs(r.signals["F1"])) for k, r in (("solid", solid), ("beam", beam))}
    assert abs(peak["solid"] / peak["beam"] - 1.0) > 0.05, peak



def test_the_acquisition_filter_is_drawn_not_the_diagnosis_s():
    """The field-like chain's anti-alias filter is drawn per case (fieldlike.AA_SHARE, AA_ORDERS), so the truth's
    acquisition is not the diagnosis's comparison filter (0.4 x the rate, order 4, track.sensors): over 40 seeds
    the corners spread over the range 0.35-0.45 (written here) and more than one order occurs. The filter comes
    from a stream of its own, so a case's other chain draws do not depend on it: a chain drawn before the filter
    was (pad_local+mismatch 7101's passage, written 2026-11-29 02:48 by 3666099: trigger 0.07858028594866613 s,
    white 0.010733347859192343, coloured 0.014231541910618647, AR 0.8964004727587735) is drawn the same now."""
    chains = [draw_case(seed, "null_clean", SLEEPERS, CHANNELS, "quarter").chain for seed in range(40)]
    shares = np.array([c.aa_share for c in chains])
    assert shares.min() >= 0.35 and shares.max() <= 0.45 and np.ptp(shares) > 0.05
    assert len({c.aa_order for c in chains}) > 1
    c = draw_case(7101, "pad_local+mismatch", SLEEPERS, CHANNELS, "quarter").chain
    assert (c.trigger, c.white, c.coloured, c.ar) == (0.07858028594866613, 0.010733347859192343,
                                                      0.014231541910618647, 0.8964004727587735)
