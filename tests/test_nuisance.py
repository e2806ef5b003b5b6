"""Nuisance parameters (issue 14, :mod:`orchestrator.inverse.nuisance`): the measurement and the vehicle
differ from the scenario, and the fit says by how much without blaming (or absorbing) the track.

The truths are made by a *different* model from the one fitted: another speed, another
wheelset mass and primary stiffness, other pad and bed damping, a mis-calibrated channel
(:func:`orchestrator.inverse.synthetic.synthesize` on a modified scenario, 2 % noise, an
unknown trigger). The fit is given the nominal scenario and the file only.

Tolerances, and why:

- speed 0.3 %: the warp estimate after a speed-corrected run was within 0.08 % on four
  truths (+-3 %, with and without a vehicle / damping mismatch); its stopping rule alone
  allows 0.1 % (``SPEED_RTOL``);
- a channel's gain 0.015: its least-squares gain against the simulation scatters with the
  noise by ~0.1 % and with the model error the channel still carries (a vehicle
  mismatch: ~1 %, measured 0.893-0.902 for a true 0.9);
- wheelset mass 1 %, primary damping and the track's damping 5 %, k1 8 %: measured 0.03 %,
  0.2 %, 0.3 %, 0.2 % and 3.2 % (k1 acts on the sprung mass's bounce, a few Hz, barely a
  period in the 0.16 s record); before the speed and the time shift were refined inside the
  fit the mass stopped 1 % short, c1 8 % (a 20 us timing error is worth 40 % of J here);
- the 90 % intervals contain the truth for the speed, the mass, c1 and both dampings
  (measured; k1's missed it by 0.5 %: not asserted);
- residual: J after the fit within 1.1x the truth model's own J on the same record (the
  noise level of this measurement; measured 1.00x).
"""
from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from orchestrator.inputs.scenario import bundled_scenario, load_scenario, scenario_from_dict
from orchestrator.inputs.sensor_layout import layout_of
from orchestrator.inverse.objective import Target
from orchestrator.inverse.screening import Pool, comparison
from orchestrator.inverse.synthetic import Effect, synthesize

SCENARIO = bundled_scenario("measurement/crossing_quarter_120.yaml")
NOISE = 0.02
SPEED_RTOL = 0.003
GAIN_ATOL = 0.015
MASS_RTOL = 0.01
DAMPING_RTOL = 0.05
K1_RTOL = 0.08
J_TRUTH_FACTOR = 1.1


@pytest.fixture(scope="module")
def sc():
    return load_scenario(SCENARIO)


@pytest.fixture(scope="module")
def pool():
    from orchestrator.sweeps.executors import make_executor

    ex = make_executor(2, None)
    yield Pool(ex, str(SCENARIO))
    ex.shutdown(wait=True, cancel_futures=True)


def _truth(sc, tmp_path, name, *, speed=1.0, start_values=None, pad_damping=1.0, bed_damping=1.0,
           effect=Effect("none"), crop=0.01, seed=7):
    """A measurement file of a model that differs from ``sc`` as given; returns (path, truth raw)."""
    raw = copy.deepcopy(sc.raw)
    raw["vehicle"]["speed"] *= speed          # same duration: a faster passage covers more track
    raw["vehicle"]["start_values"] = dict(start_values or {})
    raw["track"]["rail_pad"]["damping"] *= pad_damping
    raw["track"]["ballast"]["damping_per_length"] *= bed_damping
    truth = scenario_from_dict(raw, source=str(SCENARIO), base_dir=SCENARIO.parent)
    path = tmp_path / f"{name}.csv"
    synthesize(truth, effect, path, noise=NOISE, seed=seed, crop=crop)
    return path, effect.apply(raw)


def _target(sc, path, pool, gains=None):
    """The measurement (channels scaled by ``gains``: a mis-calibrated chain), aligned on the nominal run."""
    target = Target.read(path, layout_of(sc))
    for k, g in (gains or {}).items():
        target.measured.channels[k] = g * target.measured.channels[k]
    run = pool.map([sc.raw])[0]
    target.align_to(run.t, run.signals)
    return target, comparison(target, run)


def test_speed_from_a_faster_passage_and_the_record_covered(sc, pool, tmp_path):
    """+3 % speed, recorded to the end of the truth run (no crop): the passage that crashed the
    diagnosis (its aligned record reached past the nominal run's end, so the screened signals
    held NaN there). The speed comes back within 0.3 %, inside its interval, and the
    speed-corrected run covers the whole record."""
    from orchestrator.inverse.nuisance import speed_corrected

    path, truth = _truth(sc, tmp_path, "fast", speed=1.03, crop=0.0)
    target, base = _target(sc, path, pool)
    assert any(not np.isfinite(v).all() for v in base.simulated.values())   # the nominal run does not cover it
    notes = []
    raw_v, v, cmp, interval = speed_corrected(pool, target, sc.raw, base, notes)
    v_true = truth["vehicle"]["speed"]
    print(f"\nspeed {v:.4f} (truth {v_true:.4f}), 90 % interval {interval}, notes {notes}")
    assert v == pytest.approx(v_true, rel=SPEED_RTOL)
    assert interval[0] <= v_true <= interval[1]
    assert raw_v["vehicle"]["speed"] == v
    assert all(np.isfinite(s).all() for s in cmp.simulated.values())
    assert cmp.objective < 0.5 * base.objective


