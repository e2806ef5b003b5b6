"""The model's own time-step error as the diagnosis reports it (:func:`orchestrator.inverse.significance.step_error`)."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from orchestrator.inverse.objective import Comparison
from orchestrator.inverse.significance import step_error


def _cmp(sim: dict) -> Comparison:
    channels = {k: {"nrmse": 0.0} for k in sim}
    return Comparison(0.0, channels, {}, 0.0, 0.0, 0, {k: np.zeros_like(v) for k, v in sim.items()}, sim)


def test_step_error_is_the_nrmse_of_the_two_runs_difference_in_closed_form():
    """Two runs that differ by a sine of amplitude a on one channel and a constant c on another: the RMS of
    a sine is a / sqrt(2), of a constant c; over the channels' normalisers, grouped and weighted as J is.

    Group P (weight 1): channels p1 (sine, scale 2) and p2 (identical runs): mean (a / sqrt 2 / 2 + 0) / 2.
    Group Q (weight 3): channel q1 (constant c, scale 4, gain 1.5 on the channel: the residual is g s - m, so
    the difference enters times g): 1.5 c / 4. J = (1 x P + 3 x Q) / 4. A masked (NaN) sample is skipped.
    """
    t = np.linspace(0.0, 1.0, 4001)[:-1]                 # whole periods: the sine's mean square is exactly a^2 / 2
    a, c = 0.3, 0.02
    coarse = {"p1": np.sin(2 * np.pi * 5 * t), "p2": np.cos(t), "q1": np.full(t.size, 1.0)}
    fine = {"p1": coarse["p1"] - a * np.sin(2 * np.pi * 20 * t), "p2": coarse["p2"].copy(), "q1": coarse["q1"] - c}
    coarse["q1"][7] = np.nan
    target = SimpleNamespace(layout=SimpleNamespace(groups={"p1": "P", "p2": "P", "q1": "Q"},
                                                    weights={"P": 1.0, "Q": 3.0}),
                             scale={"p1": 2.0, "p2": 1.0, "q1": 4.0}, gains={"q1": 1.5}, measured=None)
    out = step_error(_cmp(coarse), _cmp(fine), target)
    p = (a / np.sqrt(2.0) / 2.0 + 0.0) / 2.0
    q = 1.5 * c / 4.0
    assert abs(out["channels"]["p1"] - a / np.sqrt(2.0) / 2.0) < 1e-12
    assert out["channels"]["p2"] == 0.0
    assert abs(out["groups"]["P"] - p) < 1e-12 and abs(out["groups"]["Q"] - q) < 1e-12
    assert abs(out["objective"] - (p + 3.0 * q) / 4.0) < 1e-12


def _residual_target(residuals: dict, types: dict, groups: dict | None = None):
    """A comparison of these residuals and a target whose layout has these sensor types (and groups: one
    group "A" by default)."""
    cmp = Comparison(0.0, {k: {"nrmse": 0.0} for k in residuals}, {}, 0.0, 0.0, 0, residuals, {})
    groups = groups if groups is not None else {k: "A" for k in residuals}
    return cmp, SimpleNamespace(layout=SimpleNamespace(types=types, groups=groups))


def test_a_channel_is_loud_only_when_its_residual_stands_above_its_own_first_difference_noise_level():
    """:func:`loud_channels` against closed forms. White noise: the first-difference level is the noise's
    sigma, ratio ~1. AR(1) noise of lag-1 correlation rho: its differences have variance 2 (1 - rho) sigma^2,
    so the level reads sigma sqrt(1 - rho) and the ratio is 1 / sqrt(1 - rho): 2.24 at rho 0.8, below
    LOUD_FACTOR 3 (quiet), 4.47 at rho 0.95 (loud). A smooth bump of amplitude 10 sigma on white noise: its
    differences are ~0 at the sampling interval, the level stays sigma, the RMS is ~sqrt(10^2 * 3/8 + 1) sigma
    (the mean square of a Hann bump of peak A over its support is 3 A^2 / 8) -> loud. A reconstructed
    displacement is not judged by its own differences, however loud (nor by its group's median alone in
    its group: test_a_displacement_stands_out_only_above_three_times_its_groups_median). Tolerance: 4000
    samples, the MAD-based level has a relative sampling error ~2 %, far inside the margins checked (2.24 vs
    3, 4.47 vs 3)."""
    from scipy.signal import lfilter

    from orchestrator.inverse.significance import LOUD_FACTOR, loud_channels

    rng = np.random.default_rng(11)
    n = 4000

    def ar(rho):
        return lfilter([1.0], [1.0, -rho], rng.normal(0.0, np.sqrt(1 - rho ** 2), n))

    bump = 10.0 * np.hanning(n) + rng.normal(0.0, 1.0, n)
    res = {"white": rng.normal(0.0, 1.0, n), "ar08": ar(0.8), "ar095": ar(0.95), "bump": bump,
           "disp": 50.0 * np.hanning(n)}
    types = {"white": "pressure", "ar08": "strain", "ar095": "acceleration", "bump": "pressure",
             "disp": "displacement"}
    loud = loud_channels(*_residual_target(res, types))
    assert set(loud) == {"ar095", "bump"}, loud
    # 15 %: an AR(1) of rho 0.95 over 4000 samples has N_eff = N (1 - rho) / (1 + rho) ~ 100, so its RMS
    # scatters by ~1 / sqrt(2 N_eff) = 7 % (one sigma); twice that
    assert abs(loud["ar095"] - 1.0 / np.sqrt(0.05)) < 0.15 * 4.47
    # 5 %: the bump's mean square is exact; the white noise's RMS and level scatter by ~1-2 % each
    assert abs(loud["bump"] - np.sqrt(100 * 3 / 8 + 1)) < 0.05 * 6.2
    assert LOUD_FACTOR > 1.0 / np.sqrt(1 - 0.8)                            # AR(1) 0.8 is taken as noise


def test_a_displacement_stands_out_only_above_three_times_its_groups_median():
    """:func:`standing_out` in closed form: residuals that are sines of amplitude a over whole periods have
    RMS a / sqrt(2) exactly. Group B, amplitudes 1, 1, 1, 1, 5: median RMS 1 / sqrt(2), B5 at ratio 5 stands
    out (> LOUD_FACTOR 3). Group C, 1, 1, 2.5, 1: 2.5 does not. Group D has two displacement channels, fewer
    than MIN_PEERS: not judged, though one is 10 x the other. A pressure channel in group B (white noise, 100 x
    the sines) is not a peer: not judged here, and quiet by its own differences. Through
    :func:`loud_channels` B5 vetoes ``none`` with the same ratio. Tolerance 1e-9: round-off of a mean over
    4000 samples of an exact identity."""
    from orchestrator.inverse.significance import LOUD_FACTOR, MIN_PEERS, loud_channels, standing_out

    t = np.arange(4000) / 4000.0
    sine = np.sin(2 * np.pi * 7 * t)
    amps = {"B1": 1, "B2": 1, "B3": 1, "B4": 1, "B5": 5, "C1": 1, "C2": 1, "C3": 2.5, "C4": 1, "D1": 1, "D2": 10}
    res = {k: a * sine for k, a in amps.items()}
    res["P1"] = 100.0 * np.random.default_rng(14).normal(0.0, 1.0, t.size)   # white: its own level, ratio ~1
    types = {k: "pressure" if k == "P1" else "displacement" for k in res}
    cmp, target = _residual_target(res, types, {k: "B" if k == "P1" else k[0] for k in res})
    assert MIN_PEERS > 2 and 2.5 < LOUD_FACTOR < 5                                          # the cases' premise
    out = standing_out(cmp, target)
    assert set(out) == {"B5"} and abs(out["B5"] - 5.0) < 1e-9, out
    loud = loud_channels(cmp, target)
    assert set(loud) == {"B5"} and abs(loud["B5"] - 5.0) < 1e-9, loud


def test_at_noise_level_says_no_when_one_channel_is_loud_though_the_objective_is_at_the_floor():
    """J_ref below (1 + NONE_MARGIN) J_noise alone no longer makes ``none``: a loud channel vetoes it."""
    from orchestrator.inverse.significance import at_noise_level

    rng = np.random.default_rng(12)
    n = 2000
    quiet = {"a": rng.normal(0.0, 1.0, n), "b": rng.normal(0.0, 1.0, n)}
    loud = {"a": quiet["a"], "b": 8.0 * np.hanning(n) + rng.normal(0.0, 1.0, n)}
    layout = SimpleNamespace(groups={"a": "A", "b": "A"}, weights={"A": 1.0}, types={"a": "pressure", "b": "pressure"})
    for res, want in ((quiet, True), (loud, False)):
        cmp = Comparison(0.0, {k: {"nrmse": 0.01} for k in res}, {"A": 0.01}, 0.01, 0.0, 0, res, {})
        target = SimpleNamespace(layout=layout, measured=None, scale={"a": 1.0, "b": 1.0}, sigma={"a": 1.0, "b": 1.0})
        ok, j_noise, found = at_noise_level(cmp, target)
        assert j_noise == 1.0 and ok is want and (set(found) == set() if want else set(found) == {"b"})


def test_an_unexplained_answer_locates_the_residual_when_the_scenario_leaves_x_start_to_the_job():
    """Regression (session 9): with ``simulation.x_start: null`` (the default scenario's) an answer above
    the noise crashed in ``_answer`` (``float(None)``): the wheel's start is now the job's
    (:func:`orchestrator.cosim.passage.start_position`, read once with the inputs). A residual loud on one
    channel of sleeper 2 (a Hann bump, peak at the record's middle) must be located there: the wheel at
    x_start + V (t_peak - shift) = 1.0 + 2.0 x 0.5 = 2.0 m, the sleeper nearest it index 2 (sleepers at
    0, 1, ..., 4 m)."""
    from orchestrator.inverse.diagnose import _answer

    rng = np.random.default_rng(13)
    n, dt = 1001, 1e-3
    t = np.arange(n) * dt
    res = {"a": rng.normal(0.0, 1.0, n), "b": 20.0 * np.hanning(n) + rng.normal(0.0, 1.0, n)}
    cmp = Comparison(0.0, {k: {"nrmse": float(np.sqrt(np.mean(r ** 2)))} for k, r in res.items()}, {"A": 1.0},
                     1.0, 0.0, 2 * n, res, {})
    layout = SimpleNamespace(groups={"a": "A", "b": "A"}, weights={"A": 1.0}, types={"a": "pressure", "b": "pressure"})
    target = SimpleNamespace(layout=layout, scale={"a": 1.0, "b": 1.0}, sigma={"a": 1.0, "b": 1.0},
                             measured=SimpleNamespace(t=t, dt=dt))
    sensors = [SimpleNamespace(id="a", body="sleeper_1"), SimpleNamespace(id="b", body="sleeper_2")]
    inp = SimpleNamespace(target=target, sensors=sensors, sleeper_x=np.arange(5.0), x_start=1.0)
    ref_raw = {"simulation": {"x_start": None}, "vehicle": {"speed": 2.0}}
    answer = _answer(inp, SimpleNamespace(cmp=cmp), ref_raw, [], cmp, None)
    assert answer.kind == "unexplained" and "b at" in answer.reason, answer.reason
    assert answer.where["sleeper_nearest_peak"] == 2 and answer.where["channels"][0]["id"] == "b", answer.where
