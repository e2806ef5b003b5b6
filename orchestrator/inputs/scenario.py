"""Scenario files: read, override, validate, map onto the model's dataclasses.

A scenario is a YAML mapping (DESIGN.md §4.2, documented key by key in the
README). Loading it goes

    YAML text --(read_yaml)--> dict --(overrides)--> dict --(schema)--> raw dict
        --(_build)--> Scenario (TrackParams, VehicleSpec, SimulationSpec)

The schema below is the single description of the accepted keys: it checks
types and ranges, fills defaults (taken from the dataclasses, so there is one
source for each default) and lists the keys (:func:`scenario_keys`) for the
README test. Checks that involve several keys (sleeper indices against the
number of sleepers, turnout-only keys on plain track, ...) run after it.

Every problem raises :class:`~orchestrator.inputs.errors.ScenarioError` naming the
dotted key path; the caller's dict is never modified.
"""
from __future__ import annotations

import copy
import dataclasses
import math
import numbers
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import yaml

from track.params import (
    RAIL_SECTIONS,
    BallastParams,
    LayoutParams,
    PadOverride,
    RailPadParams,
    ReductionParams,
    TrackParams,
    VoidSpec,
)

from orchestrator.inputs import keypath
from orchestrator.inputs.errors import ScenarioError, UserInputError
from orchestrator.inputs.errors import did_you_mean as _hint

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

BUILTIN_VEHICLES = ("bogie", "quarter")  # vehicle.fmu values that select our own FMUs
MAX_SPEED = 120.0  # m/s (432 km/h): above any train this model is meant for
MAX_IMPACT_ANGLE = 0.05  # rad: 50 mrad is far beyond a severely worn crossing (18 mrad)
MAX_VOID_GAP = 0.05  # m: a 5 cm gap means the sleeper hangs; not a ballast void any more
N_VOID_POINTS = 6  # gaps are given at 6 equidistant points along the sleeper (DESIGN.md §3)
MIN_SLEEPERS = 4
STEP_MULTIPLE_RTOL = 1e-9  # output_step / step must be this close to an integer
TURNOUT_ONLY_KEYS = ("crossing", "radius", "route", "hand", "transition_sleeper")


# --------------------------------------------------------------------------------------
# Result dataclasses
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PortMap:
    """Variable names of one wheel in a third-party vehicle FMU (DESIGN.md §4.4).

    The FMU's value times the sign is the value in our convention (z up, force
    on the wheel up).

    Attributes
    ----------
    x, z, vz : str
        Output variables: track coordinate [m], vertical position [m], vertical velocity [m/s].
    Fz : str
        Input variable: vertical contact force on the wheel [N].
    z_sign, vz_sign, Fz_sign : int
        +1 or -1.
    """

    x: str
    z: str
    vz: str
    Fz: str
    z_sign: int = 1
    vz_sign: int = 1
    Fz_sign: int = 1


@dataclass(frozen=True, kw_only=True)
class VehicleSpec:
    """The ``vehicle:`` section.

    Attributes
    ----------
    fmu : str
        ``"bogie"``, ``"quarter"`` or the absolute path of a third-party ``.fmu``.
    speed : float
        Constant vehicle speed [m/s].
    axle_load : float
        Static axle load [N].
    ports : tuple of PortMap
        One entry per wheel (wheelset by wheelset, left then right); only for a
        third-party FMU.
    start_values : dict
        FMU start values by variable name (float, int, bool or str).
    """

    fmu: str = "bogie"
    speed: float
    axle_load: float = 196200.0
    ports: tuple = ()
    start_values: dict = field(default_factory=dict, hash=False)

    @property
    def builtin(self) -> bool:
        """True when ``fmu`` names one of our own vehicle models."""
        return self.fmu in BUILTIN_VEHICLES


