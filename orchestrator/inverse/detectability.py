"""How visible is a field-like case's effect? Its noise-free signature against the case's own noise.

A field-like case (:class:`orchestrator.inverse.fieldlike.FieldCase`) hides effects in a
truth that passes a sensor chain. Whether a diagnosis *can* name an effect depends on how
much of the measured record the effect changes, against what the chain adds. This module
measures that, independently of any diagnosis (it never calls one, nor uses a threshold of
one): :func:`case_detectability` runs the case's truth twice through the same acquisition
as :func:`~orchestrator.inverse.fieldlike.synthesize_case` (:func:`~orchestrator.inverse.synthetic.truth_run`,
:func:`~orchestrator.inverse.synthetic.sample_signals`, the acquisition times, the layout's
high-pass for displacement channels) — once with the case's effects and once without them,
with the same model mismatch (vehicle, speed, damping, time step) — and returns per channel

* the **signature** ``d_c = s_with - s_without`` as the chain would pass it without noise:
  the faulty chain's gain is applied to both (so it scales ``d_c`` of its channel), its
  offset is left out (a constant of the channel, not part of an effect; in
  :func:`~orchestrator.inverse.fieldlike.apply_chain` it scales with each record's std and
  would leave a spurious constant in a difference), displacement channels are
  reconstructed from the accelerations (the reconstruction is linear, so this is the
  reconstruction of the accelerations' difference);
* the **noise** ``n_c``: the white + coloured noise and drift the case's own chain put on
  the measured record (:func:`~orchestrator.inverse.fieldlike.disturbance`, scaled by the
  std of the with-effect signal or its sensor kind's floor,
  :func:`~orchestrator.inverse.fieldlike.noise_scales`, times the channel's gain, reconstructed
  for displacement channels), i.e. exactly what ``apply_chain`` adds to the noise-free record;
* the **signature-to-noise ratio** ``rho_c = sum(d_c^2) / sum(n_c^2)``, and over the
  channels its plain mean and its maximum.

Why this ratio: it is scale-free per channel (units and the channel's size cancel), so
channels need no weights — and no weighting of the diagnosis's objective (the code under
test) enters. It reads at once: ``rho_c = 0.3`` means the effect's own signal carries 0.3
times the energy of the noise on that channel, over the same record (RMS ratio
``sqrt(rho_c)``). The maximum says what the best channel sees, the mean how widespread
the effect is. It is *not* a detection probability: for a known signature in white noise
of variance sigma^2 the matched-filter statistic is ``sum(d^2) / sigma^2 = N rho`` with N
samples, so a small rho can still be detectable by a test that knows the signature; the
coloured noise and the drift shrink the effective N, and a diagnosis must also find the
magnitude, the place and the nuisance parameters (time shift, speed, vehicle), which spend
part of it; the mismatch families add a model-form misfit that is in neither ``d`` nor
``n``. So rho ranks and groups cases by how much the data hold of their effect; it does
not say which of them a given method must get.

Two more summaries per signature, because the ratio of the best channel can come from a
channel whose own noise is small (the chain's noise is a share of each record's std, so a
lightly loaded pressure cell is a quiet channel): the **median** over the channels (the
typical channel), and **rho_free**, the ratio of the part of each channel's signature that
no offset, gain, time shift or time stretch of its no-effect record mimics
(:func:`nuisance_free`) — the nuisances every field record has, linearised and fitted per
channel, so a low estimate of what survives them. Neither uses the diagnosis.

Measured on the 51 cases of issue 14's field-like matrix (``benchmarks/RESULTS.md``, 2026-11-25
08:13): every single effect has a best-channel ratio >= 10 (rho_free >= 8), the misses
included — by this measure no effect of that matrix is below the chain's noise; the
misses have the lowest *median* ratios (7 of the 10 lowest of 36).

For cases with two or more effects each effect also gets its signatures, computed from the
same runs: *alone* (only that effect vs none) and *marginal* (all effects vs all but that
one: what the data hold of it given the others). With two effects, one effect's
"all but it" run is the other's "alone" run: 4 runs in all.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from orchestrator.inputs.sensor_layout import layout_of
from orchestrator.inverse.fieldlike import Chain, FieldCase, disturbance, gain_and_reconstruct, noise_scales
from orchestrator.inverse.synthetic import (acquisition_rate, acquisition_times, sample_signals, truth_run,
                                            variant_scenario)


@dataclass(frozen=True)
class Signature:
    """A set of effects' noise-free signature on every channel and its ratio to the case's noise.

    Attributes
    ----------
    label : str
        What was switched on and off (e.g. ``all effects``, ``ballast_void@21 alone``).
    d : dict
        Channel id -> the signature ``s_with - s_without`` at the acquisition times (SI units).
    rho : dict
        Channel id -> ``sum(d_c^2) / sum(n_c^2)``.
    rho_free : dict
        Channel id -> the same ratio for the part of ``d_c`` that no gain, offset, time
        shift or time stretch of the channel's no-effect record mimics (:func:`nuisance_free`).
    """

    label: str
    d: dict = field(repr=False)
    rho: dict
    rho_free: dict = field(default_factory=dict)

    @property
    def mean_rho(self) -> float:
        """Plain mean of the channels' ratios."""
        return float(np.mean(list(self.rho.values())))

    @property
    def median_rho(self) -> float:
        """Median of the channels' ratios (the typical channel; the mean follows the best one)."""
        return float(np.median(list(self.rho.values())))

    @property
    def max_channel(self) -> str:
        """The channel with the largest ratio."""
        return max(self.rho, key=self.rho.get)

    @property
    def max_rho(self) -> float:
        """The largest channel ratio (the best channel's)."""
        return float(self.rho[self.max_channel])

    def as_dict(self) -> dict:
        """JSON-able summary (no arrays): label, per-channel rho and energy, mean, max and its channel."""
        free = max(self.rho_free, key=self.rho_free.get) if self.rho_free else None
        return {"label": self.label, "rho": {c: float(v) for c, v in self.rho.items()},
                "energy": {c: float(np.sum(x ** 2)) for c, x in self.d.items()},
                "mean_rho": self.mean_rho, "median_rho": self.median_rho, "max_rho": self.max_rho,
                "max_channel": self.max_channel, "rho_free": {c: float(v) for c, v in self.rho_free.items()},
                "max_rho_free": float(self.rho_free[free]) if free else None, "max_channel_free": free}


