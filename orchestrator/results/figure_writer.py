"""A run's figures drawn by a second process while the main process goes on (``turnout run``).

Drawing the figures of a run is a third of its wall time on the default scenario: importing
matplotlib (~0.4 s) and drawing and encoding five PNGs (~0.15 s each), after a
co-simulation that keeps one core busy and leaves the other idle. A :class:`FigureWriter`
starts one spawned process when the job starts; that process imports matplotlib and the
plotting modules while the co-simulation runs, then draws each figure it is handed
(:meth:`FigureWriter.submit`: a module-level function and its arguments, plain arrays and
dataclasses) while the main process writes ``results.h5``, ``sensors.csv`` and
``summary.json``. A figure that needs nothing from the co-simulation (the layout) is
handed over before it and drawn during it. :meth:`FigureWriter.close` waits for the figures
and returns one line per figure that failed: everything else is written before, so a
failing figure loses nothing computed. (A second figure process was tried twice, 2026-11-26:
started with the first, its start-up slowed the run's set-up by 0.1-0.2 s; started when the
stepping loop starts, it slowed the loop (the first one draws the layout then: three busy
processes on two cores), 2.97 against 2.82-2.87 s for the whole run. Neither was kept.)

On a machine with one core, or with ``background=False``, or where no process can be
started, the figures are drawn in the calling process, one after the other, as before.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from typing import Callable

START_METHOD = "spawn"   # as the sweeps' workers: forking a process holding BLAS threads may deadlock


def _warm_up() -> None:
    """Import what drawing needs (in the figure process, while the co-simulation runs); the process
    will end without the interpreter's teardown (:func:`_end_at_once`)."""
    import atexit
    atexit.register(_end_at_once)   # first: the handlers registered later (matplotlib's) run before it
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401

    import orchestrator.results.plots  # noqa: F401
    import orchestrator.results.plots_layout  # noqa: F401


def _end_at_once() -> None:
    """The figure process's last exit handler: flush the standard streams and end the process.

    Every figure file is closed by then (``savefig``), and the worker has sent its last message.
    The teardown this skips frees every object of matplotlib and the plotting modules one by one:
    0.1-0.17 s that :meth:`FigureWriter.close` waited for, at the end of ``turnout run``
    (2026-11-27, benchmarks/RESULTS.md). As ``orchestrator.cli._end_process`` does for the main
    process; the status is 0, as a worker that ran its tasks exits (a figure's failure comes back
    with its result)."""
    import sys
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def _peak_rss_mb() -> float:
    """This process's peak resident memory [MB] (Linux and macOS report ru_maxrss in kB and B)."""
    import resource
    import sys
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024.0 ** 2 if sys.platform == "darwin" else 1024.0)


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
        Draw in a second process; ``None``: when this process may run on two cores or more.
    """

    def __init__(self, background: bool | None = None):
        self._pool = None
        self._jobs: list[tuple[str, cf.Future | None, str | None]] = []
        self.peak_rss_mb: float | None = None   # the figure process's peak memory, read by close()
        if background is None:
            background = _cores() >= 2
        if background:
            try:
                self._pool = cf.ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context(START_METHOD),
                                                    initializer=_warm_up)
                self._pool.submit(int)   # start the process (and its imports) now, not at the first figure
            except (OSError, RuntimeError):   # no processes here (a sandbox, an embedded interpreter)
                self._pool = None

    @property
    def background(self) -> bool:
        """Figures are drawn by the second process."""
        return self._pool is not None

    def submit(self, name: str, fn: Callable, *args) -> None:
        """Draw figure(s) ``name`` by ``fn(*args)`` (a module-level function: it runs in the other process)."""
        if self._pool is not None:
            try:
                self._jobs.append((name, self._pool.submit(fn, *args), None))
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
        :attr:`peak_rss_mb` when the figures were drawn by the second process)."""
        failed = []
        for name, fut, err in self._jobs:
            if fut is not None:
                try:
                    fut.result()
                except Exception as exc:  # noqa: BLE001 - includes a figure process that died
                    err = f"{type(exc).__name__}: {exc}"
            if err is not None:
                failed.append(f"{name}: {err}")
        self._jobs = []
        if self._pool is not None:
            try:
                self.peak_rss_mb = self._pool.submit(_peak_rss_mb).result()
            except Exception:  # noqa: BLE001 - the process died: its figures said so above
                self.peak_rss_mb = None
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
