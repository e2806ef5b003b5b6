"""Executors of a sweep's runs: local processes or a Dask cluster (:func:`make_executor`).

Both are :mod:`concurrent.futures` executors, so :func:`orchestrator.sweeps.sweep.run_sweep`,
the diagnosis and the calibration hand out and collect runs the same way on either:
local processes are spawned (safe with numpy's BLAS threads); a Dask
``distributed.Client`` is wrapped by :class:`DaskExecutor`.

Every worker process is set up once (:func:`orchestrator.sweeps.workers.setup_worker`):

- **one BLAS/OpenMP thread** (``threadpoolctl.threadpool_limits``, and the thread
  variables for libraries loaded later), unless told otherwise (``threads``, or the
  environment variable ``TURNOUT_WORKER_THREADS``): a machine's cores are used by
  running one worker per core, not by threading each run's small matrices (measured:
  16 workers with unlimited BLAS gave 1.45x the speed of 2 on 16 cores, load average 32);
- a **local worker dies with its parent** (:func:`die_with_parent`), so killing a sweep's
  main process leaves no orphan computing on.

The default number of local workers is the number of cores this process may run on
(:func:`default_workers`). A Dask cluster has its own workers; each gets the same thread
limit through a worker plugin (:class:`orchestrator.sweeps.dask_plugin.WorkerThreads`).
"""
from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os

from orchestrator.inputs.errors import UserInputError

# Re-exported: the worker setup belongs to the executors' public face.
from orchestrator.sweeps.workers import (
    check_workers,
    default_workers,
    die_with_parent,
    limit_threads,
    setup_worker,
    worker_threads,
)

__all__ = ["DaskExecutor", "executor_slots", "make_executor", "check_workers", "lost_worker", "default_workers",
           "worker_threads", "setup_worker", "limit_threads", "die_with_parent"]

START_METHOD = "spawn"  # fork with numpy/BLAS threads may deadlock a worker
DASK_CONNECT_TIMEOUT = "30s"  # how long to try to reach a --scheduler address


# --------------------------------------------------------------------------------------
# Executors
# --------------------------------------------------------------------------------------
class DaskExecutor(cf.Executor):
    """A Dask ``distributed.Client`` seen as a :class:`concurrent.futures.Executor`.

    ``submit`` goes through ``Client.get_executor()`` (whose futures are plain
    ``concurrent.futures`` futures, so ``as_completed`` works unchanged);
    ``shutdown`` also closes the client, which ``ClientExecutor.shutdown`` does not.
    On connecting it registers :class:`orchestrator.sweeps.dask_plugin.WorkerThreads`
    with the cluster (each worker's BLAS threads).

    Parameters
    ----------
    address : str
        The scheduler, e.g. ``tcp://127.0.0.1:8786``.
    connect_timeout : str
        How long to try to reach it (Dask duration text, e.g. ``"30s"``).
    threads : int
        BLAS/OpenMP threads per worker process.
    """

    def __init__(self, address: str, connect_timeout: str = DASK_CONNECT_TIMEOUT, threads: int = 1):
        try:
            from distributed import Client
        except ImportError:
            raise UserInputError("--scheduler needs Dask: pip install 'dask[distributed]'") from None
        try:
            self._client = Client(address, timeout=connect_timeout)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise UserInputError(f"--scheduler {address}: cannot connect to a Dask scheduler ({exc})") from None
        from orchestrator.sweeps.dask_plugin import WorkerThreads

        try:
            self._client.register_plugin(WorkerThreads(threads), name=WorkerThreads.name)
        except BaseException:
            self._client.close()
            raise
        # pure=False: every submit is a task of its own (no key deduplication by Dask).
        self._executor = self._client.get_executor(pure=False)

    @property
    def slots(self) -> int:
        """Tasks the cluster runs at once now: its workers' threads (at least 1)."""
        return max(1, sum(self._client.nthreads().values()))

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        return self._executor.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        try:
            self._executor.shutdown(wait=wait and not cancel_futures)
        finally:
            self._client.close()


def executor_slots(executor: cf.Executor) -> int:
    """Runs ``executor`` takes at once: a local pool's processes, a cluster's worker threads; 1 if unknown."""
    if isinstance(executor, DaskExecutor):
        return executor.slots
    # concurrent.futures' process and thread pools keep their max_workers as _max_workers (since 3.2);
    # any other executor counts as one slot (nothing runs ahead on it)
    return max(1, int(getattr(executor, "_max_workers", 1) or 1))


def make_executor(workers: int | None, scheduler: str | None, *, connect_timeout: str = DASK_CONNECT_TIMEOUT,
                  threads: int | None = None) -> cf.Executor:
    """The executor that runs a sweep, a diagnosis or a calibration.

    Parameters
    ----------
    workers : int or None
        Local worker processes (ignored with ``scheduler``: the cluster has its own);
        ``None``: one per core (:func:`default_workers`).
    scheduler : str or None
        Address of a Dask scheduler (``tcp://host:8786``); ``None`` runs locally.
    connect_timeout : str
        How long to try to reach ``scheduler`` (Dask duration text).
    threads : int, optional
        BLAS/OpenMP threads per worker process (default :func:`worker_threads`: 1).

    Returns
    -------
    concurrent.futures.Executor
        ``ProcessPoolExecutor`` with spawned workers set up by :func:`setup_worker`, or a
        :class:`DaskExecutor`.
    """
    threads = worker_threads(threads)
    if scheduler:
        return DaskExecutor(scheduler, connect_timeout, threads)
    workers = default_workers() if workers is None else workers
    check_workers(workers)
    return cf.ProcessPoolExecutor(max_workers=int(workers), mp_context=multiprocessing.get_context(START_METHOD),
                                  initializer=setup_worker, initargs=(os.getpid(), threads))


def lost_worker(exc: BaseException) -> bool:
    """True when ``exc`` says the worker died (not that the run function failed)."""
    # Dask gives up on a task whose workers keep dying with distributed.scheduler.KilledWorker.
    return isinstance(exc, (cf.BrokenExecutor, cf.CancelledError)) or type(exc).__name__ == "KilledWorker"
