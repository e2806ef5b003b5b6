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
import dataclasses
import functools
import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

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
    describe,
)
from orchestrator.inputs.schema_contact import (
    check_wheel,
    crossing_profiles_section,
    irregularity_section,
    wheel_fields,
)
from orchestrator.inputs.specs import (
    BUILTIN_VEHICLES,
    STEP_MULTIPLE_RTOL,
    SimulationSpec,
    VehicleSpec,
    duration_text,
    step_estimate,
)
from track.layout import MIN_SLEEPERS, build_layout
from track.params import (
    RAIL_SECTIONS,
    BallastParams,
    LayoutParams,
    RailPadParams,
    ReductionParams,
    ContactParams,
    TrackParams,
)

__all__ = ["SCHEMA", "KeyDoc", "scenario_keys", "MAX_SPEED", "MAX_IMPACT_ANGLE", "MAX_VOID_GAP", "N_VOID_POINTS",
           "TURNOUT_ONLY_KEYS", "PLAUSIBLE", "CROSSING_N", "MAX_STEPS"]

MAX_SPEED = 120.0  # m/s (432 km/h): above any train this model is meant for
MAX_IMPACT_ANGLE = 0.05  # rad: 50 mrad is far beyond a severely worn crossing (18 mrad)
MAX_VOID_GAP = 0.05  # m: a 5 cm gap means the sleeper hangs; not a ballast void any more
N_VOID_POINTS = 6  # gaps are given at 6 equidistant points along the sleeper (DESIGN.md §3)
TURNOUT_ONLY_KEYS = ("crossing", "radius", "route", "hand", "transition_sleeper")

# Plausibility ranges (lower, upper, reason): values outside them are typing mistakes or
# another unit, not a track or vehicle anyone builds; each range keeps a margin of about
# a decade (stiffnesses) or 2x (lengths) around what the literature reports.
PLAUSIBLE = {
    # EN 13232 turnout families: yard and tram turnouts from R ~ 150 m (1:6 - 1:7), main-line
    # R 190-1200 m (1:9 - 1:18.5), high-speed up to R ~ 10 000 m (1:46 - 1:65)
    "radius": (100.0, 20000.0, "(turnout radii run from ~150 m, yard, to ~10 km, high-speed)"),
    # concrete sleepers and turnout bearers 0.6-0.65 m apart (seed 001; DESIGN.md §6 case 0.6 m),
    # timber sleepers up to ~0.75 m
    "sleeper_spacing": (0.3, 1.0, "(sleepers are laid 0.6-0.75 m apart)"),
    # a crossing panel is 20-40 sleepers (DESIGN.md §4.2: 40); 300 (~180 m) spans a whole 1:65 turnout
    "sleepers": (MIN_SLEEPERS, 300, "(a crossing panel has 20-40 sleepers; 300 span a whole high-speed turnout)"),
    # 600 mm narrow gauge to 1676 mm broad gauge
    "gauge": (0.6, 1.7, "(track gauges run from 0.6 m to 1.676 m)"),
    # plain-line sleepers 2.6 m, turnout bearers 2.6-5 m (DESIGN.md §7)
    "sleeper_length": (1.0, 6.0, "(sleepers are 2.6 m, bearers up to 5 m long, DESIGN.md §7)"),
    # DESIGN.md §7: 120 MN/m (soft) to 1200 MN/m (direct fixing)
    "pad_stiffness": (1e7, 1e10, "(rail pads: 120-1200 MN/m, DESIGN.md §7)"),
    # measured rail-pad damping is 1e4-1e5 N s/m per seat (seed 001 uses 2e4)
    "pad_damping": (0.0, 1e6, "(rail-pad damping is 1e4-1e5 N s/m)"),
    # DESIGN.md §7: bedding modulus 0.05-0.40 N/mm^3 times a 0.26-0.30 m sleeper base
    # = 1.3e7-1.2e8 N/m per m of sleeper
    "ballast_stiffness": (1e6, 1e9, "(ballast: 0.05-0.40 N/mm^3 on a 0.26-0.30 m wide sleeper, "
                                    "i.e. 1.3e7-1.2e8 N/m per m, DESIGN.md §7)"),
    # ballast damping per metre of sleeper of the same order as the pads' (seed 001: 3e4)
    "ballast_damping": (0.0, 1e6, "(ballast damping is ~1e4-1e5 N s/m per m of sleeper)"),
    # the cause catalogue fits h1 in 0.2-5 and h2 in 0.05-20 (orchestrator.inputs.causes)
    "stiffness_scale": (0.01, 100.0, "(a scale factor; the diagnosis fits 0.05-20)"),
    # bushings at most 0.5 m apart: each 2 x SIDE_WINDOW (0.6 m) wide region under a rail
    # seat holds one (orchestrator.results.analysis), the 6 void points along a 2.6 m
    # sleeper (0.52 m apart, DESIGN.md §3) each shape the gap; below 2 cm they add dofs, not detail
    "ballast_spacing": (0.02, 0.5, "(at most 0.5 m, so that the void shape and the pressure "
                                   "under each rail seat are resolved)"),
    # DESIGN.md §7: axle load 20 t (196 kN); heavy haul runs up to 40 t (392 kN)
    "axle_load": (1e4, 5e5, "(axle loads are 10-40 t, i.e. 98-392 kN; DESIGN.md §7: 20 t)"),
    # DESIGN.md §8: the stiff Hertz contact needs 10-200 us steps; 1e-7 s is 100x below
    # the finest useful step, and above 10 ms a wheel at 33 m/s crosses half a sleeper bay per step
    "step": (1e-7, 1e-2, "(useful steps are 10-200 us, DESIGN.md §8)"),
    # the vehicle must stay on a panel of at most ~180 m (see sleepers): 180 m at 1 m/s
    "duration": (0.0, 200.0, "(a passage over the modelled panel lasts well under a minute)"),
}
CROSSING_N = (3.0, 100.0)  # 1:n; crossings in service run from ~1:4.5 (tram, yard) to 1:65 (high-speed)
# Refused above this many communication steps: at ~0.45 ms per step for the 40-sleeper
# default (benchmarks/RESULTS.md, in-process loop) 1e7 steps take more than an hour.
MAX_STEPS = 10_000_000


