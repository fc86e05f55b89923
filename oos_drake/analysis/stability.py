r"""Robust stability over the mission: mu bounds over configurations x frequencies x subsets.

For the uncertain closed loop ``F_u(M, Delta)`` of every configuration, the matrix seen by the
uncertainty ``M11(j omega)`` is evaluated on a frequency grid (modal form, one eigen-decomposition
per model) and, for each uncertainty subset (blocks outside it stay nominal), the mixed-mu
bounds are computed:

* grid: a common logarithmic grid plus, per model, points on its lightly damped closed-loop
  poles (where the real modal uncertainty makes mu peak);
* upper bound: the D-G bound of :func:`oos_drake.robust.mu_upper.mu_upper_bound`, all models
  and frequencies of a chunk in one batch (every value is a valid bound whatever the iterations);
* lower bound: the power iteration of :func:`oos_drake.robust.mu_lower.mu_lower_bound` started
  from the upper bound's worst direction (certified: ``det(I - M delta) = 0``);
* peak refinement: around the two highest local maxima of every model and subset, extra
  frequencies with more BFGS iterations.

The peaks are then certified (:func:`certify_peak`): on the critical model the local grid is
refined again and the real-parameter lower bound follows the destabilizing eigenvalue across
frequency (``Im lambda(omega) = 0``, :func:`oos_drake.robust.robstab.mu_sweep`), so that the
lower bound meets the upper one (a worst case, not only a bound).

Chunks of models run in worker processes (fork; one BLAS thread each) with a tqdm bar.
"""

from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np
import pandas as pd

from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import block_map, delta_channel_response, worst_case_values

#: Smoothing stages of the converged upper bounds (one more than mussv's default).
CONVERGED_TEMPERATURES = (30.0, 300.0, 3000.0, 30000.0)

#: Columns of the sweep table (``tightened``: upper bound recomputed with many iterations).
SWEEP_COLUMNS = [
    "subset",
    "model",
    "time [s]",
    "frequency [Hz]",
    "mu_upper",
    "mu_lower",
    "refined",
    "tightened",
]


@dataclass(frozen=True)
class SweepOptions:
    """Accuracy and parallelism of :func:`mu_sweep`.

    Attributes
    ----------
    upper_iterations : int
        BFGS iterations of the D-G upper bound at the grid frequencies.
    lower_restarts, lower_iterations : int
        Random restarts and power-iteration steps of the grid lower bound.
    refine_points : int
        Extra frequencies between the neighbours of the highest peak of each model (0: off).
    refine_iterations : int
        BFGS iterations at the refinement frequencies.
    pole_points : int
        Extra grid points per lightly damped closed-loop pole of each model (0: common grid).
    chunk_size : int
        Models per worker task.
    n_jobs : int
        Worker processes (1: in this process).
    """

    upper_iterations: int = 30
    lower_restarts: int = 1
    lower_iterations: int = 20
    refine_points: int = 3
    refine_iterations: int = 100
    pole_points: int = 1
    chunk_size: int = 10
    n_jobs: int = 2

    def __post_init__(self):
        for name in ("upper_iterations", "lower_iterations", "chunk_size", "n_jobs"):
            if getattr(self, name) < 1:
                raise ValueError(f"SweepOptions.{name} must be >= 1, got {getattr(self, name)}")


def delta_matrices(sys):
    """``(A, Bw, Cz, Dzw)`` of an LFR model array as ``(N, ...)`` arrays."""
    n_models = sys.batch_shape[0] if sys.batch_shape else 1
    return tuple(
        np.asarray(x).reshape((n_models,) + np.shape(x)[-2:])
        for x in (sys.A, sys.Bw, sys.Cz, sys.Dzw)
    )


def subset_parts(sys, subsets: dict) -> dict:
    """Subset name -> ``(z rows, w columns, BLK)`` of the Delta channels of ``sys``."""
    bmap = block_map(sys)
    parts = {}
    for name, members in subsets.items():
        sub, zrows, wcols = bmap.subset(list(members))
        parts[name] = (zrows, wcols, sub.blk)
    return parts


