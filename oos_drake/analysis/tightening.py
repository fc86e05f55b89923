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
* where a spike survives, the power-iteration lower bound runs again with restarts from the
  new worst direction, the direct destabilizing search
  (:func:`oos_drake.analysis.destabilizing.destabilizing_perturbation`) runs on the spike's model,
  and the frequency grid is refined locally (log midpoints towards both neighbours, warm
  started) around the few highest spikes;
* a point whose upper bound no longer moves when re-solved with many iterations from its own and
  its neighbours' scalings is *converged*: what separates it from ``L*`` is the conservatism of
  the D-G bound itself (typical of real parameters), not the optimizer. It is never re-solved,
  and the points below the highest converged one cannot change the gap of the peak
  ``(max U - L*) / max U``: they are not worked on either (top-down resolution);
* until no spike is left, every remaining spike is converged, or the rounds or the budget
  (BFGS work, searches, seconds) are spent. What is left is reported
  (:class:`TightenReport`), not hidden.

Why the top-down rule matters: with a controller whose real-parameter mu ridge is flat over the
mission (the baseline PD), the converged D-G bound sits 3-4 % above the exact real mu on a
thousand points; resolving every one of them (and refining around each) made the number of
points grow from round to round (1 000 -> 7 000) and took minutes per subset for no change of
the certified gap.
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
    max_points : int
        At most this many spikes (the highest unconverged ones) are re-solved per round.
    refine_spikes : int
        Local refinement, from the second round on, around at most this many of the highest
        surviving spikes (local maxima of their model).
    converged_ratio : float
        A re-solve with at least ``converged_iterations`` that lowers a point's upper bound by
        less than this (relative) marks it converged [-].
    converged_iterations : int
        See ``converged_ratio``; a re-solve with ``iterations[-1]`` always marks it converged.
    settle_ratio : float
        Unconverged spikes less than this (relative) above the highest converged spike are
        left alone, and a pass of ``converged_iterations`` or more that lowers the largest
        upper bound by less than this (with no better lower bound) marks every spike
        converged: the ridge has settled, more passes would change the gap by less [-].
    max_searches : int
        Direct destabilizing searches per subset (the seed search included).
    max_work : float
        Budget of upper-bound work per subset, in point-iterations (sum over the re-solved
        candidates of their BFGS iterations; refinement points included): deterministic.
    time_budget : float
        Wall-clock budget of the resolution per subset [s] (a safety net: a step that started
        finishes; ``inf``: none).
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
    max_points: int = 120
    refine_spikes: int = 4
    converged_ratio: float = 0.002
    converged_iterations: int = 150
    settle_ratio: float = 0.005
    max_searches: int = 8
    max_work: float = 1.5e6
    time_budget: float = 90.0

    def __post_init__(self):
        if not self.target_gap >= 0:
            raise ValueError(f"TightenOptions.target_gap must be >= 0, got {self.target_gap}")
        if self.rounds < 0:
            raise ValueError(f"TightenOptions.rounds must be >= 0, got {self.rounds}")
        if not self.iterations or min(self.iterations) < 1:
            raise ValueError(
                f"TightenOptions.iterations must be positive counts, got {self.iterations}"
            )
        for name in ("max_points", "max_searches", "refine_spikes", "peak_levels"):
            if getattr(self, name) < 0:
                raise ValueError(f"TightenOptions.{name} must be >= 0, got {getattr(self, name)}")
        if not self.settle_ratio >= 0:
            raise ValueError(f"TightenOptions.settle_ratio must be >= 0, got {self.settle_ratio}")
        for name in ("max_work", "time_budget"):
            if not getattr(self, name) > 0:
                raise ValueError(f"TightenOptions.{name} must be > 0, got {getattr(self, name)}")


