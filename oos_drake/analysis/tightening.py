r"""Resolving upper-bound spikes: the peak of mu certified within a target gap.

After the grid sweep, every point carries a valid upper bound ``U`` (a few BFGS iterations from
Osborne balancing) and a certified lower bound ``L``. The D-G optimizer, started cold, often
stops far above the converged bound on lightly damped modes: isolated spikes, two to four times
the neighbouring values. The cure measured on the mission models is continuation: the converged
scalings of a neighbouring problem (next frequency of the same model, same frequency of the next
configuration) are an excellent start.

Per subset, with ``L*`` the best certified lower bound found so far:

* a point with ``U <= (1 + target) L*`` cannot hold a peak above the certificate's tolerance: it is
  never touched again (pruning);
* the others ("spikes") are recomputed with more iterations, started from their own scalings and
  from those of every neighbour with a lower bound (the smallest result is kept: all are valid);
  iterations grow from round to round;
* where a spike survives, the frequency grid is refined locally (log midpoints towards both
  neighbours, warm started), the power-iteration lower bound runs again with restarts from the
  new worst direction, and the direct destabilizing search
  (:func:`oos_drake.analysis.destabilizing.destabilizing_perturbation`) runs on the spike's model;
* until no spike is left or the rounds are spent. What is left is reported, not hidden.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.analysis.workers import ModelPool, PointTask


@dataclass(frozen=True)
class TightenOptions:
    """How hard spikes are resolved.

    Attributes
    ----------
    target_gap : float
        A point is a spike while ``U > (1 + target_gap) L*`` [-] (0.03: 3 %).
    rounds : int
        Rounds of warm passes / refinement / lower-bound search.
    iterations : tuple of int
        BFGS iterations of the upper bound in each round (the last value repeats).
    lower_restarts, lower_iterations : int
        Power-iteration lower bound at surviving spikes.
    refine_min_ratio : float
        No midpoint is inserted between frequencies closer than this ratio.
    search_models : int
        Models given the direct destabilizing search per round (highest spikes first); the
        model of the largest upper bound is searched before the first round.
    peak_levels : int
        Rounds of local refinement around the largest upper bound (log midpoints towards
        both neighbours: the peak may sit between grid points).
    search_band : float
        Frequency band factor of the direct search around the model's spike.
    """

    target_gap: float = 0.03
    rounds: int = 6
    iterations: tuple = (30, 60, 150, 300, 600)
    lower_restarts: int = 4
    lower_iterations: int = 60
    refine_min_ratio: float = 1.0005
    search_models: int = 2
    search_band: float = 2.0
    peak_levels: int = 4

    def __post_init__(self):
        if not self.target_gap >= 0:
            raise ValueError(f"TightenOptions.target_gap must be >= 0, got {self.target_gap}")
        if self.rounds < 0:
            raise ValueError(f"TightenOptions.rounds must be >= 0, got {self.rounds}")
        if not self.iterations or min(self.iterations) < 1:
            raise ValueError(
                f"TightenOptions.iterations must be positive counts, got {self.iterations}"
            )


@dataclass
class SubsetPoints:
    """Mutable working set of one subset (internal): one entry per (model, frequency)."""

    model: np.ndarray
    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    params: np.ndarray
    refined: np.ndarray
    tightened: np.ndarray

    def sort(self):
        order = np.lexsort((self.omega, self.model))
        for name in ("model", "omega", "upper", "lower", "params", "refined", "tightened"):
            setattr(self, name, getattr(self, name)[order])

    def append(self, model, omega, upper, lower, params):
        n = len(model)
        self.model = np.concatenate([self.model, model])
        self.omega = np.concatenate([self.omega, omega])
        self.upper = np.concatenate([self.upper, upper])
        self.lower = np.concatenate([self.lower, lower])
        self.params = np.concatenate([self.params, params])
        self.refined = np.concatenate([self.refined, np.ones(n, bool)])
        self.tightened = np.concatenate([self.tightened, np.ones(n, bool)])


@dataclass(frozen=True)
class LowerCertificate:
    """The best certified lower bound of a subset and where it was found.

    Attributes
    ----------
    value : float
        ``1 / ||delta||`` [-].
    model : int
    omega : float
        Frequency [rad/s] with ``det(I - M11(j omega) delta) = 0``.
    delta : numpy.ndarray or None
        Normalized perturbation, mussv layout of the subset.
    source : str
        ``"grid"`` (power iteration) or ``"search"`` (direct destabilizing search).
    """

    value: float = 0.0
    model: int = -1
    omega: float = float("nan")
    delta: np.ndarray | None = None
    source: str = "none"


@dataclass(frozen=True)
class TightenReport:
    """What the spike resolution did for one subset.

    Attributes
    ----------
    rounds : int
        Rounds run.
    spikes : tuple of int
        Spikes at the start of each round (and after the last one).
    points_added : int
        Local refinement frequencies added.
    searched_models : tuple of int
        Models given the direct search.
    evaluations : int
        Upper-bound problems solved (all candidates of all points).
    """

    rounds: int = 0
    spikes: tuple = ()
    points_added: int = 0
    searched_models: tuple = ()
    evaluations: int = 0


def neighbours(model: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Indices of the four neighbours of every point (-1: none), points sorted by (model, omega).

    Columns: lower frequency and higher frequency of the same model, nearest frequency (in log)
    of the previous and of the next model index.
    """
    n = model.size
    out = np.full((n, 4), -1, dtype=int)
    if n == 0:
        return out
    idx = np.arange(n)
    same_left = np.r_[False, model[1:] == model[:-1]]
    out[same_left, 0] = idx[same_left] - 1
    same_right = np.r_[model[:-1] == model[1:], False]
    out[same_right, 1] = idx[same_right] + 1
    logw = np.log(omega)
    models, starts = np.unique(model, return_index=True)
    ends = np.r_[starts[1:], n]
    where = {int(m): (s, e) for m, s, e in zip(models, starts, ends, strict=True)}
    for m, s, e in zip(models, starts, ends, strict=True):
        for col, other in ((2, m - 1), (3, m + 1)):
            if int(other) not in where:
                continue
            s2, e2 = where[int(other)]
            grid = logw[s2:e2]
            j = np.clip(np.searchsorted(grid, logw[s:e]), 1, max(grid.size - 1, 1))
            if grid.size == 1:
                out[s:e, col] = s2
                continue
            left_closer = np.abs(logw[s:e] - grid[j - 1]) <= np.abs(grid[j] - logw[s:e])
            out[s:e, col] = s2 + np.where(left_closer, j - 1, j)
    return out


