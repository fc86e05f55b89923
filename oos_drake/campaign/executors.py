"""Executors: where the runs of a campaign are computed.

All executors call :func:`execute_case` on the workers and hand the results back to the driver
process, which is the only writer of the campaign directory (no file races between workers).
Each worker builds its simulator once from the picklable recipe (:func:`build_simulator` caches it
per worker thread, so threaded Dask workers never share a stateful simulator) and reuses it for
every case it receives.

- :class:`InlineExecutor`: in the calling process (``--workers 1``).
- :class:`ProcessPoolExecutor`: a local pool of ``spawn`` ed processes (the default for
  ``--workers N > 1``; ``spawn`` rather than ``fork``: Drake's threads do not survive a fork).
- :class:`DaskExecutor`: a Dask distributed cluster, either an existing scheduler
  (``--scheduler tcp://host:8786``) or a local one (``--scheduler dask`` or ``local``).

Both rest on the package's generic executors (:mod:`oos_drake.processes`: the same pool and
Dask client run the mu sweeps and the analysis); this module adds what a campaign needs on top:
a simulator built once per worker, run timeouts, the isolation of a case that kills its worker,
and bounded submission.

At most ``2 * workers`` cases are in flight at once, so a killed campaign loses little work and
the progress bar moves steadily.
"""

from __future__ import annotations

import collections
import concurrent.futures
import itertools
import math
import os
import socket
import time
import traceback
import warnings
from collections.abc import Iterable, Iterator
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Protocol

import pandas as pd

from oos_drake.blas import single_threaded_blas
from oos_drake.campaign.simulator import (
    RunCase,
    SimulationDiverged,
    SimulatorRecipe,
    build_simulator,
    simulator_builds,
)
from oos_drake.processes import DaskExecutor as DaskTasks
from oos_drake.processes import PoolExecutor, check_workers, scheduler_address


@dataclass(frozen=True)
class RunResult:
    """What a worker sends back for one case.

    Attributes
    ----------
    run_id : int
        The case's run id.
    status : str
        ``"ok"``, ``"diverged"`` (the simulator raised SimulationDiverged) or ``"failed"`` (any
        other exception, a metric that is NaN or infinite, a timeout, a dead worker).
    error : str
        ``"ExceptionType: message"`` for a run that did not finish, else ``""``.
    metrics : dict
        Metric name -> value (empty when the run did not finish).
    timeseries : pandas.DataFrame or None
        Logged signals.
    wall_time : float
        Wall-clock time of the run on its worker [s].
    worker : str
        ``"host:pid"`` of the process that ran it.
    simulator_builds : int
        Simulators built so far in that process (1 when the build-once-per-worker cache works).
    cpu_time : float
        Processor time of the worker process over the run [s] (all its threads). Unlike the wall
        time it does not grow when other jobs share the cores, so comparing it between 1- and
        2-worker campaigns separates the code's parallel overhead from machine contention.
    """

    run_id: int
    status: str
    error: str
    metrics: dict
    timeseries: pd.DataFrame | None
    wall_time: float
    worker: str = ""
    simulator_builds: int = 0
    cpu_time: float = math.nan


def execute_case(recipe: SimulatorRecipe, case: RunCase) -> RunResult:
    """Run one case on this process' simulator; never raises for a failing run.

    The run uses one OpenBLAS thread (the parallelism of a campaign is one process per core;
    a multi-threaded BLAS in each worker would oversubscribe the cores).
    """
    start, cpu_start = time.perf_counter(), time.process_time()
    try:
        simulator = build_simulator(recipe)
        with single_threaded_blas():
            output = simulator.run(case)
        status, error = "ok", ""
        metrics = {k: float(v) for k, v in output.metrics.items()}
        timeseries = output.timeseries
        bad = [f"{k} = {v}" for k, v in metrics.items() if not math.isfinite(v)]
        if bad:  # a NaN metric would pass or fail requirements silently: the run failed
            status, error = "failed", "NonFiniteMetric: " + ", ".join(bad)
    except SimulationDiverged as exc:
        status, error, metrics, timeseries = "diverged", f"SimulationDiverged: {exc}", {}, None
    except Exception as exc:  # noqa: BLE001 - a failing run is data, not a crash
        last = traceback.extract_tb(exc.__traceback__)[-1:]
        where = f" ({last[0].filename.rsplit('/', 1)[-1]}:{last[0].lineno})" if last else ""
        status, error = "failed", f"{type(exc).__name__}: {exc}{where}"
        metrics, timeseries = {}, None
    return RunResult(
        case.run_id,
        status,
        error,
        metrics,
        timeseries,
        time.perf_counter() - start,
        f"{socket.gethostname()}:{os.getpid()}",
        simulator_builds(),
        time.process_time() - cpu_start,
    )


