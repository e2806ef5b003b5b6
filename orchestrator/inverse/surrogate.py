"""The response surface of the calibration: fit with cross-validation, sensitivity, optimisation, designs.

Part of :mod:`orchestrator.inverse.calibrate` (its module docstring describes the
pipeline): stage 2, the polyharmonic-spline surrogate and its k-fold CV
(:func:`fit_surrogate`, :func:`fit_objective`); stage 3, the profiles through the
surrogate's minimiser and the narrowed box (:func:`sensitivity`); stage 5, the bounded
multistart minimisation (:func:`minimise_surrogate`); and the designs the runs are
placed on (Latin hypercube, box corners). Everything works on the unit cube; nothing
here runs a simulation.
"""
from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

__all__ = ["Surrogate", "fit_surrogate", "fit_objective", "minimise_surrogate", "multistarts", "sensitivity",
           "latin_hypercube", "corners", "TRANSFORMS"]

OBJECTIVE = "objective"  # the objective's name (the run function's scalar that is minimised)
KERNEL = "thin_plate_spline"  # polyharmonic spline r^2 log r (with its linear polynomial tail)
SMOOTHINGS = (0.0, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0)  # candidates, on standardised values in the unit cube
CV_FOLDS = 5  # k of the k-fold cross-validation
NARROW_CV_FACTOR = 2.0  # tau = this x the local CV RMSE: the profile rise the surrogate can resolve
LOCAL_SHARE = 0.1  # "local" CV error: over the runs in this lowest share of J (at least LOCAL_MIN of them)
LOCAL_MIN = 5
NARROW_KEEP_BEST = 5  # the narrowed box holds this many best runs
NARROW_MARGIN = 0.05  # unit-cube padding on each side of a narrowed interval
NARROW_MIN_WIDTH = 0.1  # smallest narrowed interval (unit cube)
PROFILE_POINTS = 101  # points per axis of a sensitivity profile
MAX_CORNER_DIM = 12  # 2^k corners only up to k = 12 (4096 runs)
N_STARTS_BEST = 8  # multistart: the best runs in the box ...
N_STARTS_RANDOM = 8  # ... and random points in the box
OPT_MAXITER = 400  # trust-constr iterations per start
LOG_FLOOR = 1e-12  # surrogate of log(J): J is floored here (J = 0 only for noise-free identity)


# ======================================================================================
# Response surface
# ======================================================================================
@dataclass
class Surrogate:
    """A polyharmonic-spline response surface on the unit cube, smoothing chosen by k-fold CV.

    Call it with points ``U`` of shape (n, k) to get predictions of shape (n,) (one
    output) or (n, m).

    Attributes
    ----------
    names : list of str
        The outputs (m of them).
    smoothing : float
        The chosen smoothing (on standardised outputs).
    cv_rmse : ndarray, shape (m,)
        RMSE of the held-out predictions, in the outputs' units.
    cv_rel : ndarray, shape (m,)
        ``cv_rmse`` / standard deviation of the output over the points.
    cv_pred : ndarray, shape (n, m)
        The held-out prediction of every point (at the chosen smoothing).
    cv_table : dict
        Smoothing -> mean standardised CV RMSE over the outputs (what chose the smoothing).
    values : ndarray, shape (n, m)
        The fitted values.
    transform : str
        The outputs were fitted as y, log(y) or y^2 (predictions are transformed back).
    """

    names: list
    smoothing: float
    cv_rmse: np.ndarray
    cv_rel: np.ndarray
    cv_pred: np.ndarray
    cv_table: dict
    transform: str
    values: np.ndarray = field(repr=False, default=None)
    candidates: dict | None = None
    _rbf: Any = field(repr=False, default=None)
    _mean: np.ndarray = field(repr=False, default=None)
    _std: np.ndarray = field(repr=False, default=None)
    _single: bool = field(repr=False, default=True)

    def __call__(self, U) -> np.ndarray:
        U = np.atleast_2d(np.asarray(U, float))
        y = _backward(self._rbf(U) * self._std + self._mean, self.transform)
        return y[:, 0] if self._single else y

    def summary(self) -> dict:
        """JSON-able description of J's surrogate (``surrogate`` in ``calibration.json``): points, smoothing,
        CV errors (all, relative, local), the CV table, folds and the transform with its candidates."""
        return {"points": int(self.cv_pred.shape[0]), "smoothing": self.smoothing, "cv_rmse": float(self.cv_rmse[0]),
                "cv_rel": float(self.cv_rel[0]), "local_cv_rmse": float(self.local_cv_rmse()[0]),
                "local_share": LOCAL_SHARE, "cv_table": {repr(k): v for k, v in self.cv_table.items()},
                "folds": CV_FOLDS, "transform": self.transform, "transforms": self.candidates}

    def local_cv_rmse(self, share: float = LOCAL_SHARE, minimum: int = LOCAL_MIN) -> np.ndarray:
        """CV RMSE over the points whose value is in the lowest ``share`` (per output), shape (m,)."""
        n = self.values.shape[0]
        m = min(n, max(minimum, int(math.ceil(share * n))))
        idx = np.argsort(self.values, axis=0)[:m]
        err = np.take_along_axis(self.cv_pred - self.values, idx, axis=0)
        return np.sqrt(np.mean(err ** 2, axis=0))


