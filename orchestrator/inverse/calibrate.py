"""Surrogate calibration of a scenario against a measurement (DESIGN.md §5, as in seed 000).

Pipeline (every stage's runs go through :func:`orchestrator.sweeps.sweep.run_sweep`, so they
are resumable and run on local processes or a Dask cluster):

0. **Parameters** (:func:`parse_params`) are mapped to the unit cube, ``u in [0, 1]^k``;
   stiffness scales on a log scale. Bounds and scales come from the cause catalogue
   (:data:`orchestrator.inverse.causes.CATALOGUE`) unless given. The objective is J of
   :mod:`orchestrator.inverse.objective` (weighted sum over sensor groups of the channels'
   nRMSE), with the time alignment fixed once from the nominal scenario.
1. **Latin hypercube** of ``n1`` runs over the whole cube (:class:`scipy.stats.qmc.LatinHypercube`).
2. **Response surface**: a polyharmonic spline (:class:`scipy.interpolate.RBFInterpolator`,
   thin-plate kernel, linear polynomial tail) of J and, jointly, of every channel's
   nRMSE (:func:`fit_surrogate`). The smoothing is chosen by k-fold cross-validation,
   and so is what is fitted of J: J, log J or J^2, whichever predicts the best runs best
   (:func:`fit_objective`). The CV error is the RMSE of the held-out predictions, also
   given relative to the standard deviation of the values (``cv_rel``: 0 perfect, 1 no
   better than the mean) and over the best runs only (``local_cv_rmse``).
3. **Sensitivity and narrowed bounds** (:func:`sensitivity`): at the surrogate's
   minimiser ``u*`` the surrogate is profiled along each axis; the sensitivity of a
   parameter is the range of its profile. The narrowed interval of a parameter is the
   part of its axis where the profile stays within ``tau`` of its minimum, with
   ``tau = NARROW_CV_FACTOR x`` the surrogate's *local* CV RMSE (over the runs with
   the lowest ``LOCAL_SHARE`` of J: the error where it matters, not at the far
   corners where J is large and the spline's error with it): a rise of the profile
   smaller than that is not resolved,
   widened to hold the ``NARROW_KEEP_BEST`` best runs, padded by ``NARROW_MARGIN`` on
   each side and at least ``NARROW_MIN_WIDTH`` wide (all in unit coordinates).
   A parameter the objective hardly sees keeps its whole range.
4. **Second Latin hypercube** of ``n2`` runs in the narrowed box plus its ``2^k``
   corners; the surrogates are refitted on every run of stages 1 and 4.
5. **Optimisation** of the surrogate in the narrowed box: bounded interior-point
   :func:`scipy.optimize.minimize` (``method="trust-constr"``), started from the best
   runs and from random points (:func:`minimise_surrogate`).
6. **Confirmation**: the optimum is simulated (with the nominal scenario, for the
   before/after comparison).
7. **Polish** (added to the seed's procedure; ``polish=0`` leaves it out): bounded
   least squares on real runs (:func:`orchestrator.inverse.fitting.fit_unit_cube`, ``trf`` over
   the *whole* unit cube, the finite-difference Jacobian's ``k`` runs in parallel) of
   the weighted residual vector whose sum of squares is J's least-squares counterpart
   (:meth:`orchestrator.inverse.objective.Target.weighted_residuals`), started from the better of
   the confirmed optimum and the best run of the design, and again from the nominal
   scenario. Why: with 8 parameters a 1256-run spline resolves J only to its CV error
   (~30 % of J's spread, measured), and near the optimum the void gaps move J by less
   than that; the surrogate finds the basin (and the sensitivities), the polish finds
   the point. Why the second start: a void gap larger than the sleeper's deflection
   there is a plateau (that end never touches, so the residuals do not change with
   it); a start on such a plateau stays there (measured: the surrogate's optimum had
   the far-end gap at 1.1 mm against 0.05 mm true, and the polish kept it at 1.4 mm),
   while the nominal scenario is in contact everywhere, where every gap has a gradient.
   Each iteration's runs are a small sweep (``OUT/polish/<start>/bNNN``) on one executor
   kept for the stage, so the stage resumes like the others: the iteration is
   deterministic, and a rerun replays the finished runs from disk.

The calibrated scenario is whichever of the confirmed optimum, the best run of the
design and the polished point has the least simulated J (``calibration.json`` says which).

Each run is one scenario whose ``name`` labels its stage and position
(``<name>-cal1-0007``); the calibrated parameters enter as scenario overrides
(``track.ballast.voids`` as a whole list, ``track.ballast.stiffness_scale``, ...).

Output folder (``OUT``)::

    OUT/base.yaml, OUT/sensors.yaml          snapshots of the nominal scenario and its sensor layout
                                             (what every run loads)
    OUT/stage1/, OUT/stage2/, OUT/confirm/   the sweeps (sweep.csv, runs/<id>/result.json)
    OUT/polish/<start>/bNNN/, OUT/final/     the polish's iterations; the calibrated point re-run with its signals
    OUT/stage2_plan.json                     the narrowed box (reused on resume)
    OUT/calibrated.yaml                      the calibrated scenario
    OUT/calibration.json                     everything measured (see :func:`calibrate`)
    OUT/report.md                            a short report
    OUT/calibration_cv.png, calibration_sensitivity.png, calibration_signals.png

``--params`` syntax (:func:`parse_params`), comma-separated items, each optionally
followed by ``=LO:HI[:log|:lin]`` (bounds in the scenario's SI units):

* ``h1`` ballast stiffness scale, ``h2`` rail-pad stiffness scale (global), ``angle``
  crossing impact angle [rad];
* ``gaps@K`` the 6 void gaps [m] of sleeper K, ``gapI@K`` one of them (I = 1..6);
  ``pad@K`` the pad stiffness scale of sleeper K. K is an index or ``T``, ``T+1``,
  ``T-2`` (relative to the crossing transition sleeper);
* any numeric scenario key path with bounds, e.g. ``track.ballast.stiffness_scale=0.3:3:log``
  or ``track.rail_pad.damping=1e4:4e4``.

Default: ``gaps@T,h1,h2`` (seed 000's 8 parameters).
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import itertools
import json
import math
import os
import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from orchestrator.inverse.causes import CATALOGUE, N_GAPS, CauseKind
from orchestrator.inputs.errors import ScenarioError, UserInputError, one_line

__all__ = [
    "Parameter",
    "Surrogate",
    "CalibrationResult",
    "CalibrationIncomplete",
    "parse_params",
    "fit_surrogate",
    "sensitivity",
    "minimise_surrogate",
    "objective_run",
    "calibrate",
    "DEFAULT_PARAMS",
]

DEFAULT_PARAMS = "gaps@T,h1,h2"  # seed 000: 6 void gaps at the transition sleeper, h1, h2
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
SIGNAL_PLOT_IDS = ("A1", "A2", "A3", "A4", "A5", "A6")  # the ballast pressures of seed 000 Fig. 2, group A
OBJECTIVE = "objective"  # the run function's scalar that is minimised
CHANNEL_PREFIX = "nrmse."  # run-function scalars "nrmse.<sensor id>": channel surrogates
SIGNALS_FILE = "signals.npz"  # the confirmation runs' sensor signals
RESIDUALS_FILE = "residuals.npy"  # a polish run's weighted residual vector (Target.weighted_residuals)
POLISH_MAX_NFEV = 15  # least-squares iterations of the polish (measured: the 8-parameter benchmark converges in ~10)
FAILED_RUN_PENALTY = 10.0  # a polish run that stops early counts as this x the start's residual vector
BASE_FILE = "base.yaml"  # OUT/base.yaml: the snapshot of the nominal scenario every run loads
LAYOUT_FILE = "sensors.yaml"  # OUT/sensors.yaml: the snapshot of its sensor layout


# ======================================================================================
# Parameters
# ======================================================================================
@dataclass(frozen=True)
class Parameter:
    """One calibrated scalar and its map to the unit interval.

    Attributes
    ----------
    name : str
        ``h1``, ``h2``, ``angle``, ``gap3@21``, ``pad@20`` or a scenario key path.
    kind : CauseKind
        The catalogue cause it belongs to (bounds, log scale, how it enters the
        scenario), with the bounds of this parameter; for a plain key path a
        one-entry kind named by the key.
    sleeper : int or None
        Sleeper of a local cause.
    index : int
        Entry of the cause's parameter vector (the gap point 0..5; 0 otherwise).
    unit : str
        SI unit of the value (``m``, ``rad``, ``-``).
    """

    name: str
    kind: CauseKind
    sleeper: int | None = None
    index: int = 0
    unit: str = "-"

    @property
    def key(self) -> str | None:
        """The scenario key path of a plain key parameter (``None`` for catalogue causes)."""
        return None if self.kind.name in CATALOGUE else self.kind.name

    @property
    def bounds(self) -> tuple[float, float]:
        """(lower, upper) in the parameter's unit."""
        return float(self.kind.lower[self.index]), float(self.kind.upper[self.index])

    @property
    def log(self) -> bool:
        return bool(self.kind.log)

    def from_unit(self, u: float) -> float:
        """The value [unit] at unit coordinate ``u``."""
        lo, hi = self.bounds
        return float(dataclasses.replace(self.kind, lower=(lo,), upper=(hi,)).from_unit([u])[0])

    def to_unit(self, value: float) -> float:
        """The unit coordinate of ``value`` (outside [0, 1] when the value is out of bounds)."""
        lo, hi = self.bounds
        return float(dataclasses.replace(self.kind, lower=(lo,), upper=(hi,)).to_unit([value])[0])

    def as_dict(self) -> dict:
        lo, hi = self.bounds
        return {"name": self.name, "cause": self.kind.name if self.key is None else None, "key": self.key,
                "sleeper": self.sleeper, "lower": lo, "upper": hi, "log": self.log, "unit": self.unit}


