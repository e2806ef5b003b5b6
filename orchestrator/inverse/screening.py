"""The runs and the 1-D screening search of a diagnosis (:mod:`orchestrator.inverse.diagnose`, steps 1-3).

:class:`Pool` runs scenario variants on an executor and counts them; :class:`Evaluated`
is one candidate at one parameter vector with its comparison and BIC; a candidate is
screened at the magnitudes of :func:`scalar_axis` and its best magnitude found by
:func:`dense_search`, which interpolates the screening runs' *signals* (monotone cubic
in the magnitude, log scale for stiffness factors) instead of running more: the
:data:`DENSE` points are ranked by their objective J computed over whole blocks of points
(:func:`orchestrator.inverse.objective.objective_rows`), and the best :data:`DENSE_EXACT` are
scored one by one, as every point once was (121 full scores a search were a tenth of a
diagnosis's wall time, in its main process while the workers waited).

Non-finite signals never reach an interpolation or a fit (issue 14: a record that
reaches beyond the simulated window put NaN into the nominal run's signals on the
measured time base, and the PCHIP of :func:`dense_search` raised ``y must contain only
finite values``). :func:`checked_comparison` sorts a finished run into a comparison or a
*dropped* variant with its reason: the run stopped early (a diverged variant), its
signals hold a non-finite value, or it does not cover the measured record;
:attr:`Pool.dropped` lists them (logged as warnings) and the answer reports them.
Samples outside the simulated window (NaN in *every* variant alike) are masked, not
dropped: the comparison skips them and the search interpolates the rest.
"""
from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from orchestrator.inputs.causes import Candidate
from orchestrator.inverse.objective import Comparison, Target

DENSE = 121          # points of the 1-D search between screening runs
DENSE_BLOCK = 16     # points interpolated and ranked at once (16 x the channels' samples in memory)
DENSE_EXACT = 4      # the best-ranked points scored exactly (the ranking's J differs in round-off)

log = logging.getLogger(__name__)


@dataclass
class Evaluated:
    """One candidate at one parameter vector, with its comparison.

    Attributes
    ----------
    candidate : Candidate
    values : ndarray
        The cause's parameter vector (units of its scenario keys).
    cmp : Comparison
        The run (or the interpolated signals) against the measurement.
    k : int
        Parameters fitted to get there (0 for the nominal model).
    stage : str
        ``nominal``, ``screened``, ``confirmed`` or ``fitted``.
    """

    candidate: Candidate
    values: np.ndarray
    cmp: Comparison
    k: int
    stage: str

    def bic(self) -> float:
        """Bayesian information criterion chi2 + k ln N."""
        return self.cmp.chi2 + self.k * math.log(self.cmp.n)


