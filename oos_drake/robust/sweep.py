"""mu bounds over model arrays, frequencies and uncertainty subsets (the paper's Fig. muanalysis).

:func:`robust_sweep` evaluates ``mu(M11(j omega))`` for every model of an LFR model array (e.g.
330 configurations along the mission), every frequency of a grid and every named subset of the
uncertain blocks (blocks outside a subset stay nominal), refines around each model's peak, and
returns a tidy ``pandas.DataFrame``. Models are spread over worker processes.

What a sweep needs is each model's peak with a tight certified bracket. The default ``"peak"``
mode gets it by branch and prune over frequency: cheap valid bounds everywhere (balancing plus
two descent steps for the upper bound, one power-iteration start for the lower one), full
bounds only where the cheap upper bound exceeds the best lower bound of the model (about 2 %
of a 500-point grid on the paper-sized benchmark), so the peak is bracketed as in the
``"full"`` mode for a fraction of the cost. The ``tightened`` column says where.
"""

from __future__ import annotations

import numpy as np

from oos_drake.processes import make_executor
from oos_drake.robust.lfr_analysis import (
    block_map,
    delta_channel_response,
    frequency_grid,
    model_matrices,
    subset_parts,
)
from oos_drake.robust.tables import sweep_table


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


def _pruned_sweep(
    M,
    blk,
    *,
    cheap_iterations=2,
    first_round=3,
    round_size=16,
    upper_iterations=None,
    upper_tol=None,
    lower_restarts=4,
    lower_iterations=60,
):
    """Peak mode: cheap bounds everywhere, full bounds only where the peak may be.

    1. Every frequency gets a cheap valid upper bound (Osborne balancing and ``cheap_iterations``
       L-BFGS iterations) and a cheap certified lower bound (one power-iteration start from the
       upper bound's worst direction).
    2. Per model, ``L*`` is the best lower bound found so far. A frequency whose upper bound is
       ``<= L*`` cannot hold the model's peak (``mu <= upper <= L* <= peak``): it is left alone.
       The others are tightened (the upper bound of :func:`~oos_drake.robust.mussv`
       warm-started from the cheap scalings, its lower bound with restarts), highest first:
       ``first_round`` per model, then ``round_size`` per model, doubling every round,
       updating ``L*`` between rounds, until no untightened frequency has an upper bound above
       ``L*``.

    The peak of each model is therefore bracketed by full-accuracy bounds (exactly as in the
    full mode); elsewhere the upper bound is valid but up to a few percent looser.

    Returns
    -------
    tuple of numpy.ndarray
        ``(upper, lower, tightened)``, each ``(nm, F)``.
    """
    from oos_drake.robust.blocks import parse_blk
    from oos_drake.robust.mu import (
        UPPER_ITERATIONS,
        UPPER_PATIENCE,
        UPPER_TEMPERATURES,
        UPPER_TOL,
        _lower_bound,
    )
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    s = parse_blk(blk)
    rng = np.random.default_rng(0)
    nm, F = M.shape[:2]
    flat = M.reshape((nm * F,) + M.shape[2:])
    cheap = mu_upper_bound(flat, s, max_iter=cheap_iterations, temperatures=(300.0,))
    lo = mu_lower_bound(
        flat, s, start_inputs=cheap.worst_input, restarts=0, iters=30, polish_starts=1
    ).lower
    up = np.maximum(cheap.upper, lo)
    params = cheap.params
    tight = np.zeros(nm * F, dtype=bool)
    model = np.repeat(np.arange(nm), F)
    per_round = first_round
    while True:
        best = np.zeros(nm)
        np.maximum.at(best, model, lo)
        cand = np.flatnonzero(~tight & (up > best[model]))
        if cand.size == 0:
            break
        # highest ``per_round`` candidates of each model
        order = cand[np.lexsort((-up[cand], model[cand]))]
        first = np.searchsorted(model[order], model[order], side="left")
        rank = np.arange(order.size) - first
        sel = order[rank < per_round]
        full_up = mu_upper_bound(
            flat[sel],
            s,
            max_iter=UPPER_ITERATIONS if upper_iterations is None else upper_iterations,
            tol=UPPER_TOL if upper_tol is None else upper_tol,
            temperatures=UPPER_TEMPERATURES,
            patience=UPPER_PATIENCE,
            x0=params[sel],
        )
        full_lo = _lower_bound(
            flat[sel],
            s,
            full_up,
            restarts=lower_restarts,
            iters=lower_iterations,
            rng=rng,
            restart_gap=1.02,
        ).lower
        lo[sel] = np.maximum(lo[sel], full_lo)
        up[sel] = np.maximum(np.minimum(up[sel], full_up.upper), lo[sel])
        tight[sel] = True
        # few rounds even where nothing prunes (e.g. mu = 0 of a real-only structure)
        per_round = round_size if per_round == first_round else 2 * per_round
    return up.reshape(nm, F), lo.reshape(nm, F), tight.reshape(nm, F)


