"""The package's one mu sweep: bounds over model arrays, frequencies and uncertainty subsets.

:func:`sweep_models` is the one loop behind :func:`~oos_drake.robust.robstab`,
:func:`robust_sweep`, :func:`mu_sweep`, ``oos robust`` and the analysis
(:mod:`oos_drake.analysis.stability`). For every subset of the uncertain blocks (blocks outside
it stay nominal) and every model of a chunk it runs, as :class:`SweepOptions` says: grid bounds
(one of four methods), refinement next to the peaks, a long polish of the highest upper bounds,
the search of real-axis crossings (real blocks) and the proof of the peak on the whole
frequency axis. Each model's points come back sorted by frequency (:class:`SweepPoints`);
:func:`mu_sweep` spreads chunks of models over worker processes and returns the one table
(:func:`~oos_drake.robust.tables.sweep_table`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from oos_drake.processes import make_executor
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import (
    block_map,
    delta_channel_response,
    frequency_grid,
    model_matrices,
    subset_parts,
)
from oos_drake.robust.memory import in_chunks, joined
from oos_drake.robust.tables import sweep_table

#: Smoothing stages of the converged upper bounds (one more than mussv's default).
CONVERGED_TEMPERATURES = (30.0, 300.0, 3000.0, 30000.0)

#: Grid methods of :class:`SweepOptions`.
GRID_METHODS = ("continued", "pruned", "warm", "cold")


@dataclass(frozen=True)
class SweepOptions:
    """The steps of :func:`sweep_models`, their accuracy and the parallelism.

    Attributes
    ----------
    grid : {"continued", "pruned", "warm", "cold"}
        How the grid bounds are computed. ``"continued"`` (the analysis): upper bounds of
        consecutive models started from the previous model's scalings (:func:`_continued_grid`),
        lower bounds at each model's highest upper bounds (0 elsewhere). ``"pruned"``: cheap
        valid bounds everywhere, full ones only where a model's peak may be
        (:func:`_pruned_grid`). ``"warm"``: all models walk up the frequency axis warm-started
        (:func:`_warm_grid`). ``"cold"``: :func:`~oos_drake.robust.mussv` everywhere.
    upper_iterations : int
        BFGS iterations of the D-G upper bound at the grid frequencies (``"continued"``: cold
        starts).
    lower_restarts, lower_iterations : int
        Random restarts and power-iteration steps of the grid lower bound (``"continued"``).
    lower_points : int
        ``"continued"``: grid lower bounds at this many highest upper bounds of every model.
    continuation_iterations : int
        ``"continued"``: BFGS iterations of every model but the first of a chunk, started
        from the previous model's scalings (0: every model from balancing with
        ``upper_iterations``).
    converge_passes, converge_iterations : int
        ``"continued"``: frequency-continuation passes and their BFGS iterations on the first
        model of a chunk.
    spike_ratio, despike_points : float, int
        ``"continued"``: the ``despike_points`` highest continued bounds above ``spike_ratio``
        times both frequency neighbours are recomputed from the neighbours' scalings.
    jump_ratio : float
        ``"continued"``: a model whose ``M11`` differs from its predecessor's by more than this
        (relative, at some frequency) is converged from scratch (a configuration switch).
    pole_points : int
        Extra grid points per lightly damped closed-loop pole of each model (0: common grid;
        ``"warm"`` needs the common grid).
    mu_options : dict, optional
        Options of :func:`~oos_drake.robust.mussv` (``"cold"`` grid, refinement with
        ``refine_iterations=None``, crossings).
    refine_points : int
        New frequencies per refined peak (0: no refinement).
    refine_peaks : int
        Highest local maxima refined per model and curve.
    refine_rounds : int
        Refinement rounds (each on the grid refined so far).
    refine_lower : bool
        Also refine around the peaks of the lower bound.
    refine_iterations : int or None
        BFGS iterations of the upper bound at the refinement points (lower bound: power
        iteration, 2 restarts of 40 steps); None: :func:`~oos_drake.robust.mussv` with
        ``mu_options``.
    polish_points, polish_rounds, polish_iterations : int
        Long upper-bound runs (``polish_iterations``) at the ``polish_points`` highest
        upper bounds of each model, for up to ``polish_rounds`` rounds (0 points: off).
    polish_temperatures : tuple of float, optional
        Smoothing stages of the polish (default: those of the upper-bound optimizer).
    crossings : bool
        Search the real-axis crossings of ``M(j omega) Delta`` (real blocks only).
    slack : float, optional
        Prove each model's peak on the whole frequency axis with this relative slack
        (None: no guarantee).
    chunk_size : int
        Models per worker task (0: ``"continued"``: one contiguous range per worker, the
        fewest cold starts; other methods: at most 40 models, a multiple of ``n_jobs`` tasks).
    n_jobs : int
        Worker processes (1: in this process).
    scheduler : str or None
        Where the workers run (``--scheduler``, :func:`oos_drake.processes.make_executor`):
        None for the local process pool, ``"dask"`` for a local Dask cluster, or an address.
    """

    grid: str = "continued"
    upper_iterations: int = 30
    lower_restarts: int = 2
    lower_iterations: int = 40
    lower_points: int = 3
    continuation_iterations: int = 15
    converge_passes: int = 1
    converge_iterations: int = 150
    spike_ratio: float = 1.1
    despike_points: int = 4
    jump_ratio: float = 0.5
    pole_points: int = 1
    mu_options: dict | None = None
    refine_points: int = 0
    refine_peaks: int = 1
    refine_rounds: int = 1
    refine_lower: bool = False
    refine_iterations: int | None = 100
    polish_points: int = 0
    polish_rounds: int = 1
    polish_iterations: int = 300
    polish_temperatures: tuple | None = None
    crossings: bool = False
    slack: float | None = None
    chunk_size: int = 0
    n_jobs: int = 2
    scheduler: str | None = None

    def __post_init__(self):
        for name in ("upper_iterations", "lower_iterations", "n_jobs"):
            if getattr(self, name) < 1:
                raise ValueError(f"SweepOptions.{name} must be >= 1, got {getattr(self, name)}")
        if self.chunk_size < 0:
            raise ValueError(f"SweepOptions.chunk_size must be >= 0, got {self.chunk_size}")
        if self.grid not in GRID_METHODS:
            raise ValueError(f"SweepOptions.grid must be one of {GRID_METHODS}, got {self.grid!r}")
        if self.grid == "warm" and self.pole_points:
            raise ValueError("SweepOptions.pole_points must be 0 with grid='warm' (common grid)")


@dataclass
class SweepPoints:
    """The points of one subset (one row per model and frequency, sorted by model, frequency).

    Attributes
    ----------
    model, omega, upper, lower : numpy.ndarray
        Model index, frequency [rad/s], bounds of mu [-] (``lower``: certified, 0 where not
        computed).
    refined, tightened : numpy.ndarray
        Added by the refinement or the crossing search; bounds of full accuracy.
    params : numpy.ndarray or None
        Upper-bound scalings of every point (None when a step used ``mussv``).
    best : dict
        Model -> ``(lower, omega, delta)``: its best certified lower bound, where, and the
        perturbation (``det(I - M delta) = 0``, ``||delta|| = 1 / lower``).
    guarantees : dict
        Model -> :class:`~oos_drake.robust.mu_intervals.AxisCertificate` (``slack`` set).
    """

    model: np.ndarray
    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    refined: np.ndarray
    tightened: np.ndarray
    params: np.ndarray | None
    best: dict
    guarantees: dict


# --- frequency points -------------------------------------------------------------------------


def refine_frequencies(omega, values, count=4, points=12):
    """New frequencies between the neighbours of the ``count`` highest local maxima of
    ``values`` (``points`` per maximum)."""
    if omega.size < 3:
        return np.zeros(0)
    interior = (values[1:-1] >= values[:-2]) & (values[1:-1] >= values[2:])
    peaks = np.flatnonzero(interior) + 1
    ends = [i for i in (0, omega.size - 1) if values[i] == values.max()]
    peaks = np.concatenate([peaks, ends]).astype(int)
    if peaks.size == 0:
        return np.zeros(0)
    peaks = peaks[np.argsort(values[peaks])[::-1][:count]]
    new = []
    for i in peaks:
        lo = omega[max(i - 1, 0)]
        hi = omega[min(i + 1, omega.size - 1)]
        if hi > lo:
            new.append(np.linspace(lo, hi, points + 2)[1:-1])
    return np.concatenate(new) if new else np.zeros(0)


def merged(omega, arrays, new, new_arrays):
    """``omega`` and its per-frequency ``arrays`` with the points ``new`` added, sorted (stable);
    an array that is None on either side is None."""
    omega = np.concatenate([omega, new])
    order = np.argsort(omega, kind="stable")
    out = (
        None if a is None or b is None else np.concatenate([a, b])[order]
        for a, b in zip(arrays, new_arrays, strict=True)
    )
    return omega[order], tuple(out)


def refined_grid(omega, arrays, evaluate, curves, rounds):
    """Per-frequency ``arrays`` on a grid refined ``rounds`` times next to the 4 highest peaks
    of each of ``curves(arrays)``; ``evaluate(new)`` returns the arrays at new frequencies (the
    refinement of :func:`~oos_drake.robust.wcgain`, whose points are not mu bounds)."""
    for _ in range(rounds):
        new = np.concatenate([refine_frequencies(omega, values) for values in curves(arrays)])
        new = np.setdiff1d(np.unique(new), omega)
        if new.size == 0:
            break
        omega, arrays = merged(omega, arrays, new, evaluate(new))
    return omega, arrays


def top_peaks(values, count: int) -> np.ndarray:
    """Indices of the ``count`` highest local maxima of ``values`` (the ends included)."""
    interior = np.r_[True, values[1:] >= values[:-1]] & np.r_[values[:-1] >= values[1:], True]
    peaks = np.flatnonzero(interior)
    return peaks[np.argsort(values[peaks])[::-1][:count]]


def peak_seeds(omega, values, count: int = 6) -> np.ndarray:
    """Frequencies of the ``count`` highest local maxima of ``values`` (plus 0): where a cover
    of the frequency axis starts."""
    return np.unique(np.concatenate([[0.0], omega[top_peaks(values, count)]]))


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


def _nearest(grid_from, grid_to):
    """Index in ``grid_from`` of the nearest (log) frequency of every point of ``grid_to``."""
    lf, lt = np.log(grid_from), np.log(grid_to)
    if lf.size == 1:
        return np.zeros(lt.size, dtype=int)
    k = np.clip(np.searchsorted(lf, lt), 1, lf.size - 1)
    return np.where(np.abs(lt - lf[k - 1]) <= np.abs(lf[k] - lt), k - 1, k)


def local_spikes(upper: np.ndarray, ratio: float) -> np.ndarray:
    """Indices of values above ``ratio`` times both neighbours (one neighbour at the ends)."""
    if upper.size < 2:
        return np.zeros(0, dtype=int)
    left = np.r_[upper[1], upper[:-1]]
    right = np.r_[upper[1:], upper[-2]]
    return np.flatnonzero(upper > ratio * np.maximum(left, right))


def _top_points(upper, model_of, count):
    """Indices of the ``count`` largest values of ``upper`` per model (by model, largest
    first)."""
    order = np.lexsort((-upper, model_of))
    first = np.searchsorted(model_of[order], model_of[order], side="left")
    return order[(np.arange(order.size) - first) < count]


# --- grid methods -----------------------------------------------------------------------------


@dataclass
class _Grid:
    """Flat grid bounds of one subset: lower bounds computed at ``at`` (with ``delta``)."""

    upper: np.ndarray
    lower: np.ndarray
    tightened: np.ndarray
    params: np.ndarray | None
    at: np.ndarray
    delta: np.ndarray


def _quick_bounds(M, structure, iterations, restarts=2, steps=40) -> _Grid:
    """Cold bounds of a flat batch ``M``: ``iterations`` BFGS iterations of the upper bound,
    the power iteration (``restarts``, ``steps``) from its worst directions."""
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    up = mu_upper_bound(M, structure, max_iter=iterations)
    lo = mu_lower_bound(M, structure, start_inputs=up.worst_input, restarts=restarts, iters=steps)
    n = up.upper.size
    lower = np.minimum(lo.lower, up.upper)
    return _Grid(up.upper, lower, np.zeros(n, dtype=bool), up.params, np.arange(n), lo.delta)


def grid_bounds(M, blk, options: SweepOptions):
    """Upper and lower bounds of mu for a flat batch ``M`` ``(B, c, r)`` (cold, batched)."""
    steps = (options.upper_iterations, options.lower_restarts, options.lower_iterations)
    got = _quick_bounds(np.ascontiguousarray(M), parse_blk(blk), *steps)
    return got.upper, got.lower


def _converge_model(M, structure, opt):
    """Converged upper bounds on one model's grid: cold start, then frequency continuation.

    Each pass restarts every frequency from its own scalings and from those of both frequency
    neighbours (``converge_iterations`` each, four smoothing stages) and keeps the smallest
    bound: started cold, the optimizer often stalls far above the converged value near lightly
    damped modes; a neighbour's converged scalings do not.
    """
    from oos_drake.robust.mu_upper import mu_upper_bound

    res = mu_upper_bound(M, structure, max_iter=opt.upper_iterations)
    upper, params, worst = res.upper.copy(), res.params.copy(), res.worst_input.copy()
    if M.shape[0] < 2:
        return upper, params, worst
    for _ in range(opt.converge_passes):
        for shift in (1, -1, 0):
            x0 = params[np.clip(np.arange(M.shape[0]) - shift, 0, M.shape[0] - 1)]
            r = mu_upper_bound(
                M,
                structure,
                max_iter=opt.converge_iterations,
                temperatures=CONVERGED_TEMPERATURES,
                x0=x0,
            )
            better = r.upper < upper
            upper[better], params[better] = r.upper[better], r.params[better]
            worst[better] = r.worst_input[better]
    return upper, params, worst


def _despike(M, structure, upper, params, worst, opt):
    """Recompute one model's highest local spikes from their frequency neighbours' scalings.

    Continuation can carry a stalled point from model to model; a genuine resonance peak is
    only recomputed (the smaller bound is kept: both are valid).
    """
    from oos_drake.robust.mu_upper import mu_upper_bound

    spikes = local_spikes(upper, opt.spike_ratio)
    if spikes.size == 0 or opt.despike_points <= 0:
        return upper, params, worst
    spikes = spikes[np.argsort(-upper[spikes])][: opt.despike_points]
    n = upper.size
    idx = np.concatenate([spikes, spikes])
    src = np.concatenate([np.maximum(spikes - 1, 0), np.minimum(spikes + 1, n - 1)])
    src = np.where(src == idx, np.where(idx == 0, 1, n - 2), src)
    r = mu_upper_bound(
        M[idx],
        structure,
        max_iter=opt.converge_iterations,
        temperatures=CONVERGED_TEMPERATURES,
        x0=params[src],
    )
    upper, params, worst = upper.copy(), params.copy(), worst.copy()
    for k, i in enumerate(idx):
        if r.upper[k] < upper[i]:
            upper[i], params[i], worst[i] = r.upper[k], r.params[k], r.worst_input[k]
    return upper, params, worst


def _jump(M_prev, M, nearest) -> float:
    """Largest relative change of ``M11`` between consecutive models over the grid [-].

    Channels that are numerically zero (a body not connected yet: norms below 1e-6) never
    count as a jump.
    """
    norm = np.linalg.norm(M, axis=(1, 2))
    if norm.size == 0 or np.max(norm) < 1e-6:
        return 0.0
    diff = np.linalg.norm(M - M_prev[nearest], axis=(1, 2))
    return float(np.max(diff / np.maximum(norm, 1e-6 * np.max(norm))))


def _continued_grid(subs, grids, structure, opt, model_of, tick) -> _Grid:
    """Upper bounds of consecutive models, each started from its predecessor's scalings, and
    lower bounds at each model's ``lower_points`` highest upper bounds.

    The first model of the chunk, and any model after a jump of the configuration, is
    converged (:func:`_converge_model`); model ``j`` starts from model ``j - 1``'s scalings at
    the nearest frequency, or from balancing where that is better, for
    ``continuation_iterations`` at one high smoothing temperature. Neighbouring configurations
    are close problems: measured on the mission, this is four times cheaper than a cold start
    and leaves no spike. ``continuation_iterations = 0``: every model cold.
    """
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    ups, pars, worsts, prev = [], [], [], None
    for j, M in enumerate(subs):
        if opt.continuation_iterations <= 0:
            r = mu_upper_bound(M, structure, max_iter=opt.upper_iterations)
            u, p, w = r.upper, r.params, r.worst_input
        elif prev is None or _jump(subs[j - 1], M, near := _nearest(grids[j - 1], grids[j])) > (
            opt.jump_ratio
        ):
            u, p, w = _converge_model(M, structure, opt)  # first model, or a switch
        else:
            r = mu_upper_bound(
                M,
                structure,
                max_iter=opt.continuation_iterations,
                temperatures=(1000.0,),
                x0=prev[near],
            )
            u, p, w = _despike(M, structure, r.upper, r.params, r.worst_input, opt)
        prev = p
        ups.append(u)
        pars.append(p)
        worsts.append(w)
        tick()
    upper = np.concatenate(ups)
    top = np.sort(_top_points(upper, model_of, max(opt.lower_points, 1)))
    lo = mu_lower_bound(
        np.concatenate(subs)[top],
        structure,
        start_inputs=np.concatenate(worsts)[top],
        restarts=opt.lower_restarts,
        iters=opt.lower_iterations,
    )
    lower = np.zeros(upper.size)
    lower[top] = np.minimum(lo.lower, upper[top])
    tight = np.zeros(upper.size, dtype=bool)
    return _Grid(upper, lower, tight, np.concatenate(pars), top, lo.delta)


def _pruned_grid(flat, structure, model_of) -> _Grid:
    """Cheap bounds everywhere, full bounds only where a model's peak may be.

    1. Every point gets a cheap valid upper bound (Osborne balancing and 2 L-BFGS iterations)
       and a cheap certified lower bound (one power-iteration start from the upper bound's
       worst direction).
    2. Per model, ``L*`` is the best lower bound found so far. A point whose upper bound is
       ``<= L*`` cannot hold the model's peak (``mu <= upper <= L* <= peak``): it is left
       alone. The others are tightened (the upper bound of :func:`~oos_drake.robust.mussv`
       warm-started from the cheap scalings, its lower bound with restarts), highest first: 3
       per model, then 16 per model, doubling every round, updating ``L*`` between rounds,
       until no untightened point has an upper bound above ``L*``.

    The peak of each model is therefore bracketed by full-accuracy bounds (as with
    ``"cold"``); elsewhere the upper bound is valid but up to a few percent looser.
    """
    from oos_drake.robust.mu import (
        UPPER_ITERATIONS,
        UPPER_PATIENCE,
        UPPER_TEMPERATURES,
        UPPER_TOL,
        _lower_bound,
    )
    from oos_drake.robust.mu_lower import mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    first_round, round_size = 3, 16
    rng = np.random.default_rng(0)
    cheap = mu_upper_bound(flat, structure, max_iter=2, temperatures=(300.0,))
    low = mu_lower_bound(
        flat, structure, start_inputs=cheap.worst_input, restarts=0, iters=30, polish_starts=1
    )
    lo, delta = low.lower, low.delta.copy()
    up = np.maximum(cheap.upper, lo)
    tight = np.zeros(up.size, dtype=bool)
    per_round = first_round
    nm = int(model_of.max()) + 1 if model_of.size else 0
    while True:
        best = np.zeros(nm)
        np.maximum.at(best, model_of, lo)
        cand = np.flatnonzero(~tight & (up > best[model_of]))
        if cand.size == 0:
            break
        sel = cand[_top_points(up[cand], model_of[cand], per_round)]  # highest first, per model
        full_up = mu_upper_bound(
            flat[sel],
            structure,
            max_iter=UPPER_ITERATIONS,
            tol=UPPER_TOL,
            temperatures=UPPER_TEMPERATURES,
            patience=UPPER_PATIENCE,
            x0=cheap.params[sel],
        )
        full = _lower_bound(
            flat[sel], structure, full_up, restarts=4, iters=60, rng=rng, restart_gap=1.02
        )
        better = full.lower > lo[sel]
        delta[sel[better]] = full.delta[better]
        lo[sel] = np.maximum(lo[sel], full.lower)
        up[sel] = np.maximum(np.minimum(up[sel], full_up.upper), lo[sel])
        tight[sel] = True
        # few rounds even where nothing prunes (e.g. mu = 0 of a real-only structure)
        per_round = round_size if per_round == first_round else 2 * per_round
    return _Grid(up, lo, tight, None, np.arange(up.size), delta)


def _warm_grid(Ms, structure) -> _Grid:
    """Bounds for ``Ms`` ``(nm, F, c, r)`` walking up the frequency axis with warm starts.

    The first frequency starts from Osborne balancing (80 iterations); each next one from the
    scalings of the previous frequency or from balancing, whichever is better, for 20
    iterations at a single high smoothing temperature. The lower bound runs once on the whole
    batch (2 restarts of 40 steps), started from the upper bound's worst directions.
    """
    from oos_drake.robust.mu_lower import LowerBoundResult, mu_lower_bound
    from oos_drake.robust.mu_upper import mu_upper_bound

    nm, F = Ms.shape[:2]
    up = np.empty((nm, F))
    worst = np.empty((nm, F, structure.n_rows), dtype=complex)
    x = None
    for f in range(F):
        if x is None:
            res = mu_upper_bound(Ms[:, f], structure, max_iter=80)
        else:
            res = mu_upper_bound(Ms[:, f], structure, max_iter=20, temperatures=(1000.0,), x0=x)
        x = res.params
        up[:, f] = res.upper
        worst[:, f] = res.worst_input
    flat = Ms.reshape((-1,) + Ms.shape[2:])
    starts = {"start_inputs": worst.reshape(-1, structure.n_rows)}
    options = dict(structure=structure, restarts=2, iters=40)  # a fresh rng per chunk
    low = in_chunks(mu_lower_bound, flat, 2048, LowerBoundResult, starts, **options)
    up = np.maximum(up.ravel(), low.lower)
    return _Grid(up, low.lower, np.ones(up.size, dtype=bool), None, np.arange(up.size), low.delta)


def _mussv_points(M, structure, opt) -> _Grid:
    """:func:`~oos_drake.robust.mussv` at every point of the flat batch ``M``."""
    from oos_drake.robust.mu import mussv

    res = mussv(M, structure, **(opt.mu_options or {}))
    up, lo = np.atleast_1d(res.upper), np.atleast_1d(res.lower)
    n = up.size
    delta = res.delta.reshape(n, *res.delta.shape[-2:])
    return _Grid(up, lo, np.ones(n, dtype=bool), None, np.arange(n), delta)


def _refine_bounds(M, structure, opt) -> _Grid:
    """Bounds at refinement points: ``refine_iterations`` BFGS iterations, or mussv."""
    if opt.refine_iterations is None:
        return _mussv_points(M, structure, opt)
    return _quick_bounds(M, structure, opt.refine_iterations)


# --- the later steps (one model at a time or all models in one batch) ------------------------


def _polish(response, structure, points, opt):
    """Long upper-bound runs at each model's highest upper bounds (the peak matters most).

    Ill-conditioned matrices (lightly damped modes with repeated real parameters) need hundreds
    of iterations; spending them on a few frequencies keeps the sweep fast. ``points`` is the
    list of per-model ``[omega, upper, lower, ...]``; ``response(j, omega)`` gives ``M``.
    """
    from oos_drake.robust.mu_upper import mu_upper_bound

    done = [set() for _ in points]
    active = list(range(len(points)))
    for _ in range(opt.polish_rounds):
        picks = []
        for j in active:
            up = points[j][1]
            order = [int(i) for i in np.argsort(up)[::-1] if int(i) not in done[j]]
            picks.append((j, order[: opt.polish_points]))
        picks = [(j, idx) for j, idx in picks if idx]
        if not picks:
            break
        M = np.concatenate([response(j, points[j][0][idx]) for j, idx in picks])
        temps = {} if opt.polish_temperatures is None else {"temperatures": opt.polish_temperatures}
        better = mu_upper_bound(M, structure, max_iter=opt.polish_iterations, **temps).upper
        k = 0
        for j, idx in picks:
            up, lo = points[j][1], points[j][2]
            for i in idx:
                up[i] = max(min(up[i], better[k]), lo[i])
                done[j].add(i)
                k += 1
        active = [j for j, _ in picks if int(np.argmax(points[j][1])) not in done[j]]


def _eig_near(Mw, delta, target):
    ev = np.linalg.eigvals(Mw @ delta)
    return ev[np.argmin(np.abs(ev - target))]


def _frequency_crossings(A, Bw, Cz, Dzw, structure, omega, up, lo, count=6, samples=16, window=8):
    """Lower-bound candidates that also move the frequency.

    With real blocks, mu can be discontinuous in omega: a destabilizing ``Delta`` gives a real
    eigenvalue of ``M(j omega) Delta`` only at isolated frequencies that a grid never hits. For
    the best unit perturbation found at a peak (of the upper bound or of the unconstrained
    power-iteration gain), follow the eigenvalues of
    ``M(j omega) Delta`` over the neighbouring interval and solve ``Im(lambda(omega)) = 0``
    (Illinois regula falsi); each root gives a certified bound ``|lambda| / ||Delta||`` at that
    frequency. Returns ``(omega_new, lower_new, delta_new)``.
    """
    from oos_drake.robust.mu_lower import certificate_residual, mu_lower_bound

    none = (np.zeros(0), np.zeros(0), np.zeros((0, structure.n_rows, structure.n_cols)))
    if omega.size < 2:
        return none

    # candidates: peaks of the upper bound, and peaks of |lambda| of the best unit perturbation
    # (real parameters at a vertex) whatever its phase: continuous in omega where mu is not
    Mall = delta_channel_response(A, Bw, Cz, Dzw, omega)
    raw = mu_lower_bound(Mall, structure, restarts=2, iters=40)
    dn_all = np.max(structure.block_norms(raw.raw_delta), axis=1)
    score = np.where(dn_all > 0, np.abs(raw.raw_lambda) / np.maximum(dn_all, 1e-300), 0.0)
    score = np.where(np.isfinite(score), score, 0.0)
    peaks = np.unique(np.concatenate([top_peaks(up, count), top_peaks(score, count)]))
    out_w, out_lo, out_d = [], [], []
    floor = float(np.max(lo)) if lo.size else 0.0
    for k in peaks:
        D = raw.raw_delta[k]
        dn = float(dn_all[k])
        if dn <= 0 or not np.isfinite(raw.raw_lambda[k]):
            continue
        # follow the eigenvalues over the whole grid (plus a dense patch around the peak): the
        # crossing of the real axis need not be next to the peak
        lo_i, hi_i = max(k - window, 0), min(k + window, omega.size - 1)
        ws = np.unique(np.concatenate([omega, np.linspace(omega[lo_i], omega[hi_i], samples + 1)]))
        Ms = delta_channel_response(A, Bw, Cz, Dzw, ws)
        evs = np.linalg.eigvals(Ms @ D)  # (S, n)
        if ws[0] == 0.0:  # at omega = 0 a real M gives real eigenvalues: no sign to compare
            ws, evs = ws[1:], evs[1:]
        best = (0.0, None, None)
        for i0 in range(evs.shape[1]):  # follow every eigenvalue of the first sample
            lam = evs[0, i0]
            track = [lam]
            for s in range(1, ws.size):
                lam = evs[s][np.argmin(np.abs(evs[s] - lam))]
                track.append(lam)
            track = np.array(track)
            for s in np.flatnonzero(np.sign(track.imag[:-1]) * np.sign(track.imag[1:]) < 0):
                wl, wr, fl, fr = ws[s], ws[s + 1], track[s].imag, track[s + 1].imag
                ll, lr = track[s], track[s + 1]
                # a crossing only matters if it can beat the best lower bound known so far
                if 1.5 * max(abs(ll), abs(lr)) / dn <= max(best[0], floor):
                    continue
                lam_m, side = ll, 0
                for _ in range(60):
                    wm = wr - fr * (wr - wl) / (fr - fl)
                    if not (min(wl, wr) < wm < max(wl, wr)):
                        wm = 0.5 * (wl + wr)
                    Mm = delta_channel_response(A, Bw, Cz, Dzw, [wm])[0]
                    lam_m = _eig_near(Mm, D, 0.5 * (ll + lr))
                    fm = lam_m.imag
                    if abs(fm) <= 1e-13 * abs(lam_m) or abs(wr - wl) <= 1e-15 * wr:
                        break
                    if np.sign(fm) == np.sign(fl):
                        wl, fl, ll = wm, fm, lam_m
                        if side == -1:
                            fr *= 0.5
                        side = -1
                    else:
                        wr, fr, lr = wm, fm, lam_m
                        if side == 1:
                            fl *= 0.5
                        side = 1
                if abs(lam_m.imag) > 1e-9 * abs(lam_m) or lam_m.real == 0:
                    continue
                value = abs(lam_m.real) / dn
                if value > best[0]:
                    best = (value, wm, D / lam_m.real)
        if best[1] is not None:
            Mm = delta_channel_response(A, Bw, Cz, Dzw, [best[1]])[0]
            if certificate_residual(Mm, best[2]) <= 1e-7:
                out_w.append(best[1])
                out_lo.append(best[0])
                out_d.append(best[2])
    return (np.array(out_w), np.array(out_lo), np.array(out_d)) if out_w else none


def axis_certificate(real, structure, omega, up, lo, slack):
    """Cover ``[0, inf)`` starting from the peaks of the points' bounds, at a level no lower
    than ``(1 + slack)`` times the best certified lower bound (a common level widens the
    intervals; the points whose bound exceeds it get long optimizer runs, so that an
    optimizer stall does not raise the level).

    Returns
    -------
    AxisCertificate
    """
    from oos_drake.robust.mu_intervals import cover_axis, mu_solver

    best = float(lo.max())
    return cover_axis(
        real,
        mu_solver(real, structure, slack=slack, polish_above=best),
        np.union1d(peak_seeds(omega, up), peak_seeds(omega, lo)),
        floor=(1.0 + slack) * best,
        slack=slack,
    )


# --- the sweep --------------------------------------------------------------------------------


def _update_best(best, model, omega, lower, delta):
    """Keep each model's largest certified lower bound (the first one on ties)."""
    order = np.lexsort((-lower, model))  # stable: the first of equal values leads
    heads = order[np.r_[True, model[order][1:] != model[order][:-1]]] if order.size else order
    for i in heads:
        m = int(model[i])
        if m not in best or lower[i] > best[m][0]:
            best[m] = (float(lower[i]), float(omega[i]), delta[i])


