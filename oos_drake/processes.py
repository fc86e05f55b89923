"""Worker process pools that never outlive the process that started them.

Every process pool of the package (mu sweeps, the analysis, worst-case gains, campaigns) is made
by :func:`process_pool`. Its workers

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

import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

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
    from oos_drake.blas import limit_blas_threads

    exit_with_parent(parent_pid)
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
    if workers < 1:
        raise ValueError(f"--workers {workers}: need at least 1 worker")
    return ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context(start_method(method)),
        initializer=_start_worker,
        initargs=(os.getpid(), initializer, initargs),
    )
