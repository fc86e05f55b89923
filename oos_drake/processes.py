"""Where parallel work runs: executors, and worker process pools that never outlive their parent.

Every parallel site of the package (the mu sweeps, the analysis and its worst-case gains, the
parameter study, the confirmation, the campaign's executors) runs on one small interface made
by :func:`make_executor` from the CLI options ``--workers N`` and ``--scheduler``:

- :class:`SerialExecutor`: in this process (one worker);
- :class:`ThreadExecutor`: threads of this process, one BLAS thread each (the fine grain: many
  small GIL-free LAPACK calls on shared arrays, e.g. the per-model eigendecompositions of a
  gamma evaluation; not a ``--scheduler`` choice: only for work that is thread-safe);
- :class:`PoolExecutor`: a local pool of worker processes (the default);
- :class:`DaskExecutor`: a local Dask cluster (``--scheduler dask``) or a running scheduler
  (``--scheduler tcp://host:8786``); Dask is optional.

Each has ``submit(fn, *args)`` (a future with ``result()`` and ``done()``), ``map(fn, items)``
(results in order), ``as_completed(futures)``, ``workers``, ``shutdown()`` and is a context
manager; an ``initializer`` runs once in every worker (model arrays installed once). The tasks
are module-level functions and picklable arguments, so any executor can run them, with the same
results.

Every process pool is made by :func:`process_pool`. Its workers

- run one OpenBLAS thread each (the parallelism is one process per core; batched small-matrix
  kernels only lose from more BLAS threads), and
- exit as soon as their parent dies, however it dies: a ``kill -9`` of ``oos run`` during the
  analysis leaves no worker behind using the cores. A watcher thread in each worker polls its
  parent process id; the parent's death re-parents the worker (to init or a sub-reaper), which
  changes that id. Polling rather than ``PR_SET_PDEATHSIG``: the kernel sends that signal when the
  *thread* that forked the worker exits, which would kill healthy workers of a pool started
  from a short-lived thread.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor

from oos_drake.blas import limit_blas_threads, preserved_blas_threads, with_single_threaded_blas

#: Seconds between two checks of the parent process id in a worker.
PARENT_POLL_S = 0.25


def exit_with_parent(parent_pid: int, period: float = PARENT_POLL_S) -> None:
    """Start a daemon thread that ends this process when ``parent_pid`` is no longer its parent.

    Parameters
    ----------
    parent_pid : int
        Process id of the parent that started this worker.
    period : float
        Polling period [s].
    """
    if os.getppid() != parent_pid:  # the parent died before this worker got here
        os._exit(0)

    def watch() -> None:
        while True:
            time.sleep(period)
            if os.getppid() != parent_pid:
                os._exit(0)

    threading.Thread(target=watch, name="oos-parent-watch", daemon=True).start()


def _start_worker(parent_pid: int, initializer: Callable | None, initargs: tuple) -> None:
    exit_with_parent(parent_pid)
    _setup_worker(initializer, initargs)


def _setup_worker(initializer: Callable | None, initargs: tuple) -> None:
    """One BLAS thread, then ``initializer`` (every worker: process pool and Dask)."""
    limit_blas_threads(1)
    if initializer is not None:
        initializer(*initargs)


def start_method(preferred: str | None = None) -> str:
    """``preferred``, else ``fork`` where the platform has it (no ``__main__`` guard needed in
    user scripts, model arrays inherited rather than pickled), else ``spawn``."""
    if preferred is not None:
        return preferred
    return "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"


def process_pool(
    workers: int,
    *,
    initializer: Callable | None = None,
    initargs: tuple = (),
    method: str | None = None,
) -> ProcessPoolExecutor:
    """A ``concurrent.futures.ProcessPoolExecutor`` whose workers die with this process.

    Parameters
    ----------
    workers : int
        Worker processes (>= 1).
    initializer : callable, optional
        Called in each worker after the parent watcher and the BLAS thread limit are set up.
    initargs : tuple
        Arguments of ``initializer``.
    method : str, optional
        Start method (``"fork"``, ``"spawn"``, ``"forkserver"``); default :func:`start_method`.
        Use ``"spawn"`` when the parent holds threads that do not survive a fork (Drake).

    Returns
    -------
    concurrent.futures.ProcessPoolExecutor
    """
    check_workers(workers)
    return ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context(start_method(method)),
        initializer=_start_worker,
        initargs=(os.getpid(), initializer, initargs),
    )


# --- executors: one interface for every parallel site ------------------------------------------

#: Help text of ``--scheduler`` (one text for every command).
SCHEDULER_HELP = (
    "where parallel work runs: 'processes' (default: a local pool of --workers processes), "
    "'dask' or 'local' (a local Dask cluster of --workers processes), or the address of a "
    "running Dask scheduler (tcp://host:8786)"
)


def _done_future(fn: Callable, args: tuple) -> Future:
    future: Future = Future()
    try:
        future.set_result(fn(*args))
    except BaseException as exc:  # noqa: BLE001 - delivered by future.result(), as in a pool
        future.set_exception(exc)
    return future


class SerialExecutor:
    """Runs every task at once in this process (``--workers 1``): no pickling, no processes.

    Parameters
    ----------
    initializer : callable, optional
        Called once in this process when the executor is made.
    initargs : tuple
        Arguments of ``initializer``.
    """

    workers = 1
    kind = "serial"

    def __init__(self, initializer: Callable | None = None, initargs: tuple = ()):
        # the initializer runs in this process: what it sets for BLAS lasts until shutdown only
        self._blas = contextlib.ExitStack()
        self._blas.enter_context(preserved_blas_threads())
        if initializer is not None:
            initializer(*initargs)

    def submit(self, fn: Callable, *args) -> Future:
        """``fn(*args)`` now; its result (or exception) in a finished future."""
        return _done_future(fn, args)

    def map(self, fn: Callable, iterable: Iterable) -> list:
        """``[fn(x) for x in iterable]``."""
        return [fn(x) for x in iterable]

    def as_completed(self, futures: Iterable) -> Iterator:
        """The futures (all finished already)."""
        return iter(list(futures))

    def shutdown(self) -> None:
        """Restore this process's BLAS thread counts (set by the initializer)."""
        self._blas.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> bool:
        self.shutdown()
        return False


