"""Time alignment of a measured and a simulated passage, and resampling onto a time base.

:func:`align` finds the time shift between a measured and a simulated passage
(normalised multichannel cross-correlation, parabolic sub-sample peak) and
:func:`resample` puts a simulation on the measured time base.

Method of :func:`align`: the simulation is interpolated onto a grid with the measured
step ``dt`` starting at ``t_sim[0]``. Each common channel (measured and simulated,
weight > 0) has its baseline removed and is divided by its standard deviation
(measured: over valid samples; masked samples are then set to 0, so they add nothing).
The baseline is the median, the quiet level before and after the train (a static
preload, a gauge offset): the mean would be raised by the pulses, and a non-zero level
left outside them correlates with the zero padding into a tent that pulls the peak
toward zero lag (0.02 sample for 10-sample pulses; the median keeps this < 1e-3). The
weighted sum over channels of the cross-correlations is computed in one FFT, its
maximum is taken over the lags with ``|s| <= max_shift``, and refined to a fraction of a
sample by a parabola through the peak and its two neighbours. The correlation is not
re-normalised per lag by the overlap energy: that would let a short overlap at an
extreme lag win by chance.
"""
from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from orchestrator.inputs.errors import UserInputError
from orchestrator.inputs.errors import did_you_mean as _hint
from orchestrator.inputs.measured_checks import MeasuredData

__all__ = ["align", "resample"]


def resample(t_sim: np.ndarray, sim: Mapping[str, np.ndarray], t_new: np.ndarray) -> dict[str, np.ndarray]:
    """Signals linearly interpolated onto a new time base.

    Parameters
    ----------
    t_sim : ndarray, shape (n,)
        Times of ``sim`` [s], strictly increasing.
    sim : mapping of str to ndarray, shape (n,)
        Signals (any unit).
    t_new : ndarray, shape (m,)
        Times to interpolate at [s].

    Returns
    -------
    dict of str to ndarray, shape (m,)
        NaN outside ``[t_sim[0], t_sim[-1]]``. To compare with a measurement
        after :func:`align` returned ``s``: ``resample(t_sim + s, sim, measured.t)``.
    """
    t_sim = np.asarray(t_sim, dtype=float)
    t_new = np.asarray(t_new, dtype=float)
    if t_sim.ndim != 1 or len(t_sim) < 2 or not (np.diff(t_sim) > 0).all():
        raise ValueError("t_sim must be a strictly increasing vector of at least 2 times")
    out = {}
    for key, y in sim.items():
        y = np.asarray(y, dtype=float)
        if y.shape != t_sim.shape:
            raise ValueError(f"signal {key!r} has shape {y.shape}, t_sim has {t_sim.shape}")
        out[key] = np.interp(t_new, t_sim, y, left=np.nan, right=np.nan)
    return out


def align(measured: MeasuredData, t_sim: np.ndarray, sim: Mapping[str, np.ndarray], *,
          max_shift: float | None = None, weights: Mapping[str, float] | None = None) -> float:
    """Time shift between a measured and a simulated passage.

    Sign convention: the returned ``s`` [s] is the delay of the measurement,
    ``measured(t) ≈ sim(t - s)``: an event the simulation shows at time ``τ``
    the measurement shows at ``τ + s``. ``resample(t_sim + s, sim, measured.t)``
    puts the simulation on the measured time base, aligned. The method is in the
    module docstring.

    Parameters
    ----------
    measured : MeasuredData
    t_sim : ndarray, shape (n,)
        Simulated times [s], strictly increasing.
    sim : mapping of str to ndarray, shape (n,)
        Simulated signals by sensor id, SI units (only the shapes matter:
        every channel is normalised).
    max_shift : float, optional
        Largest ``|s|`` [s] considered. Default: any shift with overlap.
    weights : mapping of str to float, optional
        Weight per sensor id (default 1 for each common channel); 0 leaves a
        channel out. Ids must be common channels.

    Returns
    -------
    float
        ``s`` [s].

    Raises
    ------
    UserInputError
        No common channel, a bad weight, or ``max_shift`` excluding every lag.
    """
    name = measured.source
    weights = dict(weights or {})
    used = _channels_to_align(measured, sim, weights)
    if max_shift is not None and not max_shift >= 0:
        raise UserInputError(f"{name}: max_shift must be >= 0 s, got {max_shift!r}")
    dt = measured.dt
    t_sim = np.asarray(t_sim, dtype=float)
    grid = _grid(t_sim, dt)
    corr = _cross_correlation(measured, resample(t_sim, {c: sim[c] for c in used}, grid), weights)
    lags = np.arange(-(len(grid) - 1), len(measured.t))
    shifts = measured.t[0] - grid[0] + lags * dt
    return _peak_shift(corr, shifts, dt, max_shift, name)


