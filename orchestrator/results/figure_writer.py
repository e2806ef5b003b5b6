"""A run's figures drawn by other processes while the main process goes on (``turnout run``).

Drawing the figures of a run is a third of its wall time on the default scenario: importing
matplotlib (~0.4 s) and drawing and encoding five PNGs (~0.15 s each), after a
co-simulation that keeps one core busy and leaves the other idle. A :class:`FigureWriter`
starts :data:`PROCESSES` spawned processes when the job starts; they import matplotlib and
the plotting modules while the co-simulation runs (on the core it leaves idle), then draw
the figures they are handed (:meth:`FigureWriter.submit`: a module-level function and its
arguments, plain arrays and dataclasses), each figure by whichever process is free, while
the main process writes ``results.h5``, ``sensors.csv`` and ``summary.json``. A figure
that needs nothing from the co-simulation (the layout) is handed over before it and drawn
during it. :meth:`FigureWriter.close` waits for the figures and returns one line per
figure that failed: everything else is written before, so a failing figure loses nothing
computed. (With one process the main process waited ~0.35 s for the last figures after
writing its files, benchmarks/RESULTS.md 2026-11-26.)

On a machine with one core, or with ``background=False``, or where no process can be
started, the figures are drawn in the calling process, one after the other, as before.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from typing import Callable

START_METHOD = "spawn"   # as the sweeps' workers: forking a process holding BLAS threads may deadlock
PROCESSES = 1            # figure processes: the five figures after a co-simulation are drawn two at a time


def _warm_up() -> None:
    """Import what drawing needs (in the figure process, while the co-simulation runs)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401

    import orchestrator.results.plots  # noqa: F401
    import orchestrator.results.plots_layout  # noqa: F401


def _peak_rss_mb() -> float:
    """This process's peak resident memory [MB] (Linux and macOS report ru_maxrss in kB and B)."""
    import resource
    import sys
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024.0 ** 2 if sys.platform == "darwin" else 1024.0)


def _draw(fn: Callable, *args) -> float:
    """``fn(*args)`` in a figure process; returns that process's peak memory so far [MB]."""
    fn(*args)
    return _peak_rss_mb()


def _cores() -> int:
    """Cores this process may run on (as ``orchestrator.sweeps.workers.default_workers``, a layer above)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # no affinity masks (macOS, Windows)
        return os.cpu_count() or 1


class FigureWriter:
    """Draw figures in a second process (module docstring).

    Parameters
    ----------
    background : bool or None
        Draw in other processes; ``None``: when this process may run on two cores or more.
    processes : int
        How many figure processes (default :data:`PROCESSES`).
    """

    def __init__(self, background: bool | None = None, processes: int = PROCESSES):
        self._pool = None
        self._jobs: list[tuple[str, cf.Future | None, str | None]] = []
        self.peak_rss_mb: float | None = None   # the figure processes' largest peak memory, read by close()
        if background is None:
            background = _cores() >= 2
        if background:
            try:
                self._pool = cf.ProcessPoolExecutor(max_workers=processes, initializer=_warm_up,
                                                    mp_context=multiprocessing.get_context(START_METHOD))
                for _ in range(processes):   # start the processes (and their imports) now, not at the first figure
                    self._pool.submit(int)
            except (OSError, RuntimeError):   # no processes here (a sandbox, an embedded interpreter)
                self._pool = None

    @property
    def background(self) -> bool:
        """Figures are drawn by other processes."""
        return self._pool is not None

    def submit(self, name: str, fn: Callable, *args) -> None:
        """Draw figure(s) ``name`` by ``fn(*args)`` (a module-level function: it runs in the other process)."""
        if self._pool is not None:
            try:
                self._jobs.append((name, self._pool.submit(_draw, fn, *args), None))
                return
            except (cf.BrokenExecutor, RuntimeError):   # the process died: draw here from now on
                self._pool = None
        try:
            fn(*args)
            self._jobs.append((name, None, None))
        except Exception as exc:  # noqa: BLE001 - a figure's failure is reported, the results stay
            self._jobs.append((name, None, f"{type(exc).__name__}: {exc}"))

    def close(self) -> list[str]:
        """Wait for every figure; returns ``"<name>: <why>"`` for each that failed (and sets
        :attr:`peak_rss_mb`, the largest peak memory of the figure processes that drew one,
        when the figures were drawn by other processes)."""
        failed, peaks = [], []
        for name, fut, err in self._jobs:
            if fut is not None:
                try:
                    peaks.append(fut.result())
                except Exception as exc:  # noqa: BLE001 - includes a figure process that died
                    err = f"{type(exc).__name__}: {exc}"
            if err is not None:
                failed.append(f"{name}: {err}")
        self._jobs = []
        if self._pool is not None:
            self.peak_rss_mb = max(peaks) if peaks else None
            self._pool.shutdown(wait=True)
            self._pool = None
        return failed

    def __enter__(self) -> "FigureWriter":
        return self

    def __exit__(self, *exc) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None


__all__ = ["FigureWriter"]
