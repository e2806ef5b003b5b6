"""The scenario's track model, built with the user's cache folder.

``src/track`` never chooses where its caches go (DESIGN.md §2: numerics take no paths of
their own): the orchestrator reads the environment once here and passes the folder in.
Every orchestrator module builds its track through :func:`track_model`.
"""
from __future__ import annotations

import os

from track.layout import Layout
from track.model import TrackModel, build_track
from track.params import TrackParams
from track.solid.crossing import cache_dir_from_env


def track_model(params: TrackParams, layout: Layout | None = None) -> TrackModel:
    """:func:`track.model.build_track` with the disk cache of this environment (``$TURNOUT_CACHE``)."""
    return build_track(params, layout, cache_dir=cache_dir_from_env(os.environ))


__all__ = ["track_model"]