@dataclass
class Pool:
    """Runs of scenario variants on an executor (local processes or Dask).

    Each run goes to its worker by value (the raw scenario and the files it names:
    :class:`orchestrator.cosim.portable.PortableScenario`) and its signals come back by
    value, so a worker needs no access to the client's files.

    Attributes
    ----------
    executor : concurrent.futures.Executor
    source : str
        The scenario's file on the client (named in a worker's error messages).
    runs : int
        Runs done so far.
    wall : float
        Wall time spent waiting for them [s].
    bar : tqdm or None
        Progress bar, advanced by one per run.
    dropped : list of dict
        Variants left out, each ``{"variant", "stage", "reason"}`` (:func:`checked_comparison`).
    spare : int
        Runs a batch of one can add at no extra wall time: the workers beyond the first
        (:func:`orchestrator.sweeps.executors.executor_slots` - 1). A fit of at most this many
        parameters runs its trial point's Jacobian ahead on them
        (:func:`orchestrator.inverse.fitting.fit_unit_cube`).
    ahead_runs, ahead_used : int
        Runs made ahead of being asked for, and those of them a fit then asked for.
    lock : threading.Lock
        Guards the counters and the progress bar: fits of different candidates may use the pool
        side by side, each from its own thread (:func:`orchestrator.inverse.selection.side_by_side`).
    slots : int
        Runs on the executor at once at most (its workers: :func:`orchestrator.sweeps.executors.executor_slots`);
        0: no limit, every run goes to the executor when asked for. With a limit, the runs wait
        here and a freed worker takes the next run of the thread with the fewest runs waiting
        (:meth:`_next`): the executor's own queue is first come, first served, so the single
        run of a Gauss-Newton step (a chain: the next step needs its answer) waited behind a
        Jacobian batch of the fit beside it. Only when a run starts changes, not which runs
        are made: the results are the same. :meth:`close` cancels the runs still waiting.
    """

    executor: object
    source: str = "<variant>"
    runs: int = 0
    wall: float = 0.0
    bar: object = None
    dropped: list = field(default_factory=list)
    spare: int = 0
    ahead_runs: int = 0
    ahead_used: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)
    slots: int = 0
    _waiting: dict = field(default_factory=dict, repr=False, compare=False)   # thread -> deque of (seq, job, Future)
    _running: int = field(default=0, repr=False, compare=False)
    _seq: int = field(default=0, repr=False, compare=False)
    _closed: bool = field(default=False, repr=False, compare=False)
    _sched: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def count(self, **increments: float) -> None:
        """Add to the counters (``runs``, ``wall``, ``ahead_runs``, ``ahead_used``) under :attr:`lock`."""
        with self.lock:
            for name, value in increments.items():
                setattr(self, name, getattr(self, name) + value)

    def drop(self, variant: str, stage: str, reason: str) -> None:
        """Record (and log) a variant left out of the diagnosis and why."""
        log.warning("diagnose: %s (%s) left out: %s", variant, stage, reason)
        self.dropped.append({"variant": variant, "stage": stage, "reason": reason})

    def expect(self, n: int) -> None:
        """Announce ``n`` more runs to the progress bar."""
        if self.bar is not None:
            with self.lock:
                self.bar.total += n

    def map(self, raws: list[dict], then: Callable | None = None) -> list:
        """The runs of ``raws`` (validated raw scenario dicts, file paths absolute), in their order;
        with ``then``, ``then(run)`` of each instead, computed here as each run arrives, while the
        later runs still go on (a comparison with the measurement: ~20 ms a run that the workers
        no longer wait for after a batch, e.g. 2 s after the 96 screening runs)."""
        return self.submit(raws, then)()

    def submit(self, raws: list[dict], then: Callable | None = None) -> Callable[[], list]:
        """Start the runs of ``raws`` now and return at once a function that waits for them and gives
        what :meth:`map` gives (call it once). The runs share the workers with whatever is asked for
        before the function is called: a run whose answer is needed only later (the step error's)
        no longer leaves the other workers idle while it runs alone."""
        from orchestrator.cosim.portable import PortableScenario

        futures = self._enqueue([PortableScenario.of(raw, self.source) for raw in raws])

        def collect() -> list:
            t0 = time.perf_counter()
            out = []
            for f in futures:
                run = f.result()
                out.append(run if then is None else then(run))
                if self.bar is not None:
                    with self.lock:
                        self.bar.update(1)
            self.count(runs=len(raws), wall=time.perf_counter() - t0)   # fits side by side: their waits add up
            return out

        return collect

    def _enqueue(self, jobs: list) -> list:
        """Futures of the runs of ``jobs`` (portable scenarios), started as :attr:`slots` allow."""
        from collections import deque
        from concurrent.futures import Future

        futures = [Future() for _ in jobs]
        with self._sched:
            queue = self._waiting.setdefault(threading.get_ident(), deque())
            for job, fut in zip(jobs, futures):
                queue.append((self._seq, job, fut))
                self._seq += 1
        self._start_waiting()
        return futures

    def _next(self):
        """The next waiting run (under :attr:`_sched`): the head of the shortest queue, the oldest head
        among equals; None when none waits or every slot is taken."""
        if self._closed or not self._waiting or 0 < self.slots <= self._running:
            return None
        self._running += 1
        key = min(self._waiting, key=lambda k: (len(self._waiting[k]), self._waiting[k][0][0]))
        queue = self._waiting[key]
        out = queue.popleft()
        if not queue:   # only non-empty queues are kept (a fit's thread ends; a new one gets a new queue)
            del self._waiting[key]
        return out

    def _start_waiting(self) -> None:
        """Hand waiting runs to the executor while slots are free (outside the lock: a finished
        future runs its callback at once, in this thread)."""
        from orchestrator.cosim.sensing import sensors_job

        while True:
            with self._sched:
                nxt = self._next()
            if nxt is None:
                return
            _, job, fut = nxt
            try:
                inner = self.executor.submit(sensors_job, job)
            except BaseException as exc:   # the executor is shut down: this run's caller gets the error
                self._finished(fut, None, exc)
                continue
            inner.add_done_callback(lambda f, fut=fut: self._finished(fut, f))

    def _finished(self, fut, inner, exc: BaseException | None = None) -> None:
        """A run ended (or could not start): its result or error to ``fut``, its slot to the next run."""
        with self._sched:
            self._running -= 1
        if inner is not None and inner.cancelled():
            fut.cancel()
        elif inner is not None and inner.exception() is None:
            fut.set_result(inner.result())
        else:
            fut.set_exception(exc if inner is None else inner.exception())
        self._start_waiting()

    def close(self) -> None:
        """Cancel the runs still waiting for a slot (their callers get ``CancelledError``); no run starts after."""
        with self._sched:
            self._closed = True
            waiting = [fut for q in self._waiting.values() for _, _, fut in q]
            self._waiting.clear()
        for fut in waiting:
            fut.cancel()