TRANSFORMS = ("none", "log", "square")


def _forward(y: np.ndarray, transform: str) -> np.ndarray:
    if transform == "log":
        return np.log(np.maximum(y, LOG_FLOOR))
    return y * y if transform == "square" else y


def _backward(z: np.ndarray, transform: str) -> np.ndarray:
    if transform == "log":
        return np.exp(z)
    return np.sqrt(np.maximum(z, 0.0)) if transform == "square" else z


def _folds(n: int, k: int, rng: np.random.Generator) -> list[np.ndarray]:
    """A random split of ``range(n)`` into ``min(k, n)`` folds."""
    return np.array_split(rng.permutation(n), min(k, n))


def fit_surrogate(U, Y, names: Sequence[str] | None = None, *, transform: str = "none", folds: int = CV_FOLDS,
                  smoothings: Sequence[float] = SMOOTHINGS, seed: int = 0, kernel: str = KERNEL) -> Surrogate:
    """Fit a polyharmonic-spline surrogate; choose its smoothing by k-fold cross-validation.

    Parameters
    ----------
    U : array_like, shape (n, k)
        Points in the unit cube.
    Y : array_like, shape (n,) or (n, m)
        Values; all outputs share one smoothing, chosen on standardised values.
    names : sequence of str, optional
        Output names (default ``y0, y1, ...``).
    transform : {"none", "log", "square"}
        Fit Y, log(Y) (positive outputs spanning decades) or Y^2 (non-negative outputs
        with a cone-shaped minimum, such as an RMSE: its square is smooth there);
        predictions are transformed back.
    folds : int
        k of the k-fold CV.
    smoothings : sequence of float
        Candidate smoothings of :class:`scipy.interpolate.RBFInterpolator`.
    seed : int
        Seed of the fold assignment.
    kernel : str

    Returns
    -------
    Surrogate
        Fitted on all points at the smoothing with the least mean standardised CV RMSE.
    """
    from scipy.interpolate import RBFInterpolator

    U = np.asarray(U, float)
    Y = np.asarray(Y, float)
    single = Y.ndim == 1
    Y2 = Y[:, None] if single else Y
    n, m = Y2.shape
    if n < U.shape[1] + 2 or n < folds:
        raise ValueError(f"{n} points are too few for a surrogate in {U.shape[1]} dimensions")
    if transform not in TRANSFORMS:
        raise ValueError(f"transform must be one of {', '.join(TRANSFORMS)}, got {transform!r}")
    Z = _forward(Y2, transform)
    mean, std = Z.mean(axis=0), Z.std(axis=0)
    std = np.where(std > 0, std, 1.0)
    Zs = (Z - mean) / std
    table, preds = _cross_validate(U, Zs, _folds(n, folds, np.random.default_rng(seed)), smoothings, kernel)
    best = min(table, key=table.get)
    cv_pred = _backward(preds[best] * std + mean, transform)
    cv_rmse = np.sqrt(np.mean((cv_pred - Y2) ** 2, axis=0))
    spread = Y2.std(axis=0)
    cv_rel = np.where(spread > 0, cv_rmse / np.where(spread > 0, spread, 1.0), np.nan)
    rbf = RBFInterpolator(U, Zs, smoothing=best, kernel=kernel)
    return Surrogate(list(names) if names is not None else [f"y{i}" for i in range(m)], best, cv_rmse, cv_rel,
                     cv_pred, table, transform, Y2.copy(), _rbf=rbf, _mean=mean, _std=std, _single=single)


