"""Scenario keys of the wheel–rail contact geometry (issue 15): ``track.crossing.geometry`` and
``track.crossing.profiles``, ``track.irregularity``, ``vehicle.wheel_profile``,
``vehicle.lateral_offset(_table)``, ``vehicle.wheel_flat``, ``vehicle.wheel_polygon``.

Sections built from :mod:`orchestrator.inputs.schema_nodes` for :mod:`orchestrator.inputs.schema`
(defaults from :class:`track.params.ContactParams`, :class:`track.profiles.WheelProfile` and
:class:`track.profiles.CrossingSections`); their plausibility ranges are :data:`CONTACT_PLAUSIBLE`.
"""
from __future__ import annotations

import numpy as np

from orchestrator.inputs.schema_nodes import (
    SUB,
    Field,
    FilePath,
    Invalid,
    List,
    Map,
    Node,
    Nullable,
    Num,
    Str,
    dataclass_defaults,
)
from track.params import ContactParams
from track.profiles import CrossingSections, WheelProfile

__all__ = ["CONTACT_PLAUSIBLE", "crossing_profiles_section", "irregularity_section", "wheel_fields",
           "check_wheel", "csv_columns"]

# Plausibility ranges (lower, upper, reason), as schema.PLAUSIBLE
CONTACT_PLAUSIBLE = {
    # S1002 on 1435 mm gauge: the flange meets the rail at ~7-10 mm offset (EN 15302 clearance)
    "lateral_offset": (-0.012, 0.012, "(the flange of an S1002 wheel touches the rail at about 7-10 mm)"),
    # EN 13715: S1002 flange height 28 mm new; wheels are reprofiled at 36 mm
    "flange_height": (0.012, 0.045, "(S1002: 28 mm new, reprofiled at ~36 mm)"),
    # flange thickness 32.5 mm new, limit ~22-28 mm: a change of -6 .. +4 mm
    "flange_thickness_change": (-0.006, 0.004, "(flange thickness: 32.5 mm new, worn limit ~26.5 mm)"),
    # hollow wear is reprofiled at 2-3 mm (Sawley & Wu 2005; 4 mm the worst measured)
    "hollow_depth": (0.0, 0.006, "(hollow-worn treads are reprofiled at 2-3 mm)"),
    # design nose-top lowerings are a few mm (module track.profiles); a 10 mm drop is a broken nose
    "tip_drop": (0.0, 0.01, "(a nose top is lowered a few mm near its tip)"),
    # vertical wear of noses and wing rails up to ~5-8 mm before replacement
    "rail_wear": (0.0, 0.015, "(crossings are replaced at ~5-8 mm of vertical wear)"),
    # wheel flats: removal limit 40-60 mm length (UIC 541-1), depth ~1-3 mm
    "flat_length": (0.0, 0.15, "(flats are removed from service at 40-60 mm length)"),
    "flat_depth": (0.0, 0.005, "(flats are ~1-3 mm deep)"),
    # polygons: amplitudes of tens of um up to ~1 mm (out-of-round wheels), orders 1-30
    "polygon_amplitude": (0.0, 0.002, "(wheel polygons reach ~1 mm amplitude at most)"),
}
_INDEX = Num(ge=0, integer=True)


def _ranged(key: str, unit: str = "") -> Num:
    """A number within :data:`CONTACT_PLAUSIBLE` ``[key]``."""
    lo, hi, why = CONTACT_PLAUSIBLE[key]
    return Num(ge=lo, le=hi, unit=unit, why=why)


def _stations(doc: str, value: Node) -> Field:
    """A list of numbers (stations or values), empty by default."""
    return Field(List(value), [], doc)


def crossing_profiles_section() -> Map:
    """``track.crossing.profiles``: the crossing sections' design drop and wear (``geometry: profiles``;
    defaults: track.profiles.CrossingSections)."""
    D = dataclass_defaults(CrossingSections)
    wear = _ranged("rail_wear", " m")
    return Map({
        "tip_drop": Field(_ranged("tip_drop", " m"), D["tip_drop"],
                          "[m] design lowering of the nose top at the theoretical crossing point"),
        "full_width": Field(Num(gt=0.012, le=0.2, unit=" m"), D["full_width"],
                            "[m] nose width where the design lowering has vanished"),
        "nose_wear_stations": _stations("[m] stations x - x_tcp of the nose wear", Num()),
        "nose_wear": _stations("[m] height loss of the nose at the stations", wear),
        "wing_wear_stations": _stations("[m] stations x - x_tcp of the wing-rail wear", Num()),
        "wing_wear": _stations("[m] height loss of the wing rail at the stations", wear),
    }, post=_post_profiles)