def _plausible(key: str, *, integer: bool = False, unit: str = "", gt0: bool = False) -> Num:
    """A number within :data:`PLAUSIBLE` ``[key]`` (``> 0`` first when ``gt0``: keeps "must be > 0")."""
    lo, hi, why = PLAUSIBLE[key]
    return _Ranged(lo, hi, why, integer=integer, unit=unit, gt0=gt0)


class _Ranged(Num):
    """A number checked for its sign first (the usual "must be > 0" / ">= 0"), then for plausibility."""

    def __init__(self, lo, hi, why, *, integer=False, unit="", gt0=False):
        super().__init__(gt=0 if gt0 else None, ge=None if gt0 else lo, le=hi, integer=integer, unit=unit,
                         why=why)
        self._lo = lo if gt0 else None

    def check(self, value, path, ctx):
        x = super().check(value, path, ctx)
        if self._lo is not None and x < self._lo:
            raise Invalid(path, f"must be >= {self._lo:g}{self.unit}, got {x:g} {self.why}")
        return x

# Nodes shared by several sections (nodes keep no state between checks).
_POS = Num(gt=0)
_NONNEG = Num(ge=0)
_INDEX = Num(ge=0, integer=True)
_SIGN = Sign()
_VARIABLE_NAME = Str(pattern=r".+\Z", pattern_doc="a non-empty variable name")
_ANGLE = Num(ge=0, le=MAX_IMPACT_ANGLE, unit=" rad")
_SCALE = _plausible("stiffness_scale", gt0=True)


# --------------------------------------------------------------------------------------
# Checks across keys (a section's post check, run after its per-key checks)
# --------------------------------------------------------------------------------------
def _post_layout(out, given, path, ctx):
    """``track.layout`` checked as a whole: crossing ratio, turnout-only keys, sleeper length and index.

    Returns the layout without the turnout-only keys when it is plain track.
    """
    if out["type"] == "turnout":
        n = float(out["crossing"].split(":")[1])
        if n <= 1.0:
            raise Invalid(path + ("crossing",), f'expected "1:n" with n > 1, got {out["crossing"]!r}')
        if not CROSSING_N[0] <= n <= CROSSING_N[1]:
            raise Invalid(path + ("crossing",), f'expected "1:n" with n from {CROSSING_N[0]:g} to '
                                                f'{CROSSING_N[1]:g} (crossings in service run from about '
                                                f'1:4.5 to 1:65), got {out["crossing"]!r}')
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
    _check_geometry(out, path)
    return out


def _check_geometry(layout: dict, path: tuple) -> None:
    """The layout must build (:func:`track.layout.build_layout`): the panel covers the crossing, starts
    after the curve start, ... Its error names the keys (``"sleepers/transition_sleeper: ..."``)."""
    message = _geometry_error(tuple(sorted(layout.items())))
    if message is None:
        return
    head, sep, rest = message.partition(": ")
    keys = head.split("/") if sep else []
    if keys and all(k in layout for k in keys):
        also = f" (with {', '.join(keys[1:])})" if len(keys) > 1 else ""
        raise Invalid(path + (keys[0],), f"the layout does not build{also}: {rest}")
    raise Invalid(path, f"the layout does not build: {message}")


