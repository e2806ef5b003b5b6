"""How well a named cause's parameters are determined: 90 % intervals, identifiability, which sensor would pin them.

The interval is the wider of two linearised spreads — noise plus held nuisance parameters
(1 + 3 below), and the disagreement between sensor groups (2) —, all in the unit cube the
fit works in (:class:`orchestrator.inverse.selection.CauseFitter`). Measured on ten
field-like benchmark passages re-diagnosed (seeds 7000/7101; truth from another model):
26/27 intervals contain the truth, 12/27 with term 1 alone.

1. **Noise** (the model is right, the residual is correlated noise)::

       Cov(u) = tau * s^2 * (J^T J)^-1,   s^2 = |r|^2 / (N - k),   tau = N / N_eff

   ``r`` are the weighted residuals at the fitted point (their sum of squares is the
   least-squares counterpart of J), ``J`` their forward-difference Jacobian (the fit's own
   step, :data:`orchestrator.inverse.fitting.STEP`), ``s^2`` the residual variance per
   sample, and ``tau`` the integrated autocorrelation time of the residual
   (:mod:`orchestrator.inverse.significance`): N correlated samples carry the information
   of N_eff independent ones, so the variance of a least-squares estimate grows by
   N / N_eff (exact for a slowly varying Jacobian). Half-width ``Z90 sd``.
2. **Sensor groups disagree** (model-form error: field data come from another model —
   other vehicle, damping, time step, void shape —, so each sensor group's best fit is a
   different value and the joint fit is a compromise none of them confirms): the
   delete-one-group jackknife (Efron & Stein 1981; with groups as clusters it is the
   cluster-robust variance of Cameron & Miller 2015, J. Human Resources 50(2), with the
   leverage of each group kept) of the refit with one sensor group (A-F) held out — the
   held-out check the naming rule already makes
   (:mod:`orchestrator.inverse.significance`), here linearised, so **no runs**::

       u_(-g) = clip(u - (J^T J - J_g^T J_g)^+ (J^T r - J_g^T r_g), 0, 1)
       Var(u) = (G - 1) / G * sum_g (u_(-g) - u)^2

   (one Gauss-Newton step of the bounded refit without group g from the fit; exact for a
   linear model; ``^+`` the inverse on the directions the remaining groups see: a
   direction only group g sees has no refit without it and adds nothing, the noise term
   then stands; a parameter the fit holds on a bound with the gradient pushing out —
   a void point resting on the bed — stays there, :func:`held_at_bound`, and so it does
   in term 3). The spread is taken about the fit, not about the jackknife mean: the
   interval is centred on the fit, and a fit the trust region left short of its optimum
   (``J^T r != 0``) widens it by the step it did not take. Groups' residuals are
   independent given the model only if whole groups are the clusters (the channels of a
   group share their position and model-form error), so G is small (six): the half-width
   is the Student quantile ``t_{0.95, G-1} sd`` (Cameron & Miller's few-cluster advice).

3. **Nuisance parameters** (a model-form error all groups share, invisible to 2.: the
   cause is fitted with the vehicle and the track damping held at the nuisance stage's
   values, :mod:`orchestrator.inverse.nuisance`, mostly their nominal ones since the data
   rarely identify them; a heavier wheelset or a faster passage raises the impact load
   as a steeper nose does, so a held nuisance error moves the cause's best fit). The
   fit's error from a held nuisance error ``d_theta`` is, linearised,
   ``S d_theta``, ``S = -(J^T J)^+ J^T J_n``, so term 1 becomes::

       Cov(u) = tau s^2 (J^T J)^+ + S Sigma_n S^T

   with ``J_n`` the secant of the residuals over one prior standard deviation of each
   nuisance parameter at the fitted cause (:data:`NUISANCE_SD`: the
   :data:`orchestrator.inverse.nuisance.PRIORS` ranges read as uniform priors, sd = range
   / sqrt(12); one run each, :func:`nuisance_jacobian`). The prior, not the nuisance
   stage's own interval, is used: that interval was estimated without the cause and
   with the same single-model assumption this term is there to relax. The speed's prior
   is the nuisance stage's +-0.5 % about its estimate from the data (sd 0.3 %).

Each entry's 90 % interval is ``u +- max(Z90 sd_1+3, t sd_2)``: each spread is an
estimate of the same sampling spread under a different assumption (the model is right up
to the nuisance parameters / the groups are exchangeable), and the interval must hold
under either. Clipped to the bounds and mapped to the parameter's units (log axis for
stiffness factors: the interval is then asymmetric in the factor). Directions the data
do not see (eigenvalues of ``J^T J`` below :data:`RCOND` x the largest) get an infinite
variance. Cost: the Jacobian at the fit (up to k runs, mostly cached from the fit) and
one run per nuisance parameter (six with the default vehicle) per named cause; the
groups' term needs none.

A parameter is **not identifiable** when its interval covers at least :data:`IDENT_SHARE`
of its bounds (in the unit cube, i.e. on the log axis for stiffness factors): the data
leave it anywhere in half of what is plausible. The report then says which sensor would
pin it (:func:`pinning_sensor`): for a void gap, a pressure cell under that point of the
sleeper; for one sleeper's pads, an accelerometer at that sleeper's rail seat; for a
global scale, sensors on sleepers away from the crossing; for the impact angle, a
crossing-rail accelerometer at the nose.
"""
from __future__ import annotations

