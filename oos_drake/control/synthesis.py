"""Multi-model structured H-infinity synthesis of the static 3x6 attitude gain (Eq. controlreq).

.. math::

    \\min_{K \\in \\mathbb{R}^{3 \\times 6}} \\gamma, \\qquad
    \\gamma = \\max_{i,\\;\\delta \\in \\Delta_{real}}
    \\| F_l(P_{tot}(\\text{config}_i, \\delta), K) \\|_\\infty

Algorithm (MATLAB systune-like, in the open):

1. The *working set* starts with evenly spaced configurations at nominal parameters; after
   each optimizer run every configuration is checked and those above gamma join it (neighbouring
   configurations are similar, so few rounds are needed), so gamma holds for all of them.
2. Nonsmooth minimization of ``gamma(K)`` over the working set, in gains scaled by the
   baseline, from the baseline and from a few random restarts (log-normal perturbations).
   Default method: BFGS-SQP bundle steps (:func:`~oos_drake.control.nonsmooth_bfgs.
   minimize_bundle_bfgs`): the local model is the max of the linearizations of every peak
   within 10 % of gamma (each model's refined local maxima, and the second singular value when
   it nearly coalesces with the first), with Apkarian-Noll gradients from the singular vectors
   (:mod:`objective`), plus the pieces that block a rejected trial (null steps). The BFGS
   metric is updated with the gradients of the same peaks at fixed frequencies. Unstable
   loops give ``gamma = inf`` and are rejected by the line search (stability enforced). The
   metric is reset every 50 iterations; a stall (line search failed at a kink) is retried twice
   from a small deterministic perturbation of the best point. Each gamma evaluation samples the
   closed loops from the plants' modal form (:mod:`oos_drake.control.loop_response`): only the
   closed-loop eigenvalues are computed per gain.
3. Worst-case search over ``Delta_real`` (dynamic sampling): for the worst configurations,
   sample the parameter box (vertices and random points), then climb by projected
   finite-difference ascent; if a sample raises ``gamma`` by more than ``worst_case_rtol``, add
   it to the working set and go back to 2 (warm start). Stop when the worst case no longer
   increases ``gamma``.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from oos_drake.blas import with_single_threaded_blas
from oos_drake.control.components import DesignSpecification
from oos_drake.control.interconnection import WeightedInterconnection, weighted_interconnection
from oos_drake.control.nonsmooth_bfgs import (
    QP_SOLVERS,
    minimize_bundle_cycles,
    minimize_nonsmooth,
)
from oos_drake.control.objective import active_set, evaluate, loop_sigma, peak_gradients
from oos_drake.control.plants import PlantArray
from oos_drake.robust.peak_gain import PeakGain, peak_gain


@dataclass(frozen=True)
class SynthesisOptions:
    """Options of :func:`synthesize`.

    Attributes
    ----------
    restarts : int
        Random restarts besides the start point.
    restart_spread : float
        Standard deviation of the log-normal gain perturbation of a restart [-].
    max_iterations : int
        BFGS iterations per run.
    worst_case_rounds : int
        Maximum rounds of worst-case search over the real uncertainty.
    worst_case_configurations : int
        Configurations searched per round (the worst ones).
    worst_case_samples : int
        Random samples of the parameter box per configuration (vertices are added when there
        are at most 6 parameters).
    worst_case_ascent_steps : int
        Projected finite-difference ascent steps from the best sample.
    worst_case_rtol : float
        Relative increase of gamma that adds a worst case to the model set.
    seed : int
        Seed of the random restarts and samples.
    method : str
        ``"bundle"`` (BFGS-SQP on the active peaks) or ``"bfgs"`` (plain nonsmooth BFGS).
    working_set : int
        Configurations in the initial working set of the optimizer (evenly spaced, plus the
        worst one); ``0`` means all. After each run every configuration is checked and the
        ones above gamma join the set, so the result holds for all of them.
    configurations_per_round : int
        Largest number of violating configurations added per round.
    rtol_add : float
        Relative excess over gamma that makes a configuration a violator.
    max_rounds : int
        Total rounds (optimizer run + checks).
    workers : int
        Threads for the per-model eigendecompositions of every gamma evaluation (2 on the
        paper's 2-core target machine); the runs that :func:`synthesize` gives its executor
        share them (``workers // executor.workers`` each, at least one).
    qp : str
        Solver of the bundle step's dual QP (:data:`~oos_drake.control.nonsmooth_bfgs.
        QP_SOLVERS`): ``"slsqp"`` (default, SciPy's SLSQP: the published gamma) or
        ``"active-set"`` (exact, :func:`~oos_drake.control.nonsmooth_bfgs.simplex_qp`; the
        optimizer stops at its iteration limit, so the other steps give another local result,
        lower or higher: 0.353841 vs 0.353956 on the paper's scenario,
        0.354226 vs 0.353961 on 40 of its configurations, at 0.5-0.6x the CPU time;
        docs/ANALYSIS-RESULTS.md, synthesis speed).
    """

    restarts: int = 2
    restart_spread: float = 0.3
    max_iterations: int = 150
    worst_case_rounds: int = 4
    worst_case_configurations: int = 4
    worst_case_samples: int = 24
    worst_case_ascent_steps: int = 4
    worst_case_rtol: float = 1e-3
    seed: int = 0
    method: str = "bundle"
    working_set: int = 25
    configurations_per_round: int = 5
    rtol_add: float = 1e-3
    max_rounds: int = 12
    workers: int = 1
    qp: str = "slsqp"


@dataclass(frozen=True)
class ModelSet:
    """Plants in the synthesis set: configuration indices and physical parameter values."""

    config_index: np.ndarray
    values: np.ndarray

    def extend(self, config_index, values) -> ModelSet:
        """Return the set with more models."""
        return ModelSet(
            np.concatenate([self.config_index, np.atleast_1d(config_index)]),
            np.concatenate([self.values, np.atleast_2d(values)]),
        )


@dataclass(frozen=True)
class SynthesisResult:
    """Outcome of :func:`synthesize`.

    Attributes
    ----------
    K : numpy.ndarray, shape (3, 6)
        Tuned gain ``[K_p, K_d]`` [N m/rad, N m s/rad].
    gamma : float
        ``max ||M||_inf`` over the final model set (nominal configurations and worst cases).
    K_start : numpy.ndarray
        Starting gain (the baseline).
    gamma_start : float
        Its gamma over the nominal configurations.
    models : pandas.DataFrame
        One row per model of the final set: ``config``, configuration columns (``time [s]``),
        parameter columns (physical values, named by parameter), ``gamma [-]``,
        ``peak frequency [Hz]``, ``spectral abscissa [1/s]``, ``worst_case`` (added by the
        uncertainty search), ``active`` (within 1e-3 of gamma).
    runs : pandas.DataFrame
        One row per BFGS run: round, restart, gamma start/end, iterations, evaluations, message.
    worst_cases : pandas.DataFrame
        One row per worst-case search: round, config, parameter values, gamma found.
    wall_time_s : float
        Synthesis wall time [s].
    spec : DesignSpecification
    parameter_names : tuple of str
    """

    K: np.ndarray
    gamma: float
    K_start: np.ndarray
    gamma_start: float
    models: pd.DataFrame
    runs: pd.DataFrame
    worst_cases: pd.DataFrame
    wall_time_s: float
    spec: DesignSpecification
    parameter_names: tuple[str, ...] = field(default=())


def _interconnect(plants: PlantArray, models: ModelSet, spec) -> WeightedInterconnection:
    return weighted_interconnection(plants.evaluate(models.config_index, models.values), spec)


def gamma_over(
    plants: PlantArray, models: ModelSet, K, spec=None, *, certify=False, workers: int = 1
):
    """Per-model peak gains of the closed loops with gain ``K`` (a :class:`PeakGain`).

    ``certify`` checks each value with the Hamiltonian test (see :func:`peak_gain`);
    ``workers`` threads share the eigendecompositions.
    """
    W = _interconnect(plants, models, spec)
    M = W.close(K)
    return peak_gain(
        M.A, M.B, M.C, M.D, certify=certify, workers=workers, evaluator=loop_sigma(W, K)
    )


def _gain_scale(K0: np.ndarray) -> np.ndarray:
    """Per-entry scale: the diagonal magnitude of each block of the start gain."""
    Kp, Kd = K0[:, :3], K0[:, 3:]
    sp = np.mean(np.abs(np.diag(Kp))) or 1.0
    sd = np.mean(np.abs(np.diag(Kd))) or 1.0
    return np.hstack([np.full((3, 3), sp), np.full((3, 3), sd)])


@with_single_threaded_blas
def tune(
    interconnection: WeightedInterconnection,
    K0,
    *,
    max_iterations=150,
    scale=None,
    method: str = "bundle",
    eps: float = 0.1,
    restart_every: int = 50,
    restart_rtol: float = 1e-4,
    workers: int = 1,
    kicks: int = 2,
    kick: float = 0.05,
    qp: str = "slsqp",
):
    """Minimize ``gamma(K)`` over one interconnection array from ``K0``.

    ``max_iterations`` is the total budget; with the bundle method the BFGS metric is reset
    every ``restart_every`` iterations until a cycle improves gamma by less than
    ``restart_rtol`` (relative); then up to ``kicks`` cycles restart from the best point
    perturbed by ``kick`` (relative, Gaussian, seeded by the iteration count: deterministic)
    and the best point is kept (escapes stalls of the line search at kinks).

    ``method="bundle"`` (default): BFGS-SQP steps on the nearly active peaks
    (:func:`minimize_bundle_bfgs`); ``"bfgs"``: plain nonsmooth BFGS with one subgradient
    (:func:`minimize_nonsmooth`). ``workers``: threads of the eigendecompositions; ``qp``:
    the bundle step's QP solver (see :class:`SynthesisOptions`).
    Returns ``(K, gamma, BfgsResult)``.
    """
    K0 = np.asarray(K0, dtype=float)
    scale = _gain_scale(K0) if scale is None else scale
    x0 = (K0 / scale).ravel()
    if method == "bundle":
        recent = {}  # the last evaluations: each metric cycle and kick restarts from a point
        # evaluated shortly before (the same x, bit for bit; the optimizer does not modify results)

        def fun_active(x):
            key = x.tobytes()
            if key in recent:
                return recent[key]
            a = active_set(interconnection, x.reshape(3, 6) * scale, eps=eps, workers=workers)
            grads = (a.gradients * scale).reshape(a.values.size, -1)
            which = a.which if a.which is not None else np.zeros(a.values.size, int)
            if len(recent) >= 8:
                del recent[next(iter(recent))]
            recent[key] = result = (a.gamma, a.values, grads, (a.models, a.omegas, which))
            return result

        def regrad(x, pieces):
            models, omegas, which = pieces
            if not np.all(np.isfinite(omegas)):
                return np.full(models.size, -np.inf), np.zeros((models.size, x.size))
            values, grads = peak_gradients(
                interconnection, x.reshape(3, 6) * scale, models, omegas, which
            )
            return values, (grads * scale).reshape(models.size, -1)

        res = minimize_bundle_cycles(
            fun_active,
            x0,
            regrad=regrad,
            max_iterations=max_iterations,
            restart_every=restart_every,
            restart_rtol=restart_rtol,
            kicks=kicks,
            kick=kick,
            qp=QP_SOLVERS[qp],
        )
    elif method == "bfgs":

        def fun(x):
            ev = evaluate(interconnection, x.reshape(3, 6) * scale, workers=workers)
            return ev.gamma, (ev.gradient * scale).ravel()

        res = minimize_nonsmooth(fun, x0, max_iterations=max_iterations)
    else:
        raise ValueError(f"tune: method must be 'bundle' or 'bfgs', got {method!r}")
    return res.x.reshape(3, 6) * scale, res.f, res


def _worst_case_search(plants: PlantArray, configs, K, spec, options, rng):
    """Search the parameter box of each configuration for the largest gamma.

    Returns arrays ``(values (C, P), gamma (C,))``.
    """
    lower, upper = plants.bounds
    P = lower.size
    configs = np.asarray(configs)
    C = configs.size

    def gamma(repeat: int, values) -> np.ndarray:
        """Gamma of the configurations, each repeated ``repeat`` times, at ``values``."""
        models = ModelSet(np.repeat(configs, repeat), values)
        return gamma_over(plants, models, K, spec, workers=options.workers).gamma

    samples = [plants.nominal_values[None]]
    if P <= 6:
        samples.append(np.array(list(itertools.product(*zip(lower, upper, strict=True)))))
    samples.append(lower + (upper - lower) * rng.random((options.worst_case_samples, P)))
    samples = np.concatenate(samples)
    S = samples.shape[0]
    g = gamma(S, np.tile(samples, (C, 1))).reshape(C, S)
    best = np.argmax(g, axis=1)
    x = samples[best]
    fx = g[np.arange(C), best]
    width = upper - lower
    step = 0.25 * width
    h = 1e-4 * width
    for _ in range(options.worst_case_ascent_steps):
        # central differences, batched over configurations and parameters
        plus = np.clip(x[:, None, :] + np.eye(P) * h, lower, upper)
        minus = np.clip(x[:, None, :] - np.eye(P) * h, lower, upper)
        gp = gamma(2 * P, np.concatenate([plus, minus], axis=1).reshape(-1, P)).reshape(C, 2, P)
        denom = (plus - minus)[:, np.arange(P), np.arange(P)]
        grad = np.where(denom > 0, (gp[:, 0] - gp[:, 1]) / np.where(denom > 0, denom, 1), 0.0)
        grad = np.where(np.isfinite(grad), grad, 0.0)
        trial = np.clip(x + step * np.sign(grad), lower, upper)
        ft = gamma(1, trial)
        better = ft > fx
        x = np.where(better[:, None], trial, x)
        fx = np.where(better, ft, fx)
        step = np.where(better[:, None], step, 0.5 * step)
    return x, fx


def _final_peaks(plants, models: ModelSet, N: int, K, spec, workers: int, checked):
    """Certified peaks of ``models`` (the ``N`` nominal configurations, then the worst cases)
    at ``K``. ``checked``: ``(K', peaks of the N nominal configurations at K')`` of the last
    check; when ``K'`` is ``K`` those are reused and only the worst cases are evaluated (the
    values of a model do not depend on the others in the batch: the same numbers, up to
    round-off)."""
    if checked is None or not np.array_equal(checked[0], K):
        return gamma_over(plants, models, K, spec, certify=True, workers=workers)
    nominal = checked[1]
    if models.config_index.size == N:
        return nominal
    worst = ModelSet(models.config_index[N:], models.values[N:])
    more = gamma_over(plants, worst, K, spec, certify=True, workers=workers)
    return PeakGain(
        *(np.concatenate([getattr(nominal, f), getattr(more, f)]) for f in FINAL_FIELDS)
    )


#: The :class:`PeakGain` fields of the final table (its refined local maxima are not kept).
FINAL_FIELDS = ("gamma", "omega", "spectral_abscissa")


@with_single_threaded_blas
def _tune_start(interconnection: WeightedInterconnection, K_start, scale, options, threads: int):
    """One optimizer run of a round (an executor task): ``(gamma at the start, tune's result)``,
    the result ``None`` for an unstable start."""
    g0 = evaluate(interconnection, K_start, workers=threads).gamma
    if not np.isfinite(g0):
        return g0, None
    tuned = tune(
        interconnection,
        K_start,
        max_iterations=options.max_iterations,
        scale=scale,
        method=options.method,
        workers=threads,
        qp=options.qp,
    )
    return g0, tuned


def _tune_starts(interconnection, starts, scale, options: SynthesisOptions, executor) -> list:
    """:func:`_tune_start` of every start, in order: one start runs here with
    ``options.workers`` threads; several (the restarts) run as tasks of ``executor``, the
    threads shared among its workers."""
    if len(starts) == 1 or executor is None or executor.workers == 1:
        return [_tune_start(interconnection, Ks, scale, options, options.workers) for Ks in starts]
    threads = max(1, options.workers // executor.workers)
    tasks = [
        executor.submit(_tune_start, interconnection, Ks, scale, options, threads) for Ks in starts
    ]
    return [task.result() for task in tasks]


@with_single_threaded_blas
def synthesize(
    plants: PlantArray,
    K0,
    *,
    spec: DesignSpecification | None = None,
    options: SynthesisOptions | None = None,
    progress=None,
    executor=None,
) -> SynthesisResult:
    """Tune the static 3x6 gain over a plant array with real uncertainty (see module doc).

    Parameters
    ----------
    plants : PlantArray
        Configurations and real uncertain parameters.
    K0 : array_like, shape (3, 6)
        Start gain (the baseline); its closed loops must be stable.
    spec : DesignSpecification, optional
        Weights (paper values by default).
    options : SynthesisOptions, optional
    progress : callable, optional
        ``progress(message: str)`` for log lines.
    executor : optional
        Where the independent optimizer runs of a round (the start point and the random
        restarts) run as tasks (:func:`oos_drake.processes.make_executor`: process pool, Dask);
        ``None``: one after the other in this process. The result is the same either way.

    Returns
    -------
    SynthesisResult
    """
    start_time = time.perf_counter()
    spec = spec or DesignSpecification()
    options = options or SynthesisOptions()
    rng = np.random.default_rng(options.seed)
    log = progress or (lambda message: None)
    K0 = np.asarray(K0, dtype=float)
    if K0.shape != (3, 6):
        raise ValueError(f"synthesize: start gain K0 must be 3x6, got {K0.shape}")
    if options.qp not in QP_SOLVERS:
        raise ValueError(f"synthesize: qp must be one of {sorted(QP_SOLVERS)}, got {options.qp!r}")
    N = plants.size
    P = len(plants.parameters)
    nominal = np.broadcast_to(plants.nominal_values, (N, P)).copy()
    all_configs = ModelSet(np.arange(N), nominal)
    workers = options.workers
    start_peaks = gamma_over(plants, all_configs, K0, spec, workers=workers)
    gamma_start = float(np.max(start_peaks.gamma))
    if not np.isfinite(gamma_start):
        raise ValueError("synthesize: the start gain K0 does not stabilize every configuration")
    log(f"start gamma = {gamma_start:.6g} over {N} configurations")
    if 0 < options.working_set < N:
        spaced = np.round(np.linspace(0, N - 1, options.working_set)).astype(int)
        chosen = np.unique(np.append(spaced, np.argmax(start_peaks.gamma)))
    else:
        chosen = np.arange(N)
    working = ModelSet(chosen, nominal[chosen])
    worst = ModelSet(np.zeros(0, dtype=int), np.zeros((0, P)))
    scale = _gain_scale(K0)
    runs, worst_rows = [], []
    K_best, gamma_best, checked = K0, gamma_start, None
    worst_case_rounds = 0
    for round_ in range(options.max_rounds):
        W = _interconnect(plants, working, spec)
        starts = [K_best]
        for _ in range(options.restarts if round_ == 0 else 0):
            starts.append(K_best * np.exp(options.restart_spread * rng.normal(size=K0.shape)))
        for r, (g0, tuned) in enumerate(_tune_starts(W, starts, scale, options, executor)):
            run = dict(round=round_, restart=r, models=len(working.config_index), gamma_start=g0)
            if tuned is None:
                end = dict(gamma_end=np.inf, iterations=0, evaluations=1, message="unstable start")
                runs.append(run | end)
                continue
            K, g, res = tuned
            end = dict(gamma_end=g, iterations=res.iterations, evaluations=res.evaluations)
            runs.append(run | end | dict(message=res.message))
            log(
                f"round {round_} run {r}: gamma {g0:.6g} -> {g:.6g} over "
                f"{len(working.config_index)} models ({res.iterations} it, {res.message})"
            )
            if r == 0 or g < gamma_best:
                K_best, gamma_best = K, g
        # 1. every configuration at nominal parameters: add the violators to the working set
        peaks = gamma_over(plants, all_configs, K_best, spec, certify=True, workers=workers)
        checked = (K_best, peaks)  # the final table reuses it when K_best stays
        in_set = np.zeros(N, dtype=bool)
        in_set[
            working.config_index[np.all(working.values == nominal[working.config_index], axis=1)]
        ] = True
        violators = np.flatnonzero(~in_set & (peaks.gamma > gamma_best * (1 + options.rtol_add)))
        if violators.size:
            add = violators[np.argsort(-peaks.gamma[violators])][: options.configurations_per_round]
            working = working.extend(add, nominal[add])
            log(
                f"round {round_}: {violators.size} configuration(s) above gamma "
                f"(max {peaks.gamma.max():.6g}); {add.size} added"
            )
            continue
        # 2. worst case over the real uncertainty
        if P == 0 or worst_case_rounds >= options.worst_case_rounds:
            break
        worst_case_rounds += 1
        configs = np.argsort(-peaks.gamma)[: options.worst_case_configurations]
        values, gwc = _worst_case_search(plants, configs, K_best, spec, options, rng)
        for c, v, gv in zip(configs, values, gwc, strict=True):
            worst_rows.append(
                dict(
                    round=round_,
                    config=int(c),
                    gamma=float(gv),
                    **dict(zip([p.name for p in plants.parameters], v, strict=True)),
                )
            )
        new = gwc > gamma_best * (1.0 + options.worst_case_rtol)
        log(
            f"round {round_}: worst case gamma {gwc.max():.6g} vs {gamma_best:.6g}; "
            f"{int(new.sum())} model(s) added"
        )
        if not np.any(new):
            break
        working = working.extend(configs[new], values[new])
        worst = worst.extend(configs[new], values[new])

    models = all_configs.extend(worst.config_index, worst.values)
    added = np.concatenate([np.zeros(N, dtype=bool), np.ones(worst.config_index.size, dtype=bool)])
    final = _final_peaks(plants, models, N, K_best, spec, workers, checked)
    gamma = float(np.max(final.gamma))
    table = pd.DataFrame({"config": models.config_index})
    for j, p in enumerate(plants.parameters):
        table[p.name] = models.values[:, j]
    for column in plants.configurations.columns:
        table[column] = plants.configurations[column].to_numpy()[models.config_index]
    table["gamma [-]"] = final.gamma
    table["peak frequency [Hz]"] = final.omega / (2 * np.pi)
    table["spectral abscissa [1/s]"] = final.spectral_abscissa
    table["worst_case"] = added
    table["active"] = final.gamma >= gamma * (1.0 - 1e-3)
    return SynthesisResult(
        K=K_best,
        gamma=gamma,
        K_start=K0,
        gamma_start=gamma_start,
        models=table,
        runs=pd.DataFrame(runs),
        worst_cases=pd.DataFrame(worst_rows),
        wall_time_s=time.perf_counter() - start_time,
        spec=spec,
        parameter_names=tuple(p.name for p in plants.parameters),
    )
