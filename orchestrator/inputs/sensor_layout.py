"""Sensor layout YAML (DESIGN.md §4.3): which transducers, where, and how they are weighted.

A layout file has the keys ``name``, ``rate`` [Hz] (the acquisition's sampling rate),
``displacement_highpass`` [Hz] (corner of the acceleration -> displacement
reconstruction, applied alike to measured and simulated displacements), ``weights``
(objective weight per group) and ``sensors``: a list of entries with ``id``, ``type``
(``pressure`` | ``displacement`` | ``acceleration`` | ``strain``), ``group`` and a
position: ``sleeper`` + ``y`` for a sleeper, ``rail`` + ``x`` for a rail, ``z`` for
strain gauges. Positions may be relative to the crossing, so one layout fits the
through and diverging routes and other turnouts:

- ``sleeper: T``, ``T+1``, ``T-2``: the crossing transition sleeper and its neighbours
  (an integer is an absolute index);
- ``y: seat:crossing+0.1``: metres from a rail's seat on that sleeper (a number is the
  lateral coordinate of the layout);
- ``x: T+0.3``: metres from the crossing transition (a number is the track coordinate).

:func:`load_layout` validates the file (unknown keys with a "did you mean" hint, one-line
errors naming the key); :func:`resolve` turns it into :class:`track.sensors.Sensor`
objects for a given track model. The default layout is
``scenarios/sensors/in2track_like.yaml`` (seed 000 Fig. 2).
"""
from __future__ import annotations

import copy
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from orchestrator.inputs.errors import UserInputError, UserInputWarning
from orchestrator.inputs.errors import did_you_mean as _hint
from orchestrator.inputs.track_model import track_model
from orchestrator.inputs.yaml_io import read_yaml
from track.model import TrackModel, rail_parts
from track.sensors import GAUGE_LENGTH, RECONSTRUCTION_HIGHPASS, SENSOR_TYPES, Sensor, compile_sensors


DEFAULT_LAYOUT = "in2track_like.yaml"
_TOP_KEYS = ("name", "rate", "displacement_highpass", "weights", "sensors", "description")
_SENSOR_KEYS = ("id", "type", "group", "sleeper", "y", "rail", "x", "z", "gauge_length")
_RELATIVE = re.compile(r"\s*T\s*(?:([+-])\s*([0-9.eE+-]+))?\s*\Z")
_SEAT = re.compile(r"\s*seat:([A-Za-z_][A-Za-z0-9_]*)\s*(?:([+-])\s*([0-9.eE+-]+))?\s*\Z")


@dataclass
class SensorLayout:
    """A validated sensor layout (positions not yet resolved on a model)."""

    name: str
    rate: float
    displacement_highpass: float
    weights: dict
    entries: list = field(default_factory=list)
    source: str = "<dict>"

    @property
    def ids(self) -> list[str]:
        return [e["id"] for e in self.entries]

    @property
    def types(self) -> dict[str, str]:
        return {e["id"]: e["type"] for e in self.entries}

    @property
    def groups(self) -> dict[str, str]:
        return {e["id"]: e["group"] for e in self.entries}


def default_layout_path() -> Path:
    """The bundled default layout (from the source tree or the current folder)."""
    from orchestrator.inputs.scenario import bundled_scenario

    return bundled_scenario(f"sensors/{DEFAULT_LAYOUT}")


def _err(source: str, key: str, message: str) -> UserInputError:
    return UserInputError(f"{source}: {key}: {message}")