def _warm_pass(pool, pts, act, parts, iterations, lower):
    """Recompute the points ``act`` from their own and their lower neighbours' scalings."""
    zrows, wcols, blk = parts
    nb = neighbours(pts.model, pts.omega)
    owner = [act]
    source = [act]
    for col in range(4):
        j = nb[act, col]
        ok = (j >= 0) & (pts.upper[np.maximum(j, 0)] < pts.upper[act])
        owner.append(act[ok])
        source.append(j[ok])
    owner = np.concatenate(owner)
    source = np.concatenate(source)
    res = pool.bounds(
        PointTask(
            pts.model[owner],
            pts.omega[owner],
            pts.params[source],
            zrows,
            wcols,
            blk,
            iterations,
        )
    )
    # the scalings of each owner's best candidate
    order = np.lexsort((res.upper, owner))
    first = np.r_[True, owner[order][1:] != owner[order][:-1]]
    win = order[first]
    who = owner[win]
    improved = res.upper[win] < pts.upper[who]
    pts.upper[who[improved]] = res.upper[win][improved]
    pts.params[who[improved]] = res.params[win][improved]
    pts.tightened[who] = True
    evaluations = owner.size
    found = None
    if lower is not None:
        still = act[pts.upper[act] > lower[0]]
        if still.size:
            low = pool.bounds(
                PointTask(
                    pts.model[still],
                    pts.omega[still],
                    pts.params[still],
                    zrows,
                    wcols,
                    blk,
                    1,  # one iteration from the converged scalings: the worst direction
                    lower_restarts=lower[1],
                    lower_iterations=lower[2],
                )
            )
            pts.lower[still] = np.maximum(pts.lower[still], low.lower)
            if low.best >= 0:
                k = still[low.best]
                found = LowerCertificate(
                    float(low.lower[low.best]),
                    int(pts.model[k]),
                    float(pts.omega[k]),
                    low.best_delta,
                    "grid",
                )
    return evaluations, found


def _refine(pool, pts, act, parts, iterations, options, lower_star):
    """Log midpoints towards both neighbours of spikes that are local maxima of their model."""
    zrows, wcols, blk = parts
    nb = neighbours(pts.model, pts.omega)
    new_model, new_omega, seed = [], [], []
    for i in act:
        for col in (0, 1):
            j = nb[i, col]
            if j < 0 or pts.upper[j] > pts.upper[i]:
                continue
            ratio = max(pts.omega[i], pts.omega[j]) / min(pts.omega[i], pts.omega[j])
            if ratio < options.refine_min_ratio:
                continue
            new_model.append(pts.model[i])
            new_omega.append(np.sqrt(pts.omega[i] * pts.omega[j]))
            seed.append(i)
    if not new_model:
        return 0, None
    new_model, new_omega, seed = np.array(new_model), np.array(new_omega), np.array(seed)
    res = pool.bounds(
        PointTask(
            new_model,
            new_omega,
            pts.params[seed],
            zrows,
            wcols,
            blk,
            iterations,
            lower_restarts=options.lower_restarts,
            lower_iterations=options.lower_iterations,
        )
    )
    lower = np.minimum(res.lower, res.upper)
    pts.append(new_model, new_omega, np.maximum(res.upper, lower), lower, res.params)
    found = None
    if res.best >= 0 and res.lower[res.best] > lower_star:
        found = LowerCertificate(
            float(res.lower[res.best]),
            int(new_model[res.best]),
            float(new_omega[res.best]),
            res.best_delta,
            "grid",
        )
    return new_model.size, found


