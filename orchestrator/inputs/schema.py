"""The scenario schema (DESIGN.md §4.2): every accepted key, its type, range, default and meaning.

:data:`SCHEMA` is the single description of the accepted keys, built section by section
from the nodes of :mod:`orchestrator.inputs.schema_nodes`. It checks types and ranges,
fills defaults (taken from the dataclasses, :mod:`track.params` and
:mod:`orchestrator.inputs.specs`, so there is one source for each default) and lists the
keys (:func:`scenario_keys`) for the README test. Checks that involve several keys
(sleeper indices against the number of sleepers, turnout-only keys on plain track, ...)
are the sections' ``post`` checks, run after the per-key checks.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

from track.layout import MIN_SLEEPERS
from track.params import (
    RAIL_SECTIONS,
    BallastParams,
    LayoutParams,
    RailPadParams,
    ReductionParams,
    TrackParams,
)

from orchestrator.inputs import keypath
from orchestrator.inputs.schema_nodes import (
    REQUIRED,
    SUB,
    Bool,
    Field,
    FilePath,
    Invalid,
    List,
    Map,
    Node,
    Nullable,
    Num,
    ScalarMap,
    Sign,
    Str,
    dataclass_defaults,
)
from orchestrator.inputs.specs import BUILTIN_VEHICLES, STEP_MULTIPLE_RTOL, SimulationSpec, VehicleSpec

__all__ = ["SCHEMA", "KeyDoc", "scenario_keys", "MAX_SPEED", "MAX_IMPACT_ANGLE", "MAX_VOID_GAP", "N_VOID_POINTS",
           "TURNOUT_ONLY_KEYS"]

MAX_SPEED = 120.0  # m/s (432 km/h): above any train this model is meant for
MAX_IMPACT_ANGLE = 0.05  # rad: 50 mrad is far beyond a severely worn crossing (18 mrad)
MAX_VOID_GAP = 0.05  # m: a 5 cm gap means the sleeper hangs; not a ballast void any more
N_VOID_POINTS = 6  # gaps are given at 6 equidistant points along the sleeper (DESIGN.md §3)
TURNOUT_ONLY_KEYS = ("crossing", "radius", "route", "hand", "transition_sleeper")

# Nodes shared by several sections (nodes keep no state between checks).
_POS = Num(gt=0)
_NONNEG = Num(ge=0)
_INDEX = Num(ge=0, integer=True)
_SIGN = Sign()
_VARIABLE_NAME = Str(pattern=r".+\Z", pattern_doc="a non-empty variable name")
_ANGLE = Num(ge=0, le=MAX_IMPACT_ANGLE, unit=" rad")


# --------------------------------------------------------------------------------------
# Checks across keys (a section's post check, run after its per-key checks)
# --------------------------------------------------------------------------------------
def _post_layout(out, given, path, ctx):
    """``track.layout`` checked as a whole: crossing ratio, turnout-only keys, sleeper length and index.

    Returns the layout without the turnout-only keys when it is plain track.
    """
    if out["type"] == "turnout" and float(out["crossing"].split(":")[1]) <= 1.0:
        raise Invalid(path + ("crossing",), f'expected "1:n" with n > 1, got {out["crossing"]!r}')
    if out["type"] == "plain":
        for key in given:
            if key in TURNOUT_ONLY_KEYS:
                raise Invalid(path + (key,), "only allowed with type: turnout (this layout is plain)")
        out = {k: v for k, v in out.items() if k not in TURNOUT_ONLY_KEYS}
    if out["sleeper_length"] <= out["gauge"]:
        raise Invalid(path + ("sleeper_length",),
                      f"must exceed the gauge ({out['gauge']:g} m) to carry both rails, "
                      f"got {out['sleeper_length']:g}")
    ts = out.get("transition_sleeper")
    if ts is not None and ts >= out["sleepers"]:
        raise Invalid(path + ("transition_sleeper",),
                      f"sleeper index {ts} is outside 0..{out['sleepers'] - 1}")
    return out


def _check_sleeper_items(items: list, n: int, path: tuple):
    """Sleeper indices of a list of per-sleeper entries: in 0..n-1, each at most once."""
    first: dict[int, int] = {}
    for i, item in enumerate(items):
        s = item["sleeper"]
        if s >= n:
            raise Invalid(path + (i, "sleeper"), f"sleeper index {s} is outside 0..{n - 1} "
                                                  f"(track.layout.sleepers = {n})")
        if s in first:
            raise Invalid(path + (i, "sleeper"),
                          f"sleeper {s} is already given in {keypath.join(path + (first[s],))}")
        first[s] = i


def _post_track(out, given, path, ctx):
    """``track`` checked as a whole: the model fits the layout; pad overrides and voids name real sleepers."""
    layout = out["layout"]
    n = layout["sleepers"]
    if out["model"] == "solid" and layout["type"] == "plain":
        raise Invalid(path + ("model",), "'solid' models the 3D crossing rail; a plain layout has none "
                                         "(use model: beam)")
    _check_sleeper_items(out["rail_pad"]["overrides"], n, path + ("rail_pad", "overrides"))
    _check_sleeper_items(out["ballast"]["voids"], n, path + ("ballast", "voids"))
    return out


def _post_vehicle(out, given, path, ctx):
    """``vehicle`` checked as a whole: ports only, and then one per wheel, for a third-party FMU."""
    ports = out["ports"]
    if out["fmu"] in BUILTIN_VEHICLES:
        if ports:
            raise Invalid(path + ("ports",), f"only for a third-party FMU; fmu: {out['fmu']} has its own ports")
    else:
        if not ports:
            raise Invalid(path + ("ports",), "a third-party FMU needs one ports entry per wheel "
                                             "(x, z, vz, Fz variable names)")
        seen: dict[str, int] = {}
        for i, port in enumerate(ports):
            if port["Fz"] in seen:
                raise Invalid(path + ("ports", i, "Fz"),
                              f"input {port['Fz']!r} is already the force of wheel {seen[port['Fz']] + 1}")
            seen[port["Fz"]] = i
    return out


def _post_simulation(out, given, path, ctx):
    """``simulation`` checked as a whole: ``output_step`` within ``duration`` and a multiple of ``step``."""
    step, out_step = out["step"], out["output_step"]
    if out_step > out["duration"]:
        raise Invalid(path + ("output_step",), f"must not exceed duration ({out['duration']:g} s), got {out_step:g}")
    ratio = out_step / step
    if ratio < 1.0 - STEP_MULTIPLE_RTOL or abs(ratio - round(ratio)) > STEP_MULTIPLE_RTOL * ratio:
        raise Invalid(path + ("output_step",),
                      f"must be an integer multiple of step ({step:g} s), got {out_step:g} (ratio {ratio:.6g})")
    return out


# --------------------------------------------------------------------------------------
# The sections. Defaults come from the dataclasses.
# --------------------------------------------------------------------------------------
def _layout_section() -> Map:
    """``track.layout``: plain track or turnout, sleepers, gauge, rail (defaults: LayoutParams)."""
    L = dataclass_defaults(LayoutParams)
    return Map({
        "type": Field(Str(("plain", "turnout")), L["type"], "plain track or turnout crossing panel"),
        "crossing": Field(Str(pattern=r"1:(\d+(\.\d*)?|\.\d+)\Z", pattern_doc='"1:n" with n > 1, e.g. "1:12"'),
                          L["crossing"], "crossing ratio 1:n (tan of the crossing angle = 1/n); turnout only"),
        "radius": Field(_POS, L["radius"], "[m] turnout radius; turnout only"),
        "sleeper_spacing": Field(_POS, L["sleeper_spacing"], "[m] sleeper centre distance"),
        "sleepers": Field(Num(ge=MIN_SLEEPERS, integer=True), L["sleepers"],
                          "number of sleepers, indexed 0..N-1 along the track"),
        "route": Field(Str(("through", "diverging")), L["route"], "route the vehicle runs on; turnout only"),
        "hand": Field(Str(("left", "right")), L["hand"], "side the diverging route turns to; turnout only"),
        "gauge": Field(_POS, L["gauge"], "[m] track gauge"),
        "rail": Field(Str(tuple(RAIL_SECTIONS)), L["rail"], "rail profile"),
        "transition_sleeper": Field(Nullable(_INDEX), L["transition_sleeper"],
                                    "sleeper under the wing rail -> nose transfer; null: N // 2 + 1; turnout only"),
        "sleeper_length": Field(_POS, L["sleeper_length"], "[m] plain-line sleeper length (> gauge)"),
    }, post=_post_layout)


def _rail_pad_section() -> Map:
    """``track.rail_pad``: pad stiffness and damping, global and per sleeper (defaults: RailPadParams)."""
    P = dataclass_defaults(RailPadParams)
    return Map({
        "stiffness": Field(_POS, P["stiffness"], "[N/m] per rail seat"),
        "damping": Field(_NONNEG, P["damping"], "[N s/m] per rail seat"),
        "stiffness_scale": Field(_POS, P["stiffness_scale"], "[-] global scale h2"),
        "overrides": Field(List(Map({
            "sleeper": Field(_INDEX, doc="sleeper index 0..N-1 (each at most once)"),
            "stiffness_scale": Field(_POS, doc="[-] scale of the pads on that sleeper (times h2)"),
        })), [], "local pad stiffness"),
        "two_bushings": Field(Bool(), P["two_bushings"], "two bushings across the wide crossing-rail seat"),
    })


def _ballast_section() -> Map:
    """``track.ballast``: ballast stiffness and damping, voids under sleepers (defaults: BallastParams)."""
    B = dataclass_defaults(BallastParams)
    return Map({
        "stiffness_per_length": Field(_POS, B["stiffness_per_length"], "[N/m per m of sleeper]"),
        "damping_per_length": Field(_NONNEG, B["damping_per_length"], "[N s/m per m of sleeper]"),
        "stiffness_scale": Field(_POS, B["stiffness_scale"], "[-] global scale h1"),
        "voids": Field(List(Map({
            "sleeper": Field(_INDEX, doc="sleeper index 0..N-1 (each at most once)"),
            "gaps": Field(List(Num(ge=0, lt=MAX_VOID_GAP, unit=" m"), length=N_VOID_POINTS),
                          doc="[m] gap at 6 equidistant points from end to end"),
        })), [], "ballast voids"),
        "spacing": Field(_POS, B["spacing"], "[m] max distance between ballast bushings along a sleeper"),
    })


def _reduction_section() -> Map:
    """``track.reduction``: model cut-off and mesh sizes (defaults: ReductionParams)."""
    R = dataclass_defaults(ReductionParams)
    return Map({
        "f_cut": Field(_POS, R["f_cut"], "[Hz] model cut-off frequency"),
        "mode_factor": Field(Num(ge=1), R["mode_factor"], "[-] keep fixed-interface modes up to this x f_cut"),
        "element_length": Field(_POS, R["element_length"], "[m] max FE element length"),
        "solid_mesh_size": Field(_POS, R["solid_mesh_size"],
                                 "[m] mesh size of the 3D crossing rail (track.model: solid)"),
    })


def _track_section() -> Map:
    """``track``: the model choice, its sub-sections and the geometry defects (defaults: TrackParams)."""
    T = dataclass_defaults(TrackParams)
    return Map({
        "model": Field(Str(("beam", "solid")), T["model"], "beam crossing rail or 3D solid crossing rail"),
        "layout": Field(_layout_section(), SUB),
        "rail_pad": Field(_rail_pad_section(), SUB),
        "ballast": Field(_ballast_section(), SUB),
        "crossing": Field(Map({
            "impact_angle": Field(_ANGLE, T["impact_angle"], "[rad] dip angle of the crossing"),
        }), SUB),
        "reduction": Field(_reduction_section(), SUB),
        "structural_damping": Field(_NONNEG, T["structural_damping"], "[s] stiffness-proportional Rayleigh beta"),
        "dipped_joint": Field(_ANGLE, T["dipped_joint"],
                              "[rad] plain track only: total angle of a V-shaped dipped joint at mid-panel on "
                              "both rails (the Jenkins P2 verification case)"),
    }, post=_post_track)


def _vehicle_section() -> Map:
    """``vehicle``: built-in or third-party FMU, speed, load, ports (defaults: VehicleSpec)."""
    V = dataclass_defaults(VehicleSpec)
    return Map({
        "fmu": Field(FilePath(".fmu", BUILTIN_VEHICLES), V["fmu"], "vehicle model"),
        "speed": Field(Num(gt=0, le=MAX_SPEED, unit=" m/s"), doc="[m/s] constant speed"),
        "axle_load": Field(_POS, V["axle_load"], "[N] static axle load"),
        "ports": Field(List(Map({
            "x": Field(_VARIABLE_NAME, doc="output: wheel track coordinate [m]"),
            "z": Field(_VARIABLE_NAME, doc="output: wheel vertical position [m]"),
            "vz": Field(_VARIABLE_NAME, doc="output: wheel vertical velocity [m/s]"),
            "Fz": Field(_VARIABLE_NAME, doc="input: vertical contact force on the wheel [N]"),
            "z_sign": Field(_SIGN, 1, "FMU value x sign = our value (z up)"),
            "vz_sign": Field(_SIGN, 1, "as z_sign, for vz"),
            "Fz_sign": Field(_SIGN, 1, "as z_sign, for Fz (force on the wheel, up)"),
        })), [], "third-party FMU only: one entry per wheel"),
        "start_values": Field(ScalarMap(), {}, "FMU start values by variable name"),
    }, post=_post_vehicle)


def _simulation_section() -> Map:
    """``simulation``: duration, steps and master algorithm (defaults: SimulationSpec)."""
    S = dataclass_defaults(SimulationSpec)
    return Map({
        "duration": Field(_POS, S["duration"], "[s] simulated time"),
        "step": Field(_POS, S["step"], "[s] communication step"),
        "output_step": Field(_POS, S["output_step"], "[s] output interval (integer multiple of step)"),
        "algorithm": Field(Str(("gauss-seidel", "jacobi")), S["algorithm"], "co-simulation master algorithm"),
        "extrapolation": Field(Bool(), S["extrapolation"], "extrapolate wheel inputs over a step"),
        "x_start": Field(Nullable(Num()), S["x_start"], "[m] first wheel's position at t = 0; null: job's choice"),
    }, post=_post_simulation)


def _scenario_schema() -> Map:
    """The whole scenario: name, the three sections and the sensor layout file."""
    return Map({
        "name": Field(Str(pattern=r"[A-Za-z0-9][A-Za-z0-9._-]*\Z",
                          pattern_doc="a name of letters, digits, '.', '_', '-' (it names output files)"),
                      doc="scenario name"),
        "track": Field(_track_section(), SUB),
        "vehicle": Field(_vehicle_section()),
        "simulation": Field(_simulation_section(), SUB),
        "sensors": Field(Nullable(FilePath()), None, "sensor layout YAML, relative to the scenario file"),
    })


SCHEMA = _scenario_schema()


# --------------------------------------------------------------------------------------
# Documentation of the keys (the README's table is checked against it)
# --------------------------------------------------------------------------------------
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

    def walk(node: Node, prefix: str, doc: str, default: Any):
        inner = node.inner if isinstance(node, Nullable) else node
        if isinstance(inner, Map):
            for k, f in inner.fields.items():
                walk(f.node, f"{prefix}.{k}" if prefix else k, f.doc, f.default)
        elif isinstance(inner, List) and isinstance(inner.item, Map):
            walk(inner.item, prefix + "[]", doc, REQUIRED)
        else:
            required = default is REQUIRED
            out[prefix] = KeyDoc(node.doc, required, None if required else copy.deepcopy(default), doc)

    walk(SCHEMA, "", "", REQUIRED)
    return out
