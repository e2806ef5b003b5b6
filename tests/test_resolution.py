"""What a ``none`` answer's record resolves (orchestrator.inverse.resolution), against closed forms. No simulation.

The signatures here are exactly linear in the screening axis (the interpolation the module assumes), so
the limit has a closed form: a channel of noise sigma and normaliser S whose signature grows as c u (u
the magnitude in units of its axis, RMS c per unit) reads nRMSE sqrt(sigma^2 + c^2 u^2) / S.
"""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from orchestrator.inputs.causes import Candidate
from orchestrator.inverse.resolution import resolution, summary

N = 2000
T = np.linspace(0.0, 1.0, N, endpoint=False)
SHAPE = math.sqrt(2.0) * np.sin(2 * np.pi * 7 * T)     # RMS 1 over whole periods
NOISE, SCALE = 1.0, 10.0                                # every channel: noise nRMSE 0.1


def _target(channels: dict):
    """channels: id -> (group, type)."""
    layout = SimpleNamespace(groups={k: g for k, (g, _) in channels.items()}, weights={},
                             types={k: t for k, (_, t) in channels.items()})
    return SimpleNamespace(sigma={k: NOISE for k in channels}, scale={k: SCALE for k in channels}, layout=layout,
                           measured=None)


def _proxies(cand: Candidate, axes: list, loud: str, c: float, ids: list, log: bool = False) -> dict:
    """One proxy per axis entry: channel ``loud`` carries c u SHAPE, the others nothing (u = x, or ln x)."""
    base = {k: np.full(N, 5.0) for k in ids}
    grids = []
    for _, xs, x0 in axes:
        u = (lambda x: math.log(x)) if log else (lambda x: x)
        grids.append({x: {k: base[k] + (c * (u(x) - u(x0)) * SHAPE if k == loud else 0.0) for k in ids} for x in xs})
    return {cand: (axes, grids)}


def _limit(rows, cause, proxy):
    return next(r["limit"] for r in rows if r["cause"] == cause and r["proxy"] == proxy)


def test_a_void_is_resolved_where_the_objective_leaves_the_noise_margin():
    """One channel in one group: J = sqrt(1 + c^2 u^2) / 10 against 1.5 x 0.1 gives c u = sqrt(1.25); its
    loudness sqrt(1 + c^2 u^2) reaches 3 only at sqrt(8), later. Tolerance rel 1e-4: the crossing is refined
    linearly between points 1/64 of a screening step apart on a curve this smooth (its second-order error
    at that spacing is ~1e-5 of the step)."""
    target = _target({"P1": ("p", "pressure")})
    c = 1.0 / 1e-3                        # RMS 1 per mm of gap
    axes = [(None, np.array([0.0, 0.4e-3, 1.0e-3, 2.0e-3, 3.5e-3]), 0.0)]
    rows = resolution(target, SimpleNamespace(channels={"P1": {}}),
                      _proxies(Candidate("ballast_void", 21), axes, "P1", c, ["P1"]))
    assert [r["proxy"] for r in rows] == ["uniform"]     # nothing below a gap of 0
    assert rows[0]["limit"] == pytest.approx(math.sqrt(1.25) / c, rel=1e-4)
    assert rows[0]["screened_to"] == 3.5e-3 and rows[0]["unit"] == "m"
    assert "1.1 mm under sleeper 21" in summary(rows), summary(rows)
    apart = [dict(rows[0], sleeper=19), dict(rows[0], sleeper=23, limit=None)]   # a layout with a gap in it
    assert "under sleeper(s) 23 not even one of 3.5 mm" in summary(apart) and "other than 19, 23" in summary(apart)


def test_a_loud_channel_resolves_what_the_average_over_groups_hides_but_a_displacement_does_not():
    """Five groups, the signature on one of them: J = (sqrt(1 + c^2 u^2) / 10 + 4 x 0.1) / 5 reaches 0.15 at
    sqrt(1 + c^2 u^2) = 3.5, but a pressure channel is loud (3 x its noise) already at sqrt(8). On a
    reconstructed displacement the loudness is not judged: the limit is J's, sqrt(11.25). Tolerance as above."""
    ids = ["P1", "Q1", "R1", "S1", "U1"]
    c = 1.0 / 1e-3
    axes = [(None, np.array([0.0, 1.0e-3, 2.0e-3, 3.5e-3, 5e-3]), 0.0)]
    for loud_type, expected in (("pressure", math.sqrt(8.0)), ("displacement", math.sqrt(11.25))):
        target = _target({k: (k[0], loud_type if k == "P1" else "strain") for k in ids})
        rows = resolution(target, SimpleNamespace(channels={k: {} for k in ids}),
                          _proxies(Candidate("ballast_void", 19), axes, "P1", c, ids))
        assert rows[0]["limit"] == pytest.approx(expected / c, rel=1e-4), loud_type


def test_a_stiffness_factor_is_resolved_either_side_on_its_log_axis_and_none_beyond_the_grid():
    """A pad whose signature is c ln(x): softer at exp(-sqrt(1.25) / c), stiffer at exp(+sqrt(1.25) / c); with c
    so small that even the grid's ends (0.1, 10) stay in the margin, no limit (None) and how far was looked."""
    target = _target({"P1": ("p", "pressure")})
    axes = [(None, np.array([0.1, 0.3, 1.0, 3.0, 10.0]), 1.0)]
    rows = resolution(target, SimpleNamespace(channels={"P1": {}}),
                      _proxies(Candidate("rail_pad_stiffness", 20), axes, "P1", 1.0, ["P1"], log=True))
    assert _limit(rows, "rail_pad_stiffness", "softer") == pytest.approx(math.exp(-math.sqrt(1.25)), rel=1e-4)
    assert _limit(rows, "rail_pad_stiffness", "stiffer") == pytest.approx(math.exp(math.sqrt(1.25)), rel=1e-4)
    weak = resolution(target, SimpleNamespace(channels={"P1": {}}),
                      _proxies(Candidate("rail_pad_stiffness", 20), axes, "P1", 0.1, ["P1"], log=True))
    assert [(r["limit"], r["screened_to"]) for r in weak] == [(None, 0.1), (None, 10.0)]


def test_the_report_tabulates_the_limits_in_its_units():
    """report.md's table: a void's peak gap in mm, a stiffness factor as it is, '> end' where not resolved."""
    from orchestrator.inverse.diagnose_report import _resolution_lines

    rows = [{"cause": "ballast_void", "sleeper": 21, "proxy": "uniform", "nominal": 0.0, "limit": 3.2e-5,
             "screened_to": 3.5e-3, "unit": "m"},
            {"cause": "rail_pad_stiffness", "sleeper": 24, "proxy": "softer", "nominal": 1.0, "limit": 0.123,
             "screened_to": 0.1, "unit": "-"},
            {"cause": "rail_pad_stiffness", "sleeper": 24, "proxy": "stiffer", "nominal": 1.0, "limit": None,
             "screened_to": 10.0, "unit": "-"}]
    text = "\n".join(_resolution_lines(SimpleNamespace(answer=SimpleNamespace(resolution=rows))))
    assert "| 21 | 0.032 |" in text and "| rail_pad_stiffness | 24 | 1 | 0.123 | > 10 |" in text, text
    assert _resolution_lines(SimpleNamespace(answer=SimpleNamespace(resolution=None))) == []