def sweep_models(A, Bw, Cz, Dzw, omega, parts, options: SweepOptions, *, first=0, tick=None):
    """Every step of the sweep for a chunk of models (plain arrays in, :class:`SweepPoints` out).

    Parameters
    ----------
    A, Bw, Cz, Dzw : numpy.ndarray
        ``(nm, ...)`` Delta-channel matrices of the chunk's models.
    omega : numpy.ndarray
        Common frequency grid [rad/s] (sorted, unique).
    parts : dict
        Subset name -> ``(z rows, w columns, BLK)`` (:func:`~.lfr_analysis.subset_parts`; rows
        and columns may be ``slice(None)``: all channels, no copy).
    options : SweepOptions
    first : int
        Index of the chunk's first model in the whole array (``model`` column).
    tick : callable, optional
        Called once per model and subset after its grid bounds (progress).

    Returns
    -------
    dict
        Subset name -> :class:`SweepPoints`.

    Raises
    ------
    ValueError
        With ``slack`` set, for a model with a pole within round-off of the imaginary axis.
    """
    from oos_drake.robust.mu_intervals import Realization

    opt = options
    tick = tick or (lambda: None)
    nm = A.shape[0]
    grids = [
        model_grid(A[j], omega, points=opt.pole_points) if opt.pole_points else omega
        for j in range(nm)
    ]
    Ms = [delta_channel_response(A[j], Bw[j], Cz[j], Dzw[j], g) for j, g in enumerate(grids)]
    model_of = np.concatenate([np.full(g.size, first + j) for j, g in enumerate(grids)])
    omega_of = np.concatenate(grids)
    out = {}
    for name, (zrows, wcols, blk) in parts.items():
        structure = parse_blk(blk)
        subs = [M[:, zrows][:, :, wcols] for M in Ms]

        def response(j, w, zrows=zrows, wcols=wcols):
            return delta_channel_response(A[j], Bw[j], Cz[j], Dzw[j], w)[:, zrows][:, :, wcols]

        def channels(j, zrows=zrows, wcols=wcols):  # the subset's Delta channels of model j
            rows_cols = (zrows, wcols) if isinstance(zrows, slice) else np.ix_(zrows, wcols)
            return A[j], Bw[j][:, wcols], Cz[j][zrows], Dzw[j][rows_cols]

        if opt.grid == "continued":
            grid = _continued_grid(subs, grids, structure, opt, model_of, tick)
        else:
            if opt.grid == "warm":
                grid = _warm_grid(np.stack(subs), structure)
            elif opt.grid == "pruned":
                grid = _pruned_grid(np.concatenate(subs), structure, model_of - first)
            else:
                grid = _mussv_points(np.concatenate(subs), structure, opt)
            for _ in range(nm):
                tick()
        best = {}
        _update_best(best, model_of[grid.at], omega_of[grid.at], grid.lower[grid.at], grid.delta)
        edges = np.cumsum([0] + [g.size for g in grids])
        # per model: [omega, (upper, lower, refined, tightened, params)]
        points = [
            [
                grids[j],
                (grid.upper[a:b].copy(), grid.lower[a:b].copy(), np.zeros(b - a, bool))
                + (grid.tightened[a:b], None if grid.params is None else grid.params[a:b]),
            ]
            for j, (a, b) in enumerate(zip(edges[:-1], edges[1:], strict=True))
        ]

        def insert(j, w, upper, lower, tightened, params, points=points):  # sorted in
            new = (upper, lower, np.ones(w.size, dtype=bool), tightened, params)
            points[j] = list(merged(*points[j], w, new))

        for _ in range(opt.refine_rounds if opt.refine_points > 0 else 0):
            extra = []
            for w, (up, lo, *_) in points:
                curves = (up, lo) if opt.refine_lower else (up,)
                new = [
                    refine_frequencies(w, c, opt.refine_peaks, opt.refine_points) for c in curves
                ]
                extra.append(np.setdiff1d(np.unique(np.concatenate(new)), w))
            if not any(e.size for e in extra):
                break
            got = _refine_bounds(
                np.concatenate([response(j, e) for j, e in enumerate(extra) if e.size]),
                structure,
                opt,
            )
            em = np.concatenate([np.full(e.size, first + j) for j, e in enumerate(extra)])
            _update_best(best, em, np.concatenate(extra), got.lower, got.delta)
            ends = np.cumsum([0] + [e.size for e in extra])
            for j, e in enumerate(extra):
                k = slice(ends[j], ends[j + 1])
                pars = None if got.params is None else got.params[k]
                insert(j, e, got.upper[k], got.lower[k], got.tightened[k], pars)
        if opt.polish_points > 0:
            _polish(response, structure, [(w, *cols) for w, cols in points], opt)
        if opt.crossings and structure.has_real:
            for j, (w, (up, lo, *_)) in enumerate(points):
                wx, lx, dx = _frequency_crossings(*channels(j), structure, w, up, lo)
                if wx.size:
                    # mu_upper at the crossing frequencies too: lower <= upper pointwise
                    ux = _mussv_points(response(j, wx), structure, opt).upper
                    _update_best(best, np.full(wx.size, first + j), wx, lx, dx)
                    insert(j, wx, np.maximum(ux, lx), lx, np.ones(wx.size, bool), None)
        guarantees = {}
        for j, (w, (up, lo, *_)) in enumerate(points if opt.slack is not None else []):
            try:
                real = Realization(*channels(j))
                guarantees[first + j] = axis_certificate(real, structure, w, up, lo, opt.slack)
            except ValueError as err:
                raise ValueError(f"model {first + j}: {err}") from None
        per_model = [  # the best lower bounds and the guarantees are the chunk's
            SweepPoints(np.full(w.size, first + j), w, np.maximum(up, lo), lo, *cols, {}, {})
            for j, (w, (up, lo, *cols)) in enumerate(points)
        ]
        out[name] = replace(joined(SweepPoints, per_model), best=best, guarantees=guarantees)
    return out


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