@pytest.mark.parametrize("falling", [False, True])
def test_stage_1_keeps_the_run_of_least_objective_with_the_nominal_among_them(sc, monkeypatch, falling):
    """Logic check on hand-built data (no simulation): the warp keeps asking for 2 % more speed.
    Where every run at the speeds it asks for fits worse than the nominal one (J rising with the
    speed, the case of issue 14's field-like pad_global+mismatch 7101 with the sensor kinds' noise
    floor), stage 1 keeps the scenario's speed, its comparison and its time shift, and says so
    (its interval: the warp's, widened to hold it);
    where they fit better (J falling), the best of them (here the last). Exact comparisons: the
    values are the hand-built ones passed through; rel 1e-12 where the speed was reached by three
    multiplications (v0 1.02 1.02 1.02 against v0 1.02^3: round-off only)."""
    from types import SimpleNamespace

    from orchestrator.inverse import nuisance

    v0 = float(sc.raw["vehicle"]["speed"])

    def j_of(v):
        return 0.30 + (-1.0 if falling else 1.0) * (v / v0 - 1.0)

    class FakePool:
        def map(self, raws):
            return [SimpleNamespace(t=np.array([0.0, 1.0]), signals={}, speed=float(r["vehicle"]["speed"]))
                    for r in raws]

    monkeypatch.setattr(nuisance, "comparison",
                        lambda target, run: SimpleNamespace(objective=j_of(run.speed), shift=1e-3 * run.speed))
    monkeypatch.setattr(nuisance, "speed_from_data", lambda target, cmp: (1.02, 1.01, 1.03))
    target = SimpleNamespace(measured=SimpleNamespace(t=np.array([0.0, 0.5])), shift=0.0,
                             align_to=lambda t, signals: None)
    base = SimpleNamespace(objective=j_of(v0), shift=0.007)
    notes = []
    raw_v, v, cmp, interval = nuisance.speed_corrected(FakePool(), target, sc.raw, base, notes)
    if falling:
        v_last = v0 * 1.02 ** nuisance.SPEED_RUNS
        assert v == pytest.approx(v_last, rel=1e-12) and cmp.objective == pytest.approx(j_of(v_last), rel=1e-12)
        assert raw_v["vehicle"]["speed"] == v and target.shift == cmp.shift
    else:
        assert (v, cmp, raw_v, target.shift) == (v0, base, sc.raw, 0.007)
        assert interval == [v0, v0 * 1.03]      # the warp's, widened to hold the speed kept
        assert "kept the scenario's" in notes[-1], notes


def test_a_miscalibrated_channel_is_found_and_track_causes_are_not_turned_into_gains(sc, pool, tmp_path):
    """One channel at gain 0.9 is one channel off from its peers: found. A soft pad under one
    sleeper and a void move a neighbourhood of channels together: no gain at all."""
    from orchestrator.inverse.nuisance import neighbourhoods, resolved_sensors, sensor_gains

    neighbours = neighbourhoods(resolved_sensors(sc.raw, layout_of(sc)))
    path, _ = _truth(sc, tmp_path, "nominal")
    target, base = _target(sc, path, pool, gains={"B3": 0.9})
    gains, log_gains = sensor_gains(target, base, neighbours)
    print(f"\ngain fault: {gains}")
    assert set(gains) == {"B3"} and gains["B3"] == pytest.approx(0.9, abs=GAIN_ATOL)
    for name, effect in (("pad", Effect("rail_pad_stiffness", 21, {"stiffness_scale": 0.2})),
                         ("void", Effect("ballast_void", 21, {"gaps": [0.0, 0.3e-3, 0.7e-3, 1.1e-3, 1.5e-3, 1.8e-3]}))):
        path, _ = _truth(sc, tmp_path, name, effect=effect)
        target, base = _target(sc, path, pool)
        gains, log_gains = sensor_gains(target, base, neighbours)
        print(f"{name}: gains {gains}; ln g B3 {log_gains['B3']:+.3f} C3 {log_gains['C3']:+.3f}")
        assert gains == {}, name


def test_vehicle_damping_speed_and_a_channel_recovered_from_a_different_model(sc, pool, tmp_path):
    """Truth: +3 % speed, wheelset 1750 kg (nominal 1500), k1 1.0e6 (1.2e6), c1 as nominal, pads'
    damping x1.5, bed's x0.7, channel B3 at gain 0.9. The fit recovers each of them and the
    residual falls to the truth model's own level."""
    from orchestrator.inverse.nuisance import fit_nuisance

    path, truth = _truth(sc, tmp_path, "mismatch", speed=1.03, start_values={"wheelset_mass": 1750.0, "k1": 1.0e6},
                         pad_damping=1.5, bed_damping=0.7)
    target, base = _target(sc, path, pool, gains={"B3": 0.9})
    fit = fit_nuisance(pool, target, sc.raw, base)
    j = fit.to_json()
    ref = Target.read(path, layout_of(sc))       # the truth model against the same record: the noise level
    ref.measured.channels["B3"] = 0.9 * ref.measured.channels["B3"]
    ref.gains = {"B3": 0.9}
    run = pool.map([truth])[0]
    ref.align_to(run.t, run.signals)
    j_truth = comparison(ref, run).objective
    print(f"\nJ {base.objective:.4f} -> {fit.cmp.objective:.4f} (truth model {j_truth:.4f}); {fit.runs} runs")
    print({k: (v, j["intervals"].get(k)) for k, v in j["values"].items()})
    print(j["identifiable"], j["channel_gains"], j["notes"])
    expected = {"speed": (truth["vehicle"]["speed"], SPEED_RTOL), "wheelset_mass": (1750.0, MASS_RTOL),
                "k1": (1.0e6, K1_RTOL), "c1": (2.0e4, DAMPING_RTOL), "rail_pad_damping": (3.0e4, DAMPING_RTOL),
                "ballast_damping": (2.1e4, DAMPING_RTOL)}
    for name, (value, rtol) in expected.items():
        assert fit.identifiable[name], name
        assert fit.values[name] == pytest.approx(value, rel=rtol), name
        if name != "k1":
            lo, hi = fit.intervals[name]
            assert lo <= value <= hi, (name, value, fit.intervals[name])
    assert set(fit.channel_gains) == {"B3"} and fit.channel_gains["B3"] == pytest.approx(0.9, abs=GAIN_ATOL)
    assert fit.cmp.objective <= J_TRUTH_FACTOR * j_truth
    assert fit.raw["vehicle"]["start_values"]["wheelset_mass"] == fit.values["wheelset_mass"]
    assert target.gains == fit.channel_gains and target.shift == fit.shift
    assert math.isfinite(j["objective"])


