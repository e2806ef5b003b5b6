"""The scenario's track model, built with the user's cache folder.

``src/track`` never chooses where its caches go (DESIGN.md §2: numerics take no paths of
their own): the orchestrator reads the environment once here and passes the folder in.
Every orchestrator module builds its track through :func:`track_model`.

The last model built is kept (one per process): a run asks for its model twice (its
post-processing or sensors, and the co-simulation's in-process track), and a worker's
runs of a study often share the track. Measured on the measurement scenario's quarter
vehicle: 0.16 s of a 0.57 s run was the second build. A :class:`~track.model.TrackModel`
is not changed after it is built (the steppers keep their state apart), so sharing it is safe.
"""
from __future__ import annotations

import os

from track.layout import Layout
from track.model import TrackModel, build_track
from track.params import TrackParams
from track.cache import cache_dir_from_env


_LAST: list = []   # [(params, cache folder), model] of the last build without a given layout


def track_model(params: TrackParams, layout: Layout | None = None) -> TrackModel:
    """:func:`track.model.build_track` with the disk cache of this environment (``$TURNOUT_CACHE``);
    the same model again for equal ``params`` (module docstring)."""
    cache_dir = cache_dir_from_env(os.environ)
    if layout is not None:
        return build_track(params, layout, cache_dir=cache_dir)
    key = (params, cache_dir)
    if _LAST and _LAST[0] == key:
        return _LAST[1]
    model = build_track(params, cache_dir=cache_dir)
    _LAST[:] = [key, model]
    return model


__all__ = ["track_model"]