def chunk_ranges(n_models: int, options: SweepOptions) -> list:
    """``[(first, last), ...]`` model ranges of the worker tasks (see ``chunk_size``)."""
    size = options.chunk_size
    if not size and options.grid == "continued":
        size = int(np.ceil(n_models / options.n_jobs))
    elif not size:
        # big batches share the Python overhead of the iterations; 40 models x 500 frequencies
        # of 26 x 26 matrices are ~200 MB per copy, which bounds the memory of a worker. The
        # number of tasks is a multiple of n_jobs (no idle worker at the end).
        rounds = int(np.ceil(n_models / (options.n_jobs * 40)))
        size = max(1, int(np.ceil(n_models / (options.n_jobs * rounds))))
    return [(i, min(i + size, n_models)) for i in range(0, n_models, size)]


def _sweep_task(task):
    """Worker: :func:`sweep_models` on one range of models."""
    first, A, Bw, Cz, Dzw, omega, parts, options = task
    return sweep_models(A, Bw, Cz, Dzw, omega, parts, options, first=first)


def sweep_table_of(points: dict, times):
    """The sweep table (:data:`~oos_drake.robust.tables.SWEEP_COLUMNS`, plus
    :data:`~oos_drake.robust.tables.GUARANTEE_COLUMNS` when every model has a guarantee) of
    subset name -> :class:`SweepPoints` (or any points with the same arrays, e.g. the
    analysis's tightened points)."""
    pts = list(points.values())
    model = np.concatenate([p.model for p in pts])
    guaranteed = bool(pts) and all(getattr(p, "guarantees", None) for p in pts)

    def per_model(value):  # one value per model -> one per row
        values = [{m: value(c) for m, c in p.guarantees.items()} for p in pts]
        return np.concatenate([[v[m] for m in p.model] for v, p in zip(values, pts, strict=True)])

    return sweep_table(
        subset=np.concatenate([np.full(p.model.size, n, dtype=object) for n, p in points.items()]),
        model=model,
        time=np.asarray(times, dtype=float)[model],
        omega=np.concatenate([p.omega for p in pts]),
        upper=np.concatenate([p.upper for p in pts]),
        lower=np.concatenate([p.lower for p in pts]),
        refined=np.concatenate([p.refined for p in pts]),
        tightened=np.concatenate([p.tightened for p in pts]),
        guaranteed=per_model(lambda c: float(c.upper)) if guaranteed else None,
        guarantee_points=per_model(lambda c: int(c.omega.size)) if guaranteed else None,
        covered=per_model(lambda c: bool(c.covered)) if guaranteed else True,
        reason=per_model(lambda c: c.reason) if guaranteed else "",
    )


