"""The typed result of ``turnout diagnose`` (:func:`orchestrator.inverse.diagnose.diagnose`).

:class:`Diagnosis` is the whole answer; its :meth:`Diagnosis.to_json` is the content of
``diagnosis.json`` (DESIGN.md §4.5), key for key and in the same order, and
:meth:`Diagnosis.from_json` reads it back, so ``Diagnosis.from_json(d).to_json() == d``.
The parts: :class:`Answer` (the verdict: named cause(s), ``none`` or ``unexplained``
with where the residual lives), :class:`Baseline` (the nominal model's residuals, also
written alone as ``baseline.json``), :class:`CauseFit` (one candidate cause with its
fitted parameters, evidence and, when named, its intervals; ``named_cause`` is kept for
readers of the first schema: the first named cause, or ``none`` / ``unexplained``),
:class:`Gain` and :class:`Passage` (a further measured passage compared before/after the
extension). ``nuisance`` (speed, vehicle, damping, sensor gains fitted before any
cause) and ``dropped`` (variants left out, and why) are plain dicts / lists.

:meth:`Diagnosis.from_json` also reads a ``diagnosis.json`` of the first schema (no
``answer``, ``nuisance``, ``dropped``): the answer is then derived from ``named_cause``.

The values are kept as the diagnosis computed them (floats, lists, dicts); writing the
JSON file (NumPy scalars to numbers) is the caller's business.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Baseline:
    """What the nominal model gets wrong (``baseline.json``; DESIGN.md §4.5 ``baseline``).

    Attributes
    ----------
    objective : float
        J of the nominal model [-].
    shift : float
        Time alignment of the measurement [s].
    chi2 : float
        Chi-square of the residuals.
    n : int
        Valid samples over all channels.
    groups : dict
        Group -> mean nRMSE [-].
    channels : dict
        Channel id -> ``{"rmse", "nrmse"}`` (SI units, [-]).
    bic : float
        The nominal model's BIC (no fitted parameters).
    where : dict
        ``{"groups", "sleepers", "worst_channels"}``: where the simulation is wrong.
    noise_sigma : dict
        Channel id -> noise standard deviation estimated from the measurement (SI units).
    """

    objective: float
    shift: float
    chi2: float
    n: int
    groups: dict
    channels: dict
    bic: float
    where: dict
    noise_sigma: dict

    def to_json(self) -> dict:
        """The JSON-able content of ``baseline.json`` (keys in the order of the attributes)."""
        return {"objective": self.objective, "shift": self.shift, "chi2": self.chi2, "n": self.n,
                "groups": self.groups, "channels": self.channels, "bic": self.bic, "where": self.where,
                "noise_sigma": self.noise_sigma}

    @classmethod
    def from_json(cls, data: dict) -> Baseline:
        """The baseline of :meth:`to_json`'s dict (or of a parsed ``baseline.json``)."""
        return cls(data["objective"], data["shift"], data["chi2"], data["n"], data["groups"], data["channels"],
                   data["bic"], data["where"], data["noise_sigma"])


@dataclass
class CauseFit:
    """One candidate cause, fitted, with its evidence; or the named cause ``none``.

    Attributes
    ----------
    cause : str
        A cause of :data:`orchestrator.inputs.causes.CATALOGUE`, or ``"none"``.
    parameters : dict
        JSON-able parameters (:meth:`orchestrator.inputs.causes.CauseKind.parameters`:
        gaps in m, scales as factors, the angle in rad); empty for ``none``.
    objective : float
        J with this cause [-].
    gain : float
        1 - J / J_nominal [-].
    evidence : dict
        For a candidate: ``stage``, ``objective_reduction``, ``chi2``, ``n_samples``,
        ``n_parameters``, ``bic``, ``delta_bic_vs_nominal``, ``delta_bic_vs_best``,
        ``indistinguishable_from``. For ``none``: ``best_candidate``,
        ``delta_bic_vs_nominal``, ``threshold``, ``reason``.
    sleeper : int or None
        The sleeper of a local cause; None for a global one (and for ``none``).
    ambiguity : dict or None
        The named cause only: ``{"candidates": [labels], "sleepers": [ints]}``, the
        candidates (and their sleepers) that this data cannot tell apart from it.
    uncertainty : dict or None
        A named cause only (:func:`orchestrator.inverse.uncertainty.intervals`):
        ``{"level", "intervals", "identifiable", "unit_width", "pin_with"}``, per entry
        of the parameter vector.
    """

    cause: str
    parameters: dict
    objective: float
    gain: float
    evidence: dict
    sleeper: int | None = None
    ambiguity: dict | None = None
    uncertainty: dict | None = None

    def to_json(self) -> dict:
        """JSON-able dict: ``cause``, ``sleeper`` (local causes only), ``parameters``, ``objective``,
        ``gain``, ``evidence``, ``ambiguity`` and ``uncertainty`` (a named cause only)."""
        out = {"cause": self.cause}
        if self.sleeper is not None:
            out["sleeper"] = self.sleeper
        out.update({"parameters": self.parameters, "objective": self.objective, "gain": self.gain,
                    "evidence": self.evidence})
        if self.ambiguity is not None:
            out["ambiguity"] = self.ambiguity
        if self.uncertainty is not None:
            out["uncertainty"] = self.uncertainty
        return out

    @classmethod
    def from_json(cls, data: dict) -> CauseFit:
        """The cause of :meth:`to_json`'s dict; a missing ``sleeper`` / ``ambiguity`` / ``uncertainty`` is None."""
        return cls(data["cause"], data["parameters"], data["objective"], data["gain"], data["evidence"],
                   sleeper=data.get("sleeper"), ambiguity=data.get("ambiguity"), uncertainty=data.get("uncertainty"))


