"""Simulated sensors against measured ones: residuals, the objective, the noise level.

Objective (DESIGN.md §4.3, §5) — a weighted sum over sensor groups of the normalised RMSE::

    nRMSE_i = sqrt( mean_t (s_i(t) - m_i(t))^2 ) / std_t(m_i)        (channel i, valid samples)
    J       = sum_g w_g * mean_{i in g} nRMSE_i  /  sum_g w_g

``s`` is the simulation put on the measured time base (after the time alignment), band-limited
first as the acquisition that sampled ``m`` is (:func:`track.sensors.anti_alias`, below ~0.4 of
its sampling rate: content above it depends on the model's time step and would fold into the band),
``m`` the measurement; ``w_g`` the layout's group weights (default 1 each, so a group
with six channels counts as much as one with two). Normalising by the channel's
standard deviation makes pressures [Pa], strains [-] and displacements [m] comparable;
J = 1 means "no better than the channel's mean". A channel that is constant over the
record (a pressure cell over a void reads 0) is normalised by its group's median
spread instead (:func:`channel_scales`).

Noise level of a measured channel, without any knowledge of the signal: the robust
spread of the first differences, sigma = 1.4826 MAD(diff m) / sqrt(2) — exact for white
noise on a signal that is smooth at the sampling interval (the passage signals are,
at 5 kHz: pressure, strain and displacement change over milliseconds), and robust to
the few large differences of an impact. It feeds the chi-square ``sum (r/sigma)^2``
of the information criterion used by the diagnosis (:mod:`orchestrator.inverse.diagnose`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from track.sensors import anti_alias, displacement_from_acceleration

MAD_TO_SIGMA = 1.4826   # sigma / MAD of a normal distribution
NOISE_FLOOR = 1e-12     # relative to the channel's std: keeps chi-square finite for noise-free data
DEAD_SPREAD = 1e-9      # a channel whose spread is at most this share of its group's largest is constant: the
                        # measured file's 12 digits resolve ~1e-12 of a value, a sensor's noise ~1e-3 of its range


@dataclass
class Comparison:
    """Residuals of one simulation against one measurement (see module docstring).

    Attributes
    ----------
    shift : float
        Time alignment [s] used: measured time t matches simulated time t - shift.
    channels : dict
        id -> {"rmse", "nrmse", "n", "t_peak", "window"}: RMSE in SI units, nRMSE [-],
        number of valid samples, time of the largest residual and the time window
        holding 80 % of the residual energy [s].
    groups : dict
        group -> mean nRMSE of its channels.
    objective : float
        J [-].
    chi2 : float
        sum over channels and samples of (residual / sigma)^2.
    n : int
        Valid samples over all channels.
    residuals : dict
        id -> residual g s - m on the measured time base (NaN where masked); g is the
        channel's gain (:attr:`Target.gains`, 1 unless a channel was judged mis-calibrated).
    simulated : dict
        id -> the simulation on the measured time base (before any channel gain).
    """

    shift: float
    channels: dict
    groups: dict
    objective: float
    chi2: float
    n: int
    residuals: dict = field(repr=False, default_factory=dict)
    simulated: dict = field(repr=False, default_factory=dict)

    def summary(self) -> dict:
        """JSON-able: objective and per-channel rmse / nrmse (DESIGN.md §4.5 ``baseline``)."""
        return {"objective": self.objective, "shift": self.shift, "chi2": self.chi2, "n": self.n,
                "groups": dict(self.groups),
                "channels": {k: {"rmse": v["rmse"], "nrmse": v["nrmse"]} for k, v in self.channels.items()}}


def noise_sigma(x: np.ndarray) -> float:
    """Noise standard deviation of a uniformly sampled channel (module docstring), NaNs skipped."""
    d = np.diff(np.asarray(x, float))
    d = d[np.isfinite(d)]
    if d.size < 3:
        return float("nan")
    return float(MAD_TO_SIGMA * np.median(np.abs(d - np.median(d))) / np.sqrt(2.0))


def objective_from_channels(nrmse: dict, groups: dict, weights: dict) -> tuple[float, dict]:
    """J and the per-group mean nRMSE from channel nRMSEs (module docstring)."""
    J, gmean = group_weighted(nrmse, groups, weights)
    return float(J), {g: float(v) for g, v in gmean.items()}


def group_weighted(nrmse: dict, groups: dict, weights: dict) -> tuple:
    """(J, group -> mean nRMSE) of channel nRMSEs that are numbers or equal-length arrays (one entry per
    simulation: :func:`objective_rows`), elementwise."""
    by_group: dict[str, list] = {}
    for sid, value in nrmse.items():
        by_group.setdefault(groups[sid], []).append(value)
    gmean = {g: np.mean(v, axis=0) for g, v in by_group.items()}
    wsum = sum(weights.get(g, 1.0) for g in gmean)
    J = sum(weights.get(g, 1.0) * v for g, v in gmean.items()) / wsum if wsum > 0 else float("nan")
    return J, gmean


def _energy_window(t: np.ndarray, r: np.ndarray, share: float = 0.8) -> list[float]:
    e = np.where(np.isfinite(r), r * r, 0.0)
    c = np.cumsum(e)
    if c[-1] <= 0:
        return [float(t[0]), float(t[-1])]
    lo = (1 - share) / 2 * c[-1]
    hi = (1 + share) / 2 * c[-1]
    return [float(t[np.searchsorted(c, lo)]), float(t[min(np.searchsorted(c, hi), t.size - 1)])]


class _ChannelFit(dict):
    """One channel's entry of :attr:`Comparison.channels`: ``rmse``, ``nrmse``, ``n``, and on first
    reading ``t_peak`` (the time of the largest residual) and ``window`` (the time window holding
    80 % of its energy): only the reports read those two, while a diagnosis scores thousands of
    interpolated variants (they were 40 % of a score's time)."""

    def __init__(self, t: np.ndarray, r: np.ndarray, **values):
        super().__init__(**values)
        self._t, self._r = t, r

    def __missing__(self, key):
        if key == "t_peak":
            value = float(self._t[int(np.nanargmax(np.abs(np.where(np.isfinite(self._r), self._r, 0.0))))])
        elif key == "window":
            value = _energy_window(self._t, self._r)
        else:
            raise KeyError(key)
        self[key] = value
        return value

    def __reduce__(self):                 # pickled / copied as the plain dict of every entry
        return dict, (dict(self, t_peak=self["t_peak"], window=self["window"]),)


def on_measured_base(measured, t_sim: np.ndarray, sim: dict, shift: float, types: dict | None = None,
                     highpass: float | None = None) -> dict:
    """The simulation on the measured time base, ``s(t) = sim(t - shift)`` (cubic; NaN outside), band-limited
    first by the anti-alias filter of an acquisition at the measured rate (:func:`track.sensors.anti_alias`).

    Displacement channels (``types[id] == "displacement"``, given as their
    accelerometer's signal) are reconstructed here, on the measured window, by the
    very integration and filter the measured reconstruction used.
    """
    from scipy.interpolate import CubicSpline

    t_new = measured.t - shift
    inside = (t_new >= t_sim[0]) & (t_new <= t_sim[-1])
    out = {}
    ids = list(sim)
    # one spline of all channels (columns): the same banded solve and evaluation per column as a
    # spline per channel, without a spline object per channel (a third of the function's time)
    on = CubicSpline(t_sim, anti_alias(t_sim, np.column_stack([sim[k] for k in ids]), measured.rate))(
        t_new[inside]) if ids else None
    for j, k in enumerate(ids):
        s = np.full(t_new.shape, np.nan)
        s[inside] = on[:, j]
        if types is not None and highpass is not None and types.get(k) == "displacement" and inside.any():
            idx = np.flatnonzero(inside)
            filled = np.interp(np.arange(s.size), idx, s[idx])   # edges held: the integration needs a full window
            s = np.where(inside, displacement_from_acceleration(filled, measured.dt, highpass), np.nan)
        out[k] = s
    return out


def compare(measured, t_sim: np.ndarray, sim: dict, groups: dict, weights: dict, sigma: dict,
            shift: float | None = None, max_shift: float | None = None, types: dict | None = None,
            highpass: float | None = None, scale: dict | None = None, gains: dict | None = None) -> Comparison:
    """Residuals, nRMSE per channel, J and chi-square of a simulation against a measurement.

    Parameters
    ----------
    measured : orchestrator.inputs.measured.MeasuredData
    t_sim : ndarray, shape (nt,)
        Simulated times [s].
    sim : dict
        Sensor id -> simulated signal, shape (nt,); channels missing from ``measured`` are ignored.
    groups, weights : dict
        Sensor id -> group; group -> weight.
    sigma : dict
        Sensor id -> noise standard deviation of the measured channel (:func:`noise_sigma`).
    shift : float, optional
        Time alignment [s]; ``None``: estimated by cross-correlation
        (:func:`orchestrator.inputs.measured.align`), within ``max_shift`` of 0.
    types : dict, optional
        Sensor id -> type; with ``highpass`` [Hz], displacement channels of ``sim`` are
        accelerations, reconstructed on the measured base (:func:`on_measured_base`).
        Without, ``sim`` is compared as it is.
    gains : dict, optional
        Sensor id -> gain g of a mis-calibrated channel (measured = g x true): the
        residual is g s - m (:func:`score`).
    """
    from orchestrator.inputs.measured import align

    ids = [k for k in measured.channels if k in sim]
    if not ids:
        raise ValueError("no measured channel has a simulated counterpart")
    if shift is None:
        shift = align(measured, t_sim, {k: sim[k] for k in ids}, max_shift=max_shift)
    on = on_measured_base(measured, t_sim, {k: sim[k] for k in ids}, shift, types, highpass)
    return score(measured, on, groups, weights, sigma, shift, scale, gains)


def channel_scales(measured, groups: dict) -> tuple[dict, dict]:
    """Per channel: the nRMSE normaliser (std of the measured signal) and the noise std.

    A channel that is constant over the record (a pressure cell over a void reads 0
    throughout) has no spread of its own: it is normalised by the median spread of its
    group (same sensor type, same unit), and its noise level is the group's median
    noise-to-spread ratio times that. Without this one dead channel would make J
    infinite and the chi-square undefined. Constant means a spread of at most
    :data:`DEAD_SPREAD` of the group's largest: a cell reading round-off, not a signal
    (measured: the solid crossing rail's recovered pressure under a hanging sleeper,
    ~1e-14 Pa, 4e-17 of its group's spread, made the nominal J 1.4e15 and every gain
    100 %: field-like case void_sensor+solid 7606, RESULTS session 29).

    Returns
    -------
    scale, sigma : dict
        Sensor id -> [channel unit].
    """
    scale, sigma = {}, {}
    for k, m in measured.channels.items():
        ok = np.isfinite(m)
        scale[k] = float(np.std(m[ok])) if ok.sum() > 1 else 0.0
        sigma[k] = noise_sigma(m)
    spread = dict(scale)
    largest: dict = {}
    for k, v in spread.items():
        largest[groups.get(k)] = max(largest.get(groups.get(k), 0.0), v)
    alive = {k for k, v in spread.items() if v > DEAD_SPREAD * largest[groups.get(k)]}   # 0 when all are
    for k in list(scale):
        live = [j for j in alive if groups.get(j) == groups.get(k)]
        dead = k not in alive
        if dead:
            scale[k] = float(np.median([spread[j] for j in live])) if live else 1.0
        if dead or not (np.isfinite(sigma[k]) and sigma[k] > 0):
            ratios = [sigma[j] / spread[j] for j in live if np.isfinite(sigma[j]) and sigma[j] > 0]
            sigma[k] = scale[k] * (float(np.median(ratios)) if ratios else 0.01)
    return scale, sigma


def _scale_and_sigma(k, m: np.ndarray, ok: np.ndarray, sigma: dict, scale: dict | None) -> tuple[float, float]:
    """Channel ``k``'s nRMSE normaliser and the sigma its chi-square divides by (:func:`score`)."""
    sc = float(np.std(m[ok])) if scale is None else scale[k]
    sg = max(sigma.get(k, np.nan), NOISE_FLOOR * sc) if np.isfinite(sigma.get(k, np.nan)) else sc
    return sc, sg


def objective_rows(measured, rows: np.ndarray, ids: list, sizes: np.ndarray, groups: dict, weights: dict,
                   scale: dict | None = None, gains: dict | None = None) -> np.ndarray:
    """The objective J :func:`score` gives each row of ``rows`` (many simulations on the measured base at
    once: channel ``ids[i]`` in columns ``sizes[i]:sizes[i+1]``), to rank them.

    Per channel the nRMSE over its valid samples, then the group means and weights of
    :func:`objective_from_channels` (:func:`group_weighted`), over whole arrays (equal to :func:`score`'s J to round-off). A row whose channel has
    fewer than 2 valid samples gets NaN.
    """
    gains = gains or {}
    nr = {}
    bad = np.zeros(rows.shape[0], bool)
    for i, k in enumerate(ids):
        m = measured.channels[k]
        r = gains.get(k, 1.0) * rows[:, sizes[i]:sizes[i + 1]] - m
        ok = np.isfinite(r)
        n = ok.sum(axis=1)
        sc, _ = _scale_and_sigma(k, m, ok[0], {}, scale)
        with np.errstate(invalid="ignore", divide="ignore"):
            rmse = np.sqrt(np.where(ok, r * r, 0.0).sum(axis=1) / n)
        nr[k] = rmse / sc if sc > 0 else np.full(rows.shape[0], np.inf)
        bad |= n < 2
    out = np.array(group_weighted(nr, groups, weights)[0], float)
    out[bad] = np.nan
    return out


def score(measured, on: dict, groups: dict, weights: dict, sigma: dict, shift: float = 0.0,
          scale: dict | None = None, gains: dict | None = None) -> Comparison:
    """:class:`Comparison` of a simulation already on the measured time base (``on``: id -> (nt,)).

    Used directly where simulations are interpolated between runs (the diagnosis's
    screening), so they need not be put on the measured base again. ``scale``: the
    nRMSE normaliser per channel (:func:`channel_scales`); default the std of the
    measured channel. ``gains``: sensor id -> g, the residual is ``g s - m`` (a channel
    whose measurement chain reads g times the true value); ``on`` stays the simulation.
    """
    gains = gains or {}
    ids = [k for k in measured.channels if k in on]
    channels, nrmse, residuals = {}, {}, {}
    chi2, n_all = 0.0, 0
    for k in ids:
        m = measured.channels[k]
        s = on[k]
        r = gains.get(k, 1.0) * s - m
        ok = np.isfinite(r)
        n = int(ok.sum())
        if n < 2:
            raise ValueError(f"channel {k}: the simulation does not cover the measured passage")
        if n < r.size:
            r = np.where(ok, r, np.nan)
        rok = r[ok] if n < r.size else r           # all finite (the usual case): no copy
        rmse = float(np.sqrt(np.mean(rok ** 2)))
        sc, sg = _scale_and_sigma(k, m, ok, sigma, scale)
        nr = rmse / sc if sc > 0 else float("inf")
        chi2 += float(np.sum((rok / sg) ** 2))
        n_all += n
        channels[k] = _ChannelFit(measured.t, r, rmse=rmse, nrmse=nr, n=n)
        nrmse[k] = nr
        residuals[k] = r
    J, gmean = objective_from_channels(nrmse, groups, weights)
    return Comparison(float(shift), channels, gmean, J, chi2, n_all, residuals, on)


__all__ = ["Comparison", "Target", "channel_scales", "objective_rows", "compare", "score", "on_measured_base", "noise_sigma",
           "objective_from_channels"]


# ------------------------------------------------------------------------------------------
# A measurement prepared for many comparisons (diagnosis, calibration)
# ------------------------------------------------------------------------------------------
@dataclass
class Target:
    """A measured passage with what every comparison against it needs.

    Attributes
    ----------
    measured : orchestrator.inputs.measured.MeasuredData
    layout : orchestrator.inputs.sensor_layout.SensorLayout
    sigma : dict
        Sensor id -> noise std estimated from the measurement (:func:`channel_scales`).
    shift : float or None
        Time alignment [s], fixed once by :meth:`align_to` and then held for every
        variant: the instants of a passage are set by geometry and speed, not by the
        track's stiffness, voids or nose wear, and a shift re-fitted per variant would
        soak up part of the very differences the diagnosis looks for.
    scale : dict or None
        Sensor id -> the nRMSE normaliser (:func:`channel_scales`).
    gains : dict
        Sensor id -> gain g of a channel judged mis-calibrated (measured = g x true; set
        by :func:`orchestrator.inverse.nuisance.fit_nuisance`): every comparison scores
        ``g s - m`` on it. Empty: every channel as measured.
    floor : dict
        Sensor id -> the forward model's own time-step error on that channel, as an nRMSE
        against the converged model (set by the diagnosis once its half-step run is in:
        :func:`orchestrator.inverse.diagnose._step_error`). Part of the misfit no cause can
        remove: the share a cause must take is measured above it and the noise
        (:func:`orchestrator.inverse.significance.floor_objective`). Empty: the noise alone.
    """

    measured: object
    layout: object
    sigma: dict
    shift: float | None = None
    scale: dict | None = None
    gains: dict = field(default_factory=dict)
    floor: dict = field(default_factory=dict)

    @classmethod
    def read(cls, path, layout) -> "Target":
        """Read and check a measurement file against a layout (every layout sensor optional)."""
        from orchestrator.inputs.measured import read_measured

        data = read_measured(path, layout.types)
        scale, sigma = channel_scales(data, layout.groups)
        return cls(data, layout, sigma, scale=scale)

    def align_to(self, t_sim: np.ndarray, sim: dict) -> float:
        """Fix :attr:`shift` from a simulation (its accelerometer channels when it has any).

        The acceleration channels carry the wheel's impact at the crossing nose: a sharp
        event whose instant the track's parameters hardly move (over the hidden-effect
        cases the shift found from them was within 0.07 ms of the truth, against up to
        1.2 ms from the pressures and 9 ms from all channels together).
        """
        from orchestrator.inputs.measured import align

        acc = [k for k, t in self.layout.types.items() if t == "acceleration" and k in self.measured.channels]
        use = acc or [k for k in self.measured.channels if k in sim]
        band = anti_alias(t_sim, np.column_stack([sim[k] for k in use]), self.measured.rate) if use else None
        self.shift = align(self.measured, t_sim, {k: band[:, j] for j, k in enumerate(use)},
                           weights={k: 1.0 for k in use})
        return self.shift

    def compare(self, t_sim: np.ndarray, sim: dict) -> Comparison:
        """:func:`compare` of a simulation (``reconstruct=False`` signals) against the measurement."""
        if self.shift is None:
            self.align_to(t_sim, sim)
        lay = self.layout
        return compare(self.measured, t_sim, sim, lay.groups, lay.weights, self.sigma, shift=self.shift,
                       types=lay.types, highpass=lay.displacement_highpass, scale=self.scale, gains=self.gains)

    def score(self, on: dict) -> Comparison:
        """:func:`score` of signals already on the measured time base."""
        lay = self.layout
        return score(self.measured, on, lay.groups, lay.weights, self.sigma, self.shift or 0.0, self.scale,
                     self.gains)

    def objective_rows(self, rows: np.ndarray, ids: list, sizes: np.ndarray) -> np.ndarray:
        """:func:`objective_rows` of many simulations on the measured time base (to rank them)."""
        lay = self.layout
        return objective_rows(self.measured, rows, ids, sizes, lay.groups, lay.weights, self.scale, self.gains)

    def weighted_residuals(self, cmp: Comparison) -> np.ndarray:
        """One vector whose sum of squares is ``sum_g w_g mean_{i in g} nRMSE_i^2 / sum_g w_g``.

        The least-squares counterpart of J (the same normalisation and weights, squared
        inside the mean): what :func:`scipy.optimize.least_squares` minimises in a fit.
        """
        lay = self.layout
        members: dict[str, int] = {}
        for k in cmp.channels:
            members[lay.groups[k]] = members.get(lay.groups[k], 0) + 1
        wsum = sum(lay.weights.get(g, 1.0) for g in members)
        parts = []
        for k, info in cmp.channels.items():
            m = self.measured.channels[k]
            ok = np.isfinite(cmp.residuals[k])
            scale = self.scale[k] if self.scale is not None else (float(np.std(m[ok])) or 1.0)
            g = lay.groups[k]
            f = np.sqrt(lay.weights.get(g, 1.0) / (wsum * members[g] * ok.sum())) / scale
            parts.append(np.where(ok, cmp.residuals[k], 0.0) * f)
        return np.concatenate(parts)
