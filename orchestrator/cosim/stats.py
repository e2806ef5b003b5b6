"""What a co-simulation run did and where its time went.

:class:`CosimStats` is ``CosimResult.stats``: the dict that ``summary.json`` writes as
``wall_seconds`` (backend, algorithm, step, steps, output_every, wheels, x_front_start,
wall_setup, wall_loop, wall_total), plus its :attr:`CosimStats.counters`, a
:class:`RunCounters` with the stepper's work and the wall time per phase. The counters
are an attribute and not items of the dict, so the summary stays as it was.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass


@dataclass(frozen=True)
class RunCounters:
    """Work and wall time of one run, by phase.

    Attributes
    ----------
    steps : int
        Communication steps the master took.
    wall_setup : float
        Making the units [s]: building (or reusing) and instantiating the FMUs; in-process,
        building the track model and the vehicle.
    wall_initialize : float
        Initializing the units [s] (the track FMU builds its model here).
    wall_loop : float
        The stepping loop [s]. In-process without the track's statics and factorization
        (:attr:`wall_statics`, :attr:`wall_factor`: the track initializes at its first step);
        with FMUs they are inside it.
    wall_finish : float
        Terminating the units and reading the recorded track states [s] (the track FMU
        writes its record when it terminates).
    track_steps, linear_solves, contact_iterations, passes, factorizations : int or None
        The track integrator's counters (:class:`track.dynamics.Counters`: ``steps``,
        ``solves``, ``contact_newton``, ``iterations``, ``factorizations``); with FMUs read from
        the track FMU's counter outputs at terminate. ``None`` where a track unit reports none
        (a track FMU built before the counters existed).
    wall_build, wall_statics, wall_factor : float or None
        Building the track model, its static equilibrium under the wheels and the
        integrator's set-up (factorization of the step matrix) [s]; ``wall_build`` in-process only
        (the track FMU builds its model while initializing), the others from both backends.
    """

    steps: int
    wall_setup: float
    wall_initialize: float
    wall_loop: float
    wall_finish: float
    track_steps: int | None = None
    linear_solves: int | None = None
    contact_iterations: int | None = None
    passes: int | None = None
    factorizations: int | None = None
    wall_build: float | None = None
    wall_statics: float | None = None
    wall_factor: float | None = None

    @classmethod
    def measured(cls, steps: int, wall_setup: float, wall_initialize: float, wall_loop: float,
                 wall_total: float, track_work: dict) -> "RunCounters":
        """The counters of a run from the master's clock [s] and the track unit's ``work()``.

        ``wall_loop`` is the master's loop time; the track's statics and factorization, when
        the track reports them, are taken out of it. What ``wall_total`` holds beyond set-up,
        initialization and loop is the finish.
        """
        inside = track_work.get("wall_statics", 0.0) + track_work.get("wall_factor", 0.0)
        return cls(steps=steps, wall_setup=wall_setup, wall_initialize=wall_initialize,
                   wall_loop=max(wall_loop - inside, 0.0),
                   wall_finish=max(wall_total - wall_setup - wall_initialize - wall_loop, 0.0), **track_work)

    def to_json(self) -> dict:
        """The counters as a flat dict of numbers (``None`` where not measured)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> "RunCounters":
        """Inverse of :meth:`to_json`."""
        return cls(**data)


class CosimStats(dict):
    """A run's statistics (see the module docstring): a dict with a :attr:`counters` attribute.

    Parameters
    ----------
    items : dict
        The summary's ``wall_seconds`` entries.
    counters : RunCounters, optional
    """

    def __init__(self, items=(), counters: RunCounters | None = None):
        super().__init__(items)
        self.counters = counters


__all__ = ["CosimStats", "RunCounters"]