@pytest.mark.parametrize("name, effect", [
    ("worn_nose", Effect("impact_angle", None, {"impact_angle": 0.015})),
    pytest.param("void", Effect("ballast_void", 21, {"gaps": [0.0, 0.4e-3, 0.8e-3, 1.2e-3, 1.6e-3, 2.0e-3]}),
                 marks=pytest.mark.slow),
])
def test_a_track_effect_is_not_absorbed(sc, pool, tmp_path, name, effect):
    """A worn nose (15 mrad, nominal 6) or a void with the nominal vehicle: the nuisance fit leaves
    the misfit to the track causes, and turns no channel into a gain. Measured: J unchanged for
    both (0.4278, 0.7273): k1, c1 pressed against their box, the others not identifiable, so
    nothing accepted. (Before the acceptance rules the nose moved the wheelset mass +4.4 % and
    took 0.4 % of J; a refined shift alone raised the void's J by 0.7 %.)"""
    from orchestrator.inverse.nuisance import fit_nuisance

    path, _ = _truth(sc, tmp_path, name, effect=effect)
    target, base = _target(sc, path, pool)
    fit = fit_nuisance(pool, target, sc.raw, base)
    print(f"\n{name}: J {base.objective:.4f} -> {fit.cmp.objective:.4f}; {fit.to_json()['values']}; {fit.notes}")
    assert fit.cmp.objective >= 0.97 * base.objective        # at most 3 % of the misfit absorbed
    assert fit.channel_gains == {}
    assert fit.values["speed"] == pytest.approx(sc.vehicle.speed, rel=SPEED_RTOL)


def test_a_gain_must_explain_its_channel_and_reconstructed_displacements_do_not_veto_it():
    """The gain rule's two field-like parts (nuisance module doc, stage 2), on hand-built signals (no runs).

    Four pressure channels P1..P4 and three displacements D1..D3 on neighbouring sleepers; each
    simulated signal a smooth pulse train, each measured one the simulated plus 1 % white noise.
    (1) P2 recorded 13 % high, D1 9 % high (the scatter of a displacement reconstructed from noisy
    accelerations, measured 5-12 %): P2's gain is found within GAIN_ATOL (module doc) — D1, a neighbour beyond
    NEIGHBOUR_DEV, does not veto it. (2) P3's pulses grow by up to 40 % towards the record's end (a
    change of shape, as a void far along the sleeper makes at its far-end cell): its least-squares ln g
    is an outlier like a gain fault's, but with that gain its residual stays far above its noise level:
    no gain. Closed form of (2): the residual after the best gain is the part of the ramp orthogonal to
    the signal, ~0.1 of the signal's RMS against 0.01 noise, so its loudness is ~10 > LOUD_FACTOR."""
    from types import SimpleNamespace

    from orchestrator.inverse.nuisance import GAIN_MIN, NEIGHBOUR_DEV, sensor_gains
    from orchestrator.inverse.significance import LOUD_FACTOR, loudness

    rng = np.random.default_rng(11)
    n = 2000
    t = np.linspace(0.0, 1.0, n)
    ids = ["P1", "P2", "P3", "P4", "D1", "D2", "D3"]
    sim = {k: np.sin(2 * np.pi * (5 + i) * t) ** 2 for i, k in enumerate(ids)}
    types = {k: "pressure" if k[0] == "P" else "displacement" for k in ids}
    layout = SimpleNamespace(groups={k: k[0] for k in ids}, types=types)
    neighbours = {k: set(ids) - {k} for k in ids}

    def gains_of(scale):
        meas = {k: scale.get(k, 1.0) * sim[k] + rng.normal(0, 0.01 * np.std(sim[k]), n) for k in ids}
        target = SimpleNamespace(layout=layout, measured=SimpleNamespace(channels=meas))
        return sensor_gains(target, SimpleNamespace(simulated=sim), neighbours), meas

    (gains, lg), _ = gains_of({"P2": 1.13, "D1": 1.09})
    assert abs(lg["D1"]) > NEIGHBOUR_DEV            # the old rule's veto would have fired
    assert set(gains) == {"P2"} and gains["P2"] == pytest.approx(1.13, abs=GAIN_ATOL), gains

    ramp = 1.0 + 0.4 * t ** 2
    (gains, lg), meas = gains_of({"P3": ramp})
    # the precondition: P3 stands out of its group as a gain fault would (0.1 is 30 x the peers' ln g scatter
    # at 1 % noise, ~0.003, and 3 x GAIN_MIN), so only the loudness part can refuse it
    assert abs(lg["P3"]) > GAIN_MIN and abs(lg["P3"] - np.median([lg[k] for k in ("P1", "P2", "P4")])) > 0.1
    assert loudness(meas["P3"] - np.exp(lg["P3"]) * sim["P3"]) > LOUD_FACTOR
    assert gains == {}, gains


