"""What a record at the noise level resolves: per screened candidate, the least effect that would have shown.

A ``none`` answer (:mod:`orchestrator.inverse.diagnose`, step 6) says the residual is at the
noise level. The user's next question is how large a defect could be hiding in it: "no void
under sleeper 21 larger than what?". :func:`resolution` answers it from the screening runs the
diagnosis already made (round 1, :attr:`orchestrator.inverse.selection.Round.proxies`; no runs).

For every candidate and each of its screening proxies (a void's uniform gap and its two
wedges; a stiffness factor softer and stiffer than nominal; the impact angle either side of
its nominal value), the effect's signature on channel c is the model's change

    d_c(x) = s_c(x) - s_c(x0)

between the reference (the model the causes are added to, at magnitude x0) and the candidate
at magnitude x, the signals taken linear in the screening axis between screening magnitudes
(in log x for stiffness factors, as :func:`orchestrator.inverse.screening.dense_search`
interpolates them). A record that held this effect, and otherwise only the noise measured on
this record, would leave against the reference model per channel a residual of mean square

    sigma_c^2 + mean_t d_c(x)^2

(noise and effect independent; sigma_c the channel's noise level as the diagnosis reads it,
:func:`orchestrator.inverse.objective.noise_sigma`), and the diagnosis's ``none`` rule
(:func:`orchestrator.inverse.significance.at_noise_level`) would fail where either

* J(x) from these residuals' nRMSEs exceeds (1 + NONE_MARGIN) x J_noise, or
* a channel other than a reconstructed displacement stands above LOUD_FACTOR x its own
  noise level (:func:`orchestrator.inverse.significance.loudness`): sqrt(1 + mean d_c^2 / sigma_c^2).

Why the noise and not this record's residual r: an effect hiding in the record is already in
r, so "r plus d" asks how much *more* the record could take, which is small whenever r lies near
the rule's edge (tried: 0.24-0.70 x these limits on four of issue 14's field-like nulls; one
void at 1.004 x such a limit was answered ``none``: benchmarks/RESULTS.md, session 40). sigma_c
is read from first differences, which coloured noise and drift pass less than white noise, so a
real record's residual is larger than sigma_c and the limit errs large: on six field-like nulls
(other vehicle, speed, damping, time step, the field chain), a uniform void of the stated limit
hidden in the same truth was named at its sleeper in 18/18 (sleepers 19, 21, 24), one of half the
limit was shown in 15/18, of a quarter in 3/18; a softer pad at its limit was shown in 12/12
(sleepers 20, 21), at half of it (on the log axis) in 3/12 (``benchmarks/bench_resolution.py``).
The void errs more because the naming rule names a void before the residual leaves the margin.

The **limit** is the magnitude nearest x0 at which one of the two first holds; ``None`` when
neither does up to the farthest screened magnitude (the record does not resolve that
candidate within the screened range; ``screened_to`` says how far that is).

What the limit is, and is not:

* It says when the residual would have been *above the noise*, where the diagnosis goes on to
  look for a cause; whether one is then named depends on the naming rule
  (:mod:`orchestrator.inverse.significance`), and an effect that shows may still be answered
  ``unexplained``.
* First order: the signature is the reference model's. The nuisance parameters (time shift,
  speed, vehicle, channel gains), fitted before any cause, can take up part of an effect (a
  limit then reads low). A reconstructed displacement's rule (against its group's
  median, :func:`orchestrator.inverse.significance.standing_out`) is not used: without it a
  limit can only be larger.
* A void's limit is its proxy's *peak* gap; a void of another shape with the same peak moves
  the sleeper less than the uniform gap does. Across shapes the support removed (the mean of the
  six gaps) compares better than the peak: issue 14's off-sensor voids at sleeper 17, one-sided
  and concentrated at the sleeper's end, exceed the linear wedge's peak limit but not its mean
  gap, and were answered ``none`` (benchmarks/RESULTS.md, session 40).
* Only the screened candidates: the sleepers carrying sensors and
  :data:`orchestrator.inverse.diagnose.SENSOR_REACH` beyond them (further when step 3b looked
  further). Of a sleeper outside them the record says nothing here.
"""
from __future__ import annotations

