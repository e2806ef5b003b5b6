"""The plan of a sweep: its variations (grids, run lists), its runs and their ids.

A sweep is a base scenario plus a list of variations, each a mapping
``{key.path: value}`` applied as scenario overrides (one run each). The list
comes from a grid (``--vary key=v1,v2,...``, repeatable: the Cartesian product,
:func:`grid_from_vary`) or from a YAML file (``--list FILE.yaml``,
:func:`list_from_file`). Every run's scenario is validated before anything
runs (:func:`plan_sweep`), so a bad key or value stops the sweep at once.

A run id is a digest of the run's validated scenario (base + overrides), so it
does not depend on the run's position: re-running the same command, reordering
``--vary`` options or adding values reuses every run already finished
(:mod:`orchestrator.sweeps.store`).
"""
from __future__ import annotations

import hashlib
import itertools
import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from orchestrator.inputs import keypath
from orchestrator.inputs.errors import ScenarioError, UserInputError
from orchestrator.inputs.scenario import parse_override, read_yaml, scenario_from_dict

__all__ = ["Run", "SweepPlan", "grid_from_vary", "expand_grid", "list_from_file", "plan_sweep"]

RUN_ID_CHARS = 12  # hex digits of the SHA-1 kept in a run id (48 bits: no collision in any sweep)
RUN_ID_PREFIX = "r"  # run ids start with a letter: safe as folder names and CSV cells


# --------------------------------------------------------------------------------------
# Variations
# --------------------------------------------------------------------------------------
def _override_key(key: Any, where: str) -> str:
    """Check one variation key (a scenario key path) and return it without blanks."""
    if not isinstance(key, str):
        raise UserInputError(f"{where}: a key must be a scenario key path such as vehicle.speed, got {key!r}")
    key = key.strip()
    parse_override(f"{key}=0")  # raises ScenarioError naming a malformed key path
    return key


def grid_from_vary(texts: Sequence[str]) -> list[dict[str, Any]]:
    """The variations of ``--vary key.path=v1,v2,...`` options: their Cartesian product.

    Parameters
    ----------
    texts : sequence of str
        One ``key.path=v1,v2,...`` per varied key. The values are read as YAML
        (the scenario's rules: ``1e8`` is a number, ``"1:12"`` a string); a value
        may be a flow list or mapping, e.g. ``track.ballast.voids[0].gaps=[0,0,0,0,0,0],[0,1e-3,1e-3,1e-3,1e-3,0]``.

    Returns
    -------
    list of dict
        One ``{key: value}`` per run, in grid order (the last key varies fastest).

    Raises
    ------
    UserInputError
        A text that is not ``key=values``, a value list that is not YAML, a key
        given twice or without values.
    """
    spec: dict[str, list] = {}
    for text in texts:
        if not isinstance(text, str) or "=" not in text:
            raise UserInputError(f"--vary {text!r}: expected key.path=v1,v2,...")
        key, values_text = text.split("=", 1)
        where = f"--vary {text!r}"
        key = _override_key(key, where)
        try:
            _, values = parse_override(f"{key}=[{values_text}]")
        except ScenarioError as exc:
            raise UserInputError(f"{where}: the values are not a comma-separated YAML list ({exc.message})") from None
        if not values:
            raise UserInputError(f"{where}: no values given")
        if key in spec:
            raise UserInputError(f"{where}: {key} is varied twice; give all its values in one --vary")
        spec[key] = values
    return expand_grid(spec)


