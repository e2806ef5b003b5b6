"""Worker processes of the executors (:mod:`orchestrator.sweeps.executors`): how many, and their setup.

Every worker process is set up once (:func:`setup_worker`): its BLAS/OpenMP threads are
limited (:func:`limit_threads`: one by default, :func:`worker_threads`), and a local
worker dies with its parent (:func:`die_with_parent`). The default number of local
workers is the number of cores this process may run on (:func:`default_workers`).
"""
from __future__ import annotations

import ctypes
import numbers
import os
import signal
import sys
import threading
import time
from typing import Any

from orchestrator.inputs.errors import UserInputError

__all__ = ["default_workers", "worker_threads", "check_workers", "limit_threads", "die_with_parent",
           "setup_worker", "THREADS_ENV", "THREAD_VARIABLES"]

THREADS_ENV = "TURNOUT_WORKER_THREADS"  # BLAS/OpenMP threads per worker process (default 1)
# Read by BLAS/OpenMP libraries when they load: covers those a worker loads after its setup.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS", "NUMBA_NUM_THREADS")
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>: signal the process when its parent dies
WATCHDOG_PERIOD = 0.5  # s: how often a worker without prctl checks that its parent lives


def default_workers() -> int:
    """The number of cores this process may run on (its affinity mask where the OS has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity masks (macOS, Windows)
        return max(1, os.cpu_count() or 1)


def worker_threads(threads: int | None = None) -> int:
    """BLAS/OpenMP threads per worker: ``threads``, else ``$TURNOUT_WORKER_THREADS``, else 1.

    Raises
    ------
    UserInputError
        The value is not an integer >= 1 (names the variable when it came from there).
    """
    if threads is not None:
        check_workers(threads, what="threads per worker")
        return int(threads)
    text = os.environ.get(THREADS_ENV, "").strip()
    if not text:
        return 1
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise UserInputError(f"{THREADS_ENV}={text!r}: expected an integer >= 1 (BLAS threads per worker)")
    return n


def limit_threads(threads: int) -> None:
    """Limit this process's BLAS/OpenMP thread pools to ``threads``, for good.

    The libraries numpy and scipy load are imported first, so that the limit reaches them
    (``threadpool_limits`` acts on the libraries loaded when it is called); the thread
    variables cover those loaded later.
    """
    for name in THREAD_VARIABLES:
        if name != "NUMBA_NUM_THREADS" or "numba" not in sys.modules:  # numba reads it at import only
            os.environ[name] = str(threads)
    import numpy  # noqa: F401 - loads numpy's BLAS
    import scipy.linalg  # noqa: F401 - loads scipy's BLAS/LAPACK
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=threads)


def die_with_parent(parent_pid: int) -> None:
    """End this process when process ``parent_pid`` (its parent) ends.

    On Linux the kernel does it (``prctl(PR_SET_PDEATHSIG, SIGKILL)``: immediate, even in
    the middle of a computation; it fires when the thread that started this process
    ends, and executors start their workers from the thread that submits, which outlives
    them). Elsewhere a daemon thread checks every :data:`WATCHDOG_PERIOD` seconds that
    the parent is still the parent.
    """
    armed = False
    if sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            armed = libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
        except (OSError, AttributeError):
            armed = False
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)
    if not armed:
        threading.Thread(target=_watch_parent, args=(parent_pid,), name="turnout-parent-watchdog",
                         daemon=True).start()


def _watch_parent(parent_pid: int) -> None:
    """Exit the process as soon as its parent is no longer ``parent_pid`` (re-parented: the parent died)."""
    while os.getppid() == parent_pid:
        time.sleep(WATCHDOG_PERIOD)
    os._exit(1)


def setup_worker(parent_pid: int | None, threads: int) -> None:
    """Once per worker process: die with ``parent_pid`` (when given) and limit BLAS to ``threads``."""
    if parent_pid is not None:
        die_with_parent(parent_pid)
    limit_threads(threads)


def check_workers(workers: Any, what: str = "workers") -> None:
    """Raise :class:`UserInputError` unless ``workers`` is an integer >= 1 (``what`` names it)."""
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        raise UserInputError(f"{what} must be an integer >= 1, got {workers!r}")
