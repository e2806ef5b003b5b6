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
import threading

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

    ``submit`` returns a plain ``concurrent.futures`` future (so ``as_completed`` works
    unchanged), completed by awaiting the Dask future on the client's event loop
    (:meth:`_settle`). Not through ``Client.get_executor()``: its bridge
    (``distributed.cfexecutor._cascade_future``, distributed 2026.8) gathers the result and
    then reads the Dask future's status again; when the worker holding that result dies in
    between, the status is no longer "finished" and the result is unpacked as an error
    triple — ``TypeError: cannot unpack non-iterable RunOutput object`` for a run that
    succeeded (seen in ``tests/test_sweep.py::test_dask_reschedules_a_run_whose_worker_died``:
    2 of its 6 runs, in 1 of 11 runs of the test under load, 2026-11-28). ``shutdown`` also closes the client.
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
        self._pending: dict = {}     # Dask future -> its concurrent.futures future, until settled
        self._lock = threading.Lock()

    @property
    def slots(self) -> int:
        """Tasks the cluster runs at once now: its workers' threads (at least 1)."""
        return max(1, sum(self._client.nthreads().values()))

    def submit(self, fn, /, *args, **kwargs) -> cf.Future:
        out = cf.Future()
        # pure=False: every submit is a task of its own (no key deduplication by Dask).
        task = self._client.submit(fn, *args, pure=False, **kwargs)
        with self._lock:              # held here until settled: a released Dask future cancels its task
            self._pending[task] = out
        out.add_done_callback(lambda f: task.cancel() if f.cancelled() else None)
        self._client.loop.add_callback(self._settle, task, out)
        return out

    async def _settle(self, task, out: cf.Future) -> None:
        """Complete ``out`` with ``task``'s result or error, on the client's event loop.

        ``await task`` waits, gathers, and raises the task's error; a result lost with its
        worker is computed again and gathered then (Dask's own rescheduling). Each task waits
        in its own coroutine, so one slow gather (a dead worker's address tried for Dask's
        connect timeout, 30 s) holds up no other result."""
        try:
            if out.done():
                return
            try:
                result = await task
            except cf.CancelledError:
                if out.cancel():
                    out.set_running_or_notify_cancel()
            except BaseException as exc:     # the run's own error, or Dask's (KilledWorker, ...)
                if not out.done():
                    out.set_exception(exc)
            else:
                if not out.done():
                    out.set_result(result)
        finally:
            with self._lock:
                self._pending.pop(task, None)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        with self._lock:
            tasks = list(self._pending)
        try:
            if cancel_futures and tasks:
                self._client.cancel(tasks)
            elif wait and tasks:
                from distributed import wait as wait_for

                wait_for(tasks)
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