def grid_bounds(M, blk, options: SweepOptions):
    """Upper and lower bounds of mu for a flat batch ``M`` ``(B, c, r)`` (cold, batched)."""
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    structure = parse_blk(blk)
    M = np.ascontiguousarray(M)
    up = mu_upper_bound(M, structure, max_iter=options.upper_iterations)
    lo = mu_lower_bound(
        M,
        structure,
        start_inputs=up.worst_input,
        restarts=options.lower_restarts,
        iters=options.lower_iterations,
    )
    return up.upper, np.minimum(lo.lower, up.upper)


def model_grid(A, omega, *, band=None, max_damping: float = 0.05, points: int = 1) -> np.ndarray:
    """``omega`` plus, per lightly damped closed-loop pole in ``band``, points on its peak.

    Parameters
    ----------
    A : numpy.ndarray
        Closed-loop state matrix of one model.
    omega : numpy.ndarray
        Common grid [rad/s].
    band : (float, float), optional
        Frequency band [rad/s] (default: the span of ``omega``).
    max_damping : float
        Poles with a damping ratio below this get extra points.
    points : int
        Points per pole, spread over ``+-zeta omega_n`` around ``omega_n``.
    """
    lo, hi = band if band is not None else (omega.min(), omega.max())
    p = np.linalg.eigvals(A)
    wn = np.abs(p)
    zeta = -p.real / np.maximum(wn, 1e-300)
    keep = (p.imag > 0) & (zeta < max_damping) & (wn >= lo) & (wn <= hi)
    offsets = np.linspace(-1.0, 1.0, points) if points > 1 else np.zeros(1)
    extra = [
        w0 * (1.0 + max(z0, 1e-3) * offsets) for w0, z0 in zip(wn[keep], zeta[keep], strict=True)
    ]
    return np.unique(np.concatenate([omega] + extra)) if extra else omega


def _peak_frequencies(omega, values, points):
    from oos_drake.robust.robstab import _refine

    return np.setdiff1d(_refine(omega, values, count=1, points=points), omega)


def _sweep_chunk(task):
    """Worker: every subset and frequency of a chunk of models (arrays in, tuples out)."""
    A, Bw, Cz, Dzw, first, omega, parts, opt = task
    nm = A.shape[0]
    grids = [
        model_grid(A[j], omega, points=opt.pole_points) if opt.pole_points else omega
        for j in range(nm)
    ]
    Ms = [delta_channel_response(A[j], Bw[j], Cz[j], Dzw[j], grids[j]) for j in range(nm)]
    out = []
    for name, (zrows, wcols, blk) in parts.items():
        flat = np.concatenate([M[:, zrows][:, :, wcols] for M in Ms])
        up, lo = grid_bounds(flat, blk, opt)
        k = 0
        ups = []
        for j in range(nm):
            F = grids[j].size
            out.append((name, first + j, grids[j], up[k : k + F], lo[k : k + F], False))
            ups.append(up[k : k + F])
            k += F
        if opt.refine_points <= 0:
            continue
        extra = [_peak_frequencies(grids[j], ups[j], opt.refine_points) for j in range(nm)]
        have = [j for j in range(nm) if extra[j].size]
        if not have:
            continue
        Mr = np.concatenate(
            [
                delta_channel_response(A[j], Bw[j], Cz[j], Dzw[j], extra[j])[:, zrows][:, :, wcols]
                for j in have
            ]
        )
        refine = SweepOptions(
            upper_iterations=opt.refine_iterations, lower_restarts=2, lower_iterations=40
        )
        ur, lr = grid_bounds(Mr, blk, refine)
        k = 0
        for j in have:
            e = extra[j]
            out.append((name, first + j, e, ur[k : k + e.size], lr[k : k + e.size], True))
            k += e.size
    return out


def _init_worker():
    from oos_drake.blas import limit_blas_threads

    limit_blas_threads(1)