@functools.lru_cache(maxsize=256)
def _geometry_error(items: tuple) -> str | None:
    """``build_layout``'s complaint about a layout given as sorted (key, value) pairs, or None.

    Cached: sweeps and calibrations validate the same layout for every run (~2 ms each).
    """
    try:
        with np.errstate(all="ignore"):  # a degenerate geometry reports itself below, not as a warning
            build_layout(LayoutParams(**dict(items)))
    except (ValueError, ArithmeticError) as exc:
        return str(exc)
    return None


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
    if out["crossing"]["geometry"] == "profiles" and out["dipped_joint"] > 0.0:
        raise Invalid(path + ("dipped_joint",), "the dipped joint is a dip-model geometry; not with "
                                                "track.crossing.geometry: profiles")
    if layout["type"] == "turnout" and out["dipped_joint"] > 0.0:
        raise Invalid(path + ("dipped_joint",), "only for plain track (the Jenkins P2 verification case); "
                                                "a turnout's geometry defect is track.crossing.impact_angle")
    _check_sleeper_items(out["rail_pad"]["overrides"], n, path + ("rail_pad", "overrides"))
    _check_sleeper_items(out["ballast"]["voids"], n, path + ("ballast", "voids"))
    return out


def _post_vehicle(out, given, path, ctx):
    """``vehicle`` checked as a whole: ports only, and then one per wheel, for a third-party FMU."""
    ports = out["ports"]
    if out["fmu"] in BUILTIN_VEHICLES:
        if ports:
            raise Invalid(path + ("ports",), f"only for a third-party FMU; fmu: {out['fmu']} has its own ports")
        _check_builtin_start_values(out, path + ("start_values",))
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
    check_wheel(out, path)
    return out


def _check_builtin_start_values(vehicle: dict, path: tuple) -> None:
    """Start values of our bogie / quarter FMU that name its parameters: the right type, and a
    vehicle the parameter class accepts (positive masses and stiffnesses, a car body left
    after the wheelsets, ...). Other names are left to the run, which lists the FMU's variables."""
    from vehicle.bogie import BogieParams  # the vehicle models' own checks (src/vehicle)
    from vehicle.quarter import QuarterParams

    cls = BogieParams if vehicle["fmu"] == "bogie" else QuarterParams
    fields = {f.name: f for f in dataclasses.fields(cls)}
    given = vehicle["start_values"]
    for name, value in given.items():
        numeric = name in ("speed", "x0") or re.fullmatch(r"wheel\d+_z0", name) or \
            (name in fields and fields[name].type in ("float", float))
        if name in fields and fields[name].type in ("bool", bool):
            if not isinstance(value, bool):
                raise Invalid(path + (name,), f"expected true or false, got {describe(value)}")
        elif numeric and (isinstance(value, (bool, str)) or not math.isfinite(value)):
            raise Invalid(path + (name,), f"expected a number, got {describe(value)}")
    params = {k: v for k, v in given.items() if k in fields}
    try:
        cls(**{"axle_load": vehicle["axle_load"], **params})
    except (ValueError, TypeError) as exc:
        culprit = next((k for k in params if k in str(exc)), None)
        raise Invalid(path + ((culprit,) if culprit else ()), f"not a valid {vehicle['fmu']}: {exc}") from None


def _post_simulation(out, given, path, ctx):
    """``simulation`` checked as a whole: ``output_step`` within ``duration`` and a multiple of ``step``."""
    step, out_step = out["step"], out["output_step"]
    if out_step > out["duration"]:
        raise Invalid(path + ("output_step",), f"must not exceed duration ({out['duration']:g} s), got {out_step:g}")
    n_steps = out["duration"] / step
    if n_steps > MAX_STEPS:
        raise Invalid(path + ("step",), f"{out['duration']:g} s in steps of {step:g} s is {n_steps:.3g} steps, "
                                        f"more than {MAX_STEPS:.0e} (about {duration_text(step_estimate(n_steps))} "
                                        f"of computing); use a larger step or a shorter duration")
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
        "radius": Field(_plausible("radius", unit=" m", gt0=True), L["radius"], "[m] turnout radius; turnout only"),
        "sleeper_spacing": Field(_plausible("sleeper_spacing", unit=" m", gt0=True), L["sleeper_spacing"],
                                 "[m] sleeper centre distance"),
        "sleepers": Field(_plausible("sleepers", integer=True), L["sleepers"],
                          "number of sleepers, indexed 0..N-1 along the track"),
        "route": Field(Str(("through", "diverging")), L["route"], "route the vehicle runs on; turnout only"),
        "hand": Field(Str(("left", "right")), L["hand"], "side the diverging route turns to; turnout only"),
        "gauge": Field(_plausible("gauge", unit=" m", gt0=True), L["gauge"], "[m] track gauge"),
        "rail": Field(Str(tuple(RAIL_SECTIONS)), L["rail"], "rail profile"),
        "transition_sleeper": Field(Nullable(_INDEX), L["transition_sleeper"],
                                    "sleeper under the wing rail -> nose transfer; null: N // 2 + 1; turnout only"),
        "sleeper_length": Field(_plausible("sleeper_length", unit=" m", gt0=True), L["sleeper_length"],
                                "[m] plain-line sleeper length (> gauge)"),
    }, post=_post_layout)