def irregularity_section() -> Map:
    """``track.irregularity``: vertical rail irregularity, measured or from a one-sided PSD."""
    C = dataclass_defaults(ContactParams)
    return Map({
        "file": Field(Nullable(FilePath(".csv")), None,
                      "CSV x, z_left, z_right [m] (header line optional); replaces the PSD"),
        "psd_wavenumber": _stations("[1/m] spatial frequencies of the one-sided PSD table (increasing)",
                                    Num(gt=0, unit=" 1/m")),
        "psd": _stations("[m^3] one-sided PSD at those wavenumbers (log-log interpolated)", Num(gt=0, unit=" m^3")),
        "seed": Field(_INDEX, C["rail_psd_seed"], "seed of the left rail's realisation (right rail: seed + 1)"),
        "shortest_wavelength": Field(Num(ge=0.01, unit=" m"), C["rail_psd_band"][0],
                                     "[m] shortest wavelength generated (>= 0.01 m: 5 mm sampling)"),
        "longest_wavelength": Field(Num(gt=0, le=200.0, unit=" m"), C["rail_psd_band"][1],
                                    "[m] longest wavelength generated"),
    }, post=_post_irregularity)


def wheel_fields() -> dict:
    """``vehicle.wheel_profile``, ``lateral_offset(_table)``, ``wheel_flat``, ``wheel_polygon``: the wheel's
    geometry for ``track.crossing.geometry: profiles`` and its out-of-roundness (defaults:
    track.profiles.WheelProfile)."""
    W = dataclass_defaults(WheelProfile)
    return {
        "wheel_profile": Field(Map({
            "file": Field(Nullable(FilePath(".csv")), None,
                          "measured profile: CSV s, F [m] (lateral position from the taping line, field side +; "
                          "radius increment, flange +); replaces S1002 and the wear parameters"),
            "flange_height": Field(_ranged("flange_height", " m"), W["flange_height"],
                                   "[m] S1002 flange height"),
            "flange_thickness_change": Field(_ranged("flange_thickness_change", " m"),
                                             W["flange_thickness_change"], "[m] flange thickness change (worn < 0)"),
            "hollow_depth": Field(_ranged("hollow_depth", " m"), W["hollow_depth"],
                                  "[m] depth of a hollow-worn tread"),
            "hollow_centre": Field(Num(ge=-0.03, le=0.05, unit=" m"), W["hollow_centre"],
                                   "[m] centre of the hollow band from the taping line (field side +)"),
            "hollow_half_width": Field(Num(gt=0, le=0.06, unit=" m"), W["hollow_half_width"],
                                       "[m] half width of the hollow band"),
        }), SUB),
        "lateral_offset": Field(_ranged("lateral_offset", " m"), 0.0,
                                "[m] wheelset lateral offset towards the field side of the wheel at the nose"),
        "lateral_offset_table": Field(Map({
            "x": _stations("[m] track coordinates (increasing); replaces lateral_offset when given", Num()),
            "y": _stations("[m] lateral offset there", _ranged("lateral_offset", " m")),
        }, post=_post_offset_table), SUB),
        "wheel_flat": Field(Map({
            "length": Field(_ranged("flat_length", " m"), 0.0, "[m] flat length on the leading wheelset "
                                                                         "(0: none)"),
            "depth": Field(Nullable(_ranged("flat_depth", " m")), None,
                           "[m] flat depth; null: the chord's (sharp flat)"),
            "shape": Field(Str(("rounded", "sharp")), "rounded", "worn (Newton & Clark) or new flat"),
        }), SUB),
        "wheel_polygon": Field(Map({
            "order": Field(Num(ge=1, le=30, integer=True), 1, "harmonics around the wheel"),
            "amplitude": Field(_ranged("polygon_amplitude", " m"), 0.0,
                               "[m] radius amplitude on the leading wheelset (0: none)"),
            "phase": Field(Num(unit=" rad"), 0.0, "[rad] phase"),
        }), SUB),
    }


def _same_length(out: dict, a: str, b: str, path: tuple) -> None:
    if len(out[a]) != len(out[b]):
        raise Invalid(path + (b,), f"must have as many values as {a} ({len(out[a])}), got {len(out[b])}")


def _increasing(out: dict, key: str, path: tuple) -> None:
    v = out[key]
    if any(b <= a for a, b in zip(v, v[1:])):
        raise Invalid(path + (key,), f"must be increasing, got {v}")


def _post_profiles(out, given, path, ctx):
    """``track.crossing.profiles``: wear stations increasing, one value per station."""
    for which in ("nose", "wing"):
        _increasing(out, f"{which}_wear_stations", path)
        _same_length(out, f"{which}_wear_stations", f"{which}_wear", path)
    return out