def resolve_spikes(
    pool: ModelPool,
    pts: SubsetPoints,
    parts,
    lower: LowerCertificate,
    search,
    options: TightenOptions,
    progress=None,
):
    """Tighten, refine and search until ``max U <= (1 + target) L*`` (or the rounds are spent).

    Parameters
    ----------
    pool : ModelPool
        Workers holding the model array.
    pts : SubsetPoints
        The subset's points (updated in place; refinement points appended).
    parts : tuple
        ``(zrows, wcols, blk)`` of the subset.
    lower : LowerCertificate
        Best lower bound so far.
    search : callable
        ``search([(model, omega_peak), ...]) -> [LowerCertificate, ...]`` (direct
        destabilizing searches, run in parallel by the caller).
    options : TightenOptions
    progress : callable, optional
        ``progress(round, spikes)``.

    Returns
    -------
    (LowerCertificate, TightenReport)
    """
    searched: list[int] = []
    spikes_hist = []
    added = 0
    evaluations = 0
    rounds_run = 0
    levels = 0
    pts.sort()
    if pts.upper.size and options.search_models > 0 and np.max(pts.upper) > lower.value:
        # seed: the direct search on the model of the largest upper bound
        i = int(np.argmax(pts.upper))
        searched.append(int(pts.model[i]))
        for cand in search([(int(pts.model[i]), float(pts.omega[i]))]):
            if cand.value > lower.value:
                lower = cand
    for rnd in range(options.rounds):
        pts.sort()
        threshold = (1.0 + options.target_gap) * lower.value
        act = np.flatnonzero(pts.upper > threshold)
        spikes_hist.append(int(act.size))
        if progress is not None:
            progress(rnd, act.size)
        if levels < options.peak_levels:
            # the peak may sit between grid points: midpoints around the largest upper bound
            top = np.array([int(np.argmax(pts.upper))])
            n_new, found = _refine(
                pool, pts, top, parts, options.iterations[-1], options, lower.value
            )
            levels += 1
            added += n_new
            evaluations += n_new
            if found is not None and found.value > lower.value:
                lower = found
            pts.sort()
            threshold = (1.0 + options.target_gap) * lower.value
            act = np.flatnonzero(pts.upper > threshold)
        if act.size == 0:
            if levels >= options.peak_levels:
                break
            continue
        rounds_run += 1
        iterations = options.iterations[min(rnd, len(options.iterations) - 1)]
        n_eval, found = _warm_pass(
            pool,
            pts,
            act,
            parts,
            iterations,
            (threshold, options.lower_restarts, options.lower_iterations) if rnd > 0 else None,
        )
        evaluations += n_eval
        if found is not None and found.value > lower.value:
            lower = found
        threshold = (1.0 + options.target_gap) * lower.value
        # direct search on the models of the highest surviving spikes
        still = act[pts.upper[act] > threshold]
        if still.size:
            order = still[np.argsort(-pts.upper[still])]
            requests = []
            for i in order:
                m = int(pts.model[i])
                if len(requests) >= options.search_models:
                    break
                if m in searched:
                    continue
                searched.append(m)
                requests.append((m, float(pts.omega[i])))
            for cand in search(requests) if requests else []:
                if cand.value > lower.value:
                    lower = cand
            threshold = (1.0 + options.target_gap) * lower.value
            still = act[pts.upper[act] > threshold]
        if still.size and rnd > 0:
            pts.sort()
            still = np.flatnonzero(pts.upper > threshold)
            n_new, found = _refine(pool, pts, still, parts, iterations, options, lower.value)
            added += n_new
            evaluations += n_new
            if found is not None and found.value > lower.value:
                lower = found
    pts.sort()
    final = int(np.sum(pts.upper > (1.0 + options.target_gap) * lower.value))
    spikes_hist.append(final)
    return lower, TightenReport(rounds_run, tuple(spikes_hist), added, tuple(searched), evaluations)