def _rail_pad_section() -> Map:
    """``track.rail_pad``: pad stiffness and damping, global and per sleeper (defaults: RailPadParams)."""
    P = dataclass_defaults(RailPadParams)
    return Map({
        "stiffness": Field(_plausible("pad_stiffness", unit=" N/m", gt0=True), P["stiffness"],
                           "[N/m] per rail seat"),
        "damping": Field(_plausible("pad_damping", unit=" N s/m"), P["damping"], "[N s/m] per rail seat"),
        "stiffness_scale": Field(_SCALE, P["stiffness_scale"], "[-] global scale h2"),
        "overrides": Field(List(Map({
            "sleeper": Field(_INDEX, doc="sleeper index 0..N-1 (each at most once)"),
            "stiffness_scale": Field(_SCALE, doc="[-] scale of the pads on that sleeper (times h2)"),
        })), [], "local pad stiffness"),
        "two_bushings": Field(Bool(), P["two_bushings"], "two bushings across the wide crossing-rail seat"),
    })


def _ballast_section() -> Map:
    """``track.ballast``: ballast stiffness and damping, voids under sleepers (defaults: BallastParams)."""
    B = dataclass_defaults(BallastParams)
    return Map({
        "stiffness_per_length": Field(_plausible("ballast_stiffness", unit=" N/m per m", gt0=True),
                                      B["stiffness_per_length"], "[N/m per m of sleeper]"),
        "damping_per_length": Field(_plausible("ballast_damping", unit=" N s/m per m"), B["damping_per_length"],
                                    "[N s/m per m of sleeper]"),
        "stiffness_scale": Field(_SCALE, B["stiffness_scale"], "[-] global scale h1"),
        "voids": Field(List(Map({
            "sleeper": Field(_INDEX, doc="sleeper index 0..N-1 (each at most once)"),
            "gaps": Field(List(Num(ge=0, lt=MAX_VOID_GAP, unit=" m"), length=N_VOID_POINTS),
                          doc="[m] gap at 6 equidistant points from end to end"),
        })), [], "ballast voids"),
        "spacing": Field(_plausible("ballast_spacing", unit=" m", gt0=True), B["spacing"],
                         "[m] max distance between ballast bushings along a sleeper"),
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
    C = dataclass_defaults(ContactParams)
    return Map({
        "model": Field(Str(("beam", "solid")), T["model"], "beam crossing rail or 3D solid crossing rail"),
        "layout": Field(_layout_section(), SUB),
        "rail_pad": Field(_rail_pad_section(), SUB),
        "ballast": Field(_ballast_section(), SUB),
        "crossing": Field(Map({
            "impact_angle": Field(_ANGLE, T["impact_angle"], "[rad] dip angle of the crossing"),
            "geometry": Field(Str(("dip", "profiles")), C["geometry"],
                              "dip: the impact angle's vertical dip, one Hertz constant; profiles: contact "
                              "tables of the wheel profile on the wing rail, nose and plain rail"),
            "profiles": Field(crossing_profiles_section(), SUB),
        }), SUB),
        "irregularity": Field(irregularity_section(), SUB),
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
        "axle_load": Field(_plausible("axle_load", unit=" N", gt0=True), V["axle_load"], "[N] static axle load"),
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
        **wheel_fields(),
    }, post=_post_vehicle)


def _simulation_section() -> Map:
    """``simulation``: duration, steps and master algorithm (defaults: SimulationSpec)."""
    S = dataclass_defaults(SimulationSpec)
    return Map({
        "duration": Field(Num(gt=0, le=PLAUSIBLE["duration"][1], unit=" s", why=PLAUSIBLE["duration"][2]),
                          S["duration"], "[s] simulated time"),
        "step": Field(_plausible("step", unit=" s", gt0=True), S["step"], "[s] communication step"),
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
