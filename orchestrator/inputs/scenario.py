"""Scenario files: read, override, validate, map onto the model's dataclasses.

A scenario is a YAML mapping (DESIGN.md §4.2, documented key by key in the
README). Loading it goes

    YAML text --(read_yaml)--> dict --(overrides)--> dict --(SCHEMA)--> raw dict
        --(_build)--> Scenario (TrackParams, VehicleSpec, SimulationSpec)

Where each part lives:

* :mod:`orchestrator.inputs.yaml_io`: the YAML rules (YAML 1.2 numbers, no duplicate
  keys), :func:`read_yaml` and the dumper;
* :mod:`orchestrator.inputs.schema`: the accepted keys, their checks and defaults
  (:data:`~orchestrator.inputs.schema.SCHEMA`) and :func:`scenario_keys`, built from
  the generic nodes of :mod:`orchestrator.inputs.schema_nodes`;
* :mod:`orchestrator.inputs.specs`: :class:`VehicleSpec`, :class:`SimulationSpec`,
  :class:`PortMap` (the track's dataclasses are in :mod:`track.params`);
* here: :class:`Scenario`, overrides (:func:`parse_override`), :func:`load_scenario`,
  :func:`scenario_from_dict`, :func:`dump_scenario` and :func:`bundled_scenario`.

Every problem raises :class:`~orchestrator.inputs.errors.ScenarioError` naming the
dotted key path; the caller's dict is never modified.
"""
from __future__ import annotations

import copy
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from orchestrator.inputs import keypath
from orchestrator.inputs.errors import ScenarioError, UserInputError
from orchestrator.inputs.schema import SCHEMA, KeyDoc, scenario_keys
from orchestrator.inputs.schema_contact import contact_params
from orchestrator.inputs.schema_nodes import Ctx, Invalid, describe, node_at
from orchestrator.inputs.specs import BUILTIN_VEHICLES, PortMap, SimulationSpec, VehicleSpec
from orchestrator.inputs.yaml_io import YamlLoader, dump_yaml, read_yaml, yaml_error_message
from track.params import (
    BallastParams,
    LayoutParams,
    PadOverride,
    RailPadParams,
    ReductionParams,
    TrackParams,
    VoidSpec,
)

