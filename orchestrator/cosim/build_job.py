"""``turnout build-fmus``: build the track FMU of a scenario and our vehicle FMUs.

The track FMU bakes the scenario's ``track:`` section and has one set of wheel ports
per wheel of the scenario's vehicle (bogie 4, quarter vehicle 2, a third-party FMU
one per ``vehicle.ports`` entry).  The start values of its run parameters come from
the scenario: ``speed``, ``static_wheel_load = axle_load / 2`` and ``extrapolate_force``
(``simulation.extrapolation``); ``extrapolate`` keeps the FMU's default, true (a generic
fixed-step host gives start-of-step inputs; our master sets it per algorithm). Every FMU's
``DefaultExperiment`` is the scenario's duration and step. Both vehicle FMUs are built,
so one folder serves either vehicle; the scenario's own kind has its start position,
speed and axle load as start values.

The track FMU also gets one output per sensor of the scenario's layout (``sensors:``,
default ``scenarios/sensors/in2track_like.yaml``), resolved here on the scenario's
track model (relative positions such as ``sleeper: T``, ``x: T+0.3``) and baked in, so
the FMU needs no layout file at run time.  The default layout is drawn for a turnout
(crossing rail, pressure cells across a turnout sleeper); on a track it does not fit (a
plain track) the track FMU gets no sensor outputs and a warning says why.  A layout the
scenario names must fit.

A run does not rebuild them every time (:func:`cached_fmus`): the FMUs of a scenario
are kept in the user's cache folder (``$TURNOUT_CACHE``, :func:`track.cache.cache_dir_from_env`)
under a hash of everything the build reads (:func:`build_inputs` and the sources it
bundles), and copied from there.  ``turnout build-fmus`` always builds afresh.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

from orchestrator.cosim.passage import n_wheels, start_position
from orchestrator.inputs.sensor_layout import scenario_sensors
from track.layout import build_layout
from track.cache import cache_dir_from_env

VEHICLE_KINDS = ("bogie", "quarter")
FMU_CACHE_FOLDER = "fmus"     # under the cache folder: one sub-folder per build key
CACHE_KEY_FORMAT = "turnout-fmus/1"   # part of the key: change it when the cache's layout changes
FMU_CACHE_MAX = 32            # entries kept (about 2 MB each); the least recently used go first


def build_inputs(scenario) -> dict:
    """Everything the FMUs of ``scenario`` are built from, by FMU (the arguments of the builds).

    Returns
    -------
    dict
        ``{"track": {...}, "bogie": {...}, "quarter": {...}}``: for the track FMU its
        ``track_params``, ``n_wheels``, ``sensors`` and keyword arguments
        (``fmus.build.build_track_fmu``), for each vehicle its keyword arguments
        (``fmus.build.build_fmu``).
    """
    veh, sim = scenario.vehicle, scenario.simulation
    experiment = {"stop_time": sim.duration, "step_size": sim.step}   # DefaultExperiment: the scenario's
    # The track FMU keeps its own default extrapolate = true (start-of-step inputs, what a generic
    # fixed-step host gives it); our master sets it per algorithm at run time.
    inputs = {"track": {"track_params": scenario.track, "n_wheels": n_wheels(scenario),
                        "sensors": tuple(scenario_sensors(scenario)),
                        "kwargs": dict(speed=veh.speed, static_wheel_load=0.5 * veh.axle_load,
                                       extrapolate_force=sim.extrapolation, **experiment)}}
    for kind in VEHICLE_KINDS:
        own = {"x0": start_position(scenario, build_layout(scenario.track.layout)), "speed": veh.speed,
               "axle_load": veh.axle_load} if kind == scenario.vehicle.fmu else None
        inputs[kind] = {"kwargs": dict(start_values=own, **experiment)}
    return inputs


def _build_all(inputs: dict, out_dir: Path) -> dict[str, Path]:
    """Build the FMUs of :func:`build_inputs` into ``out_dir``."""
    from fmus.build import build_fmu, build_track_fmu  # pythonfmu is only needed here

    t = inputs["track"]
    built = {"track": build_track_fmu(t["track_params"], t["n_wheels"], out_dir, sensors=t["sensors"],
                                      **t["kwargs"])}
    for kind in VEHICLE_KINDS:
        built[kind] = build_fmu(kind, out_dir, **inputs[kind]["kwargs"])
    return built


def build_fmus(scenario, out_dir: Path) -> dict[str, Path]:
    """Build ``track.fmu``, ``bogie.fmu`` and ``quarter.fmu`` into ``out_dir``.

    Parameters
    ----------
    scenario : orchestrator.inputs.scenario.Scenario
    out_dir : Path
        Destination folder (created if missing).

    Returns
    -------
    dict
        ``{"track": path, "bogie": path, "quarter": path}``.
    """
    return _build_all(build_inputs(scenario), Path(out_dir))


def cache_key(inputs: dict) -> str:
    """Hash of a build: its :func:`build_inputs`, the sources the FMUs bundle (``fmus/`` and the model
    packages ``track``, ``vehicle``: ``fmus.build``) and the Python and pythonfmu that build them."""
    import pythonfmu

    from fmus.build import FMUS_DIR, _package_dir

    h = hashlib.sha256(CACHE_KEY_FORMAT.encode())
    h.update(json.dumps(inputs, sort_keys=True, default=_jsonable).encode())
    h.update(f"{sys.version}|{sys.executable}|{pythonfmu.__version__}".encode())
    roots = [FMUS_DIR] + [_package_dir(p) for p in ("track", "vehicle")]
    for root in roots:
        for path in sorted(p for p in root.rglob("*") if p.is_file() and "__pycache__" not in p.parts):
            h.update(str(path.relative_to(root)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:32]


def _jsonable(obj):
    """JSON form of the dataclasses and arrays in :func:`build_inputs`."""
    if dataclasses.is_dataclass(obj):
        return dataclasses.asdict(obj)
    if hasattr(obj, "tolist"):
        return obj.tolist()
    return repr(obj)


def cached_fmus(scenario, out_dir: Path, environ=None) -> dict[str, Path]:
    """The FMUs of ``scenario`` in ``out_dir``, copied from the cache; built into it first on a miss.

    The cache folder is ``cache_dir_from_env(environ)`` (default ``os.environ``;
    ``TURNOUT_CACHE=off``: no cache, :func:`build_fmus` into ``out_dir``).  An entry is
    built in a temporary folder beside it and renamed into place, so a run never sees a
    half-built entry and concurrent runs build at most once each.  A cache that cannot be
    written to is skipped (built into ``out_dir``).

    Returns
    -------
    dict
        ``{"track": path, "bogie": path, "quarter": path}`` in ``out_dir``.
    """
    out_dir = Path(out_dir)
    cache = cache_dir_from_env(os.environ if environ is None else environ)
    inputs = build_inputs(scenario)
    if cache is None:
        return _build_all(inputs, out_dir)
    entry = Path(cache) / FMU_CACHE_FOLDER / cache_key(inputs)
    try:
        if not _complete(inputs, entry):
            _publish(inputs, entry)
    except OSError:   # a read-only or full cache: build where the run needs the FMUs
        return _build_all(inputs, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    os.utime(entry)   # recently used: kept by _evict
    return {kind: Path(shutil.copyfile(entry / f"{kind}.fmu", out_dir / f"{kind}.fmu")) for kind in inputs}


def _evict(folder: Path, keep: int = FMU_CACHE_MAX) -> None:
    """Remove all but the ``keep`` most recently used entries of the FMU cache (a sweep over baked
    values such as the speed makes one entry per value)."""
    entries = sorted((p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")),
                     key=lambda p: p.stat().st_mtime, reverse=True)
    for old in entries[keep:]:
        shutil.rmtree(old, ignore_errors=True)


def _complete(inputs: dict, entry: Path) -> bool:
    """Whether the cache entry holds every FMU of the build."""
    return all((entry / f"{kind}.fmu").is_file() for kind in inputs)


def _publish(inputs: dict, entry: Path) -> None:
    """Build into a temporary folder next to ``entry`` and rename it to ``entry`` (atomic)."""
    entry.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".building-", dir=entry.parent))
    try:
        _build_all(inputs, tmp)
        try:
            os.replace(tmp, entry)
        except OSError:   # an entry is there: another run's, complete, or a broken one to replace
            if not _complete(inputs, entry):
                shutil.rmtree(entry, ignore_errors=True)
                os.replace(tmp, entry)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    _evict(entry.parent)