@dataclass(frozen=True)
class SimulationSpec:
    """The ``simulation:`` section.

    Attributes
    ----------
    duration : float
        Simulated time [s].
    step : float
        Communication step [s].
    output_step : float
        Output interval [s]; an integer multiple of ``step``.
    algorithm : str
        ``"gauss-seidel"`` or ``"jacobi"``.
    extrapolation : bool
        Extrapolate the wheel inputs of the track over a step.
    x_start : float or None
        Track coordinate of the first wheel at t = 0 [m]; ``None`` lets the job choose.
    """

    duration: float = 1.0
    step: float = 2.0e-5
    output_step: float = 1.0e-4
    algorithm: str = "gauss-seidel"
    extrapolation: bool = True
    x_start: float | None = None

    @property
    def output_every(self) -> int:
        """Number of communication steps per output step."""
        return int(round(self.output_step / self.step))

    @property
    def n_steps(self) -> int:
        """Number of communication steps that cover ``duration`` (last one may end past it)."""
        return max(1, math.ceil(self.duration / self.step * (1.0 - STEP_MULTIPLE_RTOL)))


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
# Key paths
# --------------------------------------------------------------------------------------
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def _fmt(path: Sequence[str | int]) -> str:
    """``("track", "ballast", "voids", 0, "gaps")`` -> ``"track.ballast.voids[0].gaps"``."""
    out = ""
    for p in path:
        if isinstance(p, int):
            out += f"[{p}]"
        elif _IDENT.match(p):
            out += f".{p}" if out else p
        else:  # a key that would be ambiguous written with dots (or holds odd characters)
            out += f"[{p!r}]"
    return out


class _Invalid(Exception):
    """Raised inside the schema; turned into a ScenarioError with the source attached."""

    def __init__(self, path: Sequence[str | int], message: str):
        super().__init__(message)
        self.path = tuple(path)
        self.message = message


def _describe(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, str):
        return f"the string {value!r}"
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, (list, tuple)):
        return "a list"
    if isinstance(value, numbers.Number):
        return repr(value)
    return f"a {type(value).__name__}"


# --------------------------------------------------------------------------------------
# Schema nodes
# --------------------------------------------------------------------------------------
class _Ctx:
    def __init__(self, base_dir: Path):
        self.base_dir = base_dir


class _Node:
    """A schema node: ``check`` validates one value and returns its normalised form."""

    doc = ""

    def check(self, value: Any, path: tuple, ctx: _Ctx) -> Any:
        raise NotImplementedError

    def child(self, token: str | int, path: tuple) -> "_Node":
        raise _Invalid(path, "is a single value: it has no sub-keys or items")


# Numeric strings that PyYAML (YAML 1.1) leaves as str, e.g. "1.2e8" or "1e8".
_NUMERIC_STR = re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?\Z")


class _Num(_Node):
    def __init__(self, gt=None, ge=None, lt=None, le=None, integer=False, unit=""):
        self.gt, self.ge, self.lt, self.le, self.integer, self.unit = gt, ge, lt, le, integer, unit
        bounds = [f"> {gt:g}" if gt is not None else "", f">= {ge:g}" if ge is not None else "",
                  f"< {lt:g}" if lt is not None else "", f"<= {le:g}" if le is not None else ""]
        self.doc = ("integer" if integer else "number") + "".join(f" {b}" for b in bounds if b)

    def check(self, value, path, ctx):
        what = "an integer" if self.integer else "a number"
        if isinstance(value, str) and _NUMERIC_STR.match(value.strip()):
            value = float(value.strip())
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise _Invalid(path, f"expected {what}, got {_describe(value)}")
        x = float(value)
        if not math.isfinite(x):
            raise _Invalid(path, f"must be a finite number, got {x}")
        if self.integer:
            if not x.is_integer():
                raise _Invalid(path, f"expected an integer, got {value!r}")
            x = int(value) if isinstance(value, numbers.Integral) else int(x)
        for bound, ok, op in ((self.gt, lambda b: x > b, ">"), (self.ge, lambda b: x >= b, ">="),
                              (self.lt, lambda b: x < b, "<"), (self.le, lambda b: x <= b, "<=")):
            if bound is not None and not ok(bound):
                raise _Invalid(path, f"must be {op} {bound:g}{self.unit}, got {x:g}")
        return x


class _Sign(_Node):
    doc = "+1 | -1"

    def check(self, value, path, ctx):
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or float(value) not in (1.0, -1.0):
            raise _Invalid(path, f"must be +1 or -1, got {_describe(value)}")
        return int(value)