def _channels_to_align(measured: MeasuredData, sim: Mapping[str, np.ndarray], weights: Mapping[str, float]) -> list:
    """The channels both ``measured`` and ``sim`` have and ``weights`` does not set to 0 (measured order).

    Raises
    ------
    UserInputError
        A weight for a channel that is not common or that is negative or not finite, or no channel left.
    """
    name = measured.source
    common = [c for c in measured.channels if c in sim]
    for c, w in weights.items():
        if c not in common:
            raise UserInputError(f"{name}: weight given for {c!r}, which is not a channel of both the "
                                 f"measurement and the simulation{_hint(c, common)}")
        if not (w >= 0 and math.isfinite(w)):
            raise UserInputError(f"{name}: weight of {c!r} must be finite and >= 0, got {w!r}")
    used = [c for c in common if weights.get(c, 1.0) > 0]
    if not used:
        raise UserInputError(f"{name}: no channel in common with the simulation to align on "
                             f"(measured: {', '.join(measured.channels)}; simulated: {', '.join(sim)})")
    return used


def _grid(t_sim: np.ndarray, dt: float) -> np.ndarray:
    """Times from ``t_sim[0]`` with step ``dt`` [s] that stay within ``t_sim[-1]``, shape (ns,)."""
    ns = int(math.floor((t_sim[-1] - t_sim[0]) / dt * (1 + 1e-12))) + 1   # 1e-12: keep the last point when exact
    return np.minimum(t_sim[0] + dt * np.arange(ns), t_sim[-1])   # round-off must not step past the end


def _cross_correlation(measured: MeasuredData, sim_on_grid: Mapping[str, np.ndarray],
                       weights: Mapping[str, float]) -> np.ndarray:
    """Weighted sum over channels of the normalised cross-correlations, one FFT.

    Parameters
    ----------
    measured : MeasuredData
        nm samples.
    sim_on_grid : mapping of str to ndarray, shape (ns,)
        The simulated channels to use, on the measured step.
    weights : mapping of str to float
        Weight per channel (default 1).

    Returns
    -------
    ndarray, shape (ns - 1 + nm,)
        The correlation at lags ``L = -(ns-1) ... nm-1`` (``sum_k m[k+L] s[k]``).

    Raises
    ------
    UserInputError
        A simulated channel with non-finite values.
    """
    from scipy.fft import irfft, next_fast_len, rfft

    name = measured.source
    nm, ns = len(measured.t), len(next(iter(sim_on_grid.values())))
    nfft = next_fast_len(nm + ns - 1, real=True)
    spectrum = np.zeros(nfft // 2 + 1, dtype=complex)
    for c, s in sim_on_grid.items():
        valid = measured.mask[c]
        m = np.where(valid, measured.channels[c], 0.0)
        m_std = np.std(measured.channels[c][valid])
        if not np.isfinite(s).all():
            raise UserInputError(f"{name}: simulated channel {c!r} has non-finite values; cannot align")
        s_std = np.std(s)
        if m_std == 0 or s_std == 0:
            continue   # a constant channel carries no timing information
        m = np.where(valid, (m - np.median(measured.channels[c][valid])) / m_std, 0.0)
        s = (s - np.median(s)) / s_std
        spectrum += weights.get(c, 1.0) * rfft(m, nfft) * np.conj(rfft(s, nfft))
    cc = irfft(spectrum, nfft)
    # cc[L] = sum_k m[k+L] s[k]; lags L = -(ns-1) ... nm-1, negative ones wrapped to the end
    return np.concatenate((cc[nfft - (ns - 1):], cc[:nm])) if ns > 1 else cc[:nm]


def _peak_shift(corr: np.ndarray, shifts: np.ndarray, dt: float, max_shift: float | None, name: str) -> float:
    """The shift [s] of the correlation's highest allowed peak, refined by a parabola through its neighbours.

    Raises
    ------
    UserInputError
        ``max_shift`` excludes every shift, or the peak is not positive (no correlation).
    """
    allowed = np.ones(len(shifts), bool) if max_shift is None else np.abs(shifts) <= max_shift
    if not allowed.any():
        raise UserInputError(f"{name}: max_shift = {max_shift:g} s excludes every shift between the measured "
                             f"and the simulated passage ({shifts[0]:.6g} ... {shifts[-1]:.6g} s)")
    k = int(np.flatnonzero(allowed)[np.argmax(corr[allowed])])
    if not corr[k] > 0:
        raise UserInputError(f"{name}: measured and simulated signals do not correlate (no positive peak)")
    delta = 0.0
    if 0 < k < len(corr) - 1:
        y0, y1, y2 = corr[k - 1], corr[k], corr[k + 1]
        denom = y0 - 2 * y1 + y2
        if denom < 0:
            delta = float(np.clip(0.5 * (y0 - y2) / denom, -0.5, 0.5))
    s = float(shifts[k] + delta * dt)
    if max_shift is not None:
        s = float(np.clip(s, -max_shift, max_shift))
    return s