def test_log_gain_error_against_the_exact_scatter_of_the_gain_under_coloured_noise():
    """nuisance.log_gain_error against a closed form: a pulse train s measured as m = 0.3 + 1.1 s + AR(1) noise
    (lag-1 correlation 0.8, std 0.05, the field chain's colour). The least-squares gain with an offset is
    g = <s_c, m> / <s_c, s_c> (s_c = s - mean s), so its exact variance is s_c' Sigma s_c / (s_c' s_c)^2 with
    Sigma_ij = 0.05^2 0.8^|i-j| (Toeplitz, no approximation), and se(ln g) = that root / 1.1 to first order.
    Over 300 noise draws: the median estimate within 10 % of it (measured 1 %; one record's tau scatters
    +-12 % between its 10 and 90 % quantiles, the median of 300 far less, so 10 % leaves room without
    hiding a missing factor tau ~ 9), and the draws' own scatter of ln g within 10 % of it too (300 draws:
    the sample std's relative error ~ 1 / sqrt(600) = 4 %, x2.5). The offset 0.3 moves neither."""
    from scipy.linalg import toeplitz

    from orchestrator.inverse.fieldlike import ar1
    from orchestrator.inverse.nuisance import gain_fit, log_gain_error

    n, phi, sd, g = 2000, 0.8, 0.05, 1.1
    t = np.arange(n) / 5000.0
    s = np.sin(2 * np.pi * 12 * t) ** 2
    sc = s - s.mean()
    exact = math.sqrt(sc @ (sd ** 2 * toeplitz(phi ** np.arange(n))) @ sc) / (sc @ sc) / g
    rng = np.random.default_rng(3)
    draws = [0.3 + g * s + ar1(rng, n, phi, sd) for _ in range(300)]
    se = np.median([log_gain_error(*gain_fit(m, s)) for m in draws])
    scatter = np.std([math.log(gain_fit(m, s)[0]) for m in draws])
    assert se == pytest.approx(exact, rel=0.10) and scatter == pytest.approx(exact, rel=0.10), (se, scatter, exact)


def test_a_channel_offset_drift_or_scatter_is_not_a_gain_fault():
    """Stage 2's gain with an offset and its own-scatter part (nuisance module doc), on hand-built signals (no
    runs). Five pressure cells, P5 the quiet one (a tenth of its peers' spread, as A6 on the transition
    bearer), all with the group's absolute noise (the field chain's: white 1.2 %, AR(0.78) 1.5 % of the
    group's spread) and a slow drift of 3 % of it; a true 13 % fault on P2, with an offset of 6 % of its
    spread (as the chain's faulty channel), is found within GAIN_ATOL in both records.

    (1) P5 on a static load (mean 2.5 x its spread, as A6's), the drift at 0.5 Hz over the 0.4 s record:
    nearly an offset, ~1/8 of P5's mean. A gain through the origin, <s, m> / <s, s>, takes it for a gain
    (beyond 2 GAIN_MIN: asserted, the precondition); fitted with an offset, P5 is no outlier.
    (2) P5 a bare pulse train, the drift at 2 Hz: with an offset P5's gain is still beyond GAIN_MIN from its
    peers and its residual is noise (not loud) — the group and loudness parts would take it — but it lies
    within GAIN_Z of its own standard errors (the drift and the colour leave few effective samples): no
    fault. Seeds: (2)'s is the first of 0-59 whose noise moves P5 beyond GAIN_MIN (asserted)."""
    from types import SimpleNamespace

    from orchestrator.inverse.fieldlike import ar1
    from orchestrator.inverse.nuisance import GAIN_MIN, GAIN_Z, gain_fit, log_gain_error, sensor_gains
    from orchestrator.inverse.significance import LOUD_FACTOR, loudness

    n = 2000
    t = np.arange(n) / 5000.0
    ids = ["P1", "P2", "P3", "P4", "P5"]
    layout = SimpleNamespace(groups={k: "P" for k in ids}, types={k: "pressure" for k in ids})

    def record(seed, static, drift_hz, phase):
        sim = {k: np.sin(np.pi * (10 + i) * t) ** 8 for i, k in enumerate(ids)}
        p5 = sim["P5"]
        sim["P5"] = 0.1 * (p5 - p5.mean() + 2.5 * np.std(p5) if static else p5)
        rng = np.random.default_rng(seed)
        scale = float(np.median([np.std(x) for x in sim.values()]))
        meas = {k: (1.13 if k == "P2" else 1.0) * sim[k] + rng.normal(0, 0.012 * scale, n)
                + ar1(rng, n, 0.78, 0.015 * scale) + 0.03 * scale * np.sin(2 * np.pi * drift_hz * t + rng.uniform(*phase))
                for k in ids}
        meas["P2"] = meas["P2"] + 0.06 * np.std(sim["P2"])
        target = SimpleNamespace(layout=layout, measured=SimpleNamespace(channels=meas))
        gains, lg = sensor_gains(target, SimpleNamespace(simulated=sim), {k: set() for k in ids})
        assert set(gains) == {"P2"} and gains["P2"] == pytest.approx(1.13, abs=GAIN_ATOL), gains
        return sim, meas, abs(lg["P5"] - np.median(list(lg.values())))

    sim, meas, dev = record(5, True, 0.5, (np.pi / 2 - 0.5, np.pi / 2 + 0.5))                              # (1)
    assert abs(math.log(sim["P5"] @ meas["P5"] / (sim["P5"] @ sim["P5"]))) > 2 * GAIN_MIN   # precondition
    assert dev <= GAIN_MIN
    sim, meas, dev = record(6, False, 2.0, (0.0, 2 * np.pi))                                              # (2)
    assert dev > GAIN_MIN and loudness(gain_fit(meas["P5"], sim["P5"])[1]) <= LOUD_FACTOR            # precondition
    assert dev <= GAIN_Z * log_gain_error(*gain_fit(meas["P5"], sim["P5"]))