class _LocalPoolExecutor(SerialExecutor):
    """What the thread and process pools share: ``self.pool`` is a ``concurrent.futures``
    executor."""

    def as_completed(self, futures: Iterable) -> Iterator:
        """The futures in the order they finish."""
        return concurrent.futures.as_completed(list(futures))

    def shutdown(self) -> None:
        self.pool.shutdown(wait=True, cancel_futures=True)
        blas = getattr(self, "_blas", None)  # the process pool runs no initializer here
        if blas is not None:
            blas.close()


class ThreadExecutor(_LocalPoolExecutor):
    """Threads of this process, each task with one BLAS thread (no nested BLAS threads).

    For the fine grain where pickling would cost more than the work: GIL-free LAPACK calls on
    arrays this process holds. A single task (``map`` of one item) runs in the calling thread
    with the BLAS setting unchanged.

    Parameters
    ----------
    workers : int
        Threads (>= 1).
    initializer, initargs :
        Called once in this process when the executor is made.
    """

    kind = "threads"

    def __init__(self, workers: int, initializer: Callable | None = None, initargs: tuple = ()):
        check_workers(workers)
        super().__init__(initializer, initargs)
        self.workers = int(workers)
        self.pool = ThreadPoolExecutor(max_workers=self.workers, thread_name_prefix="oos")

    def submit(self, fn: Callable, *args) -> Future:
        """Start ``fn(*args)`` on a thread (one BLAS thread); a ``concurrent.futures.Future``."""
        return self.pool.submit(with_single_threaded_blas(fn), *args)

    def map(self, fn: Callable, iterable: Iterable) -> list:
        """``[fn(x) for x in iterable]`` on the threads, in order."""
        items = list(iterable)
        if len(items) < 2:
            return [fn(x) for x in items]
        return list(self.pool.map(with_single_threaded_blas(fn), items))