def _warm_up(recipe: SimulatorRecipe) -> None:
    """Build the simulator of a worker (process or Dask worker) before any case runs."""
    build_simulator(recipe)


class Executor(Protocol):
    """Runs cases and yields their results as they complete (in any order)."""

    def run(self, recipe: SimulatorRecipe, cases: Iterable[RunCase]) -> Iterator[RunResult]: ...

    def close(self) -> None: ...


class InlineExecutor:
    """Runs the cases one after the other in the calling process."""

    workers = 1

    def start(self, recipe: SimulatorRecipe) -> None:
        _warm_up(recipe)

    def run(self, recipe: SimulatorRecipe, cases: Iterable[RunCase]) -> Iterator[RunResult]:
        for case in cases:
            yield execute_case(recipe, case)

    def close(self) -> None:
        pass


class ProcessPoolExecutor:
    """A local pool of ``workers`` spawned processes, each building the simulator once.

    Parameters
    ----------
    workers : int
        Number of worker processes (>= 1).
    timeout : float, optional
        Wall-clock limit of one run [s]; a run that exceeds it is stopped (its worker process is
        killed and replaced) and recorded as ``"failed"`` with a ``Timeout`` error.
    """

    def __init__(self, workers: int, timeout: float | None = None):
        check_workers(workers)
        if timeout is not None and not timeout > 0:
            raise ValueError(f"run timeout {timeout} s must be positive")
        self.workers = workers
        self.timeout = timeout
        self._pool: PoolExecutor | None = None

    def start(self, recipe: SimulatorRecipe) -> None:
        """Start the processes and build the simulator in each (before any timing)."""
        if self._pool is None:
            # spawn rather than fork: Drake's threads do not survive a fork
            self._pool = PoolExecutor(
                self.workers, initializer=_warm_up, initargs=(recipe,), method="spawn"
            )
            # bring workers up now (one warm-up task each; the pool may reuse an idle one)
            list(self._pool.map(_warm_up, [recipe] * self.workers))

    def run(self, recipe: SimulatorRecipe, cases: Iterable[RunCase]) -> Iterator[RunResult]:
        """Run the cases; a case that kills its worker or times out is recorded as ``"failed"``.

        A worker that dies (segmentation fault in a native simulator, ``os._exit``, out of
        memory) breaks the whole pool, and every case then in flight is suspect. The pool is
        restarted and the suspects are rerun one at a time: the one that kills its worker alone
        is the culprit and gets a ``"failed"`` result; the others complete normally (runs are
        deterministic, so rerunning them changes nothing). With a timeout, at most one case per
        worker is in flight, so a case's clock starts when it starts; an overdue case is the
        culprit, the other cases in flight are requeued.
        """
        queue = collections.deque(cases)
        suspects: collections.deque[RunCase] = collections.deque()
        limit = self.workers if self.timeout else 2 * self.workers
        while queue or suspects:
            self.start(recipe)
            pool = self._pool
            if suspects:
                yield self._run_alone(recipe, suspects.popleft())
                continue
            pending: dict[concurrent.futures.Future, RunCase] = {}
            submitted: dict[concurrent.futures.Future, float] = {}
            try:
                while queue or pending:
                    while queue and len(pending) < limit:
                        # submit raises BrokenProcessPool too: pop the case only once submitted
                        future = pool.submit(execute_case, recipe, queue[0])
                        pending[future] = queue.popleft()
                        submitted[future] = time.monotonic()
                    wait = None
                    if self.timeout:
                        oldest = min(submitted[f] for f in pending)
                        wait = max(0.0, oldest + self.timeout - time.monotonic())
                    done, _ = concurrent.futures.wait(
                        pending, timeout=wait, return_when=concurrent.futures.FIRST_COMPLETED
                    )
                    if not done:  # timeout: the overdue cases are the culprits
                        now = time.monotonic()
                        overdue = [f for f in pending if now - submitted[f] >= self.timeout]
                        self._kill_pool()
                        for future in overdue:
                            yield _timeout_result(pending.pop(future), self.timeout)
                        queue.extendleft(reversed(list(pending.values())))
                        pending.clear()
                        break
                    for future in done:
                        result = future.result()  # raises BrokenProcessPool if a worker died
                        del pending[future]
                        yield result
            except BrokenProcessPool:
                suspects.extend(pending.values())
                self._kill_pool()

    def _run_alone(self, recipe: SimulatorRecipe, case: RunCase) -> RunResult:
        """Run one suspect case with nothing else in flight."""
        try:
            return self._pool.submit(execute_case, recipe, case).result(timeout=self.timeout)
        except concurrent.futures.TimeoutError:
            self._kill_pool()
            return _timeout_result(case, self.timeout)
        except BrokenProcessPool as exc:
            self._kill_pool()
            return _failed_result(case, f"WorkerDied: its worker process died ({exc})")

    def _kill_pool(self) -> None:
        """Stop every worker process now and forget the pool (the next ``start`` makes one)."""
        if self._pool is None:
            return
        self._pool.kill()
        self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def _failed_result(case: RunCase, error: str, wall_time: float = math.nan) -> RunResult:
    """The record of a case its worker did not finish (a timeout, a dead worker)."""
    return RunResult(case.run_id, "failed", error, {}, None, wall_time)