def _cross_validate(U: np.ndarray, Zs: np.ndarray, parts: list[np.ndarray], smoothings: Sequence[float],
                    kernel: str) -> tuple[dict, dict]:
    """Held-out predictions of standardised values ``Zs`` (n, m) at each smoothing.

    Returns ``table`` (smoothing -> RMSE of the held-out predictions, ``inf`` where a fit
    is singular) and ``preds`` (smoothing -> predictions, shape (n, m)).
    """
    from scipy.interpolate import RBFInterpolator

    n = Zs.shape[0]
    table, preds = {}, {}
    for s in smoothings:
        P = np.empty_like(Zs)
        for test in parts:
            train = np.setdiff1d(np.arange(n), test)
            try:
                P[test] = RBFInterpolator(U[train], Zs[train], smoothing=s, kernel=kernel)(U[test])
            except np.linalg.LinAlgError:  # singular at this smoothing: not a candidate
                P[:] = np.nan
                break
        err = float(np.sqrt(np.mean((P - Zs) ** 2))) if np.all(np.isfinite(P)) else math.inf
        table[float(s)], preds[float(s)] = err, P
    return table, preds


def fit_objective(U, y, transforms: Sequence[str] = TRANSFORMS, seed: int = 0) -> Surrogate:
    """The objective's surrogate: :func:`fit_surrogate` with the transform of least local CV error.

    J is an average of RMSEs: a cone at its minimum (rounded only by the noise), a
    plateau far from it. Which transform a spline follows best depends on the design,
    so each candidate is cross-validated and the one that predicts the best runs
    best (:meth:`Surrogate.local_cv_rmse`, the error where the optimum is sought) is kept.
    ``candidates`` on the result lists every transform's (smoothing, CV RMSE, local CV RMSE).
    """
    fits = {t: fit_surrogate(U, y, [OBJECTIVE], transform=t, seed=seed) for t in transforms}
    best = min(fits, key=lambda t: float(fits[t].local_cv_rmse()[0]))
    s = fits[best]
    s.candidates = {t: {"smoothing": f.smoothing, "cv_rmse": float(f.cv_rmse[0]),
                        "local_cv_rmse": float(f.local_cv_rmse()[0])} for t, f in fits.items()}
    return s


# ======================================================================================
# Optimisation and sensitivity on the surrogate
# ======================================================================================
def minimise_surrogate(f: Callable, lower, upper, starts, maxiter: int = OPT_MAXITER) -> tuple[np.ndarray, float, list]:
    """Bounded interior-point minimisation of a surrogate from several starts.

    Parameters
    ----------
    f : callable
        ``f(U) -> (n,)`` for points ``U`` of shape (n, k).
    lower, upper : array_like, shape (k,)
        The box (unit coordinates).
    starts : array_like, shape (s, k)
        Start points (clipped into the box).
    maxiter : int

    Returns
    -------
    u : ndarray, shape (k,)
        The best minimiser found.
    value : float
        ``f(u)``.
    runs : list of dict
        Per start: ``start``, ``u``, ``value``, ``iterations``, ``status``.
    """
    from scipy.optimize import BFGS, Bounds, minimize

    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    bounds = Bounds(lower, upper)
    fun = lambda x: float(f(x[None, :])[0])  # noqa: E731
    runs = []
    for x0 in np.atleast_2d(starts):
        x0 = np.clip(np.asarray(x0, float), lower, upper)
        # trust-constr treats the bounds as inequality constraints: its interior-point
        # (barrier) algorithm; gradients by finite differences, Hessian by BFGS updates.
        with warnings.catch_warnings():
            # BFGS warns when a step leaves the gradient unchanged (a flat or converged spot): harmless here
            warnings.filterwarnings("ignore", message="delta_grad == 0.0", category=UserWarning)
            res = minimize(fun, x0, method="trust-constr", jac="2-point", hess=BFGS(), bounds=bounds,
                           options={"maxiter": maxiter, "xtol": 1e-9, "gtol": 1e-9})
        u = np.clip(res.x, lower, upper)
        runs.append({"start": x0.tolist(), "u": u.tolist(), "value": fun(u), "iterations": int(res.nit),
                     "status": int(res.status)})
    best = min(runs, key=lambda r: r["value"])
    return np.array(best["u"]), float(best["value"]), runs