def _sweep_models(task):
    """Worker: all subsets and frequencies for a chunk of models (plain arrays in, arrays out).

    All models and frequencies of the chunk go through ``mussv`` as one batch per subset, so the
    Python overhead of the iterations is shared by thousands of matrices.
    """
    from oos_drake.robust.mu import mussv
    from oos_drake.robust.robstab import _refine

    (
        A,
        Bw,
        Cz,
        Dzw,
        first,
        omega,
        subsets,
        refine_points,
        polish,
        warm_start,
        mode,
        mu_options,
        slack,
    ) = task
    nm, F = A.shape[0], omega.size
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)  # (nm, F, nz, nw)
    rows = []
    for name, (zrows, wcols, blk) in subsets.items():
        Msub = M[:, :, zrows][:, :, :, wcols]
        tight = np.ones((nm, F), dtype=bool)
        if mode == "peak":
            up, lo, tight = _pruned_sweep(Msub, blk)
        elif warm_start:
            up, lo = _warm_sweep(Msub, blk)
        else:
            res = mussv(Msub, blk, **mu_options)
            up = np.asarray(res.upper).reshape(nm, F).copy()
            lo = np.asarray(res.lower).reshape(nm, F)
        if polish > 0:
            up = _polish_model_peaks(Msub, blk, up, lo, polish)
        axis = [(np.nan, 0)] * nm
        if slack is not None:
            axis = [
                _axis_peak(
                    A[j],
                    Bw[j][:, wcols],
                    Cz[j][zrows],
                    Dzw[j][np.ix_(zrows, wcols)],
                    blk,
                    omega,
                    up[j],
                    lo[j],
                    slack,
                    first + j,
                )
                for j in range(nm)
            ]
        for j in range(nm):
            rows.append(
                (first + j, omega, lo[j], up[j], name, np.zeros(F, dtype=bool), tight[j], axis[j])
            )
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
                        np.ones(e.size, dtype=bool),
                        axis[j],
                    )
                )
                k += e.size
    return rows


def _axis_peak(A, Bw, Cz, Dzw, blk, omega, up, lo, slack, model):
    """``(guaranteed peak of mu over [0, inf), points solved)`` of one model and subset."""
    from oos_drake.robust.mu_intervals import Realization
    from oos_drake.robust.robstab import _guarantee

    try:
        cert = _guarantee(Realization(A, Bw, Cz, Dzw), blk, omega, up, lo, slack)
    except ValueError as err:
        raise ValueError(f"robust_sweep: model {model}: {err}") from None
    return float(cert.upper), int(cert.omega.size)


def check_sweep_input(sys, omega, times, *, caller: str, zero: bool = True):
    """The checked inputs of a mu sweep: ``(omega, (A, Bw, Cz, Dzw), times)``.

    ``omega`` [rad/s] comes back sorted without duplicates (None: :func:`frequency_grid` of all
    models' poles, 20 points per decade; 0 allowed only with ``zero``), ``times`` [s] as one value
    per model (None: NaN). Errors (``ValueError``) start with ``caller``.
    """
    arrays = model_matrices(sys)
    n_models = arrays[0].shape[0]
    if omega is None:
        omega = frequency_grid(arrays[0], points_per_decade=20)
    omega = np.unique(np.asarray(omega, dtype=float))
    bad = np.any(omega < 0) if zero else np.any(omega <= 0)
    if omega.size == 0 or bad or not np.all(np.isfinite(omega)):
        bound = ">= 0" if zero else "> 0"
        raise ValueError(f"{caller}: omega must hold finite frequencies {bound} [rad/s]")
    times = np.full(n_models, np.nan) if times is None else np.asarray(times, dtype=float)
    if times.shape != (n_models,):
        raise ValueError(f"{caller}: times has shape {times.shape}, expected ({n_models},)")
    return omega, arrays, times