def mu_sweep(
    sys,
    omega,
    subsets: dict,
    *,
    times=None,
    options: SweepOptions | None = None,
    progress: bool = True,
    description: str = "mu sweep",
) -> pd.DataFrame:
    """mu bounds for every model of ``sys``, frequency of ``omega`` and subset.

    Parameters
    ----------
    sys : LFR
        Uncertain closed loop, a model array ``(N,)`` (or one model).
    omega : array_like
        Frequency grid [rad/s] (> 0), refined per model around its peaks.
    subsets : dict
        Subset name -> block names.
    times : array_like, optional
        Mission time [s] (or any scheduling value) of each model, stored as ``time [s]``.
    options : SweepOptions, optional
    progress : bool
        Show a tqdm progress bar (chunks of models).
    description : str
        Label of the progress bar.

    Returns
    -------
    pandas.DataFrame
        Columns :data:`SWEEP_COLUMNS`: ``subset``, ``model`` (index), ``time [s]``,
        ``frequency [Hz]``, ``mu_upper``, ``mu_lower`` (certified), ``refined``.
    """
    from tqdm.auto import tqdm

    options = options or SweepOptions()
    omega = np.unique(np.asarray(omega, dtype=float))
    if omega.size == 0 or np.any(omega <= 0) or not np.all(np.isfinite(omega)):
        raise ValueError("mu_sweep: omega must hold finite frequencies > 0 [rad/s]")
    A, Bw, Cz, Dzw = delta_matrices(sys)
    n_models = A.shape[0]
    times = np.full(n_models, np.nan) if times is None else np.asarray(times, dtype=float)
    if times.shape != (n_models,):
        raise ValueError(f"mu_sweep: times has shape {times.shape}, expected ({n_models},)")
    parts = subset_parts(sys, subsets)
    cs = options.chunk_size
    tasks = [
        (A[i : i + cs], Bw[i : i + cs], Cz[i : i + cs], Dzw[i : i + cs], i, omega, parts, options)
        for i in range(0, n_models, cs)
    ]
    results = []
    bar = tqdm(total=n_models, desc=description, unit="model", disable=not progress)
    if options.n_jobs == 1 or len(tasks) == 1:
        _init_worker()
        for task in tasks:
            results.append(_sweep_chunk(task))
            bar.update(task[0].shape[0])
    else:
        import multiprocessing as mp

        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        with ProcessPoolExecutor(
            options.n_jobs, mp_context=mp.get_context(method), initializer=_init_worker
        ) as pool:
            futures = {pool.submit(_sweep_chunk, t): t[0].shape[0] for t in tasks}
            for fut in as_completed(futures):
                results.append(fut.result())
                bar.update(futures[fut])
    bar.close()
    frames = []
    for rows in results:
        for name, model, w, up, lo, refined in rows:
            frames.append(
                pd.DataFrame(
                    {
                        "subset": name,
                        "model": np.full(w.size, model, dtype=int),
                        "time [s]": np.full(w.size, times[model]),
                        "frequency [Hz]": w / (2 * np.pi),
                        "mu_upper": up,
                        "mu_lower": lo,
                        "refined": np.full(w.size, refined),
                        "tightened": np.zeros(w.size, dtype=bool),
                    }
                )
            )
    table = pd.concat(frames, ignore_index=True)[SWEEP_COLUMNS]
    return table.sort_values(["subset", "model", "frequency [Hz]"], ignore_index=True)


def _tighten_task(task):
    from oos_drake.robust.mu_upper import mu_upper_bound

    M, blk, iterations = task
    return mu_upper_bound(
        np.ascontiguousarray(M),
        parse_blk(blk),
        max_iter=iterations,
        temperatures=CONVERGED_TEMPERATURES,
    ).upper