def scalar_axis(kind, raw: dict, sleeper, grid: tuple | None = None) -> tuple[np.ndarray, float]:
    """Screening magnitudes (``grid``, default the kind's) with the nominal one, sorted, and the nominal magnitude.

    The nominal magnitude of a vector cause (the 6 void gaps) is its largest entry; of a
    scalar cause, its value.
    """
    nominal = float(np.max(kind.nominal(raw, sleeper)))
    grid = sorted(set([nominal] + [g for g in (kind.grid if grid is None else grid) if abs(g - nominal) > 1e-12]))
    return np.array(grid, float), nominal


def dense_search(target: Target, kind, xs: np.ndarray, signals: list[dict]) -> tuple[float, Comparison]:
    """Best magnitude of a 1-D family of runs by interpolating their signals (module docstring).

    Samples that are not finite in every run (outside the simulated window) are left
    out of the interpolation and stay NaN, so the comparison skips them.
    """
    from scipy.interpolate import PchipInterpolator

    u = np.log(xs) if kind.log else xs
    ids = list(signals[0])
    Y = np.stack([np.concatenate([sig[k] for k in ids]) for sig in signals])   # (nx, total)
    masked = ~np.isfinite(Y).all(axis=0)
    Y[:, masked] = 0.0
    sizes = np.cumsum([0] + [signals[0][k].size for k in ids])
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):   # flat stretches of a signal
        interp = PchipInterpolator(u, Y, axis=0)
    grid = np.linspace(u[0], u[-1], DENSE)
    rank = np.empty(DENSE)
    for b in range(0, DENSE, DENSE_BLOCK):   # ranked on whole blocks of points
        rows = interp(grid[b:b + DENSE_BLOCK])
        rows[:, masked] = np.nan
        rank[b:b + DENSE_BLOCK] = target.objective_rows(rows, ids, sizes)
    best = None
    for ud in grid[np.sort(_lowest(rank, DENSE_EXACT))]:   # the best few scored one by one, in grid order
        row = interp(ud)
        row[masked] = np.nan
        on = {k: row[sizes[i]:sizes[i + 1]] for i, k in enumerate(ids)}
        cmp = target.score(on)
        if best is None or cmp.objective < best[1].objective:
            best = (float(np.exp(ud) if kind.log else ud), cmp)
    return best


def _lowest(values: np.ndarray, k: int) -> np.ndarray:
    """Indices of the ``k`` lowest values (NaN counted lowest: scoring them raises as it should)."""
    return np.argsort(np.where(np.isnan(values), -np.inf, values), kind="stable")[:k]


def comparison(target: Target, run) -> Comparison:
    """The comparison of a finished run with ``target``; a run that stopped early is an error."""
    if run.error:
        raise RuntimeError(f"a diagnosis run stopped early: {run.error}")
    return target.compare(run.t, run.signals)


def checked_comparison(target: Target, run, reference: Comparison | None = None) -> tuple[Comparison | None, str]:
    """The comparison of a run, or None and why it cannot be compared (module docstring).

    ``reference`` (the comparison of the model this variant changes): a variant whose
    signals are NaN on the measured base where the reference's are finite diverged.
    """
    if run.error:
        return None, f"the run stopped early: {run.error}"
    bad = [k for k, y in run.signals.items() if not np.isfinite(y).all()]
    if bad:
        return None, f"non-finite simulated signal(s) {', '.join(bad[:4])}"
    try:
        cmp = target.compare(run.t, run.signals)
    except ValueError as exc:   # score(): fewer than 2 samples of a channel inside the simulated window
        return None, f"the comparison window lies outside the simulated record ({exc})"
    if reference is not None:
        lost = [k for k, y in cmp.simulated.items() if (~np.isfinite(y) & np.isfinite(reference.simulated[k])).any()]
        if lost:
            return None, f"covers less of the record than the reference model (channels {', '.join(lost[:4])})"
    return cmp, ""


__all__ = ["Pool", "Evaluated", "DENSE", "scalar_axis", "dense_search", "comparison", "checked_comparison"]