def _timeout_result(case: RunCase, timeout: float) -> RunResult:
    return _failed_result(
        case, f"Timeout: the run exceeded {timeout:g} s and was stopped", float(timeout)
    )


class DaskExecutor:
    """Dask distributed: an existing scheduler, or a local cluster
    (:class:`oos_drake.processes.DaskExecutor`).

    Parameters
    ----------
    address : str or None
        Scheduler address (``tcp://host:8786``); ``None``, ``"dask"`` or ``"local"`` starts a
        LocalCluster.
    workers : int
        Workers of the local cluster (one thread each).
    processes : bool
        Local cluster with worker processes (True) or threads in this process (False).
    """

    def __init__(self, address: str | None = None, workers: int = 2, processes: bool = True):
        address = None if address is None else scheduler_address(address)
        self._tasks = DaskTasks(address, workers, processes=processes)
        self.workers = self._tasks.workers

    def start(self, recipe: SimulatorRecipe) -> None:
        self._tasks.client.run(_warm_up, recipe)

    def run(self, recipe: SimulatorRecipe, cases: Iterable[RunCase]) -> Iterator[RunResult]:
        """Run the cases, at most ``2 * workers`` in flight; results as they complete."""
        from dask.distributed import wait

        pending, iterator = set(), iter(cases)
        while True:
            for case in itertools.islice(iterator, 2 * self.workers - len(pending)):
                pending.add(self._tasks.submit(execute_case, recipe, case))
            if not pending:
                return
            result = wait(list(pending), return_when="FIRST_COMPLETED")
            pending = set(result.not_done)
            for future in result.done:
                yield future.result()

    def close(self) -> None:
        self._tasks.shutdown()


def make_executor(
    workers: int, scheduler: str | None, timeout: float | None = None
) -> InlineExecutor | ProcessPoolExecutor | DaskExecutor:
    """Executor for the CLI options ``--workers N`` and ``--scheduler`` (``processes``, the
    default; ``dask``/``local``; or a Dask scheduler address).

    A run ``timeout`` [s] needs worker processes that can be stopped: with it, one worker runs
    in a pool of one process rather than in this process. Dask does not stop running tasks, so
    the timeout is not enforced there (a warning says so).
    """
    check_workers(workers)
    if scheduler and scheduler != "processes":
        if timeout:
            warnings.warn(f"run_timeout = {timeout} s is not enforced on Dask", stacklevel=2)
        return DaskExecutor(scheduler, workers=workers)
    if workers == 1 and not timeout:
        return InlineExecutor()
    return ProcessPoolExecutor(workers, timeout)