@dataclass(frozen=True)
class Detectability:
    """The signatures of one case (module docstring).

    Attributes
    ----------
    t : ndarray
        Acquisition times on the truth's clock [s].
    noise : dict
        Channel id -> the chain's noise realisation ``n_c`` at those times.
    clean : dict
        Channel id -> the noise-free measured record with all effects (gain applied,
        displacements reconstructed, no offset); ``clean + noise`` is the measured
        record up to the faulty channel's offset.
    total : Signature
        All effects on vs off.
    effects : tuple
        Per effect (cases with >= 2 effects; else empty): ``(alone, marginal)`` signatures.
    """

    t: np.ndarray = field(repr=False)
    noise: dict = field(repr=False)
    clean: dict = field(repr=False)
    total: Signature
    effects: tuple = ()

    def as_dict(self) -> dict:
        """JSON-able summary: noise energy per channel, the total and per-effect signatures."""
        return {"noise_energy": {c: float(np.sum(x ** 2)) for c, x in self.noise.items()},
                "samples": int(self.t.size), "total": self.total.as_dict(),
                "effects": [{"alone": a.as_dict(), "marginal": m.as_dict()} for a, m in self.effects]}


# ------------------------------------------------------------------------------------------ stages
def noise_free(sampled: dict, types: dict, dt: float, highpass: float, chain: Chain | None) -> dict:
    """The channels as the chain passes them without noise, drift and offset (module docstring).

    Parameters
    ----------
    sampled : dict
        Channel id -> the true signal at the acquisition times (displacement channels as
        their accelerometer's acceleration).
    types : dict
        Channel id -> sensor type.
    dt : float
        Sampling interval [s].
    highpass : float
        Corner of the displacement reconstruction [Hz].
    chain : Chain or None
        Its gain error (if any) is applied.
    """
    return {sid: gain_and_reconstruct(sid, np.asarray(x, float), types, dt, highpass, chain)
            for sid, x in sampled.items()}