@dataclass
class SubsetPoints:
    """Mutable working set of one subset (internal): one entry per (model, frequency).

    ``converged`` (optional, created on first use) marks points whose upper bound no longer
    moves when re-solved (see :func:`resolve_spikes`).
    """

    model: np.ndarray
    omega: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    params: np.ndarray
    refined: np.ndarray
    tightened: np.ndarray
    converged: np.ndarray | None = None

    _FIELDS = ("model", "omega", "upper", "lower", "params", "refined", "tightened", "converged")

    def __post_init__(self):
        if self.converged is None:
            self.converged = np.zeros(np.asarray(self.model).size, dtype=bool)

    def sort(self):
        order = np.lexsort((self.omega, self.model))
        for name in self._FIELDS:
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
        self.converged = np.concatenate([self.converged, np.zeros(n, bool)])


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
    work : float
        Point-iterations spent (see :attr:`TightenOptions.max_work`).
    converged : int
        Spikes left whose upper bound is converged (the D-G bound's own gap).
    points_left : int
        Spikes left (``U > (1 + target) L*``) at the end.
    stop : str
        Why the resolution stopped: ``"target met"``; ``"converged"`` (every spike that could
        change the gap is converged, and no model is left to search); ``"search budget"``
        (the same, but ``max_searches`` direct searches were spent: more could raise ``L*``);
        ``"rounds"``, ``"work budget"``, ``"time budget"`` (spikes still open).
    seconds : float
        Wall-clock time of the resolution [s].
    """

    rounds: int = 0
    spikes: tuple = ()
    points_added: int = 0
    searched_models: tuple = ()
    evaluations: int = 0
    work: float = 0.0
    converged: int = 0
    points_left: int = 0
    stop: str = "target met"
    seconds: float = 0.0

    @property
    def budget_exhausted(self) -> bool:
        """True when a budget (work, time, rounds, searches) stopped the resolution with spikes
        left."""
        budgets = ("rounds", "work budget", "time budget", "search budget")
        return self.stop in budgets and self.points_left > 0


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


def _warm_pass(pool, pts, act, parts, iterations, lower, converged=None):
    """Recompute the points ``act`` from their own and their lower neighbours' scalings.

    ``converged = (ratio, min_iterations, last_iterations)``: points whose bound dropped by less
    than ``ratio`` (relative) in a pass of at least ``min_iterations`` (or any pass of
    ``last_iterations``) are marked converged.

    Returns ``(evaluations, found)``: upper-bound problems solved and a better lower bound.
    """
    before = pts.upper[act].copy()
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
        PointTask(pts.model[owner], pts.omega[owner], pts.params[source], *parts, iterations)
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
    if converged is not None:
        ratio, min_it, last_it = converged
        if iterations >= last_it:
            pts.converged[act] = True
        elif iterations >= min_it:
            drop = (before - pts.upper[act]) / np.maximum(before, 1e-300)
            pts.converged[act[drop < ratio]] = True
    found = None
    if lower is not None:
        still = act[pts.upper[act] > lower[0]]
        if still.size:
            low = pool.bounds(
                PointTask(
                    pts.model[still],
                    pts.omega[still],
                    pts.params[still],
                    *parts,
                    1,  # one iteration from the converged scalings: the worst direction
                    lower_restarts=lower[1],
                    lower_iterations=lower[2],
                )
            )
            pts.lower[still] = np.maximum(pts.lower[still], low.lower)
            if low.best >= 0:
                found = _grid_certificate(low, pts.model[still], pts.omega[still])
    return evaluations, found


def _refine(pool, pts, act, parts, iterations, options, lower_star):
    """Log midpoints towards both neighbours of spikes that are local maxima of their model."""
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
            *parts,
            iterations,
            lower_restarts=options.lower_restarts,
            lower_iterations=options.lower_iterations,
        )
    )
    lower = np.minimum(res.lower, res.upper)
    pts.append(new_model, new_omega, np.maximum(res.upper, lower), lower, res.params)
    found = None
    if res.best >= 0 and res.lower[res.best] > lower_star:
        found = _grid_certificate(res, new_model, new_omega)
    return new_model.size, found


def _grid_certificate(bounds, model: np.ndarray, omega: np.ndarray) -> LowerCertificate:
    """The certificate of the best lower bound of ``bounds`` (a :class:`PointBounds` of the
    points ``model``, ``omega`` [rad/s])."""
    best = bounds.best
    return LowerCertificate(
        float(bounds.lower[best]), int(model[best]), float(omega[best]), bounds.best_delta, "grid"
    )


def resolve_spikes(
    pool: ModelPool,
    pts: SubsetPoints,
    parts,
    lower: LowerCertificate,
    search,
    options: TightenOptions,
    progress=None,
    hints=(),
):
    """Tighten, refine and search until ``max U <= (1 + target) L*`` (or nothing can help).

    Top-down: only spikes above the highest *converged* spike can still change the gap of the
    peak ``(max U - L*) / max U``, so only they are re-solved (the ``max_points`` highest per
    round); the direct search goes to the models of the highest spikes not searched yet. The
    work is bounded by :attr:`TightenOptions.max_work` (point-iterations, deterministic),
    ``max_searches`` and ``time_budget`` (wall clock); the report says what stopped it.

    Each round (:class:`_SpikeResolution`): the budgets checked, the peak refined between grid
    points (the first ``peak_levels`` rounds), then either the open spikes re-solved, searched
    and refined around (:meth:`~_SpikeResolution.warm_round`), or, with no open spike, the
    searches spread on the models far from those searched (:meth:`~_SpikeResolution.settle`).

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
    hints : sequence of (int, float)
        ``(model, omega)`` worth a direct search besides the largest upper bound (e.g. the
        critical points of the other subsets: a ridge of mu that is flat over the models puts
        the exact peak anywhere on it, not necessarily where the upper bound is largest).

    Returns
    -------
    (LowerCertificate, TightenReport)
    """
    import time as _time

    start = _time.perf_counter()
    state = _SpikeResolution(pool, pts, parts, lower, search, options, start)
    pts.sort()
    state.seed(hints)
    for rnd in range(options.rounds):
        pts.sort()
        state.spikes.append(int(np.sum(pts.upper > state.threshold())))
        if progress is not None:
            progress(rnd, state.spikes[-1])
        stop = state.budget_spent()
        if stop:
            state.stop = stop
            break
        if state.levels < options.peak_levels:
            state.refine_peak()
        act = state.open_spikes()
        if act.size == 0:
            if state.levels >= options.peak_levels and state.settle():
                break
            continue
        state.warm_round(rnd, act)
    else:
        state.stop = state.stop_after_rounds()
    return state.lower, state.report()


class _SpikeResolution:
    """The state of one subset's spike resolution (:func:`resolve_spikes`) and its steps.

    Attributes
    ----------
    lower : LowerCertificate
        Best lower bound so far.
    searched : list of int
        Models given the direct search, in order.
    spikes : list of int
        Spikes at the start of each round.
    added, evaluations, rounds_run, levels : int
        Refinement points added, upper-bound problems solved, warm rounds run, peak
        refinements done.
    work : float
        Point-iterations spent.
    stop : str
        Why the resolution stopped (:attr:`TightenReport.stop`).
    """

    def __init__(self, pool, pts, parts, lower, search, options, start):
        self.pool, self.pts, self.parts, self.search = pool, pts, parts, search
        self.options = options
        self.start = start
        self.lower = lower
        self.searched: list[int] = []
        self.spikes: list[int] = []
        self.added = 0
        self.evaluations = 0
        self.work = 0.0
        self.rounds_run = 0
        self.levels = 0
        self.stop = "rounds"

    def threshold(self) -> float:
        """``(1 + target) L*``: upper bounds above it are spikes."""
        return (1.0 + self.options.target_gap) * self.lower.value

    def open_spikes(self) -> np.ndarray:
        """Unconverged spikes clearly above every converged spike (the only ones that matter:
        resolving the others could lower the gap of the peak by ``settle_ratio`` at most)."""
        pts = self.pts
        above = pts.upper > self.threshold()
        done = above & pts.converged
        floor = (
            float(np.max(pts.upper[done])) * (1.0 + self.options.settle_ratio)
            if np.any(done)
            else -np.inf
        )
        return np.flatnonzero(above & ~pts.converged & (pts.upper > floor))

    def improve(self, found) -> None:
        """Keep ``found`` (a :class:`LowerCertificate` or None) if it raises ``L*``."""
        if found is not None and found.value > self.lower.value:
            self.lower = found

    def run_search(self, requests) -> None:
        """The direct searches ``requests`` (``(model, omega)``); the best result kept."""
        for cand in self.search(requests) if requests else []:
            self.improve(cand)

    def next_requests(self, order, count=None) -> list:
        """Searches for the models of the points ``order`` not searched yet (at most
        ``count``, default ``search_models``, and ``max_searches`` in all)."""
        requests = []
        count = self.options.search_models if count is None else count
        for i in order:
            if len(requests) >= count or len(self.searched) >= self.options.max_searches:
                break
            m = int(self.pts.model[i])
            if m in self.searched:
                continue
            self.searched.append(m)
            requests.append((m, float(self.pts.omega[i])))
        return requests

    def spread_requests(self, order) -> list:
        """Direct searches for the spikes ``order`` (highest first): half on the highest spikes'
        models, half on models far from every model searched so far (the best grid lower
        bound there, else the highest upper bound): on a ridge of mu that is flat over the
        models, the exact peak need not be under the largest upper bound."""
        pts, options = self.pts, self.options
        half = max(options.search_models // 2, 1)
        requests = self.next_requests(order, half)
        count = options.search_models - len(requests)
        if count <= 0:
            return requests
        models = np.unique(pts.model)
        span = max(int(np.ceil(models.size / 20)), 1)  # 5 % of the models
        taken = np.array(self.searched) if self.searched else np.zeros(0, int)
        far = np.ones(pts.model.size, dtype=bool)
        for m in taken:
            far &= np.abs(pts.model - m) > span
        cand = np.flatnonzero(far & (pts.upper > self.threshold()))
        if cand.size:
            key = np.lexsort((-pts.upper[cand], -pts.lower[cand]))
            requests += self.next_requests(cand[key], count)
        return requests

    def seed(self, hints) -> None:
        """The first direct search: on the model of the largest upper bound, and the hints."""
        pts, options = self.pts, self.options
        if not (
            pts.upper.size
            and options.search_models > 0
            and options.max_searches > 0
            and np.max(pts.upper) > self.lower.value
        ):
            return
        seed = self.next_requests([int(np.argmax(pts.upper))], 1)
        for m, w in hints:
            if len(seed) > options.search_models or len(self.searched) >= options.max_searches:
                break
            if 0 <= int(m) and int(m) in set(pts.model.tolist()) and int(m) not in self.searched:
                self.searched.append(int(m))
                seed.append((int(m), float(w)))
        self.run_search(seed)

    def budget_spent(self) -> str | None:
        """``"time budget"`` or ``"work budget"`` when spent, else None."""
        import time as _time

        if _time.perf_counter() - self.start > self.options.time_budget:
            return "time budget"
        if self.work >= self.options.max_work:
            return "work budget"
        return None

    def _count(self, evaluations: int, iterations: int, points: int = 0) -> None:
        self.added += points
        self.evaluations += evaluations
        self.work += evaluations * iterations

    def refine_peak(self) -> None:
        """The peak may sit between grid points: midpoints around the largest upper bound."""
        pts, iterations = self.pts, self.options.iterations[-1]
        top = np.array([int(np.argmax(pts.upper))])
        n_new, found = _refine(
            self.pool, pts, top, self.parts, iterations, self.options, self.lower.value
        )
        self.levels += 1
        self._count(n_new, iterations, n_new)
        self.improve(found)
        pts.sort()

    def settle(self) -> bool:
        """No open spike: stop (True) with the reason, unless searches on models far from the
        searched ones are left to run (they are run; False)."""
        pts = self.pts
        self.stop = "target met" if not np.any(pts.upper > self.threshold()) else "converged"
        pending = np.flatnonzero(pts.upper > self.threshold())
        pending = pending[np.argsort(-pts.upper[pending])]
        requests = self.spread_requests(pending) if self.stop == "converged" else []
        if not requests:
            if self.stop == "converged" and len(self.searched) >= self.options.max_searches:
                self.stop = "search budget"  # more models could still raise L*
            return True
        self.run_search(requests)
        return False

    def warm_round(self, rnd: int, act: np.ndarray) -> None:
        """Round ``rnd`` on the open spikes ``act``: re-solved warm (the ``max_points``
        highest), marked converged when a long pass did not move the peak, searched, and
        refined around (distinct models) where they survive."""
        pts, options = self.pts, self.options
        act = act[np.argsort(-pts.upper[act])][: options.max_points]
        self.rounds_run += 1
        iterations = options.iterations[min(rnd, len(options.iterations) - 1)]
        top_before, lower_before = float(np.max(pts.upper)), self.lower.value
        converged_rule = (
            options.converged_ratio,
            options.converged_iterations,
            options.iterations[-1],
        )
        n_eval, found = _warm_pass(
            self.pool,
            pts,
            act,
            self.parts,
            iterations,
            (self.threshold(), options.lower_restarts, options.lower_iterations)
            if rnd > 0
            else None,
            converged_rule,
        )
        self._count(n_eval, iterations)
        self.improve(found)
        if (
            iterations >= options.converged_iterations
            and float(np.max(pts.upper)) > top_before * (1.0 - options.settle_ratio)
            and self.lower.value <= lower_before
        ):
            # a pass of converged_iterations did not move the peak: the ridge has settled,
            # more passes would lower the gap by less than settle_ratio
            pts.converged[pts.upper > self.threshold()] = True
        # direct search on the models of the highest surviving spikes
        still = act[pts.upper[act] > self.threshold()]
        if still.size:
            self.run_search(self.spread_requests(still[np.argsort(-pts.upper[still])]))
            still = act[pts.upper[act] > self.threshold()]
        if still.size and rnd > 0 and options.refine_spikes > 0:
            # local refinement around the highest surviving spikes only (distinct models)
            order = still[np.argsort(-pts.upper[still])]
            _, first = np.unique(pts.model[order], return_index=True)
            chosen = order[np.sort(first)][: options.refine_spikes]
            n_new, found = _refine(
                self.pool, pts, chosen, self.parts, iterations, options, self.lower.value
            )
            self._count(n_new, iterations, n_new)
            self.improve(found)

    def stop_after_rounds(self) -> str:
        """Why the rounds ended when all were run."""
        if not np.any(self.pts.upper > self.threshold()):
            return "target met"
        if self.open_spikes().size == 0:
            return (
                "converged" if len(self.searched) < self.options.max_searches else "search budget"
            )
        return self.stop

    def report(self) -> TightenReport:
        """The :class:`TightenReport` of the resolution (the points sorted, spikes counted)."""
        import time as _time

        pts = self.pts
        pts.sort()
        left = pts.upper > self.threshold()
        self.spikes.append(int(np.sum(left)))
        if not np.any(left):
            self.stop = "target met"
        return TightenReport(
            self.rounds_run,
            tuple(self.spikes),
            self.added,
            tuple(self.searched),
            self.evaluations,
            work=float(self.work),
            converged=int(np.sum(left & pts.converged)),
            points_left=int(np.sum(left)),
            stop=self.stop,
            seconds=_time.perf_counter() - self.start,
        )