import numpy as np

from orchestrator.inputs.causes import kind_of
from orchestrator.inverse.objective import Comparison, group_weighted
from orchestrator.inverse.significance import LOUD_FACTOR, NONE_MARGIN, noise_objective, normaliser

STEPS = 64     # points per screening interval at which the rule is evaluated (then refined linearly between
               # the two that bracket it): the interval's signals are linear in the axis, so its mean
               # squares are quadratics; 1/64 of an interval is 6 um of a 0.4 mm void step


def _direction(kind, profile, side: str) -> str:
    """A proxy's words: ``uniform`` / ``wedge (gap 1 deepest)`` for a void, ``softer`` / ``stiffer``, ``lower`` /
    ``higher`` for a scalar."""
    if kind.vector:
        if profile is None:
            return "uniform"
        return f"wedge (gap {int(np.argmax(profile)) + 1} deepest)"
    if kind.log:
        return "softer" if side == "below" else "stiffer"
    return "lower" if side == "below" else "higher"


def _moments(base: dict, a: dict, b: dict, ids: list) -> np.ndarray:
    """(3, channels): mean d_a^2, mean d_a d_b, mean d_b^2 over each channel's finite samples, d = signals - base."""
    out = np.zeros((3, len(ids)))
    for j, k in enumerate(ids):
        da, db = np.asarray(a[k], float) - base[k], np.asarray(b[k], float) - base[k]
        ok = np.isfinite(da) & np.isfinite(db)
        if ok.any():
            da, db = da[ok], db[ok]
            out[:, j] = (np.mean(da * da), np.mean(da * db), np.mean(db * db))
    return out


def _rule(ms: np.ndarray, target, ch: tuple, threshold: float) -> np.ndarray:
    """The rule's ratio (>= 1: the residual would be above the noise) at each row of ``ms`` (points, channels: the
    signature's mean square); ``ch``: the channels' (ids, noise levels, 1 / normalisers, judged loud or not)."""
    ids, level, inv, judged = ch
    rms = np.sqrt(level ** 2 + ms)
    J, _ = group_weighted({k: rms[:, j] * inv[j] for j, k in enumerate(ids)}, target.layout.groups,
                          target.layout.weights)
    loud = (rms[:, judged] / level[judged]).max(axis=1) / LOUD_FACTOR if judged.any() else np.zeros(ms.shape[0])
    return np.maximum(np.asarray(J, float) / threshold, loud)


def _limit(kind, xs: list, grid: dict, x0: float, target, ch: tuple, threshold: float) -> float | None:
    """Along the magnitudes ``xs`` (outward from ``x0``), the first magnitude at which the rule holds, or None."""
    ids = ch[0]
    sig0 = {k: np.asarray(grid[x0][k], float) for k in ids}
    u = (lambda x: np.log(x)) if kind.log else (lambda x: x)
    t = np.linspace(0.0, 1.0, STEPS + 1)
    for xa, xb in zip([x0] + xs[:-1], xs):
        m = _moments(sig0, grid[xa], grid[xb], ids)
        ms = np.outer((1 - t) ** 2, m[0]) + np.outer(2 * t * (1 - t), m[1]) + np.outer(t ** 2, m[2])
        r = _rule(ms, target, ch, threshold)
        hit = np.flatnonzero(r >= 1.0)
        if hit.size:
            i = int(hit[0])   # >= 1: at x0 the ratio is the noise's own, 1 / (1 + NONE_MARGIN) and 1 / LOUD_FACTOR
            #                   (J_noise > 0 unless no channel has noise), and each later interval starts where the
            #                   one before ended below 1
            ti = t[i - 1] + (1.0 - r[i - 1]) / (r[i] - r[i - 1]) * (t[i] - t[i - 1])
            v = u(xa) + ti * (u(xb) - u(xa))
            return float(np.exp(v) if kind.log else v)
    return None


