"""mu bounds at arbitrary (model, frequency) points of a model array, in worker processes.

The model array's Delta-channel matrices ``(A, Bw, Cz, Dzw)`` are handed to the workers once,
when the executor starts (process pool, fork: inherited, not pickled; Dask: pickled once per
worker), so that a task is only a list of points:
model indices, frequencies [rad/s], starting scalings of the upper bound, the subset's channels.
Every worker uses one BLAS thread (:mod:`oos_drake.blas`): the parallelism is one process per
core over batches of small matrices.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from oos_drake.processes import make_executor, start_method
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import delta_channel_response
from oos_drake.robust.sweep import CONVERGED_TEMPERATURES

_ARRAYS: dict = {}


def _install(arrays, queue=None) -> None:
    """Worker initializer: keep the model array (and a progress queue), one BLAS thread."""
    from oos_drake.blas import limit_blas_threads

    limit_blas_threads(1)
    _ARRAYS["models"] = arrays
    _ARRAYS["queue"] = queue


def responses(models, omega, zrows, wcols) -> np.ndarray:
    """``M11(j omega_i)`` of model ``models[i]`` restricted to a subset: ``(n, len(zrows), ...)``.

    One eigen-decomposition per distinct model (arrays installed by :func:`_install`).
    """
    A, Bw, Cz, Dzw = _ARRAYS["models"]
    models = np.asarray(models, dtype=int)
    omega = np.asarray(omega, dtype=float)
    out = np.empty((models.size, len(zrows), len(wcols)), dtype=complex)
    for m in np.unique(models):
        sel = np.flatnonzero(models == m)
        M = delta_channel_response(A[m], Bw[m], Cz[m], Dzw[m], omega[sel])
        out[sel] = M[:, zrows][:, :, wcols]
    return out


@dataclass(frozen=True)
class PointTask:
    """Bounds to compute at points of one subset.

    Attributes
    ----------
    models : numpy.ndarray
        ``(n,)`` model index of each point.
    omega : numpy.ndarray
        ``(n,)`` frequency of each point [rad/s].
    x0 : numpy.ndarray or None
        ``(n, p)`` starting scalings of the upper bound (``params`` of a neighbour), or None
        (Osborne balancing).
    zrows, wcols : numpy.ndarray
        Delta channels of the subset.
    blk : numpy.ndarray
        BLK rows of the subset.
    iterations : int
        BFGS iterations of the upper bound (0: no upper bound).
    temperatures : tuple of float
        Smoothing stages of the upper bound.
    lower_restarts, lower_iterations : int
        Power-iteration lower bound (``lower_iterations = 0``: none).
    """

    models: np.ndarray
    omega: np.ndarray
    x0: np.ndarray | None
    zrows: np.ndarray
    wcols: np.ndarray
    blk: np.ndarray
    iterations: int
    temperatures: tuple = CONVERGED_TEMPERATURES
    lower_restarts: int = 0
    lower_iterations: int = 0


@dataclass(frozen=True)
class PointBounds:
    """Result of a :class:`PointTask`.

    Attributes
    ----------
    upper : numpy.ndarray
        ``(n,)`` upper bounds (NaN where not computed).
    params : numpy.ndarray or None
        ``(n, p)`` scalings at the upper bounds (warm starts for neighbours).
    lower : numpy.ndarray
        ``(n,)`` certified lower bounds (0 where not computed).
    best : int
        Index of the largest lower bound (-1 if none).
    best_delta : numpy.ndarray or None
        Its perturbation (mussv layout of the subset), ``||delta|| = 1 / lower[best]``.
    """

    upper: np.ndarray
    params: np.ndarray | None
    lower: np.ndarray
    best: int
    best_delta: np.ndarray | None


def point_bounds(task: PointTask) -> PointBounds:
    """Upper (warm started) and lower bounds at the points of ``task``."""
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    structure = parse_blk(task.blk)
    n = task.models.size
    M = responses(task.models, task.omega, task.zrows, task.wcols)
    upper, params, start = np.full(n, np.nan), None, None
    if task.iterations > 0:
        res = mu_upper_bound(
            M,
            structure,
            max_iter=task.iterations,
            temperatures=task.temperatures,
            x0=task.x0,
        )
        upper, params, start = res.upper, res.params, res.worst_input
    lower, best, best_delta = np.zeros(n), -1, None
    if task.lower_iterations > 0:
        lo = mu_lower_bound(
            M,
            structure,
            start_inputs=start,
            restarts=task.lower_restarts,
            iters=task.lower_iterations,
        )
        lower = lo.lower if task.iterations <= 0 else np.minimum(lo.lower, upper)
        if np.any(lower > 0):
            best = int(np.argmax(lower))
            best_delta = lo.delta[best]
    return PointBounds(upper, params, lower, best, best_delta)


class ModelPool:
    """Workers holding one model array; evaluates :class:`PointTask` lists.

    Use as a context manager. The workers come from :func:`oos_drake.processes.make_executor`:
    ``n_jobs = 1`` on the process pool evaluates in this process.

    Parameters
    ----------
    arrays : tuple of numpy.ndarray
        ``(A, Bw, Cz, Dzw)`` of the model array, each ``(N, ...)``.
    n_jobs : int
        Workers.
    scheduler : str, optional
        ``--scheduler`` (``None``: the local process pool; ``"dask"``: a local Dask cluster;
        an address: that Dask scheduler).

    Attributes
    ----------
    executor : SerialExecutor, PoolExecutor or DaskExecutor
        Where the tasks run (set inside the ``with`` block).
    queue : multiprocessing.Queue or None
        Progress ticks of the process pool's workers (None in this process and on Dask).
    """

    def __init__(self, arrays, n_jobs: int = 2, scheduler: str | None = None):
        if n_jobs < 1:
            raise ValueError(f"ModelPool: n_jobs must be >= 1, got {n_jobs}")
        self.arrays = arrays
        self.n_jobs = n_jobs
        self.scheduler = scheduler
        self.executor = None
        self.queue = None

    @property
    def serial(self) -> bool:
        """True when the tasks run in this process."""
        return self.executor is None or self.executor.kind == "serial"

    def __enter__(self):
        if self.n_jobs > 1 and self.scheduler in (None, "", "processes"):
            import multiprocessing as mp

            # progress ticks: a queue inherited by the forked workers (not for Dask's workers)
            self.queue = mp.get_context(start_method()).Queue()
        self._previous = (_ARRAYS.get("models"), _ARRAYS.get("queue"))
        self.executor = make_executor(
            self.n_jobs, self.scheduler, initializer=_install, initargs=(self.arrays, self.queue)
        )
        return self

    def __exit__(self, *exc):
        if self.executor is not None:
            self.executor.shutdown()
            if self.executor.kind == "serial":
                _ARRAYS["models"], _ARRAYS["queue"] = self._previous
            self.executor = None
        return False

    def map(self, fn, tasks):
        """``[fn(t) for t in tasks]`` in the workers (order kept)."""
        return self.executor.map(fn, tasks)

    def bounds(self, task: PointTask, *, min_chunk: int = 16) -> PointBounds:
        """:func:`point_bounds` of ``task``, its points split over the workers."""
        n = task.models.size
        if n == 0:
            return PointBounds(np.zeros(0), None, np.zeros(0), -1, None)
        k = 1 if self.serial else max(1, min(self.n_jobs, n // min_chunk))
        if k == 1:
            return self.map(point_bounds, [task])[0]
        # split by model (one eigen-decomposition per model and chunk), balanced in points
        order = np.argsort(task.models, kind="stable")
        parts = np.array_split(order, k)
        x0 = task.x0
        tasks = [
            replace(
                task, models=task.models[p], omega=task.omega[p], x0=None if x0 is None else x0[p]
            )
            for p in parts
        ]
        results = self.map(point_bounds, tasks)
        upper = np.full(n, np.nan)
        lower = np.zeros(n)
        params = None
        best, best_delta, best_value = -1, None, 0.0
        for p, r in zip(parts, results, strict=True):
            upper[p] = r.upper
            lower[p] = r.lower
            if r.params is not None:
                if params is None:
                    params = np.zeros((n, r.params.shape[1]))
                params[p] = r.params
            if r.best >= 0 and r.lower[r.best] > best_value:
                best, best_delta, best_value = int(p[r.best]), r.best_delta, r.lower[r.best]
        return PointBounds(upper, params, lower, best, best_delta)