def _positive(source: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value <= 0:
        raise _err(source, key, f"must be a positive number, got {value!r}")
    return float(value)


def layout_from_dict(data, source: str = "<dict>") -> SensorLayout:
    """Validate a layout mapping (see module docstring)."""
    if not isinstance(data, dict):
        raise UserInputError(f"{source}: a sensor layout must be a mapping with a 'sensors' list")
    for k in data:
        if k not in _TOP_KEYS:
            raise _err(source, str(k), f"unknown key{_hint(k, _TOP_KEYS)}")
    rate = _positive(source, "rate", data.get("rate", 5000.0))
    hp = _positive(source, "displacement_highpass", data.get("displacement_highpass", RECONSTRUCTION_HIGHPASS))
    entries = data.get("sensors")
    if not isinstance(entries, list) or not entries:
        raise _err(source, "sensors", "must be a non-empty list of sensors")
    seen, out = set(), []
    for i, e in enumerate(entries):
        where = f"sensors[{i}]"
        if not isinstance(e, dict):
            raise _err(source, where, "must be a mapping with id, type, group and a position")
        for k in e:
            if k not in _SENSOR_KEYS:
                raise _err(source, f"{where}.{k}", f"unknown key{_hint(k, _SENSOR_KEYS)}")
        sid = e.get("id")
        if not isinstance(sid, str) or not sid.strip():
            raise _err(source, f"{where}.id", "must be a non-empty name")
        if sid in seen:
            raise _err(source, f"{where}.id", f"{sid!r} is used twice")
        seen.add(sid)
        if e.get("type") not in SENSOR_TYPES:
            raise _err(source, f"{where}.type", f"must be one of {', '.join(SENSOR_TYPES)}, got "
                       f"{e.get('type')!r}{_hint(e.get('type'), SENSOR_TYPES)}")
        if not isinstance(e.get("group"), str) or not e["group"]:
            raise _err(source, f"{where}.group", "must be a group name (A-F as in seed 000 Fig. 2)")
        on_sleeper, on_rail = "sleeper" in e, "rail" in e
        if on_sleeper == on_rail:
            raise _err(source, where, "give either sleeper + y or rail + x")
        need = ("y",) if on_sleeper else ("x",)
        for k in need:
            if k not in e:
                raise _err(source, f"{where}.{k}", "is missing")
        if e["type"] == "pressure" and not on_sleeper:
            raise _err(source, f"{where}.rail", "a pressure cell is under a sleeper: give sleeper + y")
        if e["type"] == "strain" and "z" not in e:
            raise _err(source, f"{where}.z", "a strain gauge needs its height above the neutral axis z [m]")
        if "gauge_length" in e:
            _positive(source, f"{where}.gauge_length", e["gauge_length"])
        out.append(dict(e))
    groups = {e["group"] for e in out}
    weights = data.get("weights") or {}
    if not isinstance(weights, dict):
        raise _err(source, "weights", "must map group -> weight")
    for g, w in weights.items():
        if g not in groups:
            raise _err(source, f"weights.{g}", f"no sensor is in group {g!r}{_hint(g, groups)}")
        if isinstance(w, bool) or not isinstance(w, (int, float)) or not np.isfinite(w) or w < 0:
            raise _err(source, f"weights.{g}", f"must be a number >= 0, got {w!r}")
    full = {g: float(weights.get(g, 1.0)) for g in sorted(groups)}
    if sum(full.values()) <= 0:
        raise _err(source, "weights", "at least one group needs a positive weight")
    return SensorLayout(str(data.get("name", Path(source).stem)), rate, hp, full, out, source)


_LOADED: dict = {}   # (path, mtime, size) -> SensorLayout: every run of a diagnosis reads the same file
_LOADED_MAX = 16     # (pyyaml parses the default layout in ~30 ms, a tenth of a short run's overhead)


def load_layout(path=None) -> SensorLayout:
    """Read and validate a layout file; ``None`` -> the default layout. A file read before and
    unchanged since (same modification time and size) is not parsed again (a copy is returned)."""
    path = default_layout_path() if path is None else Path(path)
    try:
        st = path.stat()
        key = (str(path.resolve()), st.st_mtime_ns, st.st_size)
    except OSError:
        key = None   # read_yaml says what is wrong with it
    if key in _LOADED:
        return copy.deepcopy(_LOADED[key])
    try:
        data = read_yaml(path)
    except UserInputError as exc:
        raise UserInputError(f"sensor layout: {exc}") from None
    layout = layout_from_dict(data, str(path))
    if key is not None:
        if len(_LOADED) >= _LOADED_MAX:
            _LOADED.pop(next(iter(_LOADED)))
        _LOADED[key] = copy.deepcopy(layout)
    return layout


def _transition(model: TrackModel) -> tuple[int, float]:
    from track.model import reference_point

    _, x_ref, k = reference_point(model)
    return k, x_ref


def _sleeper_index(value, model: TrackModel, where: str) -> int:
    k_t, _ = _transition(model)
    n = len(model.layout.sleepers)
    if isinstance(value, bool):
        value = None
    if isinstance(value, int):
        k = value
    elif isinstance(value, str) and (m := _RELATIVE.match(value)):
        off = float(m.group(2) or 0.0) * (-1 if m.group(1) == "-" else 1)
        if off != int(off):
            raise UserInputError(f"{where}: sleeper offset must be whole, got {value!r}")
        k = k_t + int(off)
    else:
        raise UserInputError(f"{where}: sleeper must be an index or T, T+k, T-k; got {value!r}")
    if not 0 <= k < n:
        raise UserInputError(f"{where}: sleeper {value!r} is sleeper {k}, outside 0..{n - 1}")
    return k


def _lateral(value, model: TrackModel, sleeper: int, where: str) -> float:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, str) and (m := _SEAT.match(value)):
        rail = m.group(1)
        parts = set(rail_parts(model, rail)) or {rail}     # the solid model splits the crossing block
        ys = [y for s, r, y in zip(model.pads.sleeper, model.pads.rail, model.pads.y) if s == sleeper and r in parts]
        if not ys:
            rails = sorted({r for s, r in zip(model.pads.sleeper, model.pads.rail) if s == sleeper})
            raise UserInputError(f"{where}: rail {rail!r} has no seat on sleeper {sleeper}"
                                 f"{_hint(rail, rails)} (seats there: {', '.join(rails)})")
        off = float(m.group(3) or 0.0) * (-1 if m.group(2) == "-" else 1)
        return float(np.mean(ys)) + off
    raise UserInputError(f"{where}: y must be a number [m] or seat:<rail>[+-offset], got {value!r}")