class _Str(_Node):
    def __init__(self, choices: Sequence[str] | None = None, pattern: str | None = None,
                 pattern_doc: str = ""):
        self.choices = tuple(choices) if choices else None
        self.pattern = re.compile(pattern) if pattern else None
        self.pattern_doc = pattern_doc
        self.doc = " | ".join(self.choices) if self.choices else (pattern_doc or "string")

    def check(self, value, path, ctx):
        if isinstance(value, (_YamlInt, _YamlFloat)):  # e.g. rail: 60E1 (a float in YAML 1.2)
            value = value.yaml_text
        if not isinstance(value, str):
            raise _Invalid(path, f"expected {self.doc if self.choices else 'a string'}, got {_describe(value)}")
        if self.choices and value not in self.choices:
            allowed = ", ".join(repr(c) for c in self.choices)
            raise _Invalid(path, f"must be one of {allowed}; got {value!r}{_hint(value, self.choices)}")
        if self.pattern and not self.pattern.match(value):
            raise _Invalid(path, f"expected {self.pattern_doc}, got {value!r}")
        return value


class _Bool(_Node):
    doc = "true | false"

    def check(self, value, path, ctx):
        if not isinstance(value, bool):
            raise _Invalid(path, f"expected true or false, got {_describe(value)}")
        return value


class _Nullable(_Node):
    def __init__(self, inner: _Node):
        self.inner = inner
        self.doc = f"{inner.doc} or null"

    def check(self, value, path, ctx):
        return None if value is None else self.inner.check(value, path, ctx)

    def child(self, token, path):
        return self.inner.child(token, path)


class _List(_Node):
    def __init__(self, item: _Node, length: int | None = None):
        self.item, self.length = item, length
        self.doc = f"list of {length} {item.doc}" if length else f"list of {item.doc}"

    def check(self, value, path, ctx):
        if not isinstance(value, (list, tuple)):
            raise _Invalid(path, f"expected a list, got {_describe(value)}")
        if self.length is not None and len(value) != self.length:
            raise _Invalid(path, f"expected exactly {self.length} items, got {len(value)}")
        return [self.item.check(v, path + (i,), ctx) for i, v in enumerate(value)]

    def child(self, token, path):
        if not isinstance(token, int):
            raise _Invalid(path, f"is a list: use an index such as [0], not .{token}")
        return self.item


class _ScalarMap(_Node):
    """Free-form mapping name -> scalar (FMU start values)."""

    doc = "mapping name -> number | bool | string"

    def check(self, value, path, ctx):
        if not isinstance(value, Mapping):
            raise _Invalid(path, f"expected a mapping, got {_describe(value)}")
        out = {}
        for k, v in value.items():
            if not isinstance(k, str) or not k:
                raise _Invalid(path, f"keys must be non-empty strings, got {_describe(k)}")
            if isinstance(v, bool) or isinstance(v, str):
                out[k] = v
            elif isinstance(v, numbers.Integral):
                out[k] = int(v)
            elif isinstance(v, numbers.Real) and math.isfinite(float(v)):
                out[k] = float(v)
            else:
                raise _Invalid(path + (k,), f"expected a number, boolean or string, got {_describe(v)}")
        return out

    def child(self, token, path):
        if not isinstance(token, str):
            raise _Invalid(path, "is a mapping: use a name, not an index")
        return _Leaf()


class _Leaf(_Node):
    def check(self, value, path, ctx):
        return value


class _FilePath(_Node):
    """A file path, resolved against the scenario's folder; must exist."""

    def __init__(self, suffix: str | None = None, keywords: Sequence[str] = ()):
        self.suffix, self.keywords = suffix, tuple(keywords)
        what = f"path to a {suffix} file" if suffix else "path to a file"
        self.doc = " | ".join(self.keywords + (what,))

    def check(self, value, path, ctx):
        if not isinstance(value, str) or not value.strip():
            raise _Invalid(path, f"expected {self.doc}, got {_describe(value)}")
        if value in self.keywords:
            return value
        if self.suffix and not value.lower().endswith(self.suffix):
            raise _Invalid(path, f"expected {self.doc}, got {value!r}{_hint(value, self.keywords)}")
        p = Path(os.path.expanduser(value))
        p = (p if p.is_absolute() else ctx.base_dir / p).resolve()
        if not p.exists():
            raise _Invalid(path, f"file not found: {value!r} (looked for {p})")
        if not p.is_file():
            raise _Invalid(path, f"{value!r} is a folder, expected a file")
        return str(p)


_REQUIRED = object()  # _Field.default: the key must be given
_SUB = object()  # _Field.default: fill from the sub-mapping's own defaults


@dataclass
class _Field:
    node: _Node
    default: Any = _REQUIRED
    doc: str = ""  # unit / meaning, for scenario_keys()