def test_refit_accepted_moves_only_the_free_entries_to_their_optimum():
    """nuisance.refit_accepted on a linear residual with a closed-form optimum: the free entries (an
    accepted value and the shift) reach the least-squares point with the held entry (a refused value,
    at nominal) fixed — a + 0.5 (b - 0.5) = 0.7 at b = 0.5 gives a = 0.7, and the shift 0.4 —, the held
    entry keeps its value to the last bit. Tolerance 0.02 in the unit cube: the refit has the stage's
    :data:`FIT_MAX_NFEV` (4) trust-region iterations, not a run to convergence, and from a start 0.5
    away they end at 0.693 (measured); a start already at the optimum is returned unchanged."""
    from orchestrator.inverse.nuisance import refit_accepted

    def residuals(ps):
        return [np.array([p[0] - 0.7 + 0.5 * (p[1] - 0.5), 2.0 * (p[2] - 0.4), p[1] - 0.99]) for p in ps]

    free = np.array([True, False, True])
    got = refit_accepted(residuals, np.array([0.2, 0.5, 0.5]), free)
    assert got[1] == 0.5
    assert abs(got[0] - 0.7) < 0.02 and abs(got[2] - 0.4) < 0.02, got
    best = np.array([0.7, 0.5, 0.4])
    assert np.array_equal(refit_accepted(residuals, best, free), best)


def test_gauss_newton_step_leaves_out_noise_extrapolated_beyond_the_box():
    """nuisance._gauss_newton_step on hand-built linear problems with closed-form answers.

    Residuals r = -0.3 x + e over 400 samples (x a known regressor, e noise of std 0.01): the first
    entry's least-squares step, by hand, is (x . -r) / (x . x). (1) A second column the residuals
    hardly feel (1e-6 x a random vector, as the gaps of a void whose sleeper hangs clear of the bed
    give: RESULTS, session 35, void_off_sensor 7202): its singular value (~2e-5) is far below Z90
    sigma (~0.016) and the step along it, the noise's projection over it, is far beyond the unit box
    — left out, the second entry's step is 0 (to round-off); without sigma (the uncut
    pseudo-inverse) it is > 10. (2) A column orthogonal to x with the residual's component along it
    set so the least-squares step there is exactly c: kept when its singular value is 2 Z90 sigma
    (determined) whatever c, and at 0.5 Z90 sigma (undetermined) when the step stays in the box
    (c = 0.5); left out there when it would leave the box (c = 3). Tolerance 1e-12: an SVD solve
    against a two-line formula, round-off only."""
    from orchestrator.inverse.nuisance import Z90, _gauss_newton_step

    rng = np.random.default_rng(5)
    x = np.sin(np.linspace(0.0, 6.0, 400))
    r = -0.3 * x + 0.01 * rng.standard_normal(400)
    flat = 1e-6 * rng.standard_normal(400)
    flat -= (flat @ x) / (x @ x) * x                        # orthogonal to x: its own singular vector
    J = np.column_stack([x, flat])
    sigma = float(np.std(r + 0.3 * x))
    by_hand = float(x @ -r) / float(x @ x)
    step = _gauss_newton_step(J, r, sigma)                                                   # (1)
    assert step[0] == pytest.approx(by_hand, abs=1e-12) and abs(step[1]) < 1e-12
    # the uncut step along it is the noise's projection over ~2e-5 (~250 here): 10, ten box widths, is far
    # from both 0 and that value, so the check does not hang on this draw of the noise
    assert abs(_gauss_newton_step(J, r)[1]) > 10.0
    y = rng.standard_normal(400)
    y -= (y @ x) / (x @ x) * x                              # orthogonal to x: y's own singular vector
    y_hat = y / np.linalg.norm(y)
    for share, c, kept in ((2.0, 0.5, True), (0.5, 0.5, True), (2.0, 3.0, True), (0.5, 3.0, False)):
        s_y = share * Z90 * sigma                           # the singular value of the column y
        r2 = r - (r @ y_hat) * y_hat - c * s_y * y_hat      # the step along y: exactly c
        got = _gauss_newton_step(np.column_stack([x, s_y * y_hat]), r2, sigma)
        assert got[0] == pytest.approx(by_hand, abs=1e-12)
        assert got[1] == pytest.approx(c if kept else 0.0, abs=1e-12), (share, c)


def test_reported_interval_holds_what_each_sensor_group_alone_would_fit():
    """The reported nuisance interval (nuisance._reported) against a closed form: a linear model, one parameter,
    two sensor groups whose data want u = 0.3 (group A) and u = 0.7 (group B), no noise. The joint fit is u = 0.5;
    the statistical interval passed in is the point u itself, so only the groups' term can widen it. Deleting
    one group leaves the other's value, so the jackknife variance is, by hand, (G - 1) / G * (0.2^2 + 0.2^2) =
    0.04 and the half-width t_{0.95,1} * 0.2 = 6.314 * 0.2 = 1.263 (t_{0.95,1} = tan(0.45 pi), the Cauchy
    quantile). Tolerance 1e-9: exact arithmetic up to round-off."""
    from types import SimpleNamespace

    from orchestrator.inverse.nuisance import _reported

    n = 50
    J = np.ones((2 * n, 1))
    u = np.array([0.5])
    y = np.r_[np.full(n, 0.3), np.full(n, 0.7)]
    r = J @ u - y
    target = SimpleNamespace(layout=SimpleNamespace(groups={"a1": "A", "b1": "B"}))
    cmp = SimpleNamespace(channels={"a1": {}, "b1": {}}, residuals={"a1": r[:n], "b1": r[n:]})
    lo, hi = _reported(J, r, u, u.copy(), u.copy(), target, cmp)
    half = math.tan(0.45 * math.pi) * 0.2
    assert lo[0] == pytest.approx(0.5 - half, abs=1e-9) and hi[0] == pytest.approx(0.5 + half, abs=1e-9)
    # a wider statistical interval is kept as it is
    lo2, hi2 = _reported(J, r, u, np.array([-5.0]), np.array([6.0]), target, cmp)
    assert (lo2[0], hi2[0]) == (-5.0, 6.0)