def _sweep(sys, omega, subsets, times, options: SweepOptions, caller, progress, description):
    """:func:`sweep_models` over the whole model array in chunks on the workers -> the table."""
    from tqdm.auto import tqdm

    zero = options.grid != "continued"  # the continuation compares log frequencies
    omega, (A, Bw, Cz, Dzw), times = check_sweep_input(sys, omega, times, caller=caller, zero=zero)
    parts = subset_parts(sys, dict(subsets or {"total": list(block_map(sys).names)}))
    ranges = chunk_ranges(A.shape[0], options)
    tasks = [(a, A[a:b], Bw[a:b], Cz[a:b], Dzw[a:b], omega, parts, options) for a, b in ranges]
    bar = tqdm(total=A.shape[0], desc=description, disable=not progress, unit="model")
    results = []
    try:
        with make_executor(options.n_jobs, options.scheduler) as executor:
            for (a, b), res in zip(ranges, executor.map(_sweep_task, tasks), strict=True):
                results.append(res)
                bar.update(b - a)
    except ValueError as err:
        raise ValueError(f"{caller}: {err}") from None
    finally:
        bar.close()
    points = {name: joined_points([r[name] for r in results]) for name in parts}
    return sweep_table_of(points, times)


def joined_points(chunks) -> SweepPoints:
    """One :class:`SweepPoints` of consecutive chunks of models."""
    return joined(SweepPoints, chunks)