class PoolExecutor(_LocalPoolExecutor):
    """A local pool of worker processes made by :func:`process_pool` (they die with this process).

    Parameters
    ----------
    workers : int
        Worker processes (>= 1).
    initializer, initargs :
        Run in every worker at its start (after the parent watcher and the BLAS limit).
    method : str, optional
        Start method (default :func:`start_method`: ``fork`` where available).
    """

    kind = "processes"

    def __init__(
        self,
        workers: int,
        initializer: Callable | None = None,
        initargs: tuple = (),
        method: str | None = None,
    ):
        self.workers = int(workers)
        self.pool = process_pool(workers, initializer=initializer, initargs=initargs, method=method)

    def submit(self, fn: Callable, *args) -> Future:
        """Start ``fn(*args)`` on a worker; a ``concurrent.futures.Future``."""
        return self.pool.submit(fn, *args)

    def map(self, fn: Callable, iterable: Iterable) -> list:
        """``[fn(x) for x in iterable]`` on the workers, in order."""
        return list(self.pool.map(fn, iterable))

    def kill(self) -> None:
        """Stop every worker now, running tasks included (a pool offers no way to cancel one)."""
        for process in list((getattr(self.pool, "_processes", None) or {}).values()):
            process.kill()
        self.shutdown()


class DaskExecutor(SerialExecutor):
    """Dask distributed: a local cluster, or a running scheduler.

    Dask is an optional dependency (``pip install "dask[distributed]"``). The tasks and their
    arguments are pickled to the workers (model arrays of an ``initializer`` once per worker).

    Parameters
    ----------
    address : str or None
        Scheduler address (``tcp://host:8786``); ``None`` starts a ``LocalCluster`` of
        ``workers`` processes with one thread each.
    workers : int
        Workers of the local cluster.
    initializer, initargs :
        Run in every worker (present and future, through a worker plugin), after the BLAS limit
        of one thread; on a local cluster of threads, once in this process (no BLAS limit).
    processes : bool
        Local cluster of worker processes (True) or of threads in this process (False).
    """

    kind = "dask"

    def __init__(
        self,
        address: str | None = None,
        workers: int = 2,
        initializer: Callable | None = None,
        initargs: tuple = (),
        processes: bool = True,
    ):
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError as exc:
            raise ValueError(
                '--scheduler dask needs Dask: pip install "dask[distributed]"'
            ) from exc
        check_workers(workers)
        self._cluster = None
        if address is None:
            self._cluster = LocalCluster(
                n_workers=int(workers),
                threads_per_worker=1,
                processes=processes,
                dashboard_address=None,
            )
            self.client = Client(self._cluster)
        else:
            try:
                self.client = Client(address, timeout="10s")
            except OSError as exc:
                raise ValueError(f"--scheduler {address}: cannot connect: {exc}") from exc
        if self._cluster is not None and not processes:  # threads of this process
            if initializer is not None:
                initializer(*initargs)
        else:
            self.client.register_plugin(
                _worker_setup_plugin(initializer, initargs), name="oos-worker-setup"
            )
        self.workers = max(1, sum(self.client.nthreads().values()))

    def submit(self, fn: Callable, *args):
        """Start ``fn(*args)`` on a worker; a Dask future (``result()``, ``done()``)."""
        return self.client.submit(fn, *args, pure=False)

    def map(self, fn: Callable, iterable: Iterable) -> list:
        """``[fn(x) for x in iterable]`` on the workers, in order."""
        items = list(iterable)
        if not items:
            return []
        return self.client.gather(self.client.map(fn, items, pure=False))

    def as_completed(self, futures: Iterable) -> Iterator:
        """The futures in the order they finish."""
        from dask.distributed import as_completed

        return iter(as_completed(list(futures)))

    def shutdown(self) -> None:
        self.client.close()
        if self._cluster is not None:
            self._cluster.close()


