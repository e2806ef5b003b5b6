"""The calibrated parameters: ``--params`` parsing and how parameter values enter a scenario.

Part of :mod:`orchestrator.inverse.calibrate` (its module docstring gives the ``--params``
syntax). Every named item is a question to the cause registry
(:data:`orchestrator.inputs.causes.CATALOGUE`): its ``aliases`` name the items (``h1``,
``gaps``, ``pad``, ...), its bounds and log scale are the defaults, its sites say where a
value goes in the scenario. A plain ``key.path=LO:HI`` item is a one-entry
:class:`~orchestrator.inputs.causes.CauseKind` named by its key, whose site is a
:class:`~orchestrator.inputs.causes.KeySite` at that key; so :func:`apply_values` and
:func:`nominal_values` treat every parameter alike.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from orchestrator.inputs import keypath
from orchestrator.inputs.causes import CATALOGUE, CauseKind
from orchestrator.inputs.errors import ScenarioError, UserInputError

__all__ = ["Parameter", "DEFAULT_PARAMS", "parse_params", "apply_values", "nominal_values", "variation",
           "values_at"]

DEFAULT_PARAMS = "gaps@T,h1,h2"  # seed 000: 6 void gaps at the transition sleeper, h1, h2
_ITEM = re.compile(r"^(?P<name>[^@=]+)(@(?P<where>[^=]*))?(=(?P<bounds>.*))?$")


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
        SI unit of the value (``m``, ``rad``, ``-``; ``""`` for a plain key path).
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

    @property
    def scenario_key(self) -> str:
        """The scenario key whose whole value carries this parameter (what a sweep varies)."""
        return self.kind.scenario_key(self.sleeper)

    def from_unit(self, u: float) -> float:
        """The value [unit] at unit coordinate ``u``."""
        lo, hi = self.bounds
        return float(dataclasses.replace(self.kind, lower=(lo,), upper=(hi,)).from_unit([u])[0])

    def to_unit(self, value: float) -> float:
        """The unit coordinate of ``value`` (outside [0, 1] when the value is out of bounds)."""
        lo, hi = self.bounds
        return float(dataclasses.replace(self.kind, lower=(lo,), upper=(hi,)).to_unit([value])[0])

    def as_dict(self) -> dict:
        """JSON-able description (an entry of ``calibration.json``'s ``parameters``)."""
        lo, hi = self.bounds
        return {"name": self.name, "cause": self.kind.name if self.key is None else None, "key": self.key,
                "sleeper": self.sleeper, "lower": lo, "upper": hi, "log": self.log, "unit": self.unit}

    @classmethod
    def from_dict(cls, d: dict) -> Parameter:
        """The parameter of an :meth:`as_dict` entry (its inverse)."""
        if d["cause"] is None:
            return cls(d["name"], _key_kind(d["key"], d["lower"], d["upper"], d["log"]), None, 0, d["unit"])
        kind = _with_bounds(CATALOGUE[d["cause"]], d["lower"], d["upper"], d["log"])
        named = _named(d["name"].split("@")[0])
        index = named[3] if named is not None and named[3] is not None else 0
        return cls(d["name"], kind, d["sleeper"], index, d["unit"])


# ======================================================================================
# --params: the registry's names
# ======================================================================================
def _key_kind(key: str, lo: float, hi: float, log: bool) -> CauseKind:
    """The one-entry kind of a plain ``key.path=LO:HI`` parameter (its site: a KeySite at ``key``)."""
    return CauseKind(key, False, (key,), (lo,), (hi,), log, (), unit="")


def _with_bounds(kind: CauseKind, lo: float, hi: float, log: bool) -> CauseKind:
    """``kind`` with the bounds ``lo``, ``hi`` on every entry and the given scale."""
    return dataclasses.replace(kind, lower=(lo,) * len(kind.lower), upper=(hi,) * len(kind.upper), log=log)


def _entry_head(alias: str) -> str:
    """The name of one entry of a vector cause: its alias in the singular (``gaps`` -> ``gap``)."""
    return alias[:-1] if alias.endswith("s") else alias


def _named(name: str) -> tuple[str, CauseKind, bool, int | None] | None:
    """A registry name of an item without its ``@sleeper`` and bounds, or ``None``.

    Returns
    -------
    (head, kind, local, entry) or None
        ``head``: the alias (``h1``, ``gaps``, ``pad``) or, for one entry ``gapI`` of a
        vector cause, the entry head ``gap``; ``local``: the alias is the cause's local
        one; ``entry``: the entry's index (I - 1) or ``None`` for the whole cause.
    """
    for kind in CATALOGUE.values():
        for scope, alias in kind.aliases.items():
            if name == alias:
                return alias, kind, scope == "local", None
            m = re.fullmatch(re.escape(_entry_head(alias)) + r"(?P<point>[1-9]\d*)", name) if kind.vector else None
            if m and int(m.group("point")) <= len(kind.names):
                return _entry_head(alias), kind, scope == "local", int(m.group("point")) - 1
    return None


def _expected() -> str:
    """The items the registry names, for error messages: ``h1, h2, angle, gaps@K, gapI@K, pad@K or key.path=...``."""
    aliases = [(scope, alias, kind) for kind in CATALOGUE.values() for scope, alias in kind.aliases.items()]
    items = [alias for scope, alias, _ in aliases if scope == "global"]
    for scope, alias, kind in aliases:
        if scope == "local":
            items += [f"{alias}@K"] + ([f"{_entry_head(alias)}I@K"] if kind.vector else [])
    return ", ".join(items) + " or key.path=LO:HI[:log]"


def _parse_bounds(text: str, item: str, default_log: bool) -> tuple[float, float, bool]:
    """``LO:HI[:log|:lin]`` -> (lo, hi, log); a user error names ``item``."""
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
    """The sleeper index of ``@K`` (an index or ``T``, ``T+1``, ``T-2``)."""
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
    """The calibrated parameters of a ``--params`` text (:mod:`orchestrator.inverse.calibrate`).

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
    spec = DEFAULT_PARAMS if spec is None or not spec.strip() else spec
    n_sleepers = int(scenario.raw["track"]["layout"]["sleepers"])

    @functools.lru_cache(maxsize=None)
    def transition() -> int:
        from track.model import build_track, reference_point

        return int(reference_point(build_track(scenario.track))[2])

    params: list[Parameter] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            raise UserInputError(f"--params {spec!r}: an empty item (two commas or a trailing comma)")
        m = _ITEM.match(item)
        if m is None:
            raise UserInputError(f"--params {item!r}: expected {_expected()}")
        name, where, bounds = m.group("name").strip(), m.group("where"), m.group("bounds")
        named = _named(name)
        if named is not None:
            sleeper = _named_sleeper(item, named, where, transition, n_sleepers)
            params.extend(_named_params(item, named, sleeper, bounds))
        else:
            params.append(_key_param(item, name, where, bounds, scenario))
    _check_distinct(spec, params)
    return params


def _named_sleeper(item: str, named: tuple, where: str | None, transition: Callable[[], int],
                   n_sleepers: int) -> int | None:
    """The sleeper of a named item (``None`` for a global cause); a user error when ``@K`` is missing or extra."""
    head, _, local, _ = named
    if local and where is None:
        raise UserInputError(f"--params {item!r}: {head} needs a sleeper, e.g. {head}@T or {head}@21")
    if not local and where is not None:
        raise UserInputError(f"--params {item!r}: {head} is global; it takes no @sleeper")
    return _sleeper(where, item, transition, n_sleepers) if local else None


def _named_params(item: str, named: tuple, sleeper: int | None, bounds: str | None) -> list[Parameter]:
    """The parameters of a named item: one per entry of a vector cause (``gaps``), else one.

    ``named`` is what :func:`_named` gives; ``bounds`` the text after ``=`` (or ``None``:
    the registry's bounds and scale).
    """
    head, kind, _, entry = named
    if bounds is not None:
        lo, hi, log = _parse_bounds(bounds, item, kind.log)
        clip = getattr(kind.site(sleeper), "lower_clip", None)  # the registry clips voids' gaps at 0
        if clip is not None and lo < clip:
            raise UserInputError(f"--params {item!r}: a void gap cannot be negative")
        kind = _with_bounds(kind, lo, hi, log)
    at = "" if sleeper is None else f"@{sleeper}"
    if not kind.vector:
        return [Parameter(f"{head}{at}", kind, sleeper, 0, kind.unit)]
    entries = range(len(kind.names)) if entry is None else (entry,)
    return [Parameter(f"{_entry_head(head)}{i + 1}{at}", kind, sleeper, i, kind.unit) for i in entries]


def _key_param(item: str, key: str, where: str | None, bounds: str | None, scenario) -> Parameter:
    """The parameter of a ``key.path=LO:HI[:log]`` item, checked on the scenario (the key must hold a number)."""
    from orchestrator.inputs.scenario import scenario_from_dict

    if where is not None or "." not in key:
        raise UserInputError(f"--params {item!r}: unknown parameter; expected {_expected()}")
    if bounds is None:
        raise UserInputError(f"--params {item!r}: a scenario key needs bounds, e.g. {key}=0.5:2")
    lo, hi, log = _parse_bounds(bounds, item, False)
    try:
        probe = scenario_from_dict(scenario.raw, source="--params", overrides=[f"{key}={lo!r}"],
                                   base_dir=_base_dir(scenario))
    except ScenarioError as exc:
        raise UserInputError(f"--params {item!r}: {exc}") from None
    value = keypath.get(probe.raw, key)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise UserInputError(f"--params {item!r}: {key} is not a number in the scenario")
    kind = _key_kind(key, lo, hi, log)
    return Parameter(key, kind, None, 0, kind.unit)


def _check_distinct(spec: str, params: Sequence[Parameter]) -> None:
    """A user error when a parameter is given twice, or a global cause both by name and as its key."""
    names = [p.name for p in params]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise UserInputError(f"--params {spec!r}: {', '.join(twice)} given twice")
    # a sleeper's cause is one entry of a list key, which a plain (numeric) key parameter cannot be
    keys = {p.scenario_key for p in params if p.key is None and p.sleeper is None}
    clash = sorted(k for k in (p.key for p in params if p.key is not None) if k in keys)
    if clash:
        raise UserInputError(f"--params {spec!r}: {', '.join(clash)} is given both by name and as a key")


def _base_dir(scenario) -> Path:
    return Path(scenario.source).parent if scenario.source and Path(scenario.source).exists() else Path.cwd()


# ======================================================================================
# Values in the scenario
# ======================================================================================
def apply_values(raw: dict, params: Sequence[Parameter], values: Sequence[float]) -> dict:
    """A copy of a validated raw scenario with the parameters set to ``values`` [their units].

    The entries of one cause at one place are set together (as one vector); entries
    not calibrated keep the scenario's value. Plain key parameters are set first.
    """
    raw = copy.deepcopy(raw)
    groups: dict[tuple, tuple[CauseKind, dict[int, float]]] = {}
    for p, v in sorted(zip(params, values), key=lambda pv: pv[0].key is None):  # stable: keys first
        groups.setdefault((p.kind.name, p.sleeper), (p.kind, {}))[1][p.index] = float(v)
    for (_, sleeper), (kind, entries) in groups.items():
        vector = kind.nominal(raw, sleeper).astype(float)
        for i, v in entries.items():
            vector[i] = v
        raw = kind.apply(raw, sleeper, vector)
    return raw


def nominal_values(raw: dict, params: Sequence[Parameter]) -> list[float]:
    """The parameters' values in a raw scenario [their units] (the inverse of :func:`apply_values`)."""
    return [float(p.kind.nominal(raw, p.sleeper)[p.index]) for p in params]


def values_at(params: Sequence[Parameter], u: np.ndarray) -> list[float]:
    """The parameters' values [their units] at the unit-cube point ``u`` (shape (k,))."""
    return [p.from_unit(x) for p, x in zip(params, u)]


def variation(raw: dict, params: Sequence[Parameter], values: Sequence[float], label: str) -> dict:
    """The sweep variation ``{"name": label, key.path: value, ...}`` of one point (whole values of the keys touched)."""
    new = apply_values(raw, params, values)
    keys = dict.fromkeys(p.scenario_key for p in params)
    # name first: the sweep plots scalars against the first varied key, and a string key means no plots
    return {"name": label, **{k: keypath.get(new, k) for k in keys}}