class _Map(_Node):
    doc = "mapping"

    def __init__(self, fields: dict[str, _Field], post: Callable | None = None):
        self.fields, self.post = fields, post

    def check(self, value, path, ctx):
        if not isinstance(value, Mapping):
            raise _Invalid(path, f"expected a mapping, got {_describe(value)}")
        for k in value:
            if not isinstance(k, str):
                raise _Invalid(path, f"keys must be strings, got {_describe(k)}")
            if k not in self.fields:
                raise _Invalid(path + (k,), _unknown(k, self.fields))
        out = {}
        for name, f in self.fields.items():
            if name in value:
                out[name] = f.node.check(value[name], path + (name,), ctx)
            elif f.default is _REQUIRED:
                raise _Invalid(path + (name,), "required key is missing")
            elif f.default is _SUB:
                out[name] = f.node.check({}, path + (name,), ctx)
            else:
                out[name] = copy.deepcopy(f.default)
        if self.post is not None:
            out = self.post(out, value, path, ctx)
        return out

    def child(self, token, path):
        if not isinstance(token, str):
            raise _Invalid(path, "is a mapping: use a key, not an index")
        if token not in self.fields:
            raise _Invalid(path + (token,), _unknown(token, self.fields))
        return self.fields[token].node


def _unknown(key: str, known: Iterable[str]) -> str:
    known = list(known)
    hint = _hint(key, known)
    if hint:
        return f"unknown key {key!r}{hint}"
    return f"unknown key {key!r}; allowed here: {', '.join(known)}"