def expand_grid(spec: Mapping[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """The Cartesian product of ``{key: values}``: one ``{key: value}`` per run (last key fastest)."""
    keys = list(spec)
    return [dict(zip(keys, combo)) for combo in itertools.product(*(spec[k] for k in keys))]


def list_from_file(path: str | os.PathLike) -> list[dict[str, Any]]:
    """The variations of ``--list FILE.yaml``: a YAML list of mappings ``{key.path: value}``.

    An empty mapping ``{}`` is a run of the base scenario. Keys missing from an
    item keep the base scenario's value.

    Raises
    ------
    UserInputError
        The file is missing, not YAML, or not a non-empty list of mappings.
    """
    data = read_yaml(path)  # ScenarioError (a UserInputError) names the file
    if not isinstance(data, list) or not data:
        raise UserInputError(f"{path}: expected a non-empty YAML list of mappings {{key.path: value}}, one per run")
    runs = []
    for i, item in enumerate(data):
        if item is None:
            item = {}
        if not isinstance(item, Mapping):
            raise UserInputError(f"{path}: item {i}: expected a mapping {{key.path: value}}, got {item!r}")
        runs.append({_override_key(k, f"{path}: item {i}"): v for k, v in item.items()})
    return runs


def _value_text(value: Any) -> str:
    """``value`` as YAML text that the scenario loader reads back to the same value.

    Numbers read from YAML keep their text (so ``rail: 60E1`` stays the string
    "60E1" where a string is expected); anything else is written as JSON, which
    is YAML flow syntax.
    """
    text = getattr(value, "yaml_text", None)
    return text if isinstance(text, str) else json.dumps(value)


def _digest(data: Any) -> str:
    """SHA-1 hex digest of ``data`` as canonical JSON (sorted keys, no blanks)."""
    text = json.dumps(data, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha1(text.encode("utf-8")).hexdigest()


# --------------------------------------------------------------------------------------
# Plan
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Run:
    """One run of a sweep.

    Attributes
    ----------
    index : int
        Position in the sweep (grid order), from 0.
    run_id : str
        Stable id: a digest of the run's validated scenario; names ``OUT/runs/<run_id>``.
    overrides : tuple of str
        ``key.path=value`` texts applied to the base scenario, in key order.
    values : dict
        Varied key -> the value the run uses (from its validated scenario, so a
        key a list item leaves out shows the base value).
    raw : dict
        The run's validated raw scenario (file paths absolute on the client): what its
        worker gets, by value (:class:`orchestrator.cosim.portable.PortableScenario`).
    """

    index: int
    run_id: str
    overrides: tuple[str, ...]
    values: dict
    raw: dict = field(repr=False, compare=False)


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep: base scenario file, the varied keys and the runs in grid order."""

    base_path: Path
    varied_keys: tuple[str, ...]
    runs: tuple[Run, ...]


def plan_sweep(base_path: str | os.PathLike, variations: Sequence[Mapping[str, Any]]) -> SweepPlan:
    """Validate every run of a sweep and give each its id; nothing runs.

    Parameters
    ----------
    base_path : path-like
        The base scenario YAML.
    variations : sequence of mapping
        One ``{key.path: value}`` per run (:func:`grid_from_vary`, :func:`list_from_file`).

    Raises
    ------
    ScenarioError
        The base scenario or a run's scenario is invalid (names the key and value).
    UserInputError
        No runs, or two runs that are the same scenario.
    """
    base_path = Path(base_path)
    if not variations:
        raise UserInputError("the sweep has no runs: give --vary key=v1,v2,... or --list FILE.yaml")
    data = read_yaml(base_path)
    source, folder = str(base_path), base_path.parent
    scenario_from_dict(data, source=source, base_dir=folder)  # the base alone first: its errors are its own
    varied: dict[str, None] = {}
    for variation in variations:
        varied.update(dict.fromkeys(_override_key(k, "variation") for k in variation))
    runs: list[Run] = []
    seen: dict[str, Run] = {}
    for index, variation in enumerate(variations):
        items = sorted((_override_key(k, f"run {index}"), v) for k, v in variation.items())
        overrides = tuple(f"{k}={_value_text(v)}" for k, v in items)
        raw = scenario_from_dict(data, source=source, overrides=overrides, base_dir=folder).raw
        run_id = RUN_ID_PREFIX + _digest(raw)[:RUN_ID_CHARS]
        run = Run(index, run_id, overrides, {k: keypath.get(raw, k) for k in varied}, raw)
        if run_id in seen:
            first = seen[run_id]
            raise UserInputError(f"run {index} ({', '.join(overrides) or 'no overrides'}) is the same scenario as "
                                 f"run {first.index} ({', '.join(first.overrides) or 'no overrides'}); "
                                 f"give each combination once")
        seen[run_id] = run
        runs.append(run)
    return SweepPlan(base_path, tuple(varied), tuple(runs))