import numpy as np

from orchestrator.inputs.causes import kind_of
from orchestrator.inverse.jackknife import (BOUND_TOL, RCOND, group_half_width, group_jackknife, held_at_bound,
                                            residual_groups)

Z90 = 1.6449         # two-sided 90 % quantile of the standard normal
IDENT_SHARE = 0.5    # an interval covering this share of the bounds (unit cube) or more: not identifiable
UNIFORM_SD = 1.0 / np.sqrt(12.0)   # sd of a uniform prior over a range of width 1


def _prior_sd() -> dict:
    """Nuisance parameter -> (catalogue cause, prior sd of its relative change; log axis or linear)."""
    from orchestrator.inverse.nuisance import PRIORS

    return {name: (cause, (np.log(b / a) if log else b - a) * UNIFORM_SD, bool(log))
            for name, (cause, (a, b), log) in PRIORS.items()}


def unit_covariance(jac: np.ndarray, r: np.ndarray, n_eff: float) -> np.ndarray:
    """Cov(u) = tau s^2 (J^T J)^-1 (module doc); infinite variance along unseen directions."""
    n, k = jac.shape
    s2 = float(r @ r) / max(n - k, 1)
    tau = n / max(n_eff, 1.0)
    lam, vec = np.linalg.eigh(jac.T @ jac)
    top = max(float(lam.max()), 1e-300)
    seen = lam > RCOND * top
    inv = np.where(seen, 1.0 / np.maximum(lam, 1e-300), 0.0)
    cov = (vec * inv) @ vec.T
    # a parameter with a share of an unseen direction (above round-off) is not determined at all
    blind = ((vec ** 2)[:, ~seen] > 1e-12).any(axis=1)
    cov[blind, blind] = np.inf
    return tau * s2 * cov


