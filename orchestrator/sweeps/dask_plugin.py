"""The Dask worker plugin of :class:`orchestrator.sweeps.executors.DaskExecutor` (imports ``distributed``,
so it is imported only when a cluster is used)."""
from __future__ import annotations

from distributed import WorkerPlugin

from orchestrator.sweeps.workers import limit_threads

__all__ = ["WorkerThreads"]


class WorkerThreads(WorkerPlugin):
    """Limits each Dask worker process's BLAS/OpenMP threads to ``threads`` (:func:`limit_threads`).

    Dask's nanny already starts workers with one thread per BLAS library; this also holds
    for workers started without a nanny, and for another ``threads``.
    """

    name = "turnout-worker-threads"

    def __init__(self, threads: int):
        self.threads = int(threads)

    def setup(self, worker=None) -> None:
        limit_threads(self.threads)