@dataclass
class Answer:
    """The verdict of a diagnosis (DESIGN.md §4.5): named cause(s), ``none`` or ``unexplained``.

    Attributes
    ----------
    kind : str
        ``named`` (one or more causes, each passing the rule of
        :mod:`orchestrator.inverse.significance`), ``none`` (the residual is at the noise
        level) or ``unexplained`` (above the noise, and no catalogue cause removes a
        practically significant share of it).
    causes : list of CauseFit
        The named causes in the order they were added (forward selection); each with its
        own gain over the model before it, its parameters, ``uncertainty`` and evidence.
    reason : str
        The verdict in plain words.
    where : dict or None
        For ``unexplained`` (and for the rest of the misfit after named causes, when it is
        above the noise): :func:`orchestrator.inverse.significance.locate`.
    resolution : list of dict or None
        For ``none``: what the record resolves, per screened candidate and screening proxy the least
        effect that would have lifted the residual above the noise
        (:func:`orchestrator.inverse.resolution.resolution`).
    """

    kind: str
    causes: list
    reason: str
    where: dict | None = None
    resolution: list | None = None

    def to_json(self) -> dict:
        """``{"kind", "causes", "reason", "where", "resolution"}``."""
        return {"kind": self.kind, "causes": [c.to_json() for c in self.causes], "reason": self.reason,
                "where": self.where, "resolution": self.resolution}

    @classmethod
    def from_json(cls, data: dict) -> Answer:
        """The answer of :meth:`to_json`'s dict (``resolution`` absent before 2026-11-30: None)."""
        return cls(data["kind"], [CauseFit.from_json(c) for c in data["causes"]], data["reason"], data.get("where"),
                   data.get("resolution"))

    @classmethod
    def of_named_cause(cls, named: dict) -> Answer:
        """The answer a first-schema ``diagnosis.json`` implies (its ``named_cause`` only)."""
        if named["cause"] in ("none", "unexplained"):
            return cls(named["cause"], [], named.get("evidence", {}).get("reason", ""))
        return cls("named", [CauseFit.from_json(named)], "read from a diagnosis.json of the first schema")


@dataclass
class Gain:
    """Gain of the extended model over the nominal one, 1 - J_after / J_before.

    Attributes
    ----------
    total : float
        On the objective J [-].
    channels : dict
        Channel id -> 1 - nRMSE_after / nRMSE_before [-].
    """

    total: float
    channels: dict

    def to_json(self) -> dict:
        """``{"total": ..., "channels": {...}}``."""
        return {"total": self.total, "channels": self.channels}

    @classmethod
    def from_json(cls, data: dict) -> Gain:
        """The gain of :meth:`to_json`'s dict."""
        return cls(data["total"], data["channels"])