def _longitudinal(value, model: TrackModel, where: str) -> float:
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if isinstance(value, str) and (m := _RELATIVE.match(value)):
        _, x_ref = _transition(model)
        return x_ref + float(m.group(2) or 0.0) * (-1 if m.group(1) == "-" else 1)
    raise UserInputError(f"{where}: x must be a number [m] or T+offset, got {value!r}")


def _on_rail(e: dict, model: TrackModel, where: str) -> tuple[str, float]:
    """Body and track coordinate of a sensor given by ``rail`` + ``x``.

    A rail the model splits into parts (the crossing block with ``track.model: solid``:
    ``crossing_front``, the solid ``crossing``, ``crossing_rear``) gives the part under
    the sensor; a strain gauge must lie on one part (its rows come from one body).
    """
    rail = e["rail"]
    parts = rail_parts(model, rail)
    if not parts:
        names = [b.name for b in model.bodies if b.sleeper < 0]
        raise UserInputError(f"{where}: no rail {rail!r} in this track{_hint(rail, names)}")
    coord = _longitudinal(e["x"], model, where)
    half = 0.5 * float(e.get("gauge_length", GAUGE_LENGTH)) if e["type"] == "strain" else 0.0
    spans = [(name, *_span(model, name)) for name in parts]
    lo, hi = spans[0][1], spans[-1][2]
    if not lo - 1e-9 <= coord <= hi + 1e-9:
        raise UserInputError(f"{where}: position {coord:.3f} m is off {rail} ({lo:.3f}..{hi:.3f} m)")
    for name, a, b in spans:
        if a - 1e-9 <= coord - half and coord + half <= b + 1e-9:
            return name, coord
    name, a, b = next(sp_ for sp_ in spans if sp_[1] - 1e-9 <= coord <= sp_[2] + 1e-9)
    raise UserInputError(f"{where}: the gauge {coord - half:.3f}..{coord + half:.3f} m crosses an end of "
                         f"{name} ({a:.3f}..{b:.3f} m; the track model joins {', '.join(parts)} there): "
                         "move it or shorten gauge_length")