def _post_irregularity(out, given, path, ctx):
    """``track.irregularity``: a PSD table of >= 2 increasing points, the band ordered, the file readable."""
    _increasing(out, "psd_wavenumber", path)
    _same_length(out, "psd_wavenumber", "psd", path)
    if len(out["psd"]) == 1:
        raise Invalid(path + ("psd",), "needs at least two points (log-log interpolation)")
    if out["shortest_wavelength"] >= out["longest_wavelength"]:
        raise Invalid(path + ("longest_wavelength",), "must exceed shortest_wavelength")
    if out["file"] is not None:
        csv_columns(out["file"], 3, path + ("file",), increasing=True)
    return out


def _post_offset_table(out, given, path, ctx):
    _increasing(out, "x", path)
    _same_length(out, "x", "y", path)
    if len(out["x"]) == 1:
        raise Invalid(path + ("x",), "needs at least two points (or use vehicle.lateral_offset)")
    return out


def csv_columns(file: str, n: int, path: tuple, increasing: bool = False) -> np.ndarray:
    """The columns of a numeric CSV (one header line allowed) as an (n, rows) array."""
    try:
        data = np.genfromtxt(file, delimiter=",", skip_header=0, dtype=float)
        if data.ndim == 2 and np.isnan(data[0]).all():
            data = data[1:]
    except (OSError, ValueError) as exc:
        raise Invalid(path, f"cannot read {file!r}: {exc}") from None
    if data.ndim != 2 or data.shape[1] != n or data.shape[0] < 2 or not np.isfinite(data).all():
        raise Invalid(path, f"{file!r}: expected {n} numeric columns and at least 2 rows")
    if increasing and not (np.diff(data[:, 0]) > 0).all():
        raise Invalid(path, f"{file!r}: the first column must be increasing")
    return data.T


def check_wheel(out: dict, path: tuple) -> None:
    """``vehicle``'s wheel keys checked together: a readable profile file, one out-of-roundness,
    a rounded flat's depth."""
    if out["wheel_profile"]["file"] is not None:
        csv_columns(out["wheel_profile"]["file"], 2, path + ("wheel_profile", "file"), increasing=True)
    if out["wheel_flat"]["length"] > 0.0 and out["wheel_polygon"]["amplitude"] > 0.0:
        raise Invalid(path + ("wheel_polygon",), "one out-of-roundness at a time: a wheel_flat is given")
    if out["wheel_flat"]["shape"] == "rounded" and out["wheel_flat"]["length"] > 0.0 and \
            not out["wheel_flat"]["depth"]:
        raise Invalid(path + ("wheel_flat", "depth"), "a rounded flat needs its depth (> 0)")


def contact_params(track: dict, vehicle: dict) -> ContactParams:
    """The validated ``track`` and ``vehicle`` sections' contact keys -> :class:`track.params.ContactParams`
    (files read here: the wheel profile, the rail irregularity)."""
    wp, irr, cr = vehicle["wheel_profile"], track["irregularity"], track["crossing"]
    wheel_table = None
    if wp["file"] is not None:
        s, F = csv_columns(wp["file"], 2, ("vehicle", "wheel_profile", "file"), increasing=True)
        wheel_table = (tuple(s.tolist()), tuple(F.tolist()))
    wheel = tuple((k, float(v)) for k, v in wp.items() if k != "file")
    rail_table = ()
    if irr["file"] is not None:
        rail_table = tuple(tuple(c.tolist()) for c in csv_columns(irr["file"], 3, ("track", "irregularity", "file"),
                                                                   increasing=True))
    lot = vehicle["lateral_offset_table"]
    flat, poly = vehicle["wheel_flat"], vehicle["wheel_polygon"]
    return ContactParams(
        geometry=cr["geometry"], wheel=wheel, wheel_table=wheel_table,
        lateral_offset=float(vehicle["lateral_offset"]),
        lateral_offset_table=(tuple(lot["x"]), tuple(lot["y"])) if lot["x"] else (),
        crossing=tuple((k, tuple(v) if isinstance(v, list) else float(v)) for k, v in cr["profiles"].items()),
        rail_psd=(tuple(irr["psd_wavenumber"]), tuple(irr["psd"])) if irr["psd"] else (),
        rail_psd_seed=int(irr["seed"]), rail_psd_band=(irr["shortest_wavelength"], irr["longest_wavelength"]),
        rail_table=rail_table,
        wheel_flat=tuple(flat.items()) if flat["length"] > 0.0 else (),
        wheel_polygon=tuple(poly.items()) if poly["amplitude"] > 0.0 else ())
