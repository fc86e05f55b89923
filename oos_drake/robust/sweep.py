"""mu bounds over model arrays, frequencies and uncertainty subsets (the paper's Fig. muanalysis).

:func:`robust_sweep` evaluates ``mu(M11(j omega))`` for every model of an LFR model array (e.g.
330 configurations along the mission), every frequency of a grid and every named subset of the
uncertain blocks (blocks outside a subset stay nominal), refines around each model's peak, and
returns a tidy ``pandas.DataFrame``. Models are spread over worker processes.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np

from oos_drake.robust.lfr_analysis import block_map, delta_channel_response, frequency_grid

#: Columns of the table returned by :func:`robust_sweep`.
COLUMNS = ["model", "time", "frequency", "mu_lower", "mu_upper", "subset", "refined"]


def _polish_model_peaks(M, blk, up, lo, count):
    """Long upper-bound runs at each model's ``count`` highest frequencies (min of two bounds)."""
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_upper import mu_upper_bound

    nm, F = up.shape
    top = np.argsort(up, axis=1)[:, ::-1][:, : min(count, F)]
    rows = np.repeat(np.arange(nm), top.shape[1])
    cols = top.ravel()
    better = mu_upper_bound(M[rows, cols], parse_blk(blk), max_iter=300).upper
    up[rows, cols] = np.maximum(np.minimum(up[rows, cols], better), lo[rows, cols])
    return up


def _warm_sweep(M, blk, *, warm_iterations=20, lower_restarts=2, lower_iterations=40):
    """Bounds for ``M`` ``(nm, F, c, r)`` walking up the frequency axis with warm starts.

    The first frequency starts from Osborne balancing (80 iterations); each next one from the
    scalings of the previous frequency or from balancing, whichever is better, for
    ``warm_iterations`` iterations at a single high smoothing temperature. The lower bound runs
    once on the whole batch, started from the upper bound's worst directions.
    """
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    s = parse_blk(blk)
    nm, F = M.shape[:2]
    up = np.empty((nm, F))
    worst = np.empty((nm, F, s.n_rows), dtype=complex)
    x = None
    for f in range(F):
        if x is None:
            res = mu_upper_bound(M[:, f], s, max_iter=80)
        else:
            res = mu_upper_bound(M[:, f], s, max_iter=warm_iterations, temperatures=(1000.0,), x0=x)
        x = res.params
        up[:, f] = res.upper
        worst[:, f] = res.worst_input
    flat = M.reshape((-1,) + M.shape[2:])
    starts = worst.reshape(-1, s.n_rows)
    lo = np.concatenate(
        [
            mu_lower_bound(
                flat[i : i + 2048],
                s,
                start_inputs=starts[i : i + 2048],
                restarts=lower_restarts,
                iters=lower_iterations,
            ).lower
            for i in range(0, flat.shape[0], 2048)
        ]
    ).reshape(nm, F)
    return np.maximum(up, lo), lo


def _sweep_models(task):
    """Worker: all subsets and frequencies for a chunk of models (plain arrays in, arrays out).

    All models and frequencies of the chunk go through ``mussv`` as one batch per subset, so the
    Python overhead of the iterations is shared by thousands of matrices.
    """
    from oos_drake.robust.mu import mussv
    from oos_drake.robust.robstab import _refine

    A, Bw, Cz, Dzw, first, omega, subsets, refine_points, polish, warm_start, mu_options = task
    nm, F = A.shape[0], omega.size
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)  # (nm, F, nz, nw)
    rows = []
    for name, (zrows, wcols, blk) in subsets.items():
        Msub = M[:, :, zrows][:, :, :, wcols]
        if warm_start:
            up, lo = _warm_sweep(Msub, blk)
        else:
            res = mussv(Msub, blk, **mu_options)
            up = np.asarray(res.upper).reshape(nm, F).copy()
            lo = np.asarray(res.lower).reshape(nm, F)
        if polish > 0:
            up = _polish_model_peaks(Msub, blk, up, lo, polish)
        for j in range(nm):
            rows.append((first + j, omega, lo[j], up[j], name, np.zeros(F, dtype=bool)))
        if refine_points <= 0 or F < 3:
            continue
        extra = [
            np.setdiff1d(_refine(omega, up[j], count=2, points=refine_points), omega)
            for j in range(nm)
        ]
        if not any(e.size for e in extra):
            continue
        Ms = [
            delta_channel_response(A[j], Bw[j], Cz[j], Dzw[j], e)[:, zrows][:, :, wcols]
            for j, e in enumerate(extra)
            if e.size
        ]
        rn = mussv(np.concatenate(Ms), blk, **mu_options)
        up_n, lo_n = np.atleast_1d(rn.upper), np.atleast_1d(rn.lower)
        k = 0
        for j, e in enumerate(extra):
            if e.size:
                rows.append(
                    (
                        first + j,
                        e,
                        lo_n[k : k + e.size],
                        up_n[k : k + e.size],
                        name,
                        np.ones(e.size, dtype=bool),
                    )
                )
                k += e.size
    return rows