def _span(model: TrackModel, body: str) -> tuple[float, float]:
    """Track coordinates [m] of the ends of a rail body (the solid: of its contact path)."""
    b = model.body(body)
    lo, hi = (b.origin + b.fom.contact_s[[0, -1]]) if b.solid else b.coords()[[0, -1]]
    return float(lo), float(hi)


def _resolve_one(e: dict, model: TrackModel, where: str) -> Sensor:
    """One layout entry placed on ``model``."""
    if "sleeper" in e:
        k = _sleeper_index(e["sleeper"], model, where)
        body, coord = f"sleeper_{k}", _lateral(e["y"], model, k, where)
        lo, hi = model.body(body).coords()[[0, -1]]
        if not lo - 1e-9 <= coord <= hi + 1e-9:
            raise UserInputError(f"{where}: position {coord:.3f} m is off {body} ({lo:.3f}..{hi:.3f} m)")
    else:
        body, coord = _on_rail(e, model, where)
    sensor = Sensor(id=e["id"], type=e["type"], group=e["group"], body=body, coord=coord,
                    z=float(e.get("z", 0.0)), gauge_length=float(e.get("gauge_length", GAUGE_LENGTH)))
    try:
        compile_sensors(model, [sensor])       # a height outside the solid rail's section, ...
    except ValueError as exc:
        raise UserInputError(f"{where}: {exc}") from None
    return sensor


def resolve(layout: SensorLayout, model: TrackModel) -> list[Sensor]:
    """The layout's sensors placed on ``model`` (body names and coordinates).

    Works on both track models: with ``track.model: solid`` the crossing rail's sensors
    land on the part of the block under them (the solid ``crossing`` or a beam part) and
    ``seat:crossing`` is the block's seat on that sleeper, whichever part it belongs to.

    Raises
    ------
    UserInputError
        A sensor that does not fit this track (one line naming it and why).
    """
    return [_resolve_one(e, model, f"{layout.source}: sensors[{i}] ({e['id']})")
            for i, e in enumerate(layout.entries)]


def layout_of(scenario) -> SensorLayout:
    """The scenario's sensor layout (``sensors:``), or the default one."""
    return load_layout(scenario.sensors)


def scenario_sensors(scenario, model=None) -> list:
    """The scenario's sensor layout resolved on its track model.

    Returns
    -------
    list of track.sensors.Sensor
        The scenario's layout: all its sensors. The default layout (the scenario names
        none, and it is drawn for a turnout): all its sensors, or none where some do not fit
        the track (a plain track has no crossing rail) -- then a :class:`UserInputWarning`
        names them and why (the command line prints it as one line), never silently.

    Raises
    ------
    UserInputError
        The scenario's layout file is invalid or one of its sensors does not fit this track.
    """
    layout = layout_of(scenario)
    model = track_model(scenario.track) if model is None else model
    if scenario.sensors is not None:
        return resolve(layout, model)
    kept, dropped = [], []
    for i, e in enumerate(layout.entries):
        try:
            kept.append(_resolve_one(e, model, f"{layout.source}: sensors[{i}] ({e['id']})"))
        except UserInputError as exc:
            dropped.append((e["id"], str(exc)))
    if not dropped:
        return kept
    warnings.warn(f"the default sensor layout does not fit this track: {', '.join(d[0] for d in dropped)} "
                  f"do not ({dropped[0][1]}), so no sensor signals are written; give the scenario a layout "
                  "(sensors:) that fits", UserInputWarning, stacklevel=2)
    return []


__all__ = ["layout_of", "scenario_sensors", "SensorLayout", "load_layout", "layout_from_dict", "resolve", "default_layout_path"]