def test_refit_with_the_named_cause_gives_back_what_stage_3_took_from_it(sc, pool, tmp_path):
    """Stage 4 (nuisance.refit_with_causes), on the case that motivated it (RESULTS 2026-11-26 15:22: under a
    softer bed the bed's damping was fitted 2x its truth and accepted). Truth, a different model from the
    one fitted: the bed 0.4x as stiff, its damping 1.2x, the pads' 0.75x, the wheelset 1350 kg (nominal
    1500), at the nominal speed. Stage 2-3 runs on the nominal scenario (measured: it accepts no value
    here, the soft bed presses them against their box); the bed's stiffness, as a diagnosis would name
    it, is then put in at its true value, and stage 4 fits the nuisance values again on that.

    Asserted: the refit lowers both chi-square and J (the function returns it unjudged; the diagnosis's
    step 5c judges) and accepts all five vehicle and
    damping values, each within the stage-3 test's tolerance of its truth (module doc: mass 1 %, k1 8 %,
    the dampings 5 %; measured 0.1 %, 1.7 %, 0.5 %, 0.4 %, 0.1 %) and with its 90 % interval holding it."""
    from orchestrator.inverse.nuisance import fit_nuisance, refit_with_causes

    bed = Effect("ballast_stiffness", None, {"stiffness_scale": 0.4})
    path, truth = _truth(sc, tmp_path, "soft_bed", start_values={"wheelset_mass": 1350.0}, pad_damping=0.75,
                         bed_damping=1.2, effect=bed)
    target, base = _target(sc, path, pool)
    nz = fit_nuisance(pool, target, sc.raw, base)
    ext = bed.apply(nz.raw)
    start = comparison(target, pool.map([ext])[0])
    got = refit_with_causes(pool, target, nz, ext, start)
    print(f"\nstage 3: {nz.values} {nz.identifiable}")
    assert got is not None, nz.notes[-1]
    fit, cmp = got
    print(f"stage 4: {fit.values} {fit.identifiable}; J {start.objective:.4f} -> {cmp.objective:.4f}; "
          f"{fit.refit['runs']} runs")
    assert cmp.objective < start.objective and cmp.chi2 < start.chi2
    expected = {"wheelset_mass": (1350.0, MASS_RTOL), "k1": (1.2e6, K1_RTOL), "c1": (2.0e4, DAMPING_RTOL),
                "rail_pad_damping": (1.5e4, DAMPING_RTOL),
                "ballast_damping": (1.2 * sc.raw["track"]["ballast"]["damping_per_length"], DAMPING_RTOL)}
    for name, (value, rtol) in expected.items():
        assert fit.identifiable[name], name
        assert fit.values[name] == pytest.approx(value, rel=rtol), name
        lo, hi = fit.intervals[name]
        assert lo <= value <= hi, (name, value, fit.intervals[name])
    assert fit.raw["vehicle"]["start_values"]["wheelset_mass"] == fit.values["wheelset_mass"]
    assert fit.raw["track"]["ballast"]["stiffness_scale"] == 0.4     # the named cause stays in the model
    assert target.shift == nz.shift                                 # left as it was (stage 3's)


def test_speed_step_bias_extrapolates_to_a_finer_model(sc, pool, tmp_path):
    """The speed interval's time-step term (nuisance.speed_step_bias, widen_speed_for_step), against an
    independent reference: a passage made by the same model at a quarter of its step (0.2 % noise, so
    the warp sees the step and not the noise), at the scenario's own speed. The speed the warp finds on
    it from the run at the scenario's step departs from 1 less than the first-order extrapolation to the
    converged model, the bias, does, and so does the half-step run's; the step makes the fitted speed low
    (bias < 0); the interval widened on that side holds the true speed, and a bias of the other sign
    widens the other side. Measured: the quarter-step passage 0.098 %, the half-step run 0.114 %, the
    bias 0.227 % (before 2026-11-29, without the comparison's anti-alias filter: 0.208 %, 0.152 %,
    0.303 %, and the finer truth departed further; band-limited at 1 kHz the two lie 0.016 % apart, near
    the warp's resolution, ~0.01 % of its 0.25 % grid through the parabola, so their order is no longer
    asserted). No tolerance: the ordering against the bias is the claim (margins 0.11 % and 0.13 %)."""
    from dataclasses import replace

    from orchestrator.inverse.nuisance import NuisanceFit, speed_from_data, speed_step_bias, widen_speed_for_step

    h = float(sc.raw["simulation"]["step"])
    raws = {}
    for div in (1, 2, 4):
        raws[div] = copy.deepcopy(sc.raw)
        raws[div]["simulation"]["step"] = h / div
    truth = scenario_from_dict(raws[4], source=str(SCENARIO), base_dir=SCENARIO.parent)
    path = tmp_path / "quarter_step.csv"
    synthesize(truth, Effect("none"), path, noise=0.002, seed=11, crop=0.01)
    target = Target.read(path, layout_of(sc))
    coarse_run, fine_run = pool.map([raws[1], raws[2]])
    target.align_to(coarse_run.t, coarse_run.signals)
    coarse, fine = comparison(target, coarse_run), comparison(target, fine_run)
    a_meas, lo, hi = speed_from_data(target, coarse)
    a_half, bias = speed_step_bias(target, coarse, fine)
    print(f"\nwarp on the quarter-step passage {a_meas:.5f} [{lo:.4f}, {hi:.4f}]; half step {a_half:.5f}, "
          f"bias {bias:+.5f}")
    assert bias < 0
    assert max(abs(a_half - 1.0), abs(a_meas - 1.0)) < abs(bias)
    v = float(sc.raw["vehicle"]["speed"])
    nz = NuisanceFit({}, {"speed": a_meas * v}, {"speed": v}, {"speed": [lo * v, hi * v]}, {"speed": True}, {}, 0.0,
                     coarse, 0)
    widen_speed_for_step(nz, a_half, bias, h)
    assert nz.intervals["speed"][0] == lo * v and nz.intervals["speed"][1] > hi * v
    assert nz.intervals["speed"][0] <= v <= nz.intervals["speed"][1]
    up = replace(nz, intervals={"speed": [lo * v, hi * v]}, notes=[])
    widen_speed_for_step(up, a_half, -bias, h)   # a bias the other way widens the other side
    assert up.intervals["speed"][1] == hi * v and up.intervals["speed"][0] < lo * v


