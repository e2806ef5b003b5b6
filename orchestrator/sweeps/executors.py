"""Executors of a sweep's runs: local processes or a Dask cluster (:func:`make_executor`).

Both are :mod:`concurrent.futures` executors, so :func:`orchestrator.sweeps.sweep.run_sweep`
hands out and collects runs the same way on either: local processes are spawned
(safe with numpy's BLAS threads); a Dask ``distributed.Client`` is wrapped by
:class:`DaskExecutor`.
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import numbers
from typing import Any

from orchestrator.inputs.errors import UserInputError

__all__ = ["DaskExecutor", "make_executor", "check_workers", "lost_worker"]

START_METHOD = "spawn"  # fork with numpy/BLAS threads may deadlock a worker
DASK_CONNECT_TIMEOUT = "30s"  # how long to try to reach a --scheduler address


class DaskExecutor(cf.Executor):
    """A Dask ``distributed.Client`` seen as a :class:`concurrent.futures.Executor`.

    ``submit`` goes through ``Client.get_executor()`` (whose futures are plain
    ``concurrent.futures`` futures, so ``as_completed`` works unchanged);
    ``shutdown`` also closes the client, which ``ClientExecutor.shutdown`` does not.

    Parameters
    ----------
    address : str
        The scheduler, e.g. ``tcp://127.0.0.1:8786``.
    connect_timeout : str
        How long to try to reach it (Dask duration text, e.g. ``"30s"``).
    """

    def __init__(self, address: str, connect_timeout: str = DASK_CONNECT_TIMEOUT):
        try:
            from distributed import Client
        except ImportError:
            raise UserInputError("--scheduler needs Dask: pip install 'dask[distributed]'") from None
        try:
            self._client = Client(address, timeout=connect_timeout)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise UserInputError(f"--scheduler {address}: cannot connect to a Dask scheduler ({exc})") from None
        # pure=False: every submit is a task of its own (no key deduplication by Dask).
        self._executor = self._client.get_executor(pure=False)

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            self._executor.shutdown(wait=wait and not cancel_futures)
        finally:
            self._client.close()


def make_executor(workers: int, scheduler: str | None, *,
                  connect_timeout: str = DASK_CONNECT_TIMEOUT) -> cf.Executor:
    """The executor that runs a sweep.

    Parameters
    ----------
    workers : int
        Local worker processes (ignored with ``scheduler``: the cluster has its own).
    scheduler : str or None
        Address of a Dask scheduler (``tcp://host:8786``); ``None`` runs locally.
    connect_timeout : str
        How long to try to reach ``scheduler`` (Dask duration text).

    Returns
    -------
    concurrent.futures.Executor
        ``ProcessPoolExecutor`` with spawned workers, or a :class:`DaskExecutor`.
    """
    if scheduler:
        return DaskExecutor(scheduler, connect_timeout)
    check_workers(workers)
    return cf.ProcessPoolExecutor(max_workers=int(workers), mp_context=multiprocessing.get_context(START_METHOD))


def check_workers(workers: Any) -> None:
    """Raise :class:`UserInputError` unless ``workers`` is an integer >= 1."""
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        raise UserInputError(f"workers must be an integer >= 1, got {workers!r}")


def lost_worker(exc: BaseException) -> bool:
    """True when ``exc`` says the worker died (not that the run function failed)."""
    # Dask gives up on a task whose workers keep dying with distributed.scheduler.KilledWorker.
    return isinstance(exc, (cf.BrokenExecutor, cf.CancelledError)) or type(exc).__name__ == "KilledWorker"