def mu_sweep(
    sys,
    omega=None,
    subsets: dict | None = None,
    *,
    times=None,
    options: SweepOptions | None = None,
    progress: bool = True,
    description: str = "mu sweep",
):
    """mu bounds for every model of ``sys``, frequency and uncertainty subset.

    Parameters
    ----------
    sys : LFR
        Uncertain closed loop, a model array ``(N,)`` (or one model).
    omega : array_like, optional
        Common frequency grid [rad/s] (default: :func:`frequency_grid` of all models' poles);
        with ``pole_points``, plus per model points on its lightly damped poles.
    subsets : dict, optional
        Subset name -> block names (default ``{"total": all blocks}``).
    times : array_like, optional
        Mission time [s] (or any scheduling value) of each model, stored as ``time [s]``
        (default NaN).
    options : SweepOptions, optional
        The steps of the sweep (default: the analysis's grid, see :class:`SweepOptions`).
    progress : bool
        Show a tqdm progress bar (models).
    description : str
        Label of the progress bar.

    Returns
    -------
    pandas.DataFrame
        Columns :data:`~oos_drake.robust.tables.SWEEP_COLUMNS` (``mu lower [-]``: certified;
        ``refined``: added by the refinement or the crossing search; ``tightened``: bounds of
        full accuracy), plus :data:`~oos_drake.robust.tables.GUARANTEE_COLUMNS` with ``slack``.
    """
    options = options or SweepOptions()
    return _sweep(sys, omega, subsets, times, options, "mu_sweep", progress, description)


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
    """mu bounds for every model, frequency and uncertainty subset: :func:`mu_sweep` with
    keyword options (every upper bound valid, every lower bound certified).

    Parameters
    ----------
    sys, omega, subsets, times
        As for :func:`mu_sweep` (``omega``: the common grid only, no pole points).
    n_jobs : int
        Worker processes (1: in this process).
    scheduler : str, optional
        Where the workers run (``--scheduler``, :func:`oos_drake.processes.make_executor`):
        None for the local process pool, ``"dask"`` for a local Dask cluster, or an address.
    refine_points : int
        Extra frequencies around each of the two highest peaks of each model and subset (0: off).
    polish : int
        Frequencies per model and subset (the highest, refinement points included) whose upper
        bound gets a long run (300 iterations): this settles the slow cases (e.g. a real block
        whose ``M`` is nearly real, where the optimal ``G`` is large).
    warm_start : bool
        ``mode="full"`` only: walk up the frequency grid reusing the previous frequency's
        scalings (``grid="warm"``; the grid must be fine enough for the scalings to change
        little between neighbours; upper bounds 1-4 % above converged ones away from the
        polished peaks). False: independent ``mussv`` calls (``grid="cold"``).
    mode : {"peak", "full"}
        ``"peak"`` (default, ``grid="pruned"``): full-accuracy bounds only where a model's
        peak may be, cheap valid ones elsewhere (the ``tightened`` column says which).
        ``"full"``: full-accuracy bounds at every frequency (the whole curve), slower.
    chunk_size : int, optional
        Models per task (default: at most 40, a multiple of ``n_jobs`` tasks).
    mu_options : dict, optional
        Options of :func:`~oos_drake.robust.mussv` (refinement points, ``"cold"`` grid).
    guaranteed : bool
        Also prove, for each model and subset, a bound of the peak of mu over the whole
        frequency axis (:func:`~oos_drake.robust.mu_intervals.cover_axis`, started from the
        peaks of the analyzed points): columns ``mu upper guaranteed [-]`` (the same value on
        every row of the model and subset; ``inf`` if the cover did not close) and
        ``guarantee points`` (frequencies solved for the proof), ``covered`` and ``reason``
        (why the proof does not cover the whole axis, where it does not). The per-frequency
        columns stay
        pointwise bounds.
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
    from oos_drake.robust.mu_intervals import SLACK

    if mode not in ("peak", "full"):
        raise ValueError(f"robust_sweep: mode must be 'peak' or 'full', got {mode!r}")
    grid = "pruned" if mode == "peak" else ("warm" if warm_start else "cold")
    options = SweepOptions(
        grid=grid,
        pole_points=0,
        mu_options=dict(mu_options or {}),
        refine_points=int(refine_points),
        refine_peaks=2,
        refine_iterations=None,
        polish_points=int(polish),
        slack=(SLACK if slack is None else float(slack)) if guaranteed else None,
        chunk_size=int(chunk_size or 0),
        n_jobs=max(1, int(n_jobs)),
        scheduler=scheduler,
    )
    return _sweep(as_lfr(sys), omega, subsets, times, options, "robust_sweep", False, "")