def tighten(
    sys,
    sweep: pd.DataFrame,
    subsets: dict,
    *,
    iterations: int = 300,
    batch: int = 120,
    rounds: int = 4,
    n_jobs: int = 1,
    progress: bool = True,
) -> pd.DataFrame:
    """Recompute the highest upper bounds with many iterations until the peak is a tight one.

    Every grid value is a valid bound, but a cheap one can sit far above the converged D-G
    bound (spikes on lightly damped poles). Per subset, the ``batch`` highest not yet tightened
    points are recomputed with ``iterations`` BFGS iterations (the new value replaces the old one
    only where lower: both are valid bounds), until the maximum of the subset is a tightened
    point or ``rounds`` is reached.

    Returns
    -------
    pandas.DataFrame
        A copy of ``sweep`` with updated ``mu_upper`` and the ``tightened`` flags.
    """
    from tqdm.auto import tqdm

    table = sweep.copy()
    A, Bw, Cz, Dzw = delta_matrices(sys)
    parts = subset_parts(sys, subsets)
    pool = None
    if n_jobs > 1:
        import multiprocessing as mp

        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        pool = ProcessPoolExecutor(
            n_jobs, mp_context=mp.get_context(method), initializer=_init_worker
        )
    for name in tqdm(list(parts), desc="tighten peaks", disable=not progress):
        zrows, wcols, blk = parts[name]
        for _ in range(rounds):
            part = table[(table["subset"] == name) & ~table["tightened"]]
            top_all = table.loc[table["subset"] == name, "mu_upper"].idxmax()
            if bool(table.at[top_all, "tightened"]) or part.empty:
                break
            pick = part.nlargest(batch, "mu_upper")
            Ms = []
            for model, rows in pick.groupby("model", sort=False):
                w = 2 * np.pi * rows["frequency [Hz]"].to_numpy()
                M = delta_channel_response(A[model], Bw[model], Cz[model], Dzw[model], w)
                Ms.append((rows.index.to_numpy(), M[:, zrows][:, :, wcols]))
            index = np.concatenate([i for i, _ in Ms])
            M = np.concatenate([m for _, m in Ms])
            if pool is None:
                new = _tighten_task((M, blk, iterations))
            else:
                chunks = np.array_split(np.arange(M.shape[0]), n_jobs)
                new = np.concatenate(
                    list(
                        pool.map(_tighten_task, [(M[c], blk, iterations) for c in chunks if c.size])
                    )
                )
            old = table.loc[index, "mu_upper"].to_numpy()
            table.loc[index, "mu_upper"] = np.maximum(
                np.minimum(old, new), table.loc[index, "mu_lower"].to_numpy()
            )
            table.loc[index, "tightened"] = True
    if pool is not None:
        pool.shutdown()
    return table


@dataclass(frozen=True)
class PeakCertificate:
    """The certified peak of mu for one subset.

    Attributes
    ----------
    subset : str
    model : int
        Index of the critical configuration.
    time : float
        Its mission time [s] (or the scheduling value of the study).
    frequency : float
        Critical frequency [Hz] (of the lower bound's destabilizing perturbation).
    mu_upper, mu_lower : float
        Peak bounds over the analyzed frequencies [-].
    mu_upper_critical : float
        Upper bound AT the critical frequency, converged (1000+ BFGS iterations, four
        smoothing stages): the bound the lower one is compared with (``gap``).
    delta : numpy.ndarray
        Normalized destabilizing perturbation (mussv structure of the subset), ``||delta|| =
        1 / mu_lower``: ``det(I - M11(j 2 pi frequency) delta) = 0``.
    worst_case : dict
        Block name -> PHYSICAL destabilizing value (ureal: float; ultidyn: a stable
        ``control.StateSpace`` realizing the complex matrix at the critical frequency).
    worst_case_normalized : dict
        Block name -> normalized value (float for ureal, complex matrix for ultidyn).
    """

    subset: str
    model: int
    time: float
    frequency: float
    mu_upper: float
    mu_lower: float
    mu_upper_critical: float
    delta: np.ndarray
    worst_case: dict
    worst_case_normalized: dict

    @property
    def gap(self) -> float:
        """Relative gap of the bounds at the critical frequency ``(upper - lower) / upper`` [-]."""
        up = self.mu_upper_critical
        return (up - self.mu_lower) / up if up > 0 else 0.0

    @property
    def margin(self) -> float:
        """Stability margin ``1 / mu_upper`` (guaranteed) [-]: > 1 means robustly stable."""
        return 1.0 / self.mu_upper if self.mu_upper > 0 else float("inf")


