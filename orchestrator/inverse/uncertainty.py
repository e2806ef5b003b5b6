"""How well a named cause's parameters are determined: 90 % intervals, identifiability, which sensor would pin them.

The interval is Jacobian-based (the linearised least-squares covariance) in the unit
cube the fit works in (:class:`orchestrator.inverse.selection.CauseFitter`)::

    Cov(u) = tau * s^2 * (J^T J)^-1,   s^2 = |r|^2 / (N - k),   tau = N / N_eff

``r`` are the weighted residuals at the fitted point (their sum of squares is the
least-squares counterpart of J), ``J`` their forward-difference Jacobian (the fit's own
step, :data:`orchestrator.inverse.fitting.STEP`), ``s^2`` the residual variance per
sample (model-form error included: it is estimated, not assumed), and ``tau`` the
integrated autocorrelation time of the residual (:mod:`orchestrator.inverse.significance`):
N correlated samples carry the information of N_eff independent ones, so the variance
of a least-squares estimate grows by N / N_eff (exact for a slowly varying Jacobian).
The 90 % interval is ``u +- 1.645 sd`` (two-sided normal quantile), clipped to the
bounds and mapped to the parameter's units (log axis for stiffness factors: the interval
is then asymmetric in the factor). Directions the data do not see (eigenvalues of
``J^T J`` below :data:`RCOND` x the largest) get an infinite variance.

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

Z90 = 1.6449         # two-sided 90 % quantile of the standard normal
IDENT_SHARE = 0.5    # an interval covering this share of the bounds (unit cube) or more: not identifiable
RCOND = 1e-10        # eigenvalues of J^T J below this x the largest: a direction the data do not see


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


def intervals(candidate, values: np.ndarray, cov_u: np.ndarray) -> dict:
    """90 % intervals, identifiability and the pinning sensors of a fitted cause (module doc).

    Returns
    -------
    dict
        ``{"level": 0.9, "intervals": [[lo, hi], ...], "identifiable": [bool, ...],
        "unit_width": [...], "pin_with": [str, ...]}`` per entry of the parameter vector
        (units of the cause's scenario keys).
    """
    kind = kind_of(candidate)
    u = np.clip(kind.to_unit(values), 0.0, 1.0)
    sd = np.sqrt(np.maximum(np.diag(cov_u), 0.0))
    lo, hi = np.clip(u - Z90 * sd, 0.0, 1.0), np.clip(u + Z90 * sd, 0.0, 1.0)
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
    """Intervals of a fitted cause from its fitter's runs (a Jacobian at ``values``: up to n more runs)."""
    jac, r = fitter.jacobian(values)
    cov = unit_covariance(jac, r, n_eff * r.size / max(fitter.start.cmp.n, 1))
    return intervals(fitter.start.candidate, values, cov)


__all__ = ["unit_covariance", "intervals", "pinning_sensor", "cause_uncertainty", "Z90", "IDENT_SHARE", "RCOND"]