def _worker_setup_plugin(initializer: Callable | None, initargs: tuple):
    """A Dask worker plugin running :func:`_setup_worker` in every worker that joins (Dask
    refuses duck-typed plugins, and is imported only here: it is optional)."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class WorkerSetup(WorkerPlugin):
        def setup(self, worker) -> None:
            _setup_worker(initializer, initargs)

    return WorkerSetup()


Executor = SerialExecutor | ThreadExecutor | PoolExecutor | DaskExecutor


def make_executor(
    workers: int,
    scheduler: str | None = None,
    *,
    initializer: Callable | None = None,
    initargs: tuple = (),
    method: str | None = None,
) -> Executor:
    """The executor of the CLI options ``--workers N`` and ``--scheduler``.

    Parameters
    ----------
    workers : int
        Workers (>= 1). On the process pool, 1 runs the tasks in this process.
    scheduler : str, optional
        ``None`` or ``"processes"``: :class:`PoolExecutor` (:class:`SerialExecutor` for one
        worker); ``"threads"``: :class:`ThreadExecutor` (:class:`SerialExecutor` for one
        worker; for thread-safe work only, so not a ``--scheduler`` value); ``"dask"`` or
        ``"local"``: a local Dask cluster; an address (``host:port``, ``tcp://host:port``): that
        Dask scheduler (:func:`scheduler_address`).
    initializer, initargs :
        Run once in every worker (in this process for :class:`SerialExecutor`).
    method : str, optional
        Start method of the process pool (``"spawn"`` when this process holds Drake threads).

    Returns
    -------
    SerialExecutor, ThreadExecutor, PoolExecutor or DaskExecutor
        Use it as a context manager (it shuts down at the end).
    """
    workers = int(workers)
    check_workers(workers)
    setup = {"initializer": initializer, "initargs": initargs}
    if scheduler in (None, "", "processes"):
        if workers == 1:
            return SerialExecutor(**setup)
        return PoolExecutor(workers, method=method, **setup)
    if scheduler == "threads":
        return SerialExecutor(**setup) if workers == 1 else ThreadExecutor(workers, **setup)
    return DaskExecutor(scheduler_address(scheduler), workers, **setup)


def check_workers(workers) -> int:
    """``workers`` as an int if it is at least 1 (one message for every ``--workers``).

    Raises
    ------
    ValueError
        ``"--workers N: need at least 1 worker"``.
    """
    if not int(workers) >= 1:
        raise ValueError(f"--workers {workers}: need at least 1 worker")
    return int(workers)


def check_scheduler(scheduler: str | None) -> str | None:
    """``scheduler`` if :func:`make_executor` accepts it (checked before any work starts).

    Raises
    ------
    ValueError
        Neither ``processes``, ``dask``, ``local`` nor a Dask scheduler address.
    """
    if scheduler not in (None, "", "processes"):
        scheduler_address(scheduler)
    return scheduler


def scheduler_address(scheduler: str | None) -> str | None:
    """The Dask scheduler address of ``--scheduler`` (None: a local cluster).

    Raises
    ------
    ValueError
        ``processes`` or a value that is neither ``dask``/``local`` nor an address (``host:port``
        or ``tcp://host:port``).
    """
    if scheduler in ("dask", "local"):
        return None
    if scheduler and ":" in scheduler:
        return scheduler
    raise ValueError(
        f"--scheduler {scheduler!r}: expected processes, dask, local or a Dask scheduler "
        "address such as tcp://host:8786"
    )