def certify_peak(
    sys,
    subset: str,
    members,
    model: int,
    frequency_hz: float,
    *,
    time: float = float("nan"),
    span: float = 0.25,
    points: int = 41,
    upper_iterations: int = 300,
    search_band: float = 2.0,
) -> PeakCertificate:
    """Bounds of the mu peak of one model near ``frequency_hz``, with the worst perturbation.

    The upper bound is recomputed with ``upper_iterations`` BFGS iterations on a local grid;
    the lower bound is the best of the power iteration on that grid and of the direct search
    for a destabilizing perturbation
    (:func:`oos_drake.analysis.destabilizing.destabilizing_perturbation`),
    whose frequency may lie anywhere in ``frequency_hz * [1/search_band, search_band]``.

    Parameters
    ----------
    sys : LFR
        Closed-loop model array (or one model).
    subset : str
        Subset name (label).
    members : sequence of str
        Blocks of the subset.
    model : int
        Model index.
    frequency_hz : float
        Approximate peak frequency [Hz] (from the sweep).
    time : float
        Scheduling value of the model (label).
    span : float
        Relative half-width of the local grid around ``frequency_hz``.
    points : int
        Points of the local grid (log spaced).
    upper_iterations : int
        BFGS iterations of the local upper bounds.
    search_band : float
        Frequency band factor of the direct search.
    """
    from oos_drake.analysis.destabilizing import destabilizing_perturbation

    one = sys.model(model) if sys.batch_shape else sys
    A_full = np.asarray(one.A)
    if A_full.size and np.max(np.linalg.eigvals(A_full).real) > -1e-9:
        one = one.reduce()  # spurious near-zero modes that neither inputs nor Delta reach
    bmap = block_map(one)
    sub, zrows, wcols = bmap.subset(list(members))
    A = np.asarray(one.A)
    Bw, Cz = np.asarray(one.Bw)[:, wcols], np.asarray(one.Cz)[zrows, :]
    Dzw = np.asarray(one.Dzw)[np.ix_(zrows, wcols)]
    w0 = 2 * np.pi * frequency_hz
    omega = w0 * np.geomspace(1 - span, 1 + span, points)
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)
    opts = SweepOptions(upper_iterations=upper_iterations, lower_restarts=4, lower_iterations=60)
    structure = parse_blk(sub.blk)
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    up_res = mu_upper_bound(
        np.ascontiguousarray(M),
        structure,
        max_iter=upper_iterations,
        temperatures=CONVERGED_TEMPERATURES,
    )
    up = up_res.upper
    lo_res = mu_lower_bound(
        M,
        structure,
        start_inputs=up_res.worst_input,
        restarts=opts.lower_restarts,
        iters=opts.lower_iterations,
    )
    k = int(np.argmax(lo_res.lower))
    lower, w_crit, delta = float(lo_res.lower[k]), float(omega[k]), lo_res.delta[k]
    direct = destabilizing_perturbation(
        A, Bw, Cz, Dzw, sub.blk, [w0 / search_band, w0 * search_band]
    )
    if direct.mu_lower > lower:
        lower, w_crit, delta = direct.mu_lower, direct.omega, direct.delta
    # the converged upper bound at the critical frequency (the certificate's other side)
    Mc = delta_channel_response(A, Bw, Cz, Dzw, [w_crit])
    up_crit = float(
        mu_upper_bound(
            Mc, structure, max_iter=max(1000, upper_iterations), temperatures=CONVERGED_TEMPERATURES
        ).upper[0]
    )
    up_crit = max(up_crit, lower)
    up = np.append(up, up_crit)
    peak_up = float(max(up.max(), lower))
    normalized, worst = {}, {}
    if lower > 0:
        worst = worst_case_values(sub, structure, delta, w_crit)
        for name, kind, rows in zip(sub.names, sub.kinds, sub.blk_rows, strict=True):
            b = structure.blocks[rows[0]]
            block = delta[b.r_slice, b.c_slice]
            normalized[name] = float(block[0, 0].real) if kind == "ureal" else block.copy()
    return PeakCertificate(
        subset,
        int(model),
        float(time),
        float(w_crit / (2 * np.pi)),
        peak_up,
        lower,
        up_crit,
        delta,
        worst,
        normalized,
    )


def peaks_table(sweep: pd.DataFrame) -> pd.DataFrame:
    """Per subset: the grid peak of the upper bound (model, time, frequency) and of the lower."""
    rows = []
    for name, group in sweep.groupby("subset", sort=False, observed=True):
        iu = group["mu_upper"].idxmax()
        il = group["mu_lower"].idxmax()
        rows.append(
            {
                "subset": name,
                "model": int(group.at[iu, "model"]),
                "time [s]": float(group.at[iu, "time [s]"]),
                "frequency [Hz]": float(group.at[iu, "frequency [Hz]"]),
                "mu_upper": float(group.at[iu, "mu_upper"]),
                "mu_lower_grid": float(group.at[il, "mu_lower"]),
            }
        )
    return pd.DataFrame(rows)