def resolution(target, ref: Comparison, proxies: dict) -> list[dict]:
    """Per screened candidate and proxy, the least effect the record would have shown (module doc).

    Parameters
    ----------
    target : Target
        The measured passage (its noise levels, normalisers and layout).
    ref : Comparison
        The reference model's comparison (its channels are the ones judged).
    proxies : dict
        Candidate -> (its screening axes, each proxy's magnitude -> signals on the measured base), as
        :attr:`orchestrator.inverse.selection.Round.proxies` holds them (the reference's signals at x0).

    Returns
    -------
    list of dict
        ``{"cause", "sleeper", "proxy", "nominal", "limit", "screened_to", "unit"}``, by cause and sleeper;
        ``limit`` the magnitude (a void's peak gap, a stiffness factor, an angle) from which the residual would
        have been above the noise, ``None`` when not within ``screened_to``.
    """
    ids = list(ref.channels)
    level = np.array([float(target.sigma[k]) for k in ids])   # the noise level the diagnosis reads
    scale = np.array([normaliser(target, k) for k in ids])
    inv = np.divide(1.0, scale, out=np.zeros_like(scale), where=scale > 0)
    judged = np.array([target.layout.types.get(k) != "displacement" for k in ids]) & (level > 0)
    ch = (ids, level, inv, judged)
    threshold = (1.0 + NONE_MARGIN) * noise_objective(target, ref)
    out = []
    for c in sorted(proxies, key=lambda c: (c.cause, -1 if c.sleeper is None else c.sleeper)):
        kind = kind_of(c)
        axes_c, screened_c = proxies[c]
        for (profile, _, x0), grid in zip(axes_c, screened_c):   # the reference's signals at x0 (selection._screen)
            for side in ("below", "above"):
                xs = sorted((x for x in grid if (x < x0 if side == "below" else x > x0)),
                            key=lambda x: abs(x - x0))
                if not xs:
                    continue
                out.append({"cause": c.cause, "sleeper": c.sleeper, "proxy": _direction(kind, profile, side),
                            "nominal": float(x0), "limit": _limit(kind, xs, grid, x0, target, ch, threshold),
                            "screened_to": float(xs[-1]), "unit": kind.unit})
    return out


def summary(limits: list[dict]) -> str:
    """The ``none`` answer's words on what the record resolves: the uniform void's limits over the sleepers (least
    and most), the sleepers where it is not resolved, and which sleepers were screened at all."""
    voids = [r for r in limits if r["cause"] == "ballast_void" and r["proxy"] == "uniform"]
    if not voids:
        return ""
    sleepers = sorted({r["sleeper"] for r in voids})
    seen = [r for r in voids if r["limit"] is not None]
    words = []
    if seen:
        lo, hi = min(seen, key=lambda r: r["limit"]), max(seen, key=lambda r: r["limit"])
        words.append(f"what can hide in it: a uniform void of {1e3 * lo['limit']:.2g} mm under sleeper {lo['sleeper']} "
                     f"(of {1e3 * hi['limit']:.2g} mm under {hi['sleeper']}) would have lifted the residual above "
                     f"the noise")
    blind = [r["sleeper"] for r in voids if r["limit"] is None]
    if blind:
        words.append(f"under sleeper(s) {', '.join(map(str, blind))} not even one of "
                     f"{1e3 * max(r['screened_to'] for r in voids):.2g} mm")
    span = (f"outside {sleepers[0]}-{sleepers[-1]}" if sleepers == list(range(sleepers[0], sleepers[-1] + 1))
            else f"other than {', '.join(map(str, sleepers))}")
    words.append(f"sleepers {span} were not screened (all limits: resolution)")
    return "; ".join(words)