@dataclass
class Passage:
    """A further measured passage at another speed, compared before/after without refitting.

    Attributes
    ----------
    file : str
        The measured file.
    speed : float
        Its speed [m/s].
    objective_before, objective_after : float
        J of the nominal and of the extended model [-].
    gain : float
        1 - objective_after / objective_before [-].
    channels : dict
        Channel id -> ``{"nrmse_before", "nrmse_after"}`` [-].
    """

    file: str
    speed: float
    objective_before: float
    objective_after: float
    gain: float
    channels: dict

    def to_json(self) -> dict:
        """JSON-able dict, keys in the order of the attributes."""
        return {"file": self.file, "speed": self.speed, "objective_before": self.objective_before,
                "objective_after": self.objective_after, "gain": self.gain, "channels": self.channels}

    @classmethod
    def from_json(cls, data: dict) -> Passage:
        """The passage of :meth:`to_json`'s dict."""
        return cls(data["file"], data["speed"], data["objective_before"], data["objective_after"], data["gain"],
                   data["channels"])


@dataclass
class Diagnosis:
    """The whole answer of a diagnosis (DESIGN.md §4.5; the module doc of :mod:`orchestrator.inverse.diagnose`).

    Attributes
    ----------
    scenario, measured : str
        The nominal scenario and the measured passage, as given.
    answer : Answer
        The verdict: named cause(s), ``none`` or ``unexplained`` (with where).
    baseline : Baseline
        What the nominal model gets wrong.
    nuisance : dict or None
        The nuisance estimates (speed, time shift, vehicle, damping, sensor gains) fitted
        before any cause: "the measurement / vehicle differs from the scenario by ...";
        None when no nuisance stage ran.
    causes : list of CauseFit
        Every candidate of the first round, best first (fitted and confirmed ones by BIC on
        the effective sample size, then the screened ones), then those of later rounds.
    named_cause : CauseFit
        The first named cause (with its ``ambiguity``), or ``none`` / ``unexplained``
        (kept for readers of the first schema).
    extended_scenario : str
        File name of the extended scenario in the output folder (``extended.yaml``).
    gain : Gain
        Of the extended model (all named causes) on the measured passage.
    validation : list of Passage
        Further passages (``--validate``).
    dropped : list of dict
        Variants left out, each ``{"variant", "stage", "reason"}``.
    runs : int
        Simulations run.
    wall_seconds : float
        Wall time of the diagnosis [s].
    settings : dict
        The thresholds used and the candidates' labels.
    runs_ahead : dict
        ``{"runs", "used"}``: of :attr:`runs`, those made ahead of being asked for (a
        one-parameter fit's Jacobian beside its trial point, on a worker that would idle:
        :func:`orchestrator.inverse.fitting.fit_unit_cube`) and how many a fit then used;
        the others changed nothing but the count. ``{}`` in files written before 2026-11-26.
    """

    scenario: str
    measured: str
    answer: Answer
    baseline: Baseline
    nuisance: dict | None
    causes: list[CauseFit]
    named_cause: CauseFit
    extended_scenario: str
    gain: Gain
    validation: list[Passage]
    dropped: list
    runs: int
    wall_seconds: float
    settings: dict
    runs_ahead: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """The content of ``diagnosis.json``: the attributes in their order, each part by its own ``to_json``."""
        return {"scenario": self.scenario, "measured": self.measured, "answer": self.answer.to_json(),
                "baseline": self.baseline.to_json(), "nuisance": self.nuisance,
                "causes": [c.to_json() for c in self.causes], "named_cause": self.named_cause.to_json(),
                "extended_scenario": self.extended_scenario, "gain": self.gain.to_json(),
                "validation": [v.to_json() for v in self.validation], "dropped": self.dropped, "runs": self.runs,
                "wall_seconds": self.wall_seconds, "settings": self.settings, "runs_ahead": self.runs_ahead}

    @classmethod
    def from_json(cls, data: dict) -> Diagnosis:
        """The diagnosis of :meth:`to_json`'s dict (or of a parsed ``diagnosis.json``, also of the first schema)."""
        answer = Answer.from_json(data["answer"]) if "answer" in data else Answer.of_named_cause(data["named_cause"])
        return cls(data["scenario"], data["measured"], answer, Baseline.from_json(data["baseline"]),
                   data.get("nuisance"), [CauseFit.from_json(c) for c in data["causes"]],
                   CauseFit.from_json(data["named_cause"]), data["extended_scenario"], Gain.from_json(data["gain"]),
                   [Passage.from_json(v) for v in data["validation"]], data.get("dropped", []), data["runs"],
                   data["wall_seconds"], data["settings"], data.get("runs_ahead", {}))


__all__ = ["Diagnosis", "Answer", "CauseFit", "Baseline", "Gain", "Passage"]
