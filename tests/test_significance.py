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