__all__ = [
    "PortMap",
    "VehicleSpec",
    "SimulationSpec",
    "Scenario",
    "load_scenario",
    "scenario_from_dict",
    "read_yaml",
    "dump_scenario",
    "parse_override",
    "scenario_keys",
    "KeyDoc",
    "BUILTIN_VEHICLES",
]


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes
    ----------
    name : str
        Scenario name (safe as a file name).
    track : TrackParams
    vehicle : VehicleSpec
    simulation : SimulationSpec
    sensors : str or None
        Absolute path of the sensor layout YAML.
    source : str
        Where it came from (file name as given, or ``"<dict>"``).
    raw : dict
        The validated, defaults-filled scenario as plain YAML data (paths made
        absolute). Treat it as read-only; :func:`dump_scenario` writes it and
        :meth:`with_overrides` derives new scenarios from it.
    """

    name: str
    track: TrackParams
    vehicle: VehicleSpec
    simulation: SimulationSpec
    sensors: str | None
    source: str
    raw: dict = field(compare=False, hash=False, repr=False)

    def with_overrides(self, overrides: Iterable[str]) -> "Scenario":
        """A new scenario with ``key.path=value`` overrides applied (see :func:`load_scenario`)."""
        return scenario_from_dict(self.raw, source=self.source, overrides=overrides)


# --------------------------------------------------------------------------------------
# Overrides
# --------------------------------------------------------------------------------------
def parse_override(text: str) -> tuple[tuple, Any]:
    """Split ``"key.path[0].sub=value"`` into path tokens and the YAML-parsed value.

    Raises
    ------
    ScenarioError
        Not of the form ``key.path=value``, or the value is not valid YAML.
    """
    if not isinstance(text, str) or "=" not in text:
        raise ScenarioError(f"override {text!r} is not of the form key.path=value")
    key, value_text = text.split("=", 1)
    key = key.strip()
    try:
        tokens = keypath.tokens(key)
    except keypath.KeyPathError:
        raise ScenarioError(f"override {text!r}: {key!r} is not a key path like track.ballast.voids[0].gaps") \
            from None
    try:
        value = yaml.load(value_text, Loader=YamlLoader)  # noqa: S506 - YamlLoader is a SafeLoader
    except yaml.YAMLError as exc:
        raise ScenarioError(f"override {text!r}: {yaml_error_message(exc)}", key=keypath.join(tokens)) from None
    return tuple(tokens), value


def _apply_override(data: dict, text: str) -> None:
    """Apply one override to ``data`` in place (``data`` is the loader's own copy).

    The key path is checked against the schema first (unknown keys are errors), then set
    in ``data``, creating a missing or null mapping on the way.
    """
    tokens, value = parse_override(text)
    try:
        node_at(SCHEMA, tokens)
    except Invalid as exc:
        raise ScenarioError(f"{exc.message} [override {text!r}]", key=keypath.join(exc.path)) from None
    try:
        keypath.set(data, tokens, value, create=True)
    except keypath.PathError as exc:
        raise _override_path_error(exc, text) from None


def _override_path_error(exc: keypath.PathError, text: str) -> ScenarioError:
    """The error for override ``text`` whose path ``data`` lacks (a list too short, a value not a mapping)."""
    tok, above = exc.toks[exc.depth], exc.toks[:exc.depth]
    here = keypath.join(above) or "the scenario"
    if isinstance(tok, int):
        size = len(exc.container) if isinstance(exc.container, list) else 0
        return ScenarioError(f"index {tok} is out of range: {here} has {size} items [override {text!r}]",
                             key=keypath.join(exc.toks[:exc.depth + 1]))
    return ScenarioError(f"{here} is not a mapping, cannot set {tok!r} [override {text!r}]",
                         key=keypath.join(above))


# --------------------------------------------------------------------------------------
# Public entry points
# --------------------------------------------------------------------------------------
def bundled_scenario(relative: str) -> Path:
    """Path of a scenario shipped in the repository's ``scenarios/`` folder.

    Looked up next to the source tree (an editable install or a checkout) and then in
    the current folder's ``scenarios/`` (a regular install run from the repository).

    Raises
    ------
    UserInputError
        If neither exists.
    """
    candidates = [Path(__file__).resolve().parents[2] / "scenarios" / relative,  # <repo>/orchestrator/inputs/
                  Path.cwd() / "scenarios" / relative]
    for c in candidates:
        if c.is_file():
            return c
    raise UserInputError(f"scenarios/{relative}: not found next to the package nor in the current folder; "
                         "run the command from the repository folder")


def load_scenario(path: str | os.PathLike, overrides: Iterable[str] = ()) -> Scenario:
    """Load and validate a scenario YAML file.

    Parameters
    ----------
    path : path-like
        The scenario file; relative paths inside it (``sensors``, ``vehicle.fmu``)
        are resolved against its folder.
    overrides : iterable of str
        ``key.path=value`` strings (value parsed as YAML, e.g. ``[1, 2]`` or
        ``1.2e8``), applied in order before validation. Items are addressed as
        ``track.ballast.voids[0].gaps``. Unknown keys are errors.

    Raises
    ------
    ScenarioError
        Anything wrong with the file, an override or a value; names the key path.
    """
    data = read_yaml(path)
    return scenario_from_dict(data, source=str(path), overrides=overrides, base_dir=Path(path).parent)


def scenario_from_dict(data: Mapping, source: str = "<dict>", overrides: Iterable[str] = (),
                       base_dir: str | os.PathLike | None = None) -> Scenario:
    """Validate a scenario given as a mapping (as read from YAML); ``data`` is not modified.

    Parameters
    ----------
    data : mapping
        The scenario.
    source : str
        Named in error messages.
    overrides : iterable of str
        As in :func:`load_scenario`.
    base_dir : path-like, optional
        Folder against which relative paths are resolved; default: the current folder.
    """
    if isinstance(overrides, str):  # a lone "k=v" would otherwise be iterated letter by letter
        overrides = [overrides]
    if data is None:
        raise ScenarioError("the scenario is empty; expected a mapping with name, track, vehicle, simulation",
                            source=source)
    if not isinstance(data, Mapping):
        raise ScenarioError(f"the scenario must be a mapping (key: value), got {describe(data)}", source=source)
    data = copy.deepcopy(dict(data))
    try:
        for text in overrides:
            _apply_override(data, text)
        ctx = Ctx(Path(base_dir) if base_dir is not None else Path.cwd())
        raw = SCHEMA.check(data, (), ctx)
    except ScenarioError as exc:
        raise exc.with_source(source) from None
    except Invalid as exc:
        raise ScenarioError(exc.message, key=keypath.join(exc.path) or None, source=source) from None
    return _build(raw, source)


def _build(raw: dict, source: str) -> Scenario:
    """The validated raw dict -> :class:`Scenario` (the model's dataclasses)."""
    return Scenario(name=raw["name"], track=_track_params(raw["track"], raw["vehicle"]),
                    vehicle=_vehicle_spec(raw["vehicle"]),
                    simulation=SimulationSpec(**raw["simulation"]), sensors=raw["sensors"], source=source, raw=raw)


def _track_params(t: dict, vehicle: dict) -> TrackParams:
    """The validated ``track`` section (and ``vehicle``'s wheel geometry) -> :class:`track.params.TrackParams`."""
    lay, pad, bal = t["layout"], t["rail_pad"], t["ballast"]
    return TrackParams(
        model=t["model"],
        layout=LayoutParams(**lay),
        rail_pad=RailPadParams(
            stiffness=pad["stiffness"], damping=pad["damping"], stiffness_scale=pad["stiffness_scale"],
            overrides=tuple(PadOverride(o["sleeper"], o["stiffness_scale"]) for o in pad["overrides"]),
            two_bushings=pad["two_bushings"]),
        ballast=BallastParams(
            stiffness_per_length=bal["stiffness_per_length"], damping_per_length=bal["damping_per_length"],
            stiffness_scale=bal["stiffness_scale"], spacing=bal["spacing"],
            voids=tuple(VoidSpec(o["sleeper"], tuple(o["gaps"])) for o in bal["voids"])),
        reduction=ReductionParams(**t["reduction"]),
        impact_angle=t["crossing"]["impact_angle"],
        structural_damping=t["structural_damping"],
        dipped_joint=t["dipped_joint"],
        contact=contact_params(t, vehicle),
    )


def _vehicle_spec(v: dict) -> VehicleSpec:
    """The validated ``vehicle`` section -> :class:`VehicleSpec`."""
    return VehicleSpec(fmu=v["fmu"], speed=v["speed"], axle_load=v["axle_load"],
                       ports=tuple(PortMap(**p) for p in v["ports"]), start_values=dict(v["start_values"]))


def dump_scenario(scenario: Scenario, path: str | os.PathLike) -> Path:
    """Write ``scenario.raw`` as YAML to ``path``; file paths are made relative to its folder.

    The file loads back (:func:`load_scenario`) to an equal scenario.
    """
    path = Path(path)
    raw = copy.deepcopy(scenario.raw)
    folder = path.parent.resolve()

    def rel(p: str) -> str:
        try:
            return Path(os.path.relpath(p, folder)).as_posix()
        except ValueError:  # another drive (Windows): keep it absolute
            return p

    if raw.get("sensors"):
        raw["sensors"] = rel(raw["sensors"])
    if raw["vehicle"]["fmu"] not in BUILTIN_VEHICLES:
        raw["vehicle"]["fmu"] = rel(raw["vehicle"]["fmu"])
    path.write_text(dump_yaml(raw), encoding="utf-8")
    return path