def test_speed_found_again_with_the_named_cause(sc, pool, tmp_path):
    """Stage 5 (nuisance.speed_again), on the pattern of the case that motivated it (RESULTS 2026-11-26,
    session 19: worn_nose+mismatch 7000, a worn nose beside a vehicle mismatch, left the speed 3.9 % low).
    Truth, a different model from the one fitted: 3.7 % faster, the nose worn (impact angle 0.0169 rad),
    the wheelset 16 % heavier and k1 18 % softer. Stages 1-3 run on the nominal scenario; the worn nose,
    as a diagnosis would name it, is then put in at its true value, and the speed is found again.

    Asserted: stage 5 lowers both chi-square and J (returned unjudged, as stage 4) and its speed is at least twice as
    close to the truth as stages 1-3 left it. Measured: stage 1 found "the data agree with the scenario"
    (33.333 m/s, warp 0.9991) for a true 34.566; stage 5, 34.052 m/s in three runs (J 0.260 -> 0.133), the
    error 1.233 -> 0.514 m/s against the 0.617 asserted; with plain steps (no secant) 33.883, which fails.
    Its interval [33.54, 34.22] still misses the truth: the warp asks for +0.3 % more at the end (not asserted)."""
    from orchestrator.inverse.nuisance import fit_nuisance, speed_again

    nose = Effect("impact_angle", None, {"impact_angle": 0.0169})
    path, truth = _truth(sc, tmp_path, "worn_fast", speed=1.037, start_values={"wheelset_mass": 1745.0, "k1": 0.99e6},
                         effect=nose)
    target, base = _target(sc, path, pool)
    nz = fit_nuisance(pool, target, sc.raw, base)
    v_true, v_before = truth["vehicle"]["speed"], nz.values["speed"]
    ext = nose.apply(nz.raw)
    start = comparison(target, pool.map([ext])[0])
    got = speed_again(pool, target, nz, ext, start)
    print(f"\nstages 1-3: speed {v_before:.4f} (truth {v_true:.4f}) {nz.notes}")
    assert got is not None, nz.notes[-1]
    fit, raw, cmp = got
    v = fit.values["speed"]
    print(f"stage 5: {v:.4f} {fit.intervals['speed']}; J {start.objective:.4f} -> {cmp.objective:.4f}; "
          f"{fit.speed_again['runs']} runs")
    assert cmp.objective < start.objective and cmp.chi2 < start.chi2
    assert abs(v - v_true) < 0.5 * abs(v_before - v_true)
    assert raw["vehicle"]["speed"] == v and raw["track"]["crossing"]["impact_angle"] == 0.0169


