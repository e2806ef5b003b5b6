"""The delete-one-sensor-group jackknife of a linearised least-squares fit, and what it needs.

Used for every reported interval of a diagnosis: a named cause's
(:mod:`orchestrator.inverse.uncertainty`, whose module doc, term 2, gives the method and its
references) and the nuisance estimates' (:mod:`orchestrator.inverse.nuisance`). Its own
module so that both can use it without importing each other. No runs: everything works on
the Jacobian and the residuals at the fit, in the fit's unit cube.
"""
from __future__ import annotations

import numpy as np

RCOND = 1e-10        # eigenvalues of J^T J below this x the largest: a direction the data do not see
BOUND_TOL = 0.01     # a parameter this close to a face of the unit cube is on it: half the Jacobian's step
#                      (fitting.STEP), closer than the forward difference resolves


def group_jackknife(jac: np.ndarray, r: np.ndarray, groups: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, int]:
    """Delete-one-sensor-group jackknife variance of the fitted unit-cube point (no runs; the method:
    :mod:`orchestrator.inverse.uncertainty`, module doc, 2.).

    Parameters
    ----------
    jac : ndarray, shape (n, k)
        Jacobian of the weighted residuals in the unit cube at ``u``.
    r : ndarray, shape (n,)
        The weighted residuals at ``u``.
    groups : ndarray, shape (n,)
        Sensor group of each residual entry.
    u : ndarray, shape (k,)
        The fitted point (the refits are clipped to ``[0, 1]`` as the bounded refit would be).

    Returns
    -------
    (ndarray, int)
        ``(G - 1) / G * sum_g (u_(-g) - u)^2`` per parameter, and G, the groups holding
        residual (a variance of zeros when G < 2).
    """
    groups = np.asarray(groups)
    labels = [g for g in dict.fromkeys(groups.tolist()) if np.any(r[groups == g] != 0.0)]
    if len(labels) < 2:
        return np.zeros(jac.shape[1]), len(labels)
    free = ~held_at_bound(jac, r, u)
    jf = jac[:, free]
    a_all, grad_all = jf.T @ jf, jf.T @ r
    top = max(float(np.linalg.eigvalsh(a_all).max()), 1e-300) if free.any() else 1.0
    shifts = []
    for g in labels:
        m = groups == g
        lam, vec = np.linalg.eigh(a_all - jf[m].T @ jf[m])
        inv = np.where(lam > RCOND * top, 1.0 / np.maximum(lam, 1e-300), 0.0)   # unseen without g: no refit
        step = np.zeros_like(u)
        step[free] = -((vec * inv) @ vec.T) @ (grad_all - jf[m].T @ r[m])
        shifts.append(np.clip(u + step, 0.0, 1.0) - u)
    n_g = len(labels)
    return (n_g - 1) / n_g * np.sum(np.square(shifts), axis=0), n_g


def group_half_width(var_groups: np.ndarray, n_groups: int) -> np.ndarray:
    """The 90 % half-width of the groups' spread, ``t_{0.95,G-1} sd_groups`` (few clusters: the Student
    quantile; :mod:`orchestrator.inverse.uncertainty`, module doc, 2.); needs ``n_groups >= 2``."""
    from scipy.special import stdtrit   # Student-t quantile (scipy.stats costs ~1 s to import)

    return float(stdtrit(n_groups - 1, 0.95)) * np.sqrt(np.maximum(var_groups, 0.0))


def held_at_bound(jac: np.ndarray, r: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Parameters the bounded fit holds on a face of the cube: within :data:`BOUND_TOL` of it, the gradient pushing out.

    A bounded refit keeps them there (a void point resting on the bed stays at gap 0),
    so the linearised refits and the held-nuisance shifts move only the others; letting
    them cross the face would let the free ones compensate a move the fit cannot make.
    """
    grad = jac.T @ r      # d(|r|^2 / 2) / du: descent is -grad
    return ((u <= BOUND_TOL) & (grad > 0)) | ((u >= 1.0 - BOUND_TOL) & (grad < 0))


def residual_groups(target, cmp) -> np.ndarray:
    """The sensor group of each entry of ``target.weighted_residuals(cmp)`` (same channel order and lengths)."""
    return np.concatenate([np.full(np.asarray(cmp.residuals[k]).size, target.layout.groups[k], dtype=object)
                           for k in cmp.channels])


__all__ = ["group_half_width", "group_jackknife", "held_at_bound", "residual_groups", "RCOND", "BOUND_TOL"]