def multistarts(U: np.ndarray, y: np.ndarray, lower, upper, rng: np.random.Generator) -> np.ndarray:
    """Multistart points: the best runs inside the box and random points in it.

    ``U`` (n, k) and ``y`` (n,) are the runs; returns up to ``N_STARTS_BEST + N_STARTS_RANDOM`` points, shape (s, k).
    """
    inside = np.all((U >= lower - 1e-12) & (U <= upper + 1e-12), axis=1) & np.isfinite(y)
    order = np.argsort(np.where(inside, y, np.inf))[:min(N_STARTS_BEST, int(inside.sum()))]
    rand = lower + rng.random((N_STARTS_RANDOM, len(lower))) * (np.asarray(upper) - lower)
    return np.vstack([U[order], rand])


def sensitivity(f: Callable, u_star, U: np.ndarray, y: np.ndarray, tau: float) -> dict:
    """Profiles of a surrogate through its minimiser and the narrowed box (module docstring, stage 3).

    Parameters
    ----------
    f : callable
        The surrogate, ``f(U) -> (n,)``.
    u_star : array_like, shape (k,)
        Its minimiser.
    U, y : ndarray, shapes (n, k), (n,)
        The runs (the narrowed box holds the ``NARROW_KEEP_BEST`` best).
    tau : float
        Rise of the objective the surrogate can resolve (``NARROW_CV_FACTOR`` x CV RMSE).

    Returns
    -------
    dict
        ``range`` (k,) profile range per parameter [objective units], ``share`` (k,)
        range / sum of ranges, ``lower``/``upper`` (k,) the narrowed box (unit),
        ``grid`` (PROFILE_POINTS,), ``profiles`` (k, PROFILE_POINTS).
    """
    u_star = np.asarray(u_star, float)
    k = u_star.size
    grid = np.linspace(0.0, 1.0, PROFILE_POINTS)
    profiles = np.empty((k, grid.size))
    for j in range(k):
        P = np.repeat(u_star[None, :], grid.size, axis=0)
        P[:, j] = grid
        profiles[j] = f(P)
    rng_ = profiles.max(axis=1) - profiles.min(axis=1)
    lower, upper = np.empty(k), np.empty(k)
    ok = np.isfinite(y)
    best = U[ok][np.argsort(y[ok])[:NARROW_KEEP_BEST]]
    for j in range(k):
        keep = grid[profiles[j] <= profiles[j].min() + tau]
        lo = min(keep.min(), u_star[j], best[:, j].min()) - NARROW_MARGIN
        hi = max(keep.max(), u_star[j], best[:, j].max()) + NARROW_MARGIN
        lo, hi = max(lo, 0.0), min(hi, 1.0)
        if hi - lo < NARROW_MIN_WIDTH:
            c = min(max(0.5 * (lo + hi), 0.5 * NARROW_MIN_WIDTH), 1.0 - 0.5 * NARROW_MIN_WIDTH)
            lo, hi = c - 0.5 * NARROW_MIN_WIDTH, c + 0.5 * NARROW_MIN_WIDTH
        lower[j], upper[j] = lo, hi
    total = rng_.sum()
    return {"range": rng_, "share": rng_ / total if total > 0 else np.full(k, np.nan), "lower": lower,
            "upper": upper, "grid": grid, "profiles": profiles}


# ======================================================================================
# Designs
# ======================================================================================
def latin_hypercube(k: int, n: int, seed: int) -> np.ndarray:
    """``n`` points of a Latin hypercube in the unit cube of dimension ``k``, shape (n, k)."""
    from scipy.stats import qmc

    try:
        sampler = qmc.LatinHypercube(d=k, rng=np.random.default_rng(seed))
    except TypeError:  # SciPy < 1.15 names the generator "seed"
        sampler = qmc.LatinHypercube(d=k, seed=np.random.default_rng(seed))
    return sampler.random(n)


def corners(lower, upper) -> np.ndarray:
    """The ``2^k`` corners of the box ``[lower, upper]`` (shapes (k,)), shape (2^k, k)."""
    return np.array([[(lo, hi)[b] for b, lo, hi in zip(bits, lower, upper)]
                     for bits in itertools.product((0, 1), repeat=len(lower))])