def robust_sweep(
    sys,
    omega=None,
    *,
    subsets=None,
    times=None,
    n_jobs: int = 1,
    scheduler: str | None = None,
    refine_points: int = 6,
    polish: int = 3,
    warm_start: bool = True,
    mode: str = "peak",
    chunk_size: int | None = None,
    mu_options=None,
    guaranteed: bool = True,
    slack: float | None = None,
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
        Mission time [s] of each model (the ``time [s]`` column); default NaN.
    n_jobs : int
        Worker processes (1: in this process).
    scheduler : str, optional
        Where the workers run (``--scheduler``, :func:`oos_drake.processes.make_executor`):
        None for the local process pool, ``"dask"`` for a local Dask cluster, or an address.
    refine_points : int
        Extra frequencies around each of the two highest peaks of each model and subset (0: off).
    polish : int
        Frequencies per model and subset (the highest) whose upper bound gets a long run
        (300 iterations) after the grid pass: this settles the slow cases (e.g. a real block
        whose ``M`` is nearly real, where the optimal ``G`` is large).
    warm_start : bool
        Walk up the frequency grid reusing the scalings of the previous frequency (20
        iterations per frequency instead of 40-80; the grid must be fine enough for the
        scalings to change little between neighbours). False: independent ``mussv`` calls.
        Only used with ``mode="full"``.
    mode : {"peak", "full"}
        ``"peak"`` (default): a cheap valid upper bound and a cheap certified lower bound at every
        frequency, full-accuracy bounds only at the frequencies whose cheap upper bound exceeds the
        model's best lower bound (branch and prune over frequency: exact for each model's peak,
        honest elsewhere; the ``tightened`` column says which frequencies got full bounds).
        ``"full"``: full-accuracy bounds at every frequency (the whole curve), slower.
    chunk_size : int, optional
        Models per task (default: at most 40, with a number of tasks that is a multiple of
        ``n_jobs``, so that no worker idles at the end).
    mu_options : dict, optional
        Options of :func:`~oos_drake.robust.mussv` for the refinement points and, with
        ``mode="full", warm_start=False``, for the grid; default: mussv's defaults (upper bound
        within ~0.25 % of a fully converged one). With ``mode="full", warm_start=True`` the grid
        upper bound is 1-4 % above a converged one away from the polished peaks; every upper
        bound is valid.
    guaranteed : bool
        Also prove, for each model and subset, a bound of the peak of mu over the whole
        frequency axis (:func:`~oos_drake.robust.mu_intervals.cover_axis`, started from the
        peaks of the grid): columns ``mu upper guaranteed [-]`` (the same value on every row of
        the model and subset; ``inf`` if the cover did not close) and ``guarantee_points``
        (frequencies solved for the proof). The per-frequency columns stay pointwise bounds.
    slack : float, optional
        Relative slack of the guaranteed bound (default
        :data:`~oos_drake.robust.mu_intervals.SLACK`).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`~oos_drake.robust.tables.SWEEP_COLUMNS` (``model``: index in the array;
        ``refined``: True for peak-refinement points; ``tightened``: True where the bounds have
        full accuracy, see ``mode``), plus :data:`~oos_drake.robust.tables.GUARANTEE_COLUMNS`
        with ``guaranteed=True``.

    Raises
    ------
    ValueError
        For unknown block names, a ``times`` of the wrong length, or bad frequencies; with
        ``guaranteed=True``, for a model with a pole within round-off of the imaginary axis.
    """
    from oos_drake.lfr import as_lfr

    sys = as_lfr(sys)
    omega, (A, Bw, Cz, Dzw), times = check_sweep_input(sys, omega, times, caller="robust_sweep")
    n_models = A.shape[0]
    parts = subset_parts(sys, dict(subsets) if subsets else {"total": list(block_map(sys).names)})
    mu_options = dict(mu_options or {})
    if mode not in ("peak", "full"):
        raise ValueError(f"robust_sweep: mode must be 'peak' or 'full', got {mode!r}")
    n_jobs = max(1, int(n_jobs))
    if guaranteed:
        from oos_drake.robust.mu_intervals import SLACK

        slack = SLACK if slack is None else float(slack)
    else:
        slack = None
    if chunk_size is None:
        # big batches share the Python overhead of the iterations; 40 models x 500 frequencies
        # of 26 x 26 matrices are ~200 MB per copy, which bounds the memory of a worker. The
        # number of tasks is a multiple of n_jobs (no idle worker at the end).
        rounds = int(np.ceil(n_models / (n_jobs * 40)))
        chunk_size = max(1, int(np.ceil(n_models / (n_jobs * rounds))))
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
            mode,
            mu_options,
            slack,
        )
        for i in range(0, n_models, chunk_size)
    ]
    with make_executor(n_jobs, scheduler) as executor:
        results = list(executor.map(_sweep_models, tasks))
    rows = [row for chunk in results for row in chunk]
    model, freqs, lower, upper, subset, refined, tightened, axis = zip(*rows, strict=True)
    sizes = [w.size for w in freqs]

    def column(values):  # one value or one array per row of points -> one flat column
        return np.concatenate(
            [np.broadcast_to(v, (n,)) for v, n in zip(values, sizes, strict=True)]
        )

    guaranteed = slack is not None
    return sweep_table(
        subset=column(subset),
        model=column(model),
        time=column(times[list(model)]),
        omega=column(freqs),
        upper=column(upper),
        lower=column(lower),
        refined=column(refined),
        tightened=column(tightened),
        guaranteed=column([a[0] for a in axis]) if guaranteed else None,
        guarantee_points=column([a[1] for a in axis]) if guaranteed else None,
    )