def nuisance_jacobian(fitter, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Secants of the weighted residuals over one prior sd of each nuisance parameter at the fitted cause.

    One run per nuisance parameter the scenario has (module doc, 3.); a parameter whose
    run fails or that the vehicle does not have is left out.

    Returns
    -------
    (ndarray, ndarray)
        ``J_n`` (n, m) per unit of the parameters' prior sd, and those sds (all ones: the
        columns are already scaled).
    """
    from orchestrator.inputs.causes import CATALOGUE
    from orchestrator.inverse.screening import checked_comparison

    c = fitter.start.candidate
    kind = kind_of(c)
    u = np.clip(kind.to_unit(values), 0.0, 1.0)
    r0 = fitter.residuals([u])[0]
    at_fit = kind.apply(fitter.raw, c.sleeper, kind.from_unit(u))
    raws, names = [], []
    for name, (cause, sd, log) in _prior_sd().items():
        try:
            x = float(CATALOGUE[cause].nominal(at_fit, None)[0])
        except ValueError:
            continue
        sd = -sd if name == "speed" else sd   # slower: the run is longer (the same stretch), the record stays covered
        raws.append(CATALOGUE[cause].apply(at_fit, None, [x * (np.exp(sd) if log else 1.0 + sd)]))
        names.append(name)
    fitter.pool.expect(len(raws))
    cols = []
    for cmp, _ in fitter.pool.map(raws, then=lambda run: checked_comparison(fitter.target, run, fitter.reference)) \
            if raws else []:
        if cmp is not None:
            cols.append(fitter.target.weighted_residuals(cmp) - r0)
    jn = np.column_stack(cols) if cols else np.zeros((r0.size, 0))
    return jn, np.ones(jn.shape[1])


def nuisance_covariance(jac: np.ndarray, jac_nuis: np.ndarray, sd: np.ndarray,
                        free: np.ndarray | None = None) -> np.ndarray:
    """``S Sigma_n S^T``, ``S = -(J^T J)^+ J^T J_n``: the fit's spread from held nuisance errors (module doc, 3.).

    ``jac_nuis`` per unit of the nuisance parameters (``sd`` their prior sds in those units).
    ``free``: the parameters the fit moves (default all; :func:`held_at_bound` gives the
    others, whose rows of S are 0). Unseen directions of ``J^T J`` are left to
    :func:`unit_covariance` (infinite there).
    """
    k = jac.shape[1]
    free = np.ones(k, bool) if free is None else np.asarray(free, bool)
    if jac_nuis.shape[1] == 0 or not free.any():
        return np.zeros((k, k))
    jf = jac[:, free]
    lam, vec = np.linalg.eigh(jf.T @ jf)
    top = max(float(lam.max()), 1e-300)
    inv = np.where(lam > RCOND * top, 1.0 / np.maximum(lam, 1e-300), 0.0)
    sens = np.zeros((k, jac_nuis.shape[1]))
    sens[free] = -((vec * inv) @ vec.T) @ (jf.T @ jac_nuis)
    return (sens * np.square(sd)) @ sens.T


def half_widths(cov_u: np.ndarray, var_groups: np.ndarray | None = None, n_groups: int = 0) -> dict:
    """Unit-cube half-widths of the 90 % intervals (module doc): ``max(Z90 sd_noise, t_{0.95,G-1} sd_groups)``.

    Returns
    -------
    dict
        ``{"noise": [...], "sensor_groups": [...] or None, "half": ndarray}`` (the first two as
        lists, ``inf`` for an unseen direction).
    """
    noise = Z90 * np.sqrt(np.maximum(np.diag(cov_u), 0.0))
    if var_groups is None or n_groups < 2:
        return {"noise": noise.tolist(), "sensor_groups": None, "half": noise}
    grp = group_half_width(var_groups, n_groups)
    return {"noise": noise.tolist(), "sensor_groups": grp.tolist(), "half": np.maximum(noise, grp)}


def intervals(candidate, values: np.ndarray, cov_u: np.ndarray, half: np.ndarray | None = None) -> dict:
    """90 % intervals, identifiability and the pinning sensors of a fitted cause (module doc).

    ``half``: the unit-cube half-widths (:func:`half_widths`); default ``Z90 sd`` of ``cov_u``.

    Returns
    -------
    dict
        ``{"level": 0.9, "intervals": [[lo, hi], ...], "identifiable": [bool, ...],
        "unit_width": [...], "pin_with": [str, ...]}`` per entry of the parameter vector
        (units of the cause's scenario keys).
    """
    kind = kind_of(candidate)
    u = np.clip(kind.to_unit(values), 0.0, 1.0)
    if half is None:
        half = Z90 * np.sqrt(np.maximum(np.diag(cov_u), 0.0))
    lo, hi = np.clip(u - half, 0.0, 1.0), np.clip(u + half, 0.0, 1.0)
    lo_v, hi_v = kind.from_unit(lo), kind.from_unit(hi)
    width = hi - lo
    ident = [bool(w < IDENT_SHARE) for w in width]
    pins = sorted({pinning_sensor(candidate, i) for i, ok in enumerate(ident) if not ok})
    return {"level": 0.9, "intervals": [[float(a), float(b)] for a, b in zip(lo_v, hi_v)],
            "identifiable": ident, "unit_width": [float(w) for w in width], "pin_with": pins}


def pinning_sensor(candidate, index: int, n_points: int | None = None) -> str:
    """Which sensor would pin entry ``index`` of a cause's parameters (module doc)."""
    kind = kind_of(candidate)
    n = n_points or len(kind.names)
    if candidate.sleeper is not None and kind.vector:
        return (f"a pressure cell under sleeper {candidate.sleeper} at gap point {index + 1} of {n} "
                f"(counted from its lower-y end)")
    if candidate.sleeper is not None:
        return f"an accelerometer at sleeper {candidate.sleeper}'s rail seats"
    if kind.unit == "rad":
        return "a crossing-rail accelerometer or strain gauge at the nose"
    return "pressure cells and sleeper accelerometers on sleepers away from the crossing"


def cause_uncertainty(fitter, values: np.ndarray, n_eff: float) -> dict:
    """Intervals of a fitted cause from its fitter's runs (module doc; runs: the Jacobian at ``values``, up
    to k, and one per nuisance parameter).

    ``unit_half_width`` reports each spread (unit cube; ``None`` for an unseen direction,
    or for the groups' when fewer than two groups hold residual): ``noise`` (term 1 alone,
    the earlier interval), ``noise_and_nuisance`` (1 + 3) and ``sensor_groups`` (2).
    """
    jac, r = fitter.jacobian(values)
    cov = unit_covariance(jac, r, n_eff * r.size / max(fitter.start.cmp.n, 1))
    u = np.clip(kind_of(fitter.start.candidate).to_unit(values), 0.0, 1.0)
    jn, sd = nuisance_jacobian(fitter, values)
    cov_n = cov + nuisance_covariance(jac, jn, sd, ~held_at_bound(jac, r, u))
    cmp = fitter.runs([u])[0]
    groups = residual_groups(fitter.target, cmp) if cmp is not None else None
    if groups is not None and groups.size == r.size:
        var_g, n_g = group_jackknife(jac, r, groups, u)
    else:   # a failed run at the fit (a penalty residual): no group structure to use
        var_g, n_g = None, 0
    hw = half_widths(cov_n, var_g, n_g)
    out = intervals(fitter.start.candidate, values, cov_n, hw["half"])
    hw["noise_and_nuisance"], hw["noise"] = hw["noise"], (Z90 * np.sqrt(np.maximum(np.diag(cov), 0.0))).tolist()
    out["unit_half_width"] = {k: None if hw[k] is None else [x if np.isfinite(x) else None for x in hw[k]]
                              for k in ("noise", "noise_and_nuisance", "sensor_groups")}
    out["sensor_groups"], out["nuisance_runs"] = n_g, int(jn.shape[1])
    return out


__all__ = ["unit_covariance", "nuisance_jacobian", "nuisance_covariance", "group_jackknife", "held_at_bound",
           "residual_groups", "half_widths", "intervals", "pinning_sensor", "cause_uncertainty", "Z90",
           "IDENT_SHARE", "RCOND", "UNIFORM_SD", "BOUND_TOL"]