def robust_sweep(
    sys,
    omega=None,
    *,
    subsets=None,
    times=None,
    n_jobs: int = 1,
    refine_points: int = 6,
    polish: int = 3,
    warm_start: bool = True,
    chunk_size: int | None = None,
    mu_options=None,
):
    """mu bounds for every model, frequency and uncertainty subset.

    Parameters
    ----------
    sys : LFR
        Uncertain closed loop, possibly a model array with batch shape ``(N,)`` (or ``()``).
    omega : array_like, optional
        Frequencies [rad/s]; default: :func:`frequency_grid` of all models' poles.
    subsets : dict str -> sequence of str, optional
        Named subsets of block names (e.g. ``{"modal": [...], "total": [...]}``); default
        ``{"total": all blocks}``.
    times : array_like, optional
        Mission time [s] of each model (a ``time`` column); default NaN.
    n_jobs : int
        Worker processes (1: in this process).
    refine_points : int
        Extra frequencies around each of the two highest peaks of each model and subset (0: off).
    polish : int
        Frequencies per model and subset (the highest) whose upper bound gets a long run
        (300 iterations) after the grid pass: accurate peaks, grid-quality elsewhere.
    warm_start : bool
        Walk up the frequency grid reusing the scalings of the previous frequency (20
        iterations per frequency instead of 40-80; the grid must be fine enough for the
        scalings to change little between neighbours). False: independent ``mussv`` calls.
    chunk_size : int, optional
        Models per task (default: ``n_models / n_jobs``, at most 40).
    mu_options : dict, optional
        Options of :func:`~oos_drake.robust.mussv` for the refinement points and, with
        ``warm_start=False``, for the grid; default ``upper_iterations=40, lower_restarts=2,
        lower_iterations=40``. Away from the polished peaks the upper bound is then about 1 %
        (warm start: 1-4 %) above a fully converged one; it is a valid bound everywhere.

    Returns
    -------
    pandas.DataFrame
        Columns ``model`` (index in the array), ``time`` [s], ``frequency`` [Hz], ``mu_lower``,
        ``mu_upper``, ``subset``, ``refined`` (True for peak-refinement points).

    Raises
    ------
    ValueError
        For unknown block names, a ``times`` of the wrong length, or bad frequencies.
    """
    import pandas as pd

    from oos_drake.lfr import as_lfr

    sys = as_lfr(sys)
    batch = sys.batch_shape
    if len(batch) > 1:
        raise ValueError(f"robust_sweep: expected a 1-D model array, got batch shape {batch}")
    n_models = batch[0] if batch else 1
    bmap = block_map(sys)
    subsets = dict(subsets) if subsets else {"total": list(bmap.names)}
    parts = {}
    for name, members in subsets.items():
        sub, zrows, wcols = bmap.subset(list(members))
        parts[name] = (zrows, wcols, sub.blk)
    A = np.asarray(sys.A).reshape((n_models,) + sys.A.shape[-2:])
    Bw = np.asarray(sys.Bw).reshape((n_models,) + sys.Bw.shape[-2:])
    Cz = np.asarray(sys.Cz).reshape((n_models,) + sys.Cz.shape[-2:])
    Dzw = np.asarray(sys.Dzw).reshape((n_models,) + sys.Dzw.shape[-2:])
    if omega is None:
        omega = frequency_grid(A, points_per_decade=20)
    omega = np.unique(np.asarray(omega, dtype=float))
    if omega.size == 0 or np.any(omega < 0) or not np.all(np.isfinite(omega)):
        raise ValueError("robust_sweep: omega must hold finite frequencies >= 0 [rad/s]")
    if times is None:
        times = np.full(n_models, np.nan)
    times = np.asarray(times, dtype=float)
    if times.shape != (n_models,):
        raise ValueError(f"robust_sweep: times has shape {times.shape}, expected ({n_models},)")
    mu_options = {
        "upper_iterations": 40,
        "lower_restarts": 2,
        "lower_iterations": 40,
        **dict(mu_options or {}),
    }
    n_jobs = max(1, int(n_jobs))
    if chunk_size is None:
        # big batches share the Python overhead of the iterations; 40 models x 500 frequencies
        # of 26 x 26 matrices are ~200 MB per copy, which bounds the memory of a worker
        chunk_size = max(1, min(int(np.ceil(n_models / n_jobs)), 40))
    tasks = [
        (
            A[i : i + chunk_size],
            Bw[i : i + chunk_size],
            Cz[i : i + chunk_size],
            Dzw[i : i + chunk_size],
            i,
            omega,
            parts,
            refine_points,
            int(polish),
            bool(warm_start),
            mu_options,
        )
        for i in range(0, n_models, chunk_size)
    ]
    if n_jobs == 1:
        results = [_sweep_models(t) for t in tasks]
    else:
        import multiprocessing as mp

        from oos_drake.blas import limit_blas_threads

        # fork where available (no __main__ guard needed in user scripts); one BLAS thread per
        # worker: batched small-matrix kernels only lose from more
        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        with ProcessPoolExecutor(
            n_jobs, mp_context=mp.get_context(method), initializer=limit_blas_threads, initargs=(1,)
        ) as pool:
            results = list(pool.map(_sweep_models, tasks))
    frames = []
    for rows in results:
        for model, w, lo, up, name, refined in rows:
            frames.append(
                pd.DataFrame(
                    {
                        "model": np.full(w.size, model, dtype=int),
                        "time": np.full(w.size, times[model]),
                        "frequency": w / (2 * np.pi),
                        "mu_lower": lo,
                        "mu_upper": up,
                        "subset": name,
                        "refined": refined,
                    }
                )
            )
    table = pd.concat(frames, ignore_index=True)[COLUMNS]
    table["subset"] = table["subset"].astype("category")
    return table.sort_values(["subset", "model", "frequency"], ignore_index=True)