# Named items of --params: name -> (catalogue cause, local?, unit)
_NAMED = {"h1": ("ballast_stiffness", False, "-"), "h2": ("rail_pad_stiffness", False, "-"),
          "angle": ("impact_angle", False, "rad"), "gaps": ("ballast_void", True, "m"),
          "gap": ("ballast_void", True, "m"), "pad": ("rail_pad_stiffness", True, "-")}
_ITEM = re.compile(r"^(?P<name>[^@=]+)(@(?P<where>[^=]*))?(=(?P<bounds>.*))?$")
_GAP = re.compile(r"gap(?P<point>[1-6])")
# Scenario key -> how a catalogue cause enters the variations of a run (the whole value of that key).
_CAUSE_KEYS = {"ballast_void": "track.ballast.voids", "ballast_stiffness": "track.ballast.stiffness_scale",
               "impact_angle": "track.crossing.impact_angle"}


def _cause_key(kind_name: str, sleeper: int | None) -> str:
    if kind_name == "rail_pad_stiffness":
        return "track.rail_pad.stiffness_scale" if sleeper is None else "track.rail_pad.overrides"
    return _CAUSE_KEYS[kind_name]


def _parse_bounds(text: str, item: str, default_log: bool) -> tuple[float, float, bool]:
    parts = [p.strip() for p in text.split(":")]
    scale = default_log
    if len(parts) == 3:
        if parts[2] not in ("log", "lin"):
            raise UserInputError(f"--params {item!r}: the scale must be 'log' or 'lin', got {parts[2]!r}")
        scale = parts[2] == "log"
        parts = parts[:2]
    if len(parts) != 2:
        raise UserInputError(f"--params {item!r}: bounds must be LO:HI or LO:HI:log, got {text!r}")
    try:
        lo, hi = float(parts[0]), float(parts[1])
    except ValueError:
        raise UserInputError(f"--params {item!r}: bounds must be numbers, got {text!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise UserInputError(f"--params {item!r}: need finite bounds with LO < HI, got {text!r}")
    if scale and lo <= 0:
        raise UserInputError(f"--params {item!r}: a log scale needs LO > 0, got {text!r}")
    return lo, hi, scale


def _sleeper(where: str, item: str, transition: Callable[[], int], n_sleepers: int) -> int:
    w = where.replace(" ", "")
    m = re.fullmatch(r"T([+-]\d+)?", w)
    try:
        k = transition() + int(m.group(1) or 0) if m else int(w)
    except ValueError:
        raise UserInputError(f"--params {item!r}: the sleeper must be an index or T, T+1, T-2, got {where!r}") \
            from None
    if not 0 <= k < n_sleepers:
        raise UserInputError(f"--params {item!r}: sleeper {k} is not in 0..{n_sleepers - 1}")
    return k


def parse_params(spec: str | None, scenario) -> list[Parameter]:
    """The calibrated parameters of a ``--params`` text (module docstring).

    Parameters
    ----------
    spec : str or None
        Comma-separated items; ``None`` or empty: :data:`DEFAULT_PARAMS`.
    scenario : Scenario
        The base scenario (sleeper count, the crossing transition sleeper ``T``,
        validation of key paths).

    Returns
    -------
    list of Parameter

    Raises
    ------
    UserInputError
        An unknown item, a bad sleeper or bound, a key that is not numeric, a parameter given twice.
    """
    from orchestrator.inputs.scenario import scenario_from_dict
    from orchestrator.inputs.keypath import get as _at

    spec = DEFAULT_PARAMS if spec is None or not spec.strip() else spec
    n_sleepers = int(scenario.raw["track"]["layout"]["sleepers"])

    @functools.lru_cache(maxsize=None)
    def transition() -> int:
        from track.model import build_track

        from track.model import reference_point
        return int(reference_point(build_track(scenario.track))[2])

    params: list[Parameter] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            raise UserInputError(f"--params {spec!r}: an empty item (two commas or a trailing comma)")
        m = _ITEM.match(item)
        if m is None:
            raise UserInputError(f"--params {item!r}: expected h1, h2, angle, gaps@K, gapI@K, pad@K or "
                                 f"key.path=LO:HI[:log]")
        name, where, bounds = m.group("name").strip(), m.group("where"), m.group("bounds")
        gap = _GAP.fullmatch(name)
        head, point = ("gap", gap.group("point")) if gap else (name, None)
        if head in _NAMED and head != "gap" or gap:
            cause, local, unit = _NAMED[head]
            kind = CATALOGUE[cause]
            if local and where is None:
                raise UserInputError(f"--params {item!r}: {head} needs a sleeper, e.g. {head}@T or {head}@21")
            if not local and where is not None:
                raise UserInputError(f"--params {item!r}: {head} is global; it takes no @sleeper")
            sleeper = _sleeper(where, item, transition, n_sleepers) if local else None
            if bounds is not None:
                lo, hi, log = _parse_bounds(bounds, item, kind.log)
                if cause == "ballast_void" and lo < 0:
                    raise UserInputError(f"--params {item!r}: a void gap cannot be negative")
                kind = dataclasses.replace(kind, lower=(lo,) * len(kind.lower), upper=(hi,) * len(kind.upper),
                                           log=log)
            if head == "gaps":
                new = [Parameter(f"gap{i + 1}@{sleeper}", kind, sleeper, i, unit) for i in range(N_GAPS)]
            elif head == "gap":
                new = [Parameter(f"gap{point}@{sleeper}", kind, sleeper, int(point) - 1, unit)]
            elif head == "pad":
                new = [Parameter(f"pad@{sleeper}", kind, sleeper, 0, unit)]
            else:
                new = [Parameter(head, kind, None, 0, unit)]
        else:
            key = name
            if where is not None or "." not in key:
                raise UserInputError(f"--params {item!r}: unknown parameter; expected h1, h2, angle, gaps@K, "
                                     f"gapI@K, pad@K or key.path=LO:HI[:log]")
            if bounds is None:
                raise UserInputError(f"--params {item!r}: a scenario key needs bounds, e.g. {key}=0.5:2")
            lo, hi, log = _parse_bounds(bounds, item, False)
            try:
                probe = scenario_from_dict(scenario.raw, source="--params", overrides=[f"{key}={lo!r}"],
                                           base_dir=_base_dir(scenario))
            except ScenarioError as exc:
                raise UserInputError(f"--params {item!r}: {exc}") from None
            value = _at(probe.raw, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise UserInputError(f"--params {item!r}: {key} is not a number in the scenario")
            kind = CauseKind(key, False, (key,), (lo,), (hi,), log, ())
            new = [Parameter(key, kind, None, 0, "")]
        params.extend(new)
    names = [p.name for p in params]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UserInputError(f"--params {spec!r}: {', '.join(twice)} given twice")
    keys = {_cause_key(p.kind.name, p.sleeper) for p in params if p.key is None}
    clash = sorted(k for k in (p.key for p in params if p.key is not None) if k in keys
                   and k not in ("track.ballast.voids", "track.rail_pad.overrides"))
    if clash:
        raise UserInputError(f"--params {spec!r}: {', '.join(clash)} is given both by name and as a key")
    return params


def _base_dir(scenario) -> Path:
    return Path(scenario.source).parent if scenario.source and Path(scenario.source).exists() else Path.cwd()


def _set_key(raw: dict, key: str, value: float) -> None:
    from orchestrator.inputs.scenario import parse_override

    tokens, _ = parse_override(f"{key}=0")
    node = raw
    for tok in tokens[:-1]:
        node = node[tok]
    node[tokens[-1]] = float(value)


def apply_values(raw: dict, params: Sequence[Parameter], values: Sequence[float]) -> dict:
    """A copy of a validated raw scenario with the parameters set to ``values`` [their units]."""
    raw = copy.deepcopy(raw)
    groups: dict[tuple, dict[int, float]] = {}
    for p, v in zip(params, values):
        if p.key is not None:
            _set_key(raw, p.key, v)
        else:
            groups.setdefault((p.kind.name, p.sleeper), {})[p.index] = float(v)
    for (name, sleeper), entries in groups.items():
        kind = CATALOGUE[name]
        vector = kind.nominal(raw, sleeper).astype(float)  # entries not calibrated keep the base value
        for i, v in entries.items():
            vector[i] = v
        raw = kind.apply(raw, sleeper, vector)
    return raw


def _variation(raw: dict, params: Sequence[Parameter], values: Sequence[float], label: str) -> dict:
    """The sweep variation ``{key.path: value}`` of one point (whole values of the keys touched)."""
    from orchestrator.inputs.keypath import get as _at

    new = apply_values(raw, params, values)
    keys = dict.fromkeys(p.key if p.key is not None else _cause_key(p.kind.name, p.sleeper) for p in params)
    # name first: the sweep plots scalars against the first varied key, and a string key means no plots
    return {"name": label, **{k: _at(new, k) for k in keys}}


def _values(params: Sequence[Parameter], u: np.ndarray) -> list[float]:
    return [p.from_unit(x) for p, x in zip(params, u)]


def nominal_values(raw: dict, params: Sequence[Parameter]) -> list[float]:
    """The parameters' values in a raw scenario [their units] (the inverse of :func:`apply_values`)."""
    from orchestrator.inputs.keypath import get as _at

    return [float(_at(raw, p.key)) if p.key is not None else float(p.kind.nominal(raw, p.sleeper)[p.index])
            for p in params]


# ======================================================================================
# The run function (executed in the sweep's workers)
# ======================================================================================
_TARGETS: dict[tuple, Any] = {}  # per worker process: (measured file, layout file) -> Target


def _target(measured: str, scenario):
    from orchestrator.inverse.objective import Target
    from orchestrator.inputs.sensor_layout import layout_of

    key = (measured, scenario.sensors)
    if key not in _TARGETS:
        _TARGETS[key] = Target.read(measured, layout_of(scenario))
    return _TARGETS[key]


def objective_run(scenario, run_dir: Path, *, measured: str, shift: float, save_signals: bool = False,
                  save_residuals: bool = False) -> dict:
    """Simulate ``scenario`` and compare it with a measurement: J and each channel's nRMSE.

    A top-level function: :func:`functools.partial` of it with the keywords pickles,
    so it is the ``run_fn`` of the calibration's sweeps.

    Parameters
    ----------
    scenario : Scenario
    run_dir : Path
        The run's folder (``signals.npz`` goes there with ``save_signals``).
    measured : str
        The measurement file (CSV, HDF5 or MAT; :func:`orchestrator.inputs.measured.read_measured`).
    shift : float
        Time alignment [s] fixed once for all runs (:meth:`orchestrator.inverse.objective.Target.align_to`).
    save_signals : bool
        Write the simulated sensor signals (``t`` [s] and one array per sensor id, shape (nt,)).
    save_residuals : bool
        Write the weighted residual vector (``residuals.npy``; the polish's least squares).

    Returns
    -------
    dict
        ``objective`` (J [-]) and ``nrmse.<id>`` [-] per measured channel; a run
        that stopped early gives ``objective = nan`` and its ``error``.
    """
    from orchestrator.cosim.sensing import simulate_sensors

    target = _target(measured, scenario)
    target.shift = float(shift)
    run = simulate_sensors(scenario, target.layout, reconstruct=False)
    if save_signals:
        np.savez(Path(run_dir) / SIGNALS_FILE, t=run.t, **run.signals)
    if run.error:
        return {OBJECTIVE: float("nan"), "error": one_line(run.error)}
    cmp = target.compare(run.t, run.signals)
    if save_residuals:
        np.save(Path(run_dir) / RESIDUALS_FILE, target.weighted_residuals(cmp))
    out = {OBJECTIVE: float(cmp.objective)}
    out.update({f"{CHANNEL_PREFIX}{k}": float(v["nrmse"]) for k, v in cmp.channels.items()})
    return out


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
    parts = _folds(n, folds, np.random.default_rng(seed))
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
    best = min(table, key=table.get)
    cv_pred = _backward(preds[best] * std + mean, transform)
    cv_rmse = np.sqrt(np.mean((cv_pred - Y2) ** 2, axis=0))
    spread = Y2.std(axis=0)
    cv_rel = np.where(spread > 0, cv_rmse / np.where(spread > 0, spread, 1.0), np.nan)
    rbf = RBFInterpolator(U, Zs, smoothing=best, kernel=kernel)
    return Surrogate(list(names) if names is not None else [f"y{i}" for i in range(m)], best, cv_rmse, cv_rel,
                     cv_pred, table, transform, Y2.copy(), _rbf=rbf, _mean=mean, _std=std, _single=single)


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


def _starts(U: np.ndarray, y: np.ndarray, lower, upper, rng: np.random.Generator) -> np.ndarray:
    """Multistart points: the best runs inside the box and random points in it."""
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


def _lhs(k: int, n: int, seed: int) -> np.ndarray:
    from scipy.stats import qmc

    try:
        sampler = qmc.LatinHypercube(d=k, rng=np.random.default_rng(seed))
    except TypeError:  # SciPy < 1.15 names the generator "seed"
        sampler = qmc.LatinHypercube(d=k, seed=np.random.default_rng(seed))
    return sampler.random(n)


def _corners(lower, upper) -> np.ndarray:
    return np.array([[(lo, hi)[b] for b, lo, hi in zip(bits, lower, upper)]
                     for bits in itertools.product((0, 1), repeat=len(lower))])


# ======================================================================================
# The calibration
# ======================================================================================
class CalibrationIncomplete(RuntimeError):
    """Runs of a stage did not finish (failed, or a worker died); finished ones are kept: rerun to resume."""


@dataclass
class CalibrationResult:
    """What :func:`calibrate` found (everything is also in ``calibration.json``).

    Attributes
    ----------
    params : list of Parameter
    values : dict
        Parameter name -> calibrated value [its unit].
    u : ndarray, shape (k,)
        The calibrated point in unit coordinates.
    summary : dict
        The content of ``calibration.json``.
    out_dir : Path
    scenario_file : Path
        ``calibrated.yaml``.
    stages : dict
        Stage -> the :class:`orchestrator.sweeps.sweep.SweepResult` of its runs.
    """

    params: list
    values: dict
    u: np.ndarray
    summary: dict
    out_dir: Path
    scenario_file: Path
    stages: dict


def _stage(base_path, points: np.ndarray, raw: dict, params, label: str, out: Path, run_fn, workers, scheduler,
           progress, executor=None) -> tuple[np.ndarray, dict, Any]:
    """Run one stage's points; returns (rows' objective (n,), channel values {id: (n,)}, SweepResult)."""
    name = raw["name"]
    variations = [_variation(raw, params, _values(params, u), f"{name}-{label}-{i:04d}") for i, u in enumerate(points)]
    res = _sweep(base_path, variations, out, f"stage {label}", run_fn=run_fn, workers=workers, scheduler=scheduler,
                 progress=progress, executor=executor)
    by_index = {row["index"]: row for row in res.rows}
    y = np.array([_float(by_index[i].get(OBJECTIVE)) for i in range(len(points))])
    channels = sorted({c for row in res.rows for c in row if c.startswith(CHANNEL_PREFIX)})
    ch = {c[len(CHANNEL_PREFIX):]: np.array([_float(by_index[i].get(c)) for i in range(len(points))])
          for c in channels}
    return y, ch, res


def _sweep(base_path, variations, out: Path, what: str, **kw):
    """:func:`orchestrator.sweeps.sweep.run_sweep`; unfinished or failed runs raise :class:`CalibrationIncomplete`."""
    from orchestrator.sweeps.sweep import SweepIncomplete, run_sweep

    try:
        res = run_sweep(base_path, variations, out, **kw)
    except SweepIncomplete as exc:
        raise CalibrationIncomplete(f"calibration {what}: {exc}") from None
    if res.failed:
        raise CalibrationIncomplete(f"calibration {what}: {res.summary()}")
    return res


def _float(v) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else float("nan")


def _digest(obj) -> str:
    import hashlib

    return hashlib.sha1(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


def calibrate(base_path: str | os.PathLike, measured: str | os.PathLike | None, out_dir: str | os.PathLike, *,
              params: str | Sequence[Parameter] | None = None, n1: int = 500, n2: int = 500, seed: int = 0,
              workers: int = 2, scheduler: str | None = None, progress: bool = True,
              run_fn: Callable | None = None, transforms: Sequence[str] = TRANSFORMS,
              polish: int = POLISH_MAX_NFEV, polish_fn: Callable | None = None) -> CalibrationResult:
    """Calibrate the parameters of a scenario against a measurement (module docstring).

    Parameters
    ----------
    base_path : path-like
        The nominal scenario YAML.
    measured : path-like or None
        The measurement file; may be ``None`` only with a custom ``run_fn``.
    out_dir : path-like
        ``OUT`` (created; a rerun with the same arguments resumes there).
    params : str or sequence of Parameter, optional
        ``--params`` text (:func:`parse_params`); default :data:`DEFAULT_PARAMS`.
    n1, n2 : int
        Runs of the first and the second Latin hypercube.
    seed : int
        Seed of the designs, the CV folds and the random starts.
    workers : int
        Local worker processes (ignored with ``scheduler``).
    scheduler : str, optional
        Dask scheduler address.
    progress : bool
        Progress bars.
    run_fn : callable, optional
        ``run_fn(scenario, run_dir) -> {"objective": J, "nrmse.<id>": ...}``, top level
        (picklable); default :func:`objective_run` against ``measured``.
    transforms : sequence of str
        Candidate transforms of J for its surrogate (:func:`fit_surrogate`); the one with
        the least local CV error is used (:func:`fit_objective`).
    polish : int
        Least-squares iterations of the polish (stage 7); 0 leaves it out.
    polish_fn : callable, optional
        The polish's run function: as ``run_fn``, and it also writes the run's residual
        vector to ``run_dir / "residuals.npy"``. Default: :func:`objective_run` with
        ``save_residuals`` (with a custom ``run_fn`` and no ``polish_fn`` there is no polish).

    Returns
    -------
    CalibrationResult

    Raises
    ------
    UserInputError
        Bad scenario, measurement file, parameters or sizes.
    CalibrationIncomplete
        Runs of a stage failed or were lost; a rerun does only the missing ones.
    """
    from orchestrator.inputs.scenario import dump_scenario, load_scenario, scenario_from_dict

    t_start = time.perf_counter()
    base_path = Path(base_path)
    out = Path(out_dir)
    for name, n, least in (("n1", n1, 1), ("n2", n2, 1), ("polish", polish, 0)):
        if isinstance(n, bool) or not isinstance(n, int) or n < least:
            raise UserInputError(f"{name} must be an integer >= {least}, got {n!r}")
    scenario = load_scenario(base_path)
    plist = parse_params(params, scenario) if params is None or isinstance(params, str) else list(params)
    k = len(plist)
    if n1 < k + 2:
        raise UserInputError(f"n1 = {n1} is too small for {k} parameters: give at least {k + 2} "
                             f"(a few hundred for a useful surrogate)")
    raw = scenario.raw
    out.mkdir(parents=True, exist_ok=True)
    # Every run loads this snapshot (scenario and sensor layout), not the user's files: a calibration takes
    # long, and an edit of a file meanwhile must not mix two models in one design (a changed file on
    # resume changes the snapshot, hence the run ids, and the runs are redone).
    snapshot = out / BASE_FILE
    scenario = _snapshot(scenario, out)

    shift, target = None, None
    if run_fn is None:
        if measured is None:
            raise UserInputError("calibrate needs --measured FILE")
        measured = Path(measured)
        if not measured.is_file():
            raise UserInputError(f"--measured {measured}: no such file")
        from orchestrator.inverse.objective import Target
        from orchestrator.cosim.sensing import simulate_sensors
        from orchestrator.inputs.sensor_layout import layout_of

        target = Target.read(measured, layout_of(scenario))  # a constant channel: objective.channel_scales
        nominal = simulate_sensors(scenario, target.layout, reconstruct=False)
        if nominal.error:
            raise UserInputError(f"{base_path}: the nominal scenario does not run to the end ({nominal.error})")
        shift = float(target.align_to(nominal.t, nominal.signals))
        run_fn = functools.partial(objective_run, measured=str(measured.resolve()), shift=shift)
        confirm_fn = functools.partial(run_fn, save_signals=True)
        polish_fn = polish_fn or functools.partial(run_fn, save_residuals=True)
    else:
        confirm_fn = run_fn
    common = dict(run_fn=run_fn, workers=workers, scheduler=scheduler, progress=progress)

    # ---- stage 1: Latin hypercube over the whole cube
    U1 = _lhs(k, n1, seed)
    y1, ch1, res1 = _stage(snapshot, U1, raw, plist, "cal1", out / "stage1", **common)
    ok1 = np.isfinite(y1)
    if ok1.sum() < k + 2:
        raise CalibrationIncomplete(f"calibration stage 1: only {int(ok1.sum())} of {n1} runs gave an objective")
    s1 = fit_objective(U1[ok1], y1[ok1], transforms, seed)

    # ---- stage 3: sensitivity and narrowed box (kept on disk, so a resume reuses it)
    plan_file = out / "stage2_plan.json"
    stage1_id = _digest([res1.rows[i]["run_id"] for i in range(len(res1.rows))] + [y1.tolist()])
    plan = json.loads(plan_file.read_text()) if plan_file.is_file() else None
    rng = np.random.default_rng([seed, 1])
    u1_star, f1_star, _ = minimise_surrogate(s1, np.zeros(k), np.ones(k), _starts(U1[ok1], y1[ok1], np.zeros(k),
                                                                                  np.ones(k), rng))
    tau = NARROW_CV_FACTOR * float(s1.local_cv_rmse()[0])
    sens = sensitivity(s1, u1_star, U1[ok1], y1[ok1], tau)
    if plan is None or plan.get("stage1") != stage1_id or plan.get("n2") != n2 or plan.get("seed") != seed:
        plan = {"stage1": stage1_id, "n2": n2, "seed": seed, "lower": sens["lower"].tolist(),
                "upper": sens["upper"].tolist()}
        plan_file.write_text(json.dumps(plan, indent=1))
    lo2, hi2 = np.array(plan["lower"]), np.array(plan["upper"])

    # ---- stage 4: second hypercube in the narrowed box + its corners
    U2 = lo2 + _lhs(k, n2, seed + 1) * (hi2 - lo2)
    corners = _corners(lo2, hi2) if k <= MAX_CORNER_DIM else np.empty((0, k))
    U2 = np.vstack([U2, corners])
    y2, ch2, res2 = _stage(snapshot, U2, raw, plist, "cal2", out / "stage2", **common)
    U = np.vstack([U1, U2])
    y = np.concatenate([y1, y2])
    ok = np.isfinite(y)
    surrogate = fit_objective(U[ok], y[ok], transforms, seed)
    ch_names = sorted(set(ch1) & set(ch2))
    channel_s = None
    if ch_names:
        C = np.column_stack([np.concatenate([ch1[c], ch2[c]]) for c in ch_names])
        okc = ok & np.all(np.isfinite(C), axis=1)
        channel_s = fit_surrogate(U[okc], C[okc], ch_names, seed=seed)

    # ---- stage 5: optimisation of the surrogate in the narrowed box
    u_opt, f_opt, opt_runs = minimise_surrogate(surrogate, lo2, hi2, _starts(U, y, lo2, hi2, rng))

    # ---- stage 6: confirmation (with the nominal scenario for before/after)
    v_opt = _values(plist, u_opt)
    conf_vars = [{"name": f"{raw['name']}-nominal"},
                 _variation(raw, plist, v_opt, f"{raw['name']}-calibrated")]
    conf = _sweep(snapshot, conf_vars, out / "confirm", "confirmation", run_fn=confirm_fn, workers=workers,
                  scheduler=scheduler, progress=False)
    rows = {r["index"]: r for r in conf.rows}
    j_before, j_confirmed = _float(rows[0].get(OBJECTIVE)), _float(rows[1].get(OBJECTIVE))
    i_best = int(np.nanargmin(y))
    use_best_run = bool(np.isfinite(y[i_best]) and not (j_confirmed <= y[i_best]))
    # the calibrated point: (source, u, J, its result row, (runs folder, run id) of its signals or None)
    chosen = ("best run", U[i_best], float(y[i_best]), _best_row(res1, res2, n1, i_best), None) if use_best_run \
        else ("surrogate optimum", u_opt, j_confirmed, rows[1], (out / "confirm" / "runs", rows[1]["run_id"]))

    # ---- stage 7: polish by least squares on real runs, then the polished point re-run with its signals
    polished = None
    if polish and polish_fn is not None:
        starts = {"surrogate optimum" if chosen[0] != "best run" else "best run": chosen[1],
                  "nominal": np.array([p.to_unit(v) for p, v in zip(plist, nominal_values(raw, plist))])}
        polished = _polish(snapshot, raw, plist, starts, out / "polish", polish_fn, polish, workers, scheduler,
                           progress)
        if polished["objective"] < chosen[2]:
            fin = _stage(snapshot, np.asarray(polished["u"])[None], raw, plist, "final", out / "final",
                         run_fn=confirm_fn, workers=workers, scheduler=scheduler, progress=False)[2]
            chosen = ("polish", np.asarray(polished["u"]), polished["objective"], polished["row"],
                      (out / "final" / "runs", fin.rows[0]["run_id"]))
    source, u_cal, j_after, after_row, signals_at = chosen
    v_cal = _values(plist, u_cal)

    cal_raw = apply_values(raw, plist, v_cal)
    cal_raw["name"] = f"{raw['name']}-calibrated"
    cal_scn = scenario_from_dict(cal_raw, source="<calibrated>", base_dir=base_path.parent)
    scenario_file = dump_scenario(cal_scn, out / "calibrated.yaml")

    chan_before = {c[len(CHANNEL_PREFIX):]: _float(v) for c, v in rows[0].items() if c.startswith(CHANNEL_PREFIX)}
    chan_after = {c[len(CHANNEL_PREFIX):]: _float(v) for c, v in after_row.items() if c.startswith(CHANNEL_PREFIX)}
    chan_pred = dict(zip(channel_s.names, map(float, channel_s(u_cal[None])[0]))) if channel_s else {}

    def box(lo, hi):
        return {p.name: [p.from_unit(a), p.from_unit(b)] for p, a, b in zip(plist, lo, hi)}

    summary = {
        "scenario": str(base_path), "measured": str(measured) if measured is not None else None,
        "parameters": [p.as_dict() for p in plist],
        "runs": {"stage1": n1, "stage2_lhs": n2, "stage2_corners": int(len(corners)), "total": int(len(y)),
                 "without_objective": int((~ok).sum()),
                 "done": int(res1.done + res2.done), "already_finished": int(res1.skipped + res2.skipped)},
        "shift": shift, "seed": seed, "kernel": KERNEL,
        "bounds": {"stage1": box(np.zeros(k), np.ones(k)), "stage2": box(lo2, hi2),
                   "stage2_unit": {p.name: [float(a), float(b)] for p, a, b in zip(plist, lo2, hi2)}},
        "surrogate_stage1": _surrogate_summary(s1),
        "surrogate": _surrogate_summary(surrogate),
        "channel_surrogates": (None if channel_s is None else
                               {"smoothing": channel_s.smoothing,
                                "cv_rmse": dict(zip(channel_s.names, map(float, channel_s.cv_rmse))),
                                "cv_rel": dict(zip(channel_s.names, map(float, channel_s.cv_rel)))}),
        "sensitivity": {"tau": tau, "u_star": dict(zip([p.name for p in plist], map(float, u1_star))),
                        "objective_at_u_star": float(f1_star),
                        "range": dict(zip([p.name for p in plist], map(float, sens["range"]))),
                        "share": dict(zip([p.name for p in plist], map(float, sens["share"])))},
        "optimum": {"u": dict(zip([p.name for p in plist], map(float, u_opt))),
                    "values": dict(zip([p.name for p in plist], v_opt)),
                    "predicted_objective": float(f_opt), "confirmed_objective": j_confirmed,
                    "starts": len(opt_runs)},
        "best_run": {"objective": float(y[i_best]), "stage": 1 if i_best < n1 else 2,
                     "values": dict(zip([p.name for p in plist], _values(plist, U[i_best])))},
        "polish": ({"max_nfev": polish, "done": False,
                    "why_not": "polish = 0" if not polish else "a custom run function without a polish_fn"}
                   if polished is None else
                   {"max_nfev": polish, "done": True,
                    **{k: v for k, v in polished.items() if k not in ("row", "u")},
                    "u": dict(zip([p.name for p in plist], map(float, polished["u"]))),
                    "values": dict(zip([p.name for p in plist], _values(plist, polished["u"])))}),
        "calibrated": {"source": source,
                       "values": dict(zip([p.name for p in plist], v_cal)), "file": scenario_file.name},
        "objective_before": j_before, "objective_after": j_after,
        "gain": (1.0 - j_after / j_before) if j_before > 0 else None,
        "channels": {c: {"nrmse_before": chan_before.get(c), "nrmse_after": chan_after.get(c),
                         "nrmse_predicted": chan_pred.get(c)} for c in sorted(set(chan_before) | set(chan_after))},
        "wall_time_s": None,
    }
    shown = {"nominal": (out / "confirm" / "runs", rows[0]["run_id"]),
             "surrogate optimum": (out / "confirm" / "runs", rows[1]["run_id"])}
    if signals_at is not None and source != "surrogate optimum":
        shown[f"calibrated ({source})"] = signals_at
    plots = _plots(out, plist, s1, surrogate, y1[ok1], y[ok], sens, lo2, hi2, target, shown, source)
    summary["plots"] = [p.name for p in plots]
    summary["wall_time_s"] = time.perf_counter() - t_start
    (out / "calibration.json").write_text(json.dumps(summary, indent=1, default=_json_default))
    (out / "report.md").write_text(_report(summary))
    return CalibrationResult(plist, dict(zip([p.name for p in plist], v_cal)), np.asarray(u_cal), summary, out,
                             scenario_file, {"stage1": res1, "stage2": res2, "confirm": conf})


def _polish(snapshot: Path, raw: dict, params, starts: dict, out: Path, polish_fn, max_nfev: int, workers,
            scheduler, progress) -> dict:
    """Stage 7 (module doc): least squares on real runs from each start; returns what it found.

    Parameters
    ----------
    starts : dict
        Label -> start in unit coordinates; each gets its own folder ``out/<label>``
        (a start equal to an earlier one is not run again).

    Returns
    -------
    dict
        ``u`` (the point with the least sum of squares over all starts), its ``start``,
        ``objective`` J and result ``row``, ``cost_start`` (at that start) and ``cost``
        (sums of squared residuals), ``runs``, ``iterations`` (sweeps of parallel runs),
        ``wall_time_s`` and ``starts`` (per start: where it began and ended, J, runs).
    """
    from tqdm import tqdm

    from orchestrator.inverse.fitting import fit_unit_cube
    from orchestrator.sweeps.sweep import make_executor

    t0 = time.perf_counter()
    found: dict[bytes, tuple[float, dict]] = {}
    bar = tqdm(desc="polish", unit="run", disable=not progress)
    executor = make_executor(workers, scheduler)
    fits, per_start = {}, {}
    names = [p.name for p in params]
    try:
        items = list(starts.items())
        for n, (label, u0) in enumerate(items):
            if any(np.allclose(u0, v) for _, v in items[:n]):
                continue
            folder = out / label.replace(" ", "_")
            first: list[np.ndarray] = []  # the start's residuals

            # the iteration is deterministic: call b of a rerun is call b before, and finds its runs on disk
            def batch(ps: list[np.ndarray], folder=folder, first=first, calls=itertools.count()) -> list[np.ndarray]:
                b = next(calls)
                res = _stage(snapshot, np.asarray(ps), raw, params, f"pol-{folder.name}-{b:03d}", folder / f"b{b:03d}",
                             run_fn=polish_fn, workers=workers, scheduler=scheduler, progress=False,
                             executor=executor)[2]
                bar.update(len(ps))
                by_index = {row["index"]: row for row in res.rows}
                rs = []
                for i, p in enumerate(ps):
                    row = by_index[i]
                    f = res.runs_dir / row["run_id"] / RESIDUALS_FILE
                    if f.is_file() and np.isfinite(_float(row.get(OBJECTIVE))):
                        r = np.load(f)
                    elif first:  # the run stopped early: a residual far worse than the start's
                        r = FAILED_RUN_PENALTY * first[0]
                    else:
                        raise CalibrationIncomplete(f"calibration polish: the start point ({folder.name}) gives no "
                                                    f"residuals ({row.get('error', 'no ' + RESIDUALS_FILE)})")
                    if not first:
                        first.append(r)
                    found[p.tobytes()] = (_float(row.get(OBJECTIVE)), row)
                    rs.append(r)
                return rs

            fit = fit_unit_cube(batch, u0, max_nfev=max_nfev)
            fits[label] = fit
            per_start[label] = {"u0": dict(zip(names, map(float, np.clip(u0, 0, 1)))),
                                "u": dict(zip(names, map(float, fit.p))), "cost_start": fit.cost_start,
                                "cost": fit.cost, "objective": found[fit.p.tobytes()][0], "runs": fit.evaluations,
                                "iterations": fit.batches}
    finally:
        bar.close()
        executor.shutdown()
    label = min(fits, key=lambda k: fits[k].cost)
    fit = fits[label]
    j, row = found[fit.p.tobytes()]
    return {"u": fit.p, "start": label, "objective": j, "row": row, "cost_start": fit.cost_start, "cost": fit.cost,
            "runs": sum(f.evaluations for f in fits.values()), "iterations": sum(f.batches for f in fits.values()),
            "wall_time_s": time.perf_counter() - t0, "starts": per_start}


def _snapshot(scenario, out: Path):
    """Write ``OUT/base.yaml`` and ``OUT/sensors.yaml`` (its sensor layout); returns the snapshot's scenario."""
    from orchestrator.inputs.scenario import dump_scenario, scenario_from_dict
    from orchestrator.inputs.sensor_layout import default_layout_path

    raw = copy.deepcopy(scenario.raw)
    layout = Path(raw["sensors"]) if raw.get("sensors") else default_layout_path()
    text = layout.read_text(encoding="utf-8")
    target = out / LAYOUT_FILE
    if not target.is_file() or target.read_text(encoding="utf-8") != text:
        target.write_text(text, encoding="utf-8")
    raw["sensors"] = str(target.resolve())
    snap = scenario_from_dict(raw, source=str(out / BASE_FILE), base_dir=out)
    dump_scenario(snap, out / BASE_FILE)
    return snap


def _best_row(res1, res2, n1: int, i: int) -> dict:
    res, j = (res1, i) if i < n1 else (res2, i - n1)
    return next(r for r in res.rows if r["index"] == j)


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    raise TypeError(type(o).__name__)


def _surrogate_summary(s: Surrogate) -> dict:
    return {"points": int(s.cv_pred.shape[0]), "smoothing": s.smoothing, "cv_rmse": float(s.cv_rmse[0]),
            "cv_rel": float(s.cv_rel[0]), "local_cv_rmse": float(s.local_cv_rmse()[0]), "local_share": LOCAL_SHARE, "cv_table": {repr(k): v for k, v in s.cv_table.items()},
            "folds": CV_FOLDS, "transform": s.transform, "transforms": s.candidates}


# ======================================================================================
# Plots and report
# ======================================================================================
def _plots(out: Path, params, s1: Surrogate, s: Surrogate, y1, y, sens, lo2, hi2, target, shown: dict,
           source: str) -> list[Path]:
    """The CV, sensitivity and signal plots; ``shown``: label -> (runs folder, run id) of saved signals."""
    from orchestrator.results.plots import _plt, save

    plt = _plt()
    files = []
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    for ax, sur, yy, title in ((axes[0], s1, y1, "stage 1"), (axes[1], s, y, "all runs")):
        pred = sur.cv_pred[:, 0]
        ax.loglog(yy, pred, ".", ms=3, alpha=0.6)
        lim = [min(yy.min(), pred.min()), max(yy.max(), pred.max())]
        ax.plot(lim, lim, "k-", lw=0.8)
        ax.set_xlabel("objective J, simulated [-]")
        ax.set_ylabel("J, surrogate held-out prediction [-]")
        ax.set_title(f"{title}: {len(yy)} runs, CV RMSE {sur.cv_rmse[0]:.3g} ({100 * sur.cv_rel[0]:.1f} % of spread)")
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    save(fig, out / "calibration_cv.png")
    files.append(out / "calibration_cv.png")

    names = [p.name for p in params]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    axes[0].bar(names, sens["range"])
    axes[0].set_ylabel("range of the surrogate's profile [J]")
    axes[0].set_title("sensitivity at the stage-1 optimum")
    axes[0].tick_params(axis="x", rotation=45)
    axes[1].barh(names, np.asarray(hi2) - np.asarray(lo2), left=lo2)
    axes[1].set_xlim(0, 1)
    axes[1].set_xlabel("unit coordinate")
    axes[1].set_title("narrowed bounds (stage 2)")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save(fig, out / "calibration_sensitivity.png")
    files.append(out / "calibration_sensitivity.png")

    if target is not None:
        ids = [i for i in SIGNAL_PLOT_IDS if i in target.measured.channels] or list(target.measured.channels)[:6]
        sims = {}
        for label, (runs_dir, rid) in shown.items():
            f = runs_dir / rid / SIGNALS_FILE
            if f.is_file():
                data = np.load(f)
                sig = {k: data[k] for k in data.files if k != "t"}
                sims[label] = target.compare(data["t"], sig).simulated
        fig, axes = plt.subplots(len(ids), 1, figsize=(8, 1.8 * len(ids) + 0.6), sharex=True, squeeze=False)
        t = target.measured.t
        for ax, sid in zip(axes[:, 0], ids):
            ax.plot(t, target.measured.channels[sid], "k-", lw=0.8, label="measured")
            for label, sim in sims.items():
                ax.plot(t, sim[sid], lw=1.0, label=label)
            ax.set_ylabel(sid)
            ax.grid(True, alpha=0.3)
        axes[0, 0].legend(fontsize="small", ncol=3)
        axes[-1, 0].set_xlabel("measured time [s]")
        if source == "best run":
            axes[0, 0].set_title("(the calibrated scenario is the best run of the design; its optimum is shown)")
        fig.tight_layout()
        save(fig, out / "calibration_signals.png")
        files.append(out / "calibration_signals.png")
    return files


def _fmt(v, unit: str) -> str:
    if unit == "m":
        return f"{1e3 * v:.3f} mm"
    return f"{v:.4g}" + (f" {unit}" if unit not in ("-", "") else "")


def _report(s: dict) -> str:
    lines = [f"# Calibration of {s['scenario']}", "",
             f"Measurement: {s['measured']}; {s['runs']['total']} runs ({s['runs']['stage1']} + "
             f"{s['runs']['stage2_lhs']} + {s['runs']['stage2_corners']} corners).", "",
             f"Objective J: {s['objective_before']:.4g} (nominal) -> {s['objective_after']:.4g} (calibrated, "
             f"{s['calibrated']['source']}); gain {100 * (s['gain'] or 0):.1f} %.", "",
             f"Surrogate (thin-plate spline, smoothing by {CV_FOLDS}-fold CV): stage 1 CV RMSE "
             f"{s['surrogate_stage1']['cv_rmse']:.3g} ({100 * s['surrogate_stage1']['cv_rel']:.1f} % of the spread "
             f"of J), all runs {s['surrogate']['cv_rmse']:.3g} ({100 * s['surrogate']['cv_rel']:.1f} %).", "",
             f"Surrogate optimum: predicted J = {s['optimum']['predicted_objective']:.4g}, "
             f"simulated J = {s['optimum']['confirmed_objective']:.4g}.", "",
             (f"Polish (least squares on real runs, from the {s['polish']['start']}): {s['polish']['runs']} runs in "
              f"{s['polish']['iterations']} parallel sweeps, J = {s['polish']['objective']:.4g}; sum of squared "
              f"residuals {s['polish']['cost_start']:.4g} -> {s['polish']['cost']:.4g}." if s["polish"]["done"] else
              f"No polish ({s['polish']['why_not']})."), "",
             "| parameter | stage-1 bounds | narrowed bounds | sensitivity share | calibrated |",
             "|---|---|---|---|---|"]
    for p in s["parameters"]:
        n, u = p["name"], p["unit"]
        b1, b2 = s["bounds"]["stage1"][n], s["bounds"]["stage2"][n]
        lines.append(f"| {n} | {_fmt(b1[0], u)} - {_fmt(b1[1], u)} | {_fmt(b2[0], u)} - {_fmt(b2[1], u)} | "
                     f"{100 * s['sensitivity']['share'][n]:.1f} % | {_fmt(s['calibrated']['values'][n], u)} |")
    lines += ["", "| channel | nRMSE nominal | nRMSE calibrated |", "|---|---|---|"]
    for c, v in s["channels"].items():
        b, a = v["nrmse_before"], v["nrmse_after"]
        lines.append(f"| {c} | {b:.3g} | {a:.3g} |" if b is not None and a is not None else f"| {c} | | |")
    lines += ["", "Plots: " + ", ".join(s.get("plots", [])), ""]
    return "\n".join(lines)