def chain_noise(sampled: dict, types: dict, dt: float, highpass: float, chain: Chain) -> dict:
    """The chain's noise realisation per channel: white + coloured + drift, as the measured record carries it.

    Written from :func:`~orchestrator.inverse.fieldlike.disturbance` (channel number =
    position in ``sampled``, scale = :func:`~orchestrator.inverse.fieldlike.noise_scales`), times
    the faulty channel's gain, reconstructed for displacement channels — the same as ``apply_chain(sampled)`` minus
    ``apply_chain`` of a chain without noise and drift (tests/test_detectability.py checks it).
    """
    scales = noise_scales(sampled, types, chain)
    return {sid: gain_and_reconstruct(sid, disturbance(chain, index, len(x), dt, scales[sid]), types, dt, highpass,
                                      chain)
            for index, (sid, x) in enumerate(sampled.items())}


def nuisance_free(d: np.ndarray, without: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The part of a channel's signature ``d`` that no offset, gain, time shift or time stretch of the
    channel's no-effect record ``without`` mimics (least-squares residual, linearised).

    Every field record has an unknown offset and gain per channel and an unknown trigger and
    speed (here: a shift and a stretch of the time axis). To first order they change the
    record by ``a + b x + c x' + e (t - t_mid) x'`` (``x'`` the record's time derivative);
    what of ``d`` lies in that span, a method must tell from them. Fitted per channel,
    which is more freedom than a passage has (its shift and speed are common to all
    channels): the ratio of what is left is a low estimate. Vehicle and damping
    parameters are not removed.
    """
    dx = np.gradient(without, t)
    basis = np.column_stack([np.ones_like(t), without, dx, (t - 0.5 * (t[0] + t[-1])) * dx])
    return d - basis @ np.linalg.lstsq(basis, d, rcond=None)[0]


def _ratio(signal: float, floor: float) -> float:
    """``signal / floor``; 0 without signal, ``inf`` with a signal and no noise (:func:`signature`)."""
    return 0.0 if signal == 0.0 else signal / floor if floor > 0.0 else float("inf")


def signature(label: str, with_: dict, without: dict, noise: dict, t: np.ndarray | None = None) -> Signature:
    """The signature ``with_ - without`` per channel and its energy ratio to ``noise``.

    A channel the effects leave exactly as it was has ratio 0; one they change where the
    noise is zero has ratio ``inf`` (a pressure cell under a void whose sleeper never
    touches the ballast, its record all zeros, in a passage written before the chain's
    noise floor per sensor kind, or before that floor left out the cells reading nothing:
    :func:`orchestrator.inverse.fieldlike.noise_scales`). With the times ``t`` also the
    ratio of the signature's nuisance-free part (:func:`nuisance_free`).
    """
    d = {sid: with_[sid] - without[sid] for sid in with_}
    floor = {sid: float(np.sum(noise[sid] ** 2)) for sid in d}
    rho = {sid: _ratio(float(np.sum(x ** 2)), floor[sid]) for sid, x in d.items()}
    free = {} if t is None else {
        sid: _ratio(float(np.sum(nuisance_free(x, without[sid], t) ** 2)) if np.any(x) else 0.0, floor[sid])
        for sid, x in d.items()}
    return Signature(label, d, rho, free)


def effect_label(effect) -> str:
    """``cause`` or ``cause@sleeper``."""
    return effect.cause + (f"@{effect.sleeper}" if effect.sleeper is not None else "")


def _subsets(n: int) -> list[tuple[int, ...]]:
    """The effect subsets whose truth runs are needed besides the no-effect one: all, and with >= 2 effects
    each alone and all but each."""
    full = tuple(range(n))
    need = [full]
    if n >= 2:
        need += [(i,) for i in full] + [tuple(j for j in full if j != i) for i in full]
    return list(dict.fromkeys(need))


def _truth_runs(scenario, case: FieldCase, layout, progress) -> dict:
    """Effect subset -> its truth run; key None: the nominal with the case's mismatch and no effect.

    The no-effect run is built as ``case.mismatch.apply`` of the nominal, the others as the
    case's ``truth_raw`` with a subset of its effects: for a case without effects these are
    two runs by two paths (their difference checks that they are one model).
    """
    raws = {s: replace(case, effects=tuple(case.effects[i] for i in s)).truth_raw(scenario.raw)
            for s in _subsets(len(case.effects))}
    raws[None] = case.mismatch.apply(scenario.raw)
    runs = {}
    for s, raw in raws.items():
        if progress:
            progress(f"{case.family} {case.seed}: truth with effects {'none' if s is None else list(s)}")
        runs[s] = truth_run(variant_scenario(scenario, raw, f"<{case.family} {s}>"), layout)
    t_sim = runs[None].t
    if any(r.t.shape != t_sim.shape or not np.array_equal(r.t, t_sim) for r in runs.values()):
        raise RuntimeError(f"{case.family} {case.seed}: the truth runs with and without effects differ in time grid")
    return runs


# ------------------------------------------------------------------------------------------ the measure
def case_detectability(scenario, case: FieldCase, crop: float = 0.01, progress=None) -> Detectability:
    """The signatures of a case's effects and their ratios to the case's noise (module docstring).

    Parameters
    ----------
    scenario : Scenario
        The nominal scenario (its sensor layout and output step make the acquisition),
        as given to :func:`~orchestrator.inverse.fieldlike.synthesize_case`.
    case : FieldCase
    crop : float
        Time cut from both ends of the simulated window [s] (as ``synthesize_case``).
    progress : callable, optional
        Called with a short text before each truth run.

    Returns
    -------
    Detectability

    Raises
    ------
    RuntimeError
        A truth run failed, or two runs of one case do not share their time grid.
    ValueError
        The case has no sensor chain (no noise to compare with).
    """
    if case.chain is None:
        raise ValueError(f"{case.family} {case.seed}: the case has no sensor chain, so no noise to compare with")
    layout = layout_of(scenario)
    runs = _truth_runs(scenario, case, layout, progress)
    full = tuple(range(len(case.effects)))
    t_sim = runs[full].t
    rate = acquisition_rate(t_sim, layout.rate)
    t_acq, _ = acquisition_times(t_sim, rate, crop)
    dt, hp = 1.0 / rate, layout.displacement_highpass
    sampled = {s: sample_signals(r, layout, t_acq, case.chain.aa_share, case.chain.aa_order) for s, r in runs.items()}
    clean = {s: noise_free(x, layout.types, dt, hp, case.chain) for s, x in sampled.items()}
    noise = chain_noise(sampled[full], layout.types, dt, hp, case.chain)
    total = signature("all effects" if case.effects else "no effect", clean[full], clean[None], noise, t_acq)
    per_effect = []
    if len(case.effects) >= 2:
        for i, e in enumerate(case.effects):
            rest = tuple(j for j in full if j != i)
            per_effect.append((signature(f"{effect_label(e)} alone", clean[(i,)], clean[None], noise, t_acq),
                               signature(f"{effect_label(e)} given the others", clean[full], clean[rest], noise,
                                         t_acq)))
    return Detectability(t_acq, noise, clean[full], total, tuple(per_effect))


__all__ = ["Signature", "Detectability", "case_detectability", "noise_free", "chain_noise", "signature",
           "nuisance_free", "effect_label"]
