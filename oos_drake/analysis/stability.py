r"""Robust stability over a model array: mu bounds over configurations x frequencies x subsets.

For the uncertain closed loop ``F_u(M, Delta)`` of every configuration, the matrix seen by the
uncertainty ``M11(j omega)`` is evaluated on a frequency grid (modal form, one eigen-decomposition
per model) and, for each uncertainty subset (blocks outside it stay nominal), the mixed-mu
bounds are computed:

* grid: a common logarithmic grid plus, per model, points on its lightly damped closed-loop
  poles (where the real modal uncertainty makes mu peak);
* bounds: the package's one sweep (:func:`oos_drake.robust.sweep.sweep_models`, grid method
  ``"continued"``): D-G upper bounds continued from configuration to configuration (every
  value is a valid bound whatever the iterations), power-iteration lower bounds at each
  configuration's highest upper bounds (certified: ``det(I - M delta) = 0``).

:func:`certified_sweep` then resolves the upper-bound spikes of every subset
(:mod:`oos_drake.analysis.tightening`: warm-started passes, local frequency refinement,
lower-bound searches) until the peak upper bound is within the target gap of the best certified
lower bound, and returns a :class:`PeakCertificate` per subset: a worst case, not only a bound.
Finally (:func:`axis_guarantee`) it proves, for every configuration, a bound of mu on the whole
frequency axis, not only on the grid (:mod:`oos_drake.robust.mu_intervals`): an
:class:`AxisGuarantee` per subset. Configurations between the analyzed ones stay sampled.

Chunks of models run in worker processes (fork; one BLAS thread each) with a tqdm bar.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from oos_drake.analysis.tightening import (
    LowerCertificate,
    SubsetPoints,
    TightenOptions,
    neighbours,
    resolve_spikes,
)
from oos_drake.analysis.workers import ModelPool, PointTask
from oos_drake.robust.blocks import REAL, parse_blk
from oos_drake.robust.lfr_analysis import block_map, subset_parts, worst_case_values
from oos_drake.robust.sweep import (
    SweepOptions,
    check_sweep_input,
    chunk_ranges,
    joined_points,
    sweep_models,
    sweep_table_of,
)
from oos_drake.robust.sweep import mu_sweep as mu_sweep  # the analysis's grid-only sweep


def _sweep_chunk(task):
    """Worker: :func:`~oos_drake.robust.sweep.sweep_models` on a range of models (model arrays
    in the worker, one progress tick per model and subset)."""
    from oos_drake.analysis.workers import _ARRAYS

    first, last, omega, parts, opt = task
    A, Bw, Cz, Dzw = (x[first:last] for x in _ARRAYS["models"])
    queue = _ARRAYS.get("queue")
    tick = None if queue is None else (lambda: queue.put(1))
    return sweep_models(A, Bw, Cz, Dzw, omega, parts, opt, first=first, tick=tick)


def _collect(results, parts):
    """Merge the chunks' points into one :class:`SubsetPoints` and best lower bound per subset
    (the first model with the largest one)."""
    points, lowers = {}, {}
    for name in parts:
        pts = joined_points([res[name] for res in results])
        points[name] = SubsetPoints(
            pts.model.astype(int),
            pts.omega.astype(float),
            pts.upper,
            pts.lower,
            pts.params,
            pts.refined,
            pts.tightened,
        )
        model = max(sorted(pts.best), key=lambda m: pts.best[m][0])
        value, omega, delta = pts.best[model]
        lowers[name] = LowerCertificate(value, int(model), omega, delta, "grid")
    return points, lowers


def _grid_points(pool, n_models, omega, parts, options, progress, description):
    """The grid sweep: contiguous model ranges (one per worker task), a bar over models."""
    import queue as _queue

    from tqdm.auto import tqdm

    tasks = [(a, b, omega, parts, options) for a, b in chunk_ranges(n_models, options)]
    bar = tqdm(
        total=n_models,
        desc=description,
        disable=not progress,
        bar_format="{l_bar}{bar}| {n:.0f}/{total} models [{elapsed}<{remaining}]",
    )
    step = 1.0 / max(len(parts), 1)
    results = []
    if pool.serial:
        for task in tasks:
            results.append(_sweep_chunk(task))
            bar.update(task[1] - task[0])
    else:
        futures = [pool.executor.submit(_sweep_chunk, t) for t in tasks]
        if pool.queue is None:  # Dask: no progress queue, the bar moves by finished task
            for future, task in zip(futures, tasks, strict=True):
                future.result()
                bar.update(task[1] - task[0])
        while not all(f.done() for f in futures):
            try:
                pool.queue.get(timeout=0.5)
                bar.update(step)
            except _queue.Empty:
                pass
        results = [f.result() for f in futures]
    bar.n = n_models
    bar.refresh()
    bar.close()
    return _collect(results, parts)


def _search_task(task):
    """Worker: direct destabilizing search on one model (matrices in the task)."""
    from oos_drake.analysis.destabilizing import destabilizing_perturbation

    A, Bw, Cz, Dzw, blk, band, alpha_max = task
    return destabilizing_perturbation(A, Bw, Cz, Dzw, blk, band, alpha_max=alpha_max)


def _analysis_model(sys, model: int, members):
    """One model restricted to a subset: ``(A, Bw, Cz, Dzw, blk, sub_map, reduced)``.

    Models with spurious near-zero modes that neither the inputs nor Delta reach (the phase-8
    closed kinematic loop) are reduced first: the direct search looks at eigenvalues.
    """
    one = sys.model(model) if sys.batch_shape else sys
    A_full = np.asarray(one.A)
    reduced = bool(A_full.size and np.max(np.linalg.eigvals(A_full).real) > -1e-9)
    if reduced:
        one = one.reduce()
    bmap = block_map(one)
    sub, zrows, wcols = bmap.subset(list(members))
    A = np.asarray(one.A)
    Bw, Cz = np.asarray(one.Bw)[:, wcols], np.asarray(one.Cz)[zrows, :]
    Dzw = np.asarray(one.Dzw)[np.ix_(zrows, wcols)]
    return A, Bw, Cz, Dzw, sub.blk, sub, reduced


#: Contiguous ranges of configurations per worker and subset in :func:`axis_guarantee` (each
#: range starts its continuation cold).
CHUNKS_PER_WORKER = 3
#: Default ``tight`` of :func:`axis_guarantee`: the first level of the covers is at most this
#: relative margin above the largest bound found on the grid (or the lower bound, if higher).
#: The covers' cost falls as it grows: 0.015 instead of 0.01 took 10 % of the Hamiltonian tests
#: off the make-run mission study and raised every guaranteed level by 0.5 % (branch rb10,
#: ``benchmarks/bench_guarantee_levels.py --tight 0.01,0.015``); not adopted.
TIGHT_GAP = 0.01


@dataclass(frozen=True)
class AxisGuarantee:
    """The peak of mu proved on the whole frequency axis, for every analyzed configuration.

    Every configuration's bound is proved by D-G scalings on frequency intervals that cover
    ``[0, inf)`` (:func:`~oos_drake.robust.mu_intervals.cover_axis`), all at a common level
    (at least ``floor``: the subset's certified lower bound plus the target gap, raised where
    a configuration's mu is above it). Configurations between the analyzed ones are NOT
    covered: they remain sampled.

    Attributes
    ----------
    mu_upper : float
        ``max`` over configurations of the proved level (``inf`` if one has no certificate).
    floor : float
        The common starting level [-]: ``min((1 + gap) mu_lower, (1 + tight) max(mu_lower,
        largest grid upper bound))`` (``gap``, ``tight``: see :func:`axis_guarantee`).
    levels : numpy.ndarray
        ``(N,)`` level proved for each configuration.
    points : numpy.ndarray
        ``(N,)`` frequencies whose scalings each configuration's cover tested.
    solved : numpy.ndarray
        ``(N,)`` of them optimized for the cover (the others: the grid's or the previous
        configuration's scalings).
    failures : tuple of str
        Configurations without a certificate and why (e.g. a pole on the imaginary axis).
    slack : float
        Relative slack above each point's bound.
    seconds : float
        Time the workers spent on this subset's covers [s] (the sum over its tasks of
        configurations; the covers of all the subsets of a study run in one map).
    models : numpy.ndarray
        ``(N,)`` the configurations (model indices) of ``levels``.
    grid_upper, grid_lower : numpy.ndarray
        ``(N,)`` each configuration's largest upper / lower bound on the analyzed frequencies.
    fallback : float
        The level ``(1 + gap) mu_lower`` covers restart from when they do not close at
        ``floor`` (NaN when ``floor`` is that level already).
    fell_back : numpy.ndarray
        ``(N,)`` True for the configurations whose cover was done again from ``fallback``.
    """

    mu_upper: float
    floor: float
    levels: np.ndarray
    points: np.ndarray
    failures: tuple
    slack: float
    seconds: float
    models: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    grid_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    grid_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    solved: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    fallback: float = float("nan")
    fell_back: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def covered(self) -> bool:
        """True when every configuration's cover closed (``mu_upper`` holds on the whole axis)."""
        return not self.failures

    @property
    def reason(self) -> str:
        """Why not (the configurations whose cover stayed open, one per line); empty when
        ``covered``."""
        return "\n".join(self.failures)

    @property
    def raised(self) -> int:
        """Configurations whose cover needed a level above ``floor``."""
        return int(np.sum(self.levels > self.floor * (1 + 1e-12)))


def _axis_task(task):
    """Worker: :func:`_range_covers` of one task ``(blk, floor, slack, configurations)`` ->
    ``(its list, seconds)``."""
    import time as _time

    clock = _time.perf_counter()
    out = _range_covers(*task)
    return out, _time.perf_counter() - clock


def _range_covers(blk, floor, slack, configurations, lazy_polish=True, fallback=None):
    """The covers of a range of neighbouring configurations, one after the other ->
    ``[(level, tested points, failure, solved points, fell back), ...]``.

    ``lazy_polish``: see :func:`~oos_drake.robust.mu_intervals.mu_solver` (False: the cost
    reference of ``benchmarks/bench_axis_guarantee.py``).

    ``fallback``: a higher starting level tried when a cover at ``floor`` does not close for
    want of scalings (``max_rounds`` rounds without a proof in a gap: a level so close to mu
    over a band that the intervals stay too narrow); not for a pole on the axis or an
    infinite level, which no level closes. The configuration's result is then the fallback
    cover's (``fell back`` True), a bound still proved on the whole axis.

    Each cover tries first the scalings that covered the previous configuration (its
    :meth:`~oos_drake.robust.mu_intervals.AxisCertificate.essential` points: neighbouring
    configurations are close problems, so they usually prove the same level on nearly the same
    intervals, with no optimization), then the grid's own scalings, and only then solves.
    """
    from oos_drake.robust.mu_intervals import Realization, cover_axis, mu_solver, scalings_at

    out, prior = [], None
    for A, Bw, Cz, Dzw, seeds, grid_omega, grid_params, grid_upper in configurations:
        real = Realization(A, Bw, Cz, Dzw)

        def grid_scalings(rows, real=real, w=grid_omega, params=grid_params):
            return scalings_at(real, blk, w[rows], params[rows])

        known = (grid_omega, grid_upper, grid_scalings)
        starts = (grid_omega, grid_params)

        def cover(level, seeds=seeds, real=real, prior=prior, known=known, starts=starts):
            # the grid's own scalings are the next candidates: no second optimization there
            # (evaluated only where the cover tries them); the peaks are solved only where
            # their grid bound is above the level
            peaks = seeds[0][seeds[1] * (1.0 + slack) > level]
            return cover_axis(
                real,
                mu_solver(
                    real,
                    blk,
                    slack=slack,
                    polish_above=level / (1 + slack),
                    starts=starts,
                    lazy_polish=lazy_polish,
                ),
                peaks,
                floor=level,
                slack=slack,
                known=known,
                prior=prior,
            )

        try:
            cert = cover(floor)
            fell_back = False
            if (
                not cert.covered
                and fallback is not None
                and fallback > floor
                and not np.any(np.isposinf(cert.optimal))  # no level closes it
                and not real.axis_poles().size
            ):
                cert, fell_back = cover(fallback), True
        except ValueError as err:
            out.append((np.inf, 0, str(err), 0, False))
            prior = None
            continue
        keep = cert.essential()
        prior = (cert.omega[keep], [cert.scalings[i] for i in keep]) if keep.size else None
        failure = cert.reason
        out.append(
            (float(cert.upper), int(cert.omega.size), failure, int(cert.added.sum()), fell_back)
        )
    return out


@dataclass(frozen=True)
class GuaranteeSubset:
    """What :func:`axis_guarantee` needs of one subset.

    Attributes
    ----------
    points : SubsetPoints
        The subset's points (their peaks seed each configuration's cover).
    parts : tuple
        ``(z rows, w columns, BLK)`` of the subset.
    lower : float
        The subset's certified lower bound (the levels of :func:`axis_guarantee` start from it).
    model_matrices : callable
        ``model -> (A, Bw, Cz, Dzw)`` of the subset's Delta channels.
    """

    points: object
    parts: tuple
    lower: float
    model_matrices: object


def axis_guarantee(pool, subsets: dict, slack=None, gap=None, tight=None) -> dict:
    """Prove the peak of mu of every configuration of each subset on the whole frequency axis.

    Parameters
    ----------
    pool : ModelPool
        Worker processes.
    subsets : dict
        Subset name -> :class:`GuaranteeSubset`.
    slack : float, optional
        Relative slack above each solved point's bound; default
        :data:`oos_drake.robust.mu_intervals.SLACK`.
    gap : float, optional
        Relative gap of the starting level above ``lower`` (default and at least ``slack``).
        The cost of the covers falls fast as it grows (a level close to mu over a wide band
        needs many narrow intervals); the analysis uses its target gap, so the guaranteed
        peak is within the target of the lower bound unless a configuration's mu is above it.
    tight : float, optional
        Relative margin of the first level tried above the subset's largest bound found so
        far, ``max(lower, largest grid upper bound)`` (default :data:`TIGHT_GAP`): each
        configuration's cover starts from ``min((1 + gap) lower, (1 + tight) max(...))`` and
        only a cover that does not close at it is done again from ``(1 + gap) lower``. Where
        the grid's upper bound is below the lower bound (the grid missed the peak, the lower
        bound found it) or close to it, the guaranteed level is then within about ``tight``
        of the peak instead of ``gap`` above the lower bound. None of the levels is assumed
        to hold: each configuration's cover raises its own level where its points need it.

    Returns
    -------
    dict
        Subset name -> :class:`AxisGuarantee`.

    Each configuration's cover starts from the grid's own scalings (an interval test each,
    no optimization: :func:`~oos_drake.robust.mu_intervals.scalings_at`); only the gaps they
    leave are solved, and the grid's peaks only where their grid bound is above the level.
    The covers of all the subsets go to the workers in one map (contiguous ranges of
    configurations, a few per worker and subset, the subsets with the largest ``M`` first), so
    that both workers stay busy to the end instead of waiting for each subset's last range;
    within a range each cover continues from the previous one.
    """
    from oos_drake.robust.mu_intervals import SLACK

    slack = SLACK if slack is None else float(slack)
    gap = slack if gap is None else max(float(gap), slack)
    tight = TIGHT_GAP if tight is None else float(tight)
    tasks, owner, prepared = [], [], {}
    # largest M first: the costly covers start first and the cheap ones fill the end
    order = sorted(subsets, key=lambda name: -len(subsets[name].parts[0]))
    for name in order:
        sub = subsets[name]
        pts, blk = sub.points, sub.parts[2]
        models = np.unique(pts.model)
        loose = (1.0 + gap) * max(float(sub.lower), 0.0)
        found = max(float(sub.lower), float(np.max(pts.upper, initial=0.0)), 0.0)
        floor = min(loose, (1.0 + tight) * found)
        fallback = loose if loose > floor * (1 + 1e-12) else None
        configurations = []
        for m in models:
            mine = pts.model == m
            w, up, lo = pts.omega[mine], pts.upper[mine], pts.lower[mine]
            # the peaks are solved (long runs where their bound is above the level) unless
            # their grid scalings prove the level already (:func:`_range_covers`)
            peaks = np.unique([np.argmax(up), np.argmax(lo)])
            seeds = (w[peaks], up[peaks])
            configurations.append((*sub.model_matrices(int(m)), seeds, w, pts.params[mine], up))
        # contiguous ranges (continuation from one configuration to the next), a few per
        # worker so that the costly ranges (configurations near the peak) spread over them
        n_ranges = min(len(configurations), CHUNKS_PER_WORKER * pool.n_jobs)
        bounds = np.linspace(0, len(configurations), n_ranges + 1).round().astype(int)
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            tasks.append((blk, floor, slack, configurations[a:b], True, fallback))
            owner.append(name)
        prepared[name] = (models, floor, fallback)
    done = pool.map(_axis_task, tasks)
    result = {}
    for name in subsets:
        models, floor, fallback = prepared[name]
        mine = [d for d, o in zip(done, owner, strict=True) if o == name]
        out = [o for chunk, _ in mine for o in chunk]
        pts = subsets[name].points
        levels = np.array([o[0] for o in out], dtype=float)
        failures = tuple(f"model {m}: {o[2]}" for m, o in zip(models, out, strict=True) if o[2])
        result[name] = AxisGuarantee(
            mu_upper=float(np.max(levels)) if levels.size else 0.0,
            floor=floor,
            levels=levels,
            points=np.array([o[1] for o in out], dtype=int),
            failures=failures,
            slack=slack,
            seconds=float(sum(t for _, t in mine)),
            models=models.astype(int),
            grid_upper=np.array([pts.upper[pts.model == m].max() for m in models], dtype=float),
            grid_lower=np.array([pts.lower[pts.model == m].max() for m in models], dtype=float),
            solved=np.array([o[3] for o in out], dtype=int),
            fallback=np.nan if fallback is None else fallback,
            fell_back=np.array([o[4] for o in out], dtype=bool),
        )
    return result


@dataclass(frozen=True)
class StudyResult:
    """mu bounds of one study (model array) with the certified peak of every subset.

    Attributes
    ----------
    table : pandas.DataFrame
        Columns :data:`~oos_drake.robust.tables.SWEEP_COLUMNS` (grid points plus the
        refinement points).
    certificates : dict
        Subset name -> :class:`PeakCertificate`.
    reports : dict
        Subset name -> :class:`~oos_drake.analysis.tightening.TightenReport`.
    timings : dict
        Seconds spent in ``grid``, ``tighten+certify`` and ``guarantee``.
    guarantees : dict
        Subset name -> :class:`AxisGuarantee` (empty with ``guarantee=False``).
    """

    table: pd.DataFrame
    certificates: dict
    reports: dict
    timings: dict = field(default_factory=dict)
    guarantees: dict = field(default_factory=dict)


def certified_sweep(
    sys,
    omega,
    subsets: dict,
    *,
    times=None,
    options: SweepOptions | None = None,
    tighten: TightenOptions | None = None,
    critical_iterations: int = 1000,
    progress: bool = True,
    description: str = "mu sweep",
    time_budget: float = float("inf"),
    guarantee: bool = False,
    guarantee_gap: float | None = None,
    guarantee_tight: float | None = None,
) -> StudyResult:
    """Grid sweep, spike resolution and certified peak of every subset.

    Parameters
    ----------
    sys : LFR
        Uncertain closed loop, a model array ``(N,)`` (or one model).
    omega : array_like
        Common frequency grid [rad/s].
    subsets : dict
        Subset name -> block names.
    times : array_like, optional
        Scheduling value of each model (label ``time [s]``).
    options : SweepOptions, optional
        Accuracy of the grid sweep and workers.
    tighten : TightenOptions, optional
        Target gap and effort of the spike resolution.
    critical_iterations : int
        BFGS iterations of the upper bound at the critical frequency of each certificate.
    progress : bool
        Progress bars.
    description : str
        Label of the progress bars.
    time_budget : float
        Wall-clock budget of the spike resolution of all subsets together [s]: each subset
        gets ``min(tighten.time_budget, what is left)`` (reported in its
        :class:`~oos_drake.analysis.tightening.TightenReport`).
    guarantee : bool
        Also prove each configuration's peak on the whole frequency axis
        (:func:`axis_guarantee`, timed as ``guarantee``).
    guarantee_gap : float, optional
        ``gap`` of :func:`axis_guarantee`: the level starts at ``(1 + guarantee_gap)`` times
        the certified lower bound (default the slack: tightest, most points; the analysis
        passes its target gap).
    guarantee_tight : float, optional
        ``tight`` of :func:`axis_guarantee` (default :data:`TIGHT_GAP`).

    Returns
    -------
    StudyResult
    """
    import dataclasses
    import time as _time

    from tqdm.auto import tqdm

    options = options or SweepOptions()
    if options.grid != "continued" or options.refine_iterations is None:
        raise ValueError(
            "certified_sweep: SweepOptions.grid must be 'continued' and refine_iterations set "
            "(the spike resolution restarts from every point's scalings)"
        )
    tighten = tighten or TightenOptions()
    omega, arrays, times = check_sweep_input(sys, omega, times, caller="mu_sweep", zero=False)
    n_models = arrays[0].shape[0]
    parts = subset_parts(sys, subsets)
    bmap_all = block_map(sys)
    timings = {}
    clock = _time.perf_counter()
    certificates, reports = {}, {}
    with ModelPool(arrays, options.n_jobs, options.scheduler) as pool:
        points, lowers = _grid_points(pool, n_models, omega, parts, options, progress, description)
        timings["grid"] = _time.perf_counter() - clock
        clock = _time.perf_counter()
        cache = {}

        def model_parts(model, name):
            key = (model, name)
            if key not in cache:
                cache[key] = _analysis_model(sys, model, subsets[name])
            return cache[key]

        bar = tqdm(
            total=len(parts), desc=f"{description}: certify", unit="subset", disable=not progress
        )
        spent = 0.0
        for name in parts:
            pts = points[name]

            def search(requests, name=name, pts=pts):
                tasks = []
                for model, w_peak in requests:
                    A, Bw, Cz, Dzw, blk, _, _ = model_parts(model, name)
                    u_model = float(pts.upper[pts.model == model].max())
                    alpha_max = max(8.0, 4.0 / max(u_model, 1e-9))
                    band = [w_peak / tighten.search_band, w_peak * tighten.search_band]
                    tasks.append((A, Bw, Cz, Dzw, blk, band, alpha_max))
                found = pool.map(_search_task, tasks)
                return [
                    LowerCertificate(float(d.mu_lower), int(m), float(d.omega), d.delta, "search")
                    if d.mu_lower > 0 and not np.isnan(d.omega)  # inf: ill-posed loop
                    else LowerCertificate()
                    for (m, _), d in zip(requests, found, strict=True)
                ]

            def note(rnd, spikes, name=name):
                bar.set_postfix_str(f"{name}: round {rnd}, {spikes} spike(s)")

            # the critical points of the subsets done so far: where mu peaks for a larger or
            # smaller set is a good place to look for this one's exact peak
            hints = [
                (c.model, 2 * np.pi * c.frequency)
                for c in certificates.values()
                if c.mu_lower > 0 and np.isfinite(c.frequency) and c.frequency > 0
            ]
            left = max(time_budget - spent, 1e-3)
            own = dataclasses.replace(tighten, time_budget=min(tighten.time_budget, left))
            lower, report = resolve_spikes(
                pool, pts, parts[name], lowers[name], search, own, progress=note, hints=hints
            )
            spent += report.seconds
            reports[name] = report
            certificates[name] = _certificate(
                pool,
                name,
                pts,
                parts[name],
                lower,
                times,
                model_parts,
                bmap_all.subset(list(subsets[name]))[0],
                critical_iterations,
                tighten.target_gap,
            )
            certificates[name] = _with_infinite_frequency(
                certificates[name],
                arrays[3],
                parts[name],
                bmap_all.subset(list(subsets[name]))[0],
                times,
                critical_iterations,
            )
            certificates[name] = _with_box_search(certificates[name], model_parts, name, times)
            bar.update(1)
        bar.close()
        timings["tighten+certify"] = _time.perf_counter() - clock
        clock = _time.perf_counter()
        guarantees = {}
        if guarantee:

            def matrices(model, name):
                A, Bw, Cz, Dzw = (x[model] for x in arrays)
                if A.size and np.max(np.linalg.eigvals(A).real) > -1e-9:
                    return model_parts(model, name)[:4]  # reduced: spurious near-zero modes
                zrows, wcols, _ = parts[name]
                return A, Bw[:, wcols], Cz[zrows], Dzw[np.ix_(zrows, wcols)]

            guarantees = axis_guarantee(
                pool,
                {
                    name: GuaranteeSubset(
                        points[name],
                        parts[name],
                        certificates[name].mu_lower,
                        lambda m, name=name: matrices(m, name),
                    )
                    for name in parts
                },
                gap=guarantee_gap,
                tight=guarantee_tight,
            )
            timings["guarantee"] = _time.perf_counter() - clock
    return StudyResult(sweep_table_of(points, times), certificates, reports, timings, guarantees)


def _certificate(
    pool, name, pts, parts, lower, times, model_parts, grid_map, iterations, target_gap
):
    """The :class:`PeakCertificate` of one subset from its resolved points and best lower bound."""
    zrows, wcols, blk = parts
    pts.sort()
    ipk = int(np.argmax(pts.upper))
    # polish the two points that make the certificate: the largest upper bound and the
    # critical point of the lower bound. Upper: from the point's own, its frequency
    # neighbours' and cold scalings; lower: power iteration with restarts from the result.
    targets = [(int(pts.model[ipk]), float(pts.omega[ipk]))]
    if lower.model >= 0:
        targets.append((lower.model, lower.omega))
    nb = neighbours(pts.model, pts.omega)
    models, omegas, sources, owners = [], [], [], []
    for t, (m, w) in enumerate(targets):
        same = np.flatnonzero(pts.model == m)
        # (an ill-posed crossing, w = inf, takes the highest analyzed frequency as its neighbour)
        w_near = min(max(w, 1e-9 * float(pts.omega.min())), float(pts.omega.max()))
        gap = np.abs(np.log(pts.omega[same] / w_near))
        j = same[np.argmin(gap)] if same.size else ipk
        for src in (j, nb[j, 0], nb[j, 1]):
            if src >= 0:
                models.append(m)
                omegas.append(w)
                sources.append(src)
                owners.append(t)
    owners = np.array(owners)
    warm = pool.bounds(
        PointTask(
            np.array(models),
            np.array(omegas),
            pts.params[np.array(sources)],
            zrows,
            wcols,
            blk,
            iterations,
            lower_restarts=8,
            lower_iterations=100,
        )
    )
    cold = pool.bounds(
        PointTask(
            np.array([m for m, _ in targets]),
            np.array([w for _, w in targets]),
            None,
            zrows,
            wcols,
            blk,
            iterations,
        )
    )
    best_up = [
        min(float(np.min(warm.upper[owners == t])), float(cold.upper[t]))
        for t in range(len(targets))
    ]
    if warm.best >= 0 and warm.lower[warm.best] > lower.value:
        k = warm.best
        lower = LowerCertificate(
            float(warm.lower[k]), int(models[k]), float(omegas[k]), warm.best_delta, "grid"
        )
    if best_up[0] < pts.upper[ipk]:
        pts.upper[ipk] = max(best_up[0], pts.lower[ipk])
    peak_upper = float(np.max(pts.upper))
    ipk = int(np.argmax(pts.upper))
    if lower.model < 0:
        # no destabilizing perturbation at all (mu = 0 everywhere the search looked)
        model, w_crit = int(pts.model[ipk]), float(pts.omega[ipk])
        up_crit = best_up[0]
    else:
        model, w_crit = lower.model, lower.omega
        at_crit = [
            best_up[t] for t, (m, w) in enumerate(targets) if m == model and np.isclose(w, w_crit)
        ]
        up_crit = min(at_crit) if at_crit else best_up[-1]
        if not at_crit:  # the lower bound moved to the peak point during the polish
            up_crit = best_up[0]
    up_crit = max(up_crit, lower.value)
    threshold = (1.0 + target_gap) * lower.value * (1 + 1e-12)
    normalized, worst = {}, {}
    if lower.value > 0 and lower.delta is not None:
        sub = model_parts(model, name)[5] if lower.source == "search" else grid_map
        worst, normalized = _named_perturbation(sub, lower.delta, w_crit)
    return PeakCertificate(
        name,
        int(model),
        float(times[model]),
        float(w_crit / (2 * np.pi)),
        max(peak_upper, up_crit),
        float(lower.value),
        up_crit,
        lower.delta if lower.delta is not None else np.zeros((0, 0), complex),
        worst,
        normalized,
        peak_model=int(pts.model[ipk]),
        peak_time=float(times[pts.model[ipk]]),
        peak_frequency=float(pts.omega[ipk] / (2 * np.pi)),
        source=lower.source,
        spikes_left=int(np.sum(pts.upper > threshold)) + int(up_crit > threshold),
    )


def _named_perturbation(sub, delta: np.ndarray, omega: float) -> tuple[dict, dict]:
    """Block name -> physical worst value, and -> normalized value (float for a ``ureal``, the
    complex matrix of a dynamic block), of a perturbation in the mussv layout of ``sub``."""
    structure = parse_blk(sub.blk)
    worst = worst_case_values(sub, structure, delta, omega)
    normalized = {}
    for name, kind, rows in zip(sub.names, sub.kinds, sub.blk_rows, strict=True):
        b = structure.blocks[rows[0]]
        block = delta[b.r_slice, b.c_slice]
        normalized[name] = float(block[0, 0].real) if kind == "ureal" else block.copy()
    return worst, normalized


#: Effort of the analysis's box search (:func:`_with_box_search`): the configurations' models
#: are large, the peak's lower bound already good; a light search keeps the analysis' cost.
BOX_SEARCH_EFFORT = dict(random_directions=32, local_starts=1, rounds=4, max_vertices=256)


def _with_box_search(cert, model_parts, name, times):
    """A better lower bound of a real-parameter subset's peak from the box searches.

    For subsets of ``ureal`` blocks only, the vertices, edges, random directions and a local
    search of the parameter box (:func:`~oos_drake.robust.worst_search.real_destabilizing`)
    at the critical configuration; a certified perturbation smaller than the peak's replaces
    it (``source = "box search"``).

    Parameters
    ----------
    cert : PeakCertificate
    model_parts : callable
        ``(model, subset name) -> (A, Bw, Cz, Dzw, blk, block map, reduced)``.
    name : str
        The subset.
    times : numpy.ndarray
        Scheduling value of each configuration.

    Returns
    -------
    PeakCertificate
    """
    import dataclasses

    from oos_drake.robust.worst_search import real_destabilizing

    if cert.model < 0 or (cert.mu_lower <= 0 and cert.mu_upper <= 0):
        return cert
    A, Bw, Cz, Dzw, blk, sub, _ = model_parts(cert.model, name)
    structure = parse_blk(blk)
    if any(b.kind != REAL for b in structure.blocks):
        return cert
    if A.size and np.max(np.linalg.eigvals(A).real) >= 0:
        return cert
    scale = 1.0 / cert.mu_lower if cert.mu_lower > 0 else 4.0 / cert.mu_upper
    found = real_destabilizing(A, Bw, Cz, Dzw, structure, scale=scale, **BOX_SEARCH_EFFORT)
    if found is None or found.mu_lower <= cert.mu_lower * (1 + 1e-12):
        return cert
    worst, normalized = _named_perturbation(sub, found.delta, found.omega)
    return dataclasses.replace(
        cert,
        frequency=float(found.omega / (2 * np.pi)),
        mu_lower=float(found.mu_lower),
        mu_upper=max(cert.mu_upper, found.mu_lower),
        mu_upper_critical=max(cert.mu_upper, found.mu_lower),  # the peak's bound holds there
        delta=found.delta,
        worst_case=worst,
        worst_case_normalized=normalized,
        source="box search",
    )


def _with_infinite_frequency(cert, Dzw, part, sub, times, iterations: int):
    """Add the point ``omega = inf`` (the loop's well-posedness) to a certified peak.

    A grid of finite frequencies misses a perturbation that makes ``I - Dzw delta`` singular:
    a pole then leaves through infinity (masses driven negative until a mass matrix is
    singular). Upper bounds of ``mu(Dzw)`` over all models, and the exact ill-posing vertex
    perturbation (:func:`~oos_drake.analysis.destabilizing.ill_posed_perturbation`) of the
    models with the largest ones, enter the peak like any other analyzed point.
    """
    import dataclasses

    from oos_drake.analysis.destabilizing import ill_posed_perturbation
    from oos_drake.robust import mussv

    zrows, wcols, blk = part
    M = np.ascontiguousarray(Dzw[:, zrows][:, :, wcols])
    upper = np.atleast_1d(mussv(M, blk).upper)
    k_up = int(np.argmax(upper))
    if upper[k_up] > cert.mu_upper:  # polish the one that would raise the peak
        upper[k_up] = min(upper[k_up], mussv(M[k_up], blk, upper_iterations=iterations).upper)
    changes = {}
    if upper[k_up] > cert.mu_upper:
        changes.update(
            mu_upper=float(upper[k_up]),
            peak_model=k_up,
            peak_time=float(times[k_up]),
            peak_frequency=np.inf,
        )
    candidates = [int(k) for k in np.argsort(upper)[::-1][:3] if upper[k] > cert.mu_lower]
    found = [(ill_posed_perturbation(M[k], blk), k) for k in candidates]
    found = [(d, k) for d, k in found if d.mu_lower > cert.mu_lower and d.residual <= 1e-6]
    if found:
        best, k = max(found, key=lambda pair: pair[0].mu_lower)
        worst, normalized = _named_perturbation(sub, best.delta, np.inf)
        changes.update(
            model=k,
            time=float(times[k]),
            frequency=np.inf,
            mu_lower=float(best.mu_lower),
            mu_upper_critical=float(max(upper[k], best.mu_lower)),
            delta=best.delta,
            worst_case=worst,
            worst_case_normalized=normalized,
            source="well-posedness",
        )
        changes["mu_upper"] = max(changes.get("mu_upper", cert.mu_upper), best.mu_lower)
    return dataclasses.replace(cert, **changes) if changes else cert


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
    peak_model : int
        Model of the largest upper bound (-1: same as ``model``).
    peak_time, peak_frequency : float
        Its scheduling value and frequency [Hz].
    source : str
        Where the lower bound comes from: ``"grid"`` (power iteration), ``"search"`` (direct
        search of a pole crossing), ``"box search"`` (vertices, edges and a local search of a
        real parameter box) or ``"well-posedness"`` (a perturbation making the loop
        ill-posed: ``frequency`` is then ``inf``).
    spikes_left : int
        Analyzed points whose upper bound still exceeds ``(1 + target gap) mu_lower``.
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
    peak_model: int = -1
    peak_time: float = float("nan")
    peak_frequency: float = float("nan")
    source: str = "search"
    spikes_left: int = 0

    @property
    def gap(self) -> float:
        """Honest gap of the peak: ``(max upper - best lower) / max upper`` over everything [-]."""
        up = self.mu_upper
        return (up - self.mu_lower) / up if up > 0 else 0.0

    @property
    def gap_critical(self) -> float:
        """Gap at the critical frequency ``(upper there - lower) / upper there`` [-]."""
        up = self.mu_upper_critical
        return (up - self.mu_lower) / up if up > 0 else 0.0