def test_a_named_pad_fitted_again_after_the_nuisance_refit(sc, pool, tmp_path):
    """Step 5d (diagnose._causes_again), on the pattern of the case that motivated it (RESULTS 2026-11-28,
    session 27, lead 1: pad_global 7303, the scale fitted 3.83 for a true 4.16 because it was fitted with
    stage 3's nuisance values, which step 5c then moved). Truth, a different model from the one fitted: the
    pads 2.0x as stiff, the wheelset 1350 kg (nominal 1500), the pads' damping 0.75x. Stages 1-3 run on the
    nominal scenario; the pad's scale is fitted on their model, as the diagnosis fits a named cause; step
    5c (diagnose._nuisance_again) fits the nuisance values again with it, and step 5d fits the scale again.

    Asserted: step 5c moves the nuisance values (the precondition of 5d); step 5d lowers J below step 5c's
    and brings the scale closer to the truth than the fit on stage 3's model; the entry then carries the
    new scale, the one before under ``evidence.refit_nuisance``, and its 90 % interval at the new scale.
    Last, step 5c's joint path from the same start (asserted below, where it runs)."""
    from types import SimpleNamespace

    from orchestrator.inputs.causes import Candidate, kind_of
    from orchestrator.inverse.diagnose import _causes_again, _Named, _nuisance_again
    from orchestrator.inverse.diagnosis import CauseFit
    from orchestrator.inverse.nuisance import fit_nuisance
    from orchestrator.inverse.screening import Evaluated
    from orchestrator.inverse.selection import FINE_MAX_NFEV, CauseFitter
    from orchestrator.inverse.significance import channel_neff

    true_scale = 2.0
    pad = Effect("rail_pad_stiffness", None, {"stiffness_scale": true_scale})
    path, truth = _truth(sc, tmp_path, "stiff_pads", start_values={"wheelset_mass": 1350.0}, pad_damping=0.75,
                         effect=pad)
    target, base = _target(sc, path, pool)
    nz = fit_nuisance(pool, target, sc.raw, base)
    c = Candidate("rail_pad_stiffness")
    kind = kind_of(c)
    screened = kind.apply(nz.raw, None, [1.5])
    start = Evaluated(c, np.array([1.5]), comparison(target, pool.map([screened])[0]), 1, "confirmed")
    fitted = CauseFitter(pool, target, nz.raw, start, nz.cmp).fit(start, slice(0, None), FINE_MAX_NFEV)
    ext = kind.apply(nz.raw, None, fitted.values)
    inp = SimpleNamespace(target=target)
    nz5, ext5, cmp5, _ = _nuisance_again(pool, inp, nz, ext, fitted.cmp)   # no named causes: no joint path
    print(f"\nstage 3 {nz.values}; scale on it {fitted.values[0]:.4f} (J {fitted.cmp.objective:.4f}); "
          f"step 5c {nz5.values} (J {cmp5.objective:.4f}) {nz5.notes[-1]}")
    assert nz5.refit is not None or nz5.speed_again is not None, nz5.notes
    entry = CauseFit(c.cause, kind.parameters(fitted.values), fitted.cmp.objective, 0.0, {})
    evidence = SimpleNamespace(n_eff=sum(channel_neff(fitted.cmp).values()))
    named = [_Named(fitted, evidence, None, ext)]
    ext6, cmp6 = _causes_again(pool, inp, named, [entry], nz5, ext5, cmp5)
    scale = entry.parameters["stiffness_scale"]
    print(f"step 5d: scale {scale:.4f} (J {cmp6.objective:.4f}), interval {entry.uncertainty}")
    assert cmp6.objective < cmp5.objective
    assert abs(scale - true_scale) < abs(fitted.values[0] - true_scale)
    assert entry.evidence["refit_nuisance"]["parameters_before"]["stiffness_scale"] == fitted.values[0]
    assert ext6["track"]["rail_pad"]["stiffness_scale"] == scale
    assert entry.uncertainty is not None

    # step 5c's joint path (nuisance.refit_jointly): from the same start, the nuisance values and the scale
    # fitted together reach a lower J than the alternation above (step 5c's refit, then step 5d), the scale
    # the wheelset mass within the stage-3 tolerance of its truth (MASS_RTOL: the mass is the value stage 3
    # took the pads' effect into), the scale within a third of the distance from the truth (2.0) to the scale
    # fitted on stage 3's model (so it fails when the joint steps leave the scale where stage 3 put it), the
    # wheelset's interval holding its truth, and the extended model carries the joint scale. Measured: scale
    # 1.9745 (stage 3's 1.891), mass 1352 kg, J 0.0237 in 11 runs, against 1.972 and J 0.0239 by steps 5c
    # and 5d (~20 runs). Before 2026-11-29 (no anti-alias filter in the comparison): 1.998 from 1.89, and the
    # scale was held to 1 %; band-limited at 1 kHz the pads' signature above it is not compared.
    import copy

    from orchestrator.inverse.nuisance import refit_jointly

    fit_j, cmp_j, (scale_j,) = refit_jointly(pool, target, copy.deepcopy(nz), [(kind, None, fitted.values)],
                                             fitted.cmp)
    print(f"joint: scale {scale_j[0]:.4f}, {fit_j.values} (J {cmp_j.objective:.4f}, {fit_j.refit['runs']} runs)")
    assert cmp_j.objective < cmp6.objective
    assert abs(scale_j[0] - true_scale) < abs(fitted.values[0] - true_scale) / 3
    assert fit_j.values["wheelset_mass"] == pytest.approx(1350.0, rel=MASS_RTOL)
    lo, hi = fit_j.intervals["wheelset_mass"]
    assert lo <= 1350.0 <= hi, (lo, hi)
    assert fit_j.raw["track"]["rail_pad"]["stiffness_scale"] == scale_j[0]
    assert fit_j.refit["causes"] == ["rail_pad_stiffness"]


def test_the_time_shift_aligned_again_on_a_worn_nose_moves_to_the_truths(sc, pool, tmp_path):
    """Step 4b's alignment (diagnose._aligned_again), on the pattern of the cases that motivated it (issue 14's
    field-like two_nose_void 7505 and 7606: aligned on the nominal run, the worn nose's model was misaligned,
    and a void beside it removed too small a share of the misfit to be named). Truth, a different model from
    the one fitted: the nose worn (impact angle 0.0188 rad, 7505's), the wheelset 8 % heavier; the file's
    time offset to the truth's clock is known here (``synthesize``), never to the diagnosis.

    The stage-1 alignment (on the nominal run's accelerometers) is the reference. The worn nose, as round 1
    would name it, is put in at its true value and the shift aligned again on its run. Asserted: the shift
    moves closer to the truth's offset, J falls (the rule that keeps it), the target given keeps its shift
    (round 2 gets a copy), and the nuisance estimates carry the new shift and say so. The model a nose is
    put in is another one than the truth's (the wheelset mass), so the new shift need not be exact; asserted
    only that it is closer than the nominal run's."""
    from orchestrator.inverse.diagnose import _aligned_again
    from orchestrator.inverse.nuisance import NuisanceFit

    nose = Effect("impact_angle", None, {"impact_angle": 0.0188})
    raw = copy.deepcopy(sc.raw)
    raw["vehicle"]["start_values"] = {"wheelset_mass": 1620.0}
    truth = scenario_from_dict(raw, source=str(SCENARIO), base_dir=SCENARIO.parent)
    path = tmp_path / "worn_nose.csv"
    offset = synthesize(truth, nose, path, noise=NOISE, seed=11)["time_offset"]
    target, start = _target(sc, path, pool)
    shift0 = target.shift
    ext = nose.apply(sc.raw)
    cmp = comparison(target, pool.map([ext])[0])
    nz = NuisanceFit(sc.raw, {"speed": sc.raw["vehicle"]["speed"]}, {}, {}, {}, {}, shift0, start, 1)
    own, got = _aligned_again(pool, target, nz, ext, cmp, "the worn nose")
    print(f"\ntruth's offset {1e3 * offset:.4f} ms; aligned on the nominal run {1e3 * shift0:.4f} ms (J "
          f"{cmp.objective:.4f}), on the worn nose's {1e3 * own.shift:.4f} ms (J {got.objective:.4f})")
    assert abs(own.shift - offset) < abs(shift0 - offset)
    assert got.objective < cmp.objective and got.shift == own.shift
    assert target.shift == shift0 and own is not target
    assert nz.shift == own.shift and "time shift aligned again on the model with the worn nose" in nz.notes[-1]
