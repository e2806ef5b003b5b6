"""Where the track's on-disk caches live (the reduced bodies, the solid crossing rail).

A module of its own, with nothing heavy imported: the orchestrator and the track FMU
ask for the folder at start-up, and importing it from :mod:`track.solid.crossing` (where it
was) loaded the whole solid-rail chain (~30 ms, twice in a run via FMUs: the FMU bundles
its own copy of the package) for a run that has no solid in it.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping


def cache_dir_from_env(environ: Mapping[str, str]) -> Path | None:
    """The on-disk cache folder an environment asks for; None for no disk cache.

    ``TURNOUT_CACHE`` (a folder, or ``off``), else ``$XDG_CACHE_HOME/turnout``, else
    ``~/.cache/turnout``. A pure function of ``environ``: the caller passes its
    environment and hands the result to :func:`track.solid.crossing.solid_crossing` /
    :func:`track.model.build_track`.
    """
    env = environ.get("TURNOUT_CACHE")
    if env is not None and env.strip().lower() in ("off", "0", "none", ""):
        return None
    if env:
        return Path(env)
    base = environ.get("XDG_CACHE_HOME")
    return (Path(base) if base else Path.home() / ".cache") / "turnout"