def _defaults(cls) -> dict[str, Any]:
    """Default value of every field of dataclass ``cls`` (default_factory called)."""
    out = {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


# --------------------------------------------------------------------------------------
# Checks across keys (run after the per-key checks of a mapping)
# --------------------------------------------------------------------------------------
def _post_layout(out, given, path, ctx):
    if out["type"] == "turnout" and float(out["crossing"].split(":")[1]) <= 1.0:
        raise _Invalid(path + ("crossing",), f'expected "1:n" with n > 1, got {out["crossing"]!r}')
    if out["type"] == "plain":
        for key in given:
            if key in TURNOUT_ONLY_KEYS:
                raise _Invalid(path + (key,), "only allowed with type: turnout (this layout is plain)")
        out = {k: v for k, v in out.items() if k not in TURNOUT_ONLY_KEYS}
    if out["sleeper_length"] <= out["gauge"]:
        raise _Invalid(path + ("sleeper_length",),
                       f"must exceed the gauge ({out['gauge']:g} m) to carry both rails, "
                       f"got {out['sleeper_length']:g}")
    ts = out.get("transition_sleeper")
    if ts is not None and ts >= out["sleepers"]:
        raise _Invalid(path + ("transition_sleeper",),
                       f"sleeper index {ts} is outside 0..{out['sleepers'] - 1}")
    return out


def _check_sleeper_items(items: list, n: int, path: tuple):
    """Sleeper indices of a list of per-sleeper entries: in 0..n-1, each at most once."""
    first: dict[int, int] = {}
    for i, item in enumerate(items):
        s = item["sleeper"]
        if s >= n:
            raise _Invalid(path + (i, "sleeper"), f"sleeper index {s} is outside 0..{n - 1} "
                                                   f"(track.layout.sleepers = {n})")
        if s in first:
            raise _Invalid(path + (i, "sleeper"), f"sleeper {s} is already given in {_fmt(path + (first[s],))}")
        first[s] = i


def _post_track(out, given, path, ctx):
    layout = out["layout"]
    n = layout["sleepers"]
    if out["model"] == "solid" and layout["type"] == "plain":
        raise _Invalid(path + ("model",), "'solid' models the 3D crossing rail; a plain layout has none "
                                          "(use model: beam)")
    _check_sleeper_items(out["rail_pad"]["overrides"], n, path + ("rail_pad", "overrides"))
    _check_sleeper_items(out["ballast"]["voids"], n, path + ("ballast", "voids"))
    return out


def _post_vehicle(out, given, path, ctx):
    ports = out["ports"]
    if out["fmu"] in BUILTIN_VEHICLES:
        if ports:
            raise _Invalid(path + ("ports",), f"only for a third-party FMU; fmu: {out['fmu']} has its own ports")
    else:
        if not ports:
            raise _Invalid(path + ("ports",), "a third-party FMU needs one ports entry per wheel "
                                              "(x, z, vz, Fz variable names)")
        seen: dict[str, int] = {}
        for i, port in enumerate(ports):
            if port["Fz"] in seen:
                raise _Invalid(path + ("ports", i, "Fz"),
                               f"input {port['Fz']!r} is already the force of wheel {seen[port['Fz']] + 1}")
            seen[port["Fz"]] = i
    return out


def _post_simulation(out, given, path, ctx):
    step, out_step = out["step"], out["output_step"]
    if out_step > out["duration"]:
        raise _Invalid(path + ("output_step",), f"must not exceed duration ({out['duration']:g} s), got {out_step:g}")
    ratio = out_step / step
    if ratio < 1.0 - STEP_MULTIPLE_RTOL or abs(ratio - round(ratio)) > STEP_MULTIPLE_RTOL * ratio:
        raise _Invalid(path + ("output_step",),
                       f"must be an integer multiple of step ({step:g} s), got {out_step:g} (ratio {ratio:.6g})")
    return out


# --------------------------------------------------------------------------------------
# The schema (DESIGN.md §4.2). Defaults come from the dataclasses.
# --------------------------------------------------------------------------------------
def _build_schema() -> _Map:
    L, P, B, R, T = (_defaults(c) for c in (LayoutParams, RailPadParams, BallastParams,
                                             ReductionParams, TrackParams))
    V, S = _defaults(VehicleSpec), _defaults(SimulationSpec)
    pos = _Num(gt=0)
    nonneg = _Num(ge=0)
    index = _Num(ge=0, integer=True)
    sign = _Sign()
    name_str = _Str(pattern=r".+\Z", pattern_doc="a non-empty variable name")

    layout = _Map({
        "type": _Field(_Str(("plain", "turnout")), L["type"], "plain track or turnout crossing panel"),
        "crossing": _Field(_Str(pattern=r"1:(\d+(\.\d*)?|\.\d+)\Z", pattern_doc='"1:n" with n > 1, e.g. "1:12"'),
                           L["crossing"], "crossing ratio 1:n (tan of the crossing angle = 1/n); turnout only"),
        "radius": _Field(pos, L["radius"], "[m] turnout radius; turnout only"),
        "sleeper_spacing": _Field(pos, L["sleeper_spacing"], "[m] sleeper centre distance"),
        "sleepers": _Field(_Num(ge=MIN_SLEEPERS, integer=True), L["sleepers"],
                           "number of sleepers, indexed 0..N-1 along the track"),
        "route": _Field(_Str(("through", "diverging")), L["route"], "route the vehicle runs on; turnout only"),
        "hand": _Field(_Str(("left", "right")), L["hand"], "side the diverging route turns to; turnout only"),
        "gauge": _Field(pos, L["gauge"], "[m] track gauge"),
        "rail": _Field(_Str(tuple(RAIL_SECTIONS)), L["rail"], "rail profile"),
        "transition_sleeper": _Field(_Nullable(index), L["transition_sleeper"],
                                     "sleeper under the wing rail -> nose transfer; null: N // 2 + 1; turnout only"),
        "sleeper_length": _Field(pos, L["sleeper_length"], "[m] plain-line sleeper length (> gauge)"),
    }, post=_post_layout)

    rail_pad = _Map({
        "stiffness": _Field(pos, P["stiffness"], "[N/m] per rail seat"),
        "damping": _Field(nonneg, P["damping"], "[N s/m] per rail seat"),
        "stiffness_scale": _Field(pos, P["stiffness_scale"], "[-] global scale h2"),
        "overrides": _Field(_List(_Map({
            "sleeper": _Field(index, doc="sleeper index 0..N-1 (each at most once)"),
            "stiffness_scale": _Field(pos, doc="[-] scale of the pads on that sleeper (times h2)"),
        })), [], "local pad stiffness"),
        "two_bushings": _Field(_Bool(), P["two_bushings"], "two bushings across the wide crossing-rail seat"),
    })

    ballast = _Map({
        "stiffness_per_length": _Field(pos, B["stiffness_per_length"], "[N/m per m of sleeper]"),
        "damping_per_length": _Field(nonneg, B["damping_per_length"], "[N s/m per m of sleeper]"),
        "stiffness_scale": _Field(pos, B["stiffness_scale"], "[-] global scale h1"),
        "voids": _Field(_List(_Map({
            "sleeper": _Field(index, doc="sleeper index 0..N-1 (each at most once)"),
            "gaps": _Field(_List(_Num(ge=0, lt=MAX_VOID_GAP, unit=" m"), length=N_VOID_POINTS),
                           doc="[m] gap at 6 equidistant points from end to end"),
        })), [], "ballast voids"),
        "spacing": _Field(pos, B["spacing"], "[m] max distance between ballast bushings along a sleeper"),
    })

    track = _Map({
        "model": _Field(_Str(("beam", "solid")), T["model"], "beam crossing rail or 3D solid crossing rail"),
        "layout": _Field(layout, _SUB),
        "rail_pad": _Field(rail_pad, _SUB),
        "ballast": _Field(ballast, _SUB),
        "crossing": _Field(_Map({
            "impact_angle": _Field(_Num(ge=0, le=MAX_IMPACT_ANGLE, unit=" rad"), T["impact_angle"],
                                   "[rad] dip angle of the crossing"),
        }), _SUB),
        "reduction": _Field(_Map({
            "f_cut": _Field(pos, R["f_cut"], "[Hz] model cut-off frequency"),
            "mode_factor": _Field(_Num(ge=1), R["mode_factor"], "[-] keep fixed-interface modes up to this x f_cut"),
            "element_length": _Field(pos, R["element_length"], "[m] max FE element length"),
            "solid_mesh_size": _Field(pos, R["solid_mesh_size"],
                                      "[m] mesh size of the 3D crossing rail (track.model: solid)"),
        }), _SUB),
        "structural_damping": _Field(nonneg, T["structural_damping"], "[s] stiffness-proportional Rayleigh beta"),
        "dipped_joint": _Field(_Num(ge=0, le=MAX_IMPACT_ANGLE, unit=" rad"), T["dipped_joint"],
                               "[rad] plain track only: total angle of a V-shaped dipped joint at mid-panel on "
                               "both rails (the Jenkins P2 verification case)"),
    }, post=_post_track)

    vehicle = _Map({
        "fmu": _Field(_FilePath(".fmu", BUILTIN_VEHICLES), V["fmu"], "vehicle model"),
        "speed": _Field(_Num(gt=0, le=MAX_SPEED, unit=" m/s"), doc="[m/s] constant speed"),
        "axle_load": _Field(pos, V["axle_load"], "[N] static axle load"),
        "ports": _Field(_List(_Map({
            "x": _Field(name_str, doc="output: wheel track coordinate [m]"),
            "z": _Field(name_str, doc="output: wheel vertical position [m]"),
            "vz": _Field(name_str, doc="output: wheel vertical velocity [m/s]"),
            "Fz": _Field(name_str, doc="input: vertical contact force on the wheel [N]"),
            "z_sign": _Field(sign, 1, "FMU value x sign = our value (z up)"),
            "vz_sign": _Field(sign, 1, "as z_sign, for vz"),
            "Fz_sign": _Field(sign, 1, "as z_sign, for Fz (force on the wheel, up)"),
        })), [], "third-party FMU only: one entry per wheel"),
        "start_values": _Field(_ScalarMap(), {}, "FMU start values by variable name"),
    }, post=_post_vehicle)

    simulation = _Map({
        "duration": _Field(pos, S["duration"], "[s] simulated time"),
        "step": _Field(pos, S["step"], "[s] communication step"),
        "output_step": _Field(pos, S["output_step"], "[s] output interval (integer multiple of step)"),
        "algorithm": _Field(_Str(("gauss-seidel", "jacobi")), S["algorithm"], "co-simulation master algorithm"),
        "extrapolation": _Field(_Bool(), S["extrapolation"], "extrapolate wheel inputs over a step"),
        "x_start": _Field(_Nullable(_Num()), S["x_start"], "[m] first wheel's position at t = 0; null: job's choice"),
    }, post=_post_simulation)

    return _Map({
        "name": _Field(_Str(pattern=r"[A-Za-z0-9][A-Za-z0-9._-]*\Z",
                            pattern_doc="a name of letters, digits, '.', '_', '-' (it names output files)"),
                       doc="scenario name"),
        "track": _Field(track, _SUB),
        "vehicle": _Field(vehicle),
        "simulation": _Field(simulation, _SUB),
        "sensors": _Field(_Nullable(_FilePath()), None, "sensor layout YAML, relative to the scenario file"),
    })




_SCHEMA = _build_schema()


@dataclass(frozen=True)
class KeyDoc:
    """Documentation of one accepted scenario key (see :func:`scenario_keys`)."""

    type: str  # type and range, e.g. "number > 0"
    required: bool
    default: Any  # None when required (or when the default is null)
    doc: str  # unit and meaning


def scenario_keys() -> dict[str, KeyDoc]:
    """Every accepted leaf key path, in schema order, with its type, default and meaning.

    List items are written ``[]``: ``track.ballast.voids[].gaps``.
    """
    out: dict[str, KeyDoc] = {}

    def walk(node: _Node, prefix: str, doc: str, default: Any):
        inner = node.inner if isinstance(node, _Nullable) else node
        if isinstance(inner, _Map):
            for k, f in inner.fields.items():
                walk(f.node, f"{prefix}.{k}" if prefix else k, f.doc, f.default)
        elif isinstance(inner, _List) and isinstance(inner.item, _Map):
            walk(inner.item, prefix + "[]", doc, _REQUIRED)
        else:
            required = default is _REQUIRED
            out[prefix] = KeyDoc(node.doc, required, None if required else copy.deepcopy(default), doc)

    walk(_SCHEMA, "", "", _REQUIRED)
    return out


# --------------------------------------------------------------------------------------
# YAML
# --------------------------------------------------------------------------------------
class _Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 numbers and no duplicate keys.

    PyYAML follows YAML 1.1: ``1e8`` and ``1.2e8`` stay strings (the exponent
    needs a dot *and* a sign), and ``1:12`` is the sexagesimal integer 72. Here
    ints and floats follow YAML 1.2 (core schema), so ``crossing: 1:12`` is the
    string "1:12" and ``stiffness: 1.2e8`` is a float.
    """


_INT_TAG, _FLOAT_TAG = "tag:yaml.org,2002:int", "tag:yaml.org,2002:float"
_Loader.yaml_implicit_resolvers = {
    ch: [(tag, rx) for tag, rx in resolvers if tag not in (_INT_TAG, _FLOAT_TAG)]
    for ch, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
_Loader.add_implicit_resolver(_INT_TAG, re.compile(r"[-+]?[0-9]+\Z|0o[0-7]+\Z|0x[0-9a-fA-F]+\Z"),
                              list("-+0123456789"))
_Loader.add_implicit_resolver(
    _FLOAT_TAG,
    re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?\Z|[-+]?\.(inf|Inf|INF)\Z|\.(nan|NaN|NAN)\Z"),
    list("-+0123456789."))


class _YamlInt(int):
    """An int read from YAML that remembers its text (``yaml_text``)."""


class _YamlFloat(float):
    """A float read from YAML that remembers its text: where the schema wants a
    string, the text is used, so ``rail: 60E1`` means "60E1", not 600.0."""


def _construct_int(loader, node):
    text = loader.construct_scalar(node)
    if text.startswith("0o"):
        value = _YamlInt(int(text[2:], 8))
    elif text.startswith("0x"):
        value = _YamlInt(int(text[2:], 16))
    else:
        value = _YamlInt(int(text, 10))
    value.yaml_text = text
    return value


def _construct_float(loader, node):
    text = loader.construct_scalar(node)
    low = text.lower()
    if low.endswith(".inf"):
        value = _YamlFloat(-math.inf if low.startswith("-") else math.inf)
    elif low == ".nan":
        value = _YamlFloat(math.nan)
    else:
        value = _YamlFloat(text)
    value.yaml_text = text
    return value


def _construct_mapping(loader, node, deep=False):
    # Duplicates among the mapping's own keys; keys brought in by a merge (<<: *anchor)
    # may legitimately be overridden, so they are not compared.
    seen = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":
            continue
        key = loader.construct_object(key_node, deep=deep)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(None, None, "a mapping key must be a scalar",
                                                    key_node.start_mark) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r} (first at line {seen[key] + 1})", key_node.start_mark)
        seen[key] = key_node.start_mark.line
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


class _Dumper(yaml.SafeDumper):
    """SafeDumper that quotes every string _Loader would read as a number (``"60E1"``)."""


_Dumper.yaml_implicit_resolvers = {ch: list(r) for ch, r in _Loader.yaml_implicit_resolvers.items()}

_Loader.add_constructor(_INT_TAG, _construct_int)
_Loader.add_constructor(_FLOAT_TAG, _construct_float)
_Loader.construct_mapping = _construct_mapping  # type: ignore[assignment]


def _yaml_error_message(exc: yaml.YAMLError) -> str:
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    problem = getattr(exc, "problem", None) or str(exc)
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    return f"{where}invalid YAML: {problem}"


def _parse_yaml(text: str, source: str) -> Any:
    try:
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except yaml.YAMLError as exc:
        raise ScenarioError(_yaml_error_message(exc), source=source) from None


def read_yaml(path: str | os.PathLike) -> Any:
    """Read a YAML file with the scenario rules (YAML 1.2 numbers, no duplicate keys).

    Raises
    ------
    ScenarioError
        File missing or unreadable, or not valid YAML (with line and column).
    """
    source = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError("file not found", source=source) from None
    except IsADirectoryError:
        raise ScenarioError("is a folder, expected a YAML file", source=source) from None
    except UnicodeDecodeError:
        raise ScenarioError("is not a UTF-8 text file", source=source) from None
    except OSError as exc:
        raise ScenarioError(f"cannot read: {exc.strerror or exc}", source=source) from None
    return _parse_yaml(text, source)


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
        value = yaml.load(value_text, Loader=_Loader)  # noqa: S506
    except yaml.YAMLError as exc:
        raise ScenarioError(f"override {text!r}: {_yaml_error_message(exc)}", key=_fmt(tokens)) from None
    return tuple(tokens), value


def _apply_override(data: dict, text: str) -> None:
    """Apply one override to ``data`` in place (``data`` is the loader's own copy)."""
    tokens, value = parse_override(text)
    node: _Node = _SCHEMA
    for i, tok in enumerate(tokens):
        try:
            node = node.child(tok, tokens[:i])
        except _Invalid as exc:
            raise ScenarioError(f"{exc.message} [override {text!r}]", key=_fmt(exc.path)) from None
    container: Any = data
    for i, tok in enumerate(tokens):
        last = i == len(tokens) - 1
        here = _fmt(tokens[:i]) or "the scenario"
        if isinstance(tok, int):
            if not isinstance(container, list) or not tok < len(container):
                size = len(container) if isinstance(container, list) else 0
                raise ScenarioError(f"index {tok} is out of range: {here} has {size} items [override {text!r}]",
                                    key=_fmt(tokens[:i + 1]))
        elif not isinstance(container, dict):
            raise ScenarioError(f"{here} is not a mapping, cannot set {tok!r} [override {text!r}]",
                                key=_fmt(tokens[:i]))
        if last:
            container[tok] = value
        else:
            if isinstance(container, dict) and container.get(tok) is None:
                container[tok] = {} if isinstance(tokens[i + 1], str) else []
            container = container[tok]


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
    candidates = [Path(__file__).resolve().parents[1] / "scenarios" / relative,
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
        raise ScenarioError(f"the scenario must be a mapping (key: value), got {_describe(data)}", source=source)
    data = copy.deepcopy(dict(data))
    try:
        for text in overrides:
            _apply_override(data, text)
        ctx = _Ctx(Path(base_dir) if base_dir is not None else Path.cwd())
        raw = _SCHEMA.check(data, (), ctx)
    except ScenarioError as exc:
        raise exc.with_source(source) from None
    except _Invalid as exc:
        raise ScenarioError(exc.message, key=_fmt(exc.path) or None, source=source) from None
    return _build(raw, source)


def _build(raw: dict, source: str) -> Scenario:
    t, v, s = raw["track"], raw["vehicle"], raw["simulation"]
    lay, pad, bal = t["layout"], t["rail_pad"], t["ballast"]
    track = TrackParams(
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
    )
    vehicle = VehicleSpec(fmu=v["fmu"], speed=v["speed"], axle_load=v["axle_load"],
                          ports=tuple(PortMap(**p) for p in v["ports"]),
                          start_values=dict(v["start_values"]))
    return Scenario(name=raw["name"], track=track, vehicle=vehicle, simulation=SimulationSpec(**s),
                    sensors=raw["sensors"], source=source, raw=raw)


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
    path.write_text(yaml.dump(raw, Dumper=_Dumper, sort_keys=False, default_flow_style=None), encoding="utf-8")
    return path
