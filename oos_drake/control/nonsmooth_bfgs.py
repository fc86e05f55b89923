"""BFGS for nonsmooth, locally Lipschitz objectives (Lewis & Overton, 2013).

The H-infinity norm of a closed loop is nonsmooth in the gains (max over frequencies and
models). BFGS with an inexact *weak Wolfe* line search handles such max-functions well: the
inverse-Hessian approximation becomes ill-conditioned along the nonsmooth directions, which
is exactly what lets it progress along the "V-shaped" valleys (this is how HIFOO and, in
spirit, MATLAB's hinfstruct/systune proceed). ``f = inf`` (an unstable closed loop) is treated
as a failed sufficient-decrease test, so the search backtracks into the stable set.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class BfgsResult:
    """Outcome of :func:`minimize_nonsmooth`.

    Attributes
    ----------
    x : numpy.ndarray
        Best point found.
    f : float
        Objective at ``x``.
    iterations : int
        BFGS iterations done.
    evaluations : int
        Objective/gradient evaluations.
    history : tuple of float
        Objective after each iteration.
    message : str
        Why the iteration stopped.
    """

    x: np.ndarray
    f: float
    iterations: int
    evaluations: int
    history: tuple[float, ...]
    message: str


def _bfgs_update(H: np.ndarray, s: np.ndarray, y: np.ndarray, sy: float) -> np.ndarray:
    """The BFGS update of the inverse Hessian ``H`` from the step ``s`` and the gradient change
    ``y`` (``sy = s @ y > 0``; Nocedal-Wright (6.17))."""
    rho = 1.0 / sy
    Hy = H @ y
    return (
        H
        - rho * (np.outer(s, Hy) + np.outer(Hy, s))
        + (rho * rho * (y @ Hy) + rho) * np.outer(s, s)
    )


def _weak_wolfe(fun, x, f0, g0, d, c1=1e-4, c2=0.9, max_steps=40):
    """Bisection/expansion weak Wolfe line search; returns ``(t, x, f, g, evals, ok)``."""
    slope = float(g0 @ d)
    lo, hi, t = 0.0, np.inf, 1.0
    best = None
    for k in range(1, max_steps + 1):
        x_t = x + t * d
        f_t, g_t = fun(x_t)
        if np.isfinite(f_t) and (best is None or f_t < best[2]):
            best = (t, x_t, f_t, g_t)
        if not np.isfinite(f_t) or f_t > f0 + c1 * t * slope:
            hi = t
        elif float(g_t @ d) < c2 * slope:
            lo = t
        else:
            return t, x_t, f_t, g_t, k, True
        t = 0.5 * (lo + hi) if np.isfinite(hi) else 2.0 * lo
    if best is not None and best[2] < f0:
        return (*best, max_steps, False)
    return 0.0, x, f0, g0, max_steps, False


def minimize_nonsmooth(
    fun: Callable[[np.ndarray], tuple[float, np.ndarray]],
    x0,
    *,
    max_iterations: int = 200,
    rtol: float = 1e-7,
    stall_iterations: int = 15,
    initial_step: float = 0.05,
) -> BfgsResult:
    """Minimize ``fun`` (returning value and a (sub)gradient) by nonsmooth BFGS.

    Parameters
    ----------
    fun : callable
        ``x -> (f, g)``; ``f`` may be ``inf`` outside the feasible (stable) set.
    x0 : array_like
        Starting point (must give a finite ``f``).
    max_iterations : int
        Iteration limit.
    rtol : float
        Relative decrease below which an iteration counts as stalled.
    stall_iterations : int
        Stop after this many consecutive stalled iterations.
    initial_step : float
        Length of the first trial step (the initial inverse Hessian is scaled to it).
    """
    x = np.asarray(x0, dtype=float).copy()
    f, g = fun(x)
    evaluations = 1
    if not np.isfinite(f):
        raise ValueError("minimize_nonsmooth: the starting point is infeasible (f = inf)")
    n = x.size
    H = np.eye(n) * (initial_step / max(np.linalg.norm(g), 1e-300))
    history = [f]
    stalled = 0
    message = "iteration limit"
    it = 0
    for it in range(1, max_iterations + 1):  # noqa: B007 - reported after the loop
        d = -H @ g
        if not float(g @ d) < 0:
            H = np.eye(n) * (initial_step / max(np.linalg.norm(g), 1e-300))
            d = -H @ g
        t, x_new, f_new, g_new, k, ok = _weak_wolfe(fun, x, f, g, d)
        evaluations += k
        if t == 0.0:
            message = "line search failed (nonsmooth stationary point reached)"
            break
        s, y = x_new - x, g_new - g
        sy = float(s @ y)
        if sy > 1e-16 * np.linalg.norm(s) * np.linalg.norm(y):
            H = _bfgs_update(H, s, y, sy)
        decrease = f - f_new
        x, f, g = x_new, f_new, g_new
        history.append(f)
        stalled = stalled + 1 if decrease <= rtol * max(abs(f), 1e-12) else 0
        if stalled >= stall_iterations:
            message = "stalled"
            break
        if np.linalg.norm(s) <= 1e-12 * max(1.0, np.linalg.norm(x)):
            message = "step below tolerance"
            break
    return BfgsResult(x, float(f), it, evaluations, tuple(history), message)


def simplex_qp(Q, c):
    """``min_{lam in simplex} 1/2 lam^T Q lam - c^T lam`` (small dense QP, ``Q`` PSD).

    Primal active-set method: from the best vertex, solve the equality-constrained problem
    on the support (KKT system, least squares when ``Q`` is singular), step back to the first
    bound that a negative weight crosses, else add the index whose multiplier is most
    negative; exact (to rounding) in at most a few times ``k`` iterations. Falls back to
    :func:`simplex_qp_slsqp` on a singular inconsistent KKT system (degenerate support).
    The primal step ``d = -H G^T lam`` of the bundle method is unique even when ``lam`` is not.
    """
    k = c.size
    if k == 1:
        return np.ones(1)
    tol = 1e-12 * max(np.abs(Q).max(), np.abs(c).max(), 1e-300)
    i0 = int(np.argmin(0.5 * np.diag(Q) - c))
    lam = np.zeros(k)
    lam[i0] = 1.0
    support = [i0]
    for _ in range(20 * k + 50):
        s = np.array(support)
        m = s.size
        kkt = np.zeros((m + 1, m + 1))
        kkt[:m, :m] = Q[np.ix_(s, s)]
        kkt[:m, m] = kkt[m, :m] = 1.0
        rhs = np.append(c[s], 1.0)
        sol = np.linalg.lstsq(kkt, rhs, rcond=None)[0]
        if not np.allclose(kkt @ sol, rhs, rtol=0.0, atol=1e-9 * (1.0 + np.abs(rhs).max())):
            break
        target = sol[:m]
        if np.all(target >= 0):
            lam = np.zeros(k)
            lam[s] = target
            grad = Q @ lam - c
            violation = grad - grad[s].mean()  # multipliers of lam_j >= 0 off the support
            violation[s] = np.inf
            j = int(np.argmin(violation))
            if violation[j] >= -tol:
                return lam
            support.append(j)
            continue
        p = target - lam[s]
        ratios = np.full(m, np.inf)
        ratios[p < 0] = lam[s][p < 0] / -p[p < 0]
        b = int(np.argmin(ratios))
        lam[s] = lam[s] + ratios[b] * p
        lam[s[b]] = 0.0
        support = [i for i in support if lam[i] > 0]
        if not support:
            break
    return simplex_qp_slsqp(Q, c)


def simplex_qp_slsqp(Q, c):
    """:func:`simplex_qp` by SciPy's SLSQP (the default of the bundle method: the published
    results; and the fallback of the active-set method)."""
    from scipy.optimize import minimize

    k = c.size
    if k == 1:
        return np.ones(1)
    lam0 = np.full(k, 1.0 / k)
    res = minimize(
        lambda lam: 0.5 * lam @ Q @ lam - c @ lam,
        lam0,
        jac=lambda lam: Q @ lam - c,
        bounds=[(0.0, 1.0)] * k,
        constraints=[
            {"type": "eq", "fun": lambda lam: lam.sum() - 1.0, "jac": lambda lam: np.ones_like(lam)}
        ],
        method="SLSQP",
        options={"maxiter": 200, "ftol": 1e-14},
    )
    lam = np.clip(res.x, 0.0, None)
    return lam / lam.sum()


#: The bundle step's QP solvers by name (``SynthesisOptions.qp``, ``SystuneOptions.qp``).
QP_SOLVERS = {"active-set": simplex_qp, "slsqp": simplex_qp_slsqp}


def minimize_bundle_bfgs(
    fun: Callable,
    x0,
    *,
    regrad: Callable | None = None,
    max_iterations: int = 200,
    rtol: float = 1e-6,
    initial_step: float = 0.05,
    max_backtracks: int = 30,
    stall_window: int = 10,
    stall_rtol: float = 1e-5,
    max_enrich: int = 3,
    merge: Callable | None = None,
    qp: Callable = simplex_qp_slsqp,
) -> BfgsResult:
    """Minimize a max of smooth functions from its nearly active pieces (BFGS-SQP step).

    At each iterate ``fun`` returns the objective ``f``, the values ``f_k`` and gradients
    ``g_k`` of the pieces within a tolerance of the max (for the H-infinity norm: the peaks of
    the worst models at their peak frequencies) and an identifier of the pieces. The step
    minimizes the local model ``max_k (f_k + g_k^T d) + 1/2 d^T H^-1 d`` (solved in its dual over
    the simplex), as in Apkarian-Noll's nonsmooth H-infinity method; ``H`` is a BFGS
    inverse-Hessian estimate of the Lagrangian ``sum_k lambda_k f_k``: when ``regrad`` is given,
    the gradients of the same pieces (same models, same frequencies) are recomputed at the new
    point for the update, as in BFGS-SQP. A backtracking line search on the true ``f``
    (``inf`` = unstable, rejected) accepts the step. Stops when the predicted decrease falls
    below ``rtol * f``.

    Parameters
    ----------
    fun : callable
        ``x -> (f, values (k,), gradients (k, n), pieces)``.
    x0 : array_like
        Starting point (finite ``f``).
    regrad : callable, optional
        ``(x, pieces) -> (values (k,), gradients (k, n))`` of the given pieces at ``x``. Used
        for the BFGS update and for *null steps*: when a trial point is rejected, the pieces
        active there are evaluated at ``x`` and join the local model (at most ``max_enrich``
        times per iteration) before backtracking, as bundle methods do.
    merge : callable, optional
        ``(pieces, more_pieces) -> pieces`` (default: concatenate tuples of arrays).
    qp : callable
        ``(Q, c) -> lam``, the solver of the step's dual (default :func:`simplex_qp_slsqp`;
        :func:`simplex_qp` is exact).
    stall_window, stall_rtol : int, float
        Also stop when ``f`` decreased by less than ``stall_rtol`` (relative) over the last
        ``stall_window`` iterations.
    """
    if merge is None:

        def merge(a, b):
            return tuple(np.concatenate([u, v]) for u, v in zip(a, b, strict=True))

    x = np.asarray(x0, dtype=float).copy()
    f, vals, grads, pieces = fun(x)
    evaluations = 1
    if not np.isfinite(f):
        raise ValueError("minimize_bundle_bfgs: the starting point is infeasible (f = inf)")
    n = x.size

    def fresh_metric(g):
        return np.eye(n) * (initial_step / max(np.linalg.norm(g), 1e-300))

    H = fresh_metric(grads[0])
    fresh = True

    def step(H, f, vals, grads):
        lam = qp(grads @ H @ grads.T, vals - f)
        d = -H @ (lam @ grads)
        model = np.max(vals + grads @ d)
        return d, lam, f - model

    d, lam, predicted = step(H, f, vals, grads)
    history = [f]
    message = "iteration limit"
    iterations = 0
    for iterations in range(1, max_iterations + 1):  # noqa: B007 - reported after the loop
        if predicted <= rtol * abs(f):
            message = "predicted decrease below tolerance (stationary)"
            break
        t, accepted, enriched = 1.0, False, 0
        for _ in range(max_backtracks):
            x_t = x + t * d
            f_t, vals_t, grads_t, pieces_t = fun(x_t)
            evaluations += 1
            if np.isfinite(f_t) and f_t <= f - 1e-4 * t * predicted:
                accepted = True
                break
            if regrad is not None and np.isfinite(f_t) and enriched < max_enrich:
                # null step: the pieces that blocked the trial join the local model at x
                vals_new, grads_new = regrad(x, pieces_t)
                vals = np.concatenate([vals, vals_new])
                grads = np.concatenate([grads, grads_new])
                pieces = merge(pieces, pieces_t)
                enriched += 1
                d, lam, predicted = step(H, f, vals, grads)
                if predicted <= rtol * abs(f):
                    break
                t = 1.0
                continue
            t *= 0.5
        if not accepted:
            if not fresh:
                H = fresh_metric(lam @ grads)
                fresh = True
                d, lam, predicted = step(H, f, vals, grads)
                continue
            message = "line search failed"
            break
        s = x_t - x
        if regrad is not None:
            y = lam @ (regrad(x_t, pieces)[1] - grads)
        else:
            y = grads_t[0] - grads[0]
        x, f, vals, grads, pieces = x_t, f_t, vals_t, grads_t, pieces_t
        history.append(f)
        sy = float(s @ y)
        if sy > 1e-12 * np.linalg.norm(s) * np.linalg.norm(y):
            if fresh:  # Nocedal-Wright (6.20): size the first metric from the curvature seen
                H = np.eye(n) * (sy / float(y @ y))
                fresh = False
            H = _bfgs_update(H, s, y, sy)
        d, lam, predicted = step(H, f, vals, grads)
        if len(history) > stall_window and (history[-stall_window - 1] - f <= stall_rtol * abs(f)):
            message = f"stalled (< {stall_rtol:g} relative decrease in {stall_window} iterations)"
            break
    return BfgsResult(x, float(f), iterations, evaluations, tuple(history), message)


def minimize_bundle_cycles(
    fun: Callable,
    x0,
    *,
    regrad: Callable | None = None,
    max_iterations: int = 150,
    restart_every: int = 50,
    restart_rtol: float = 1e-4,
    kicks: int = 2,
    kick: float = 0.05,
    qp: Callable = simplex_qp_slsqp,
) -> BfgsResult:
    """:func:`minimize_bundle_bfgs` in metric cycles, then kicks (escapes stalls at kinks).

    ``max_iterations`` is the total budget; the BFGS metric is reset every ``restart_every``
    iterations until a cycle improves ``f`` by less than ``restart_rtol`` (relative): the metric
    goes stale along valleys. Then up to ``kicks`` cycles restart from the best point perturbed
    by ``kick`` (relative to its mean magnitude, Gaussian, seeded by the iteration count:
    deterministic; a kick to ``f = inf`` is discarded) and the best point is kept.

    Parameters
    ----------
    fun, regrad, qp : callable
        As for :func:`minimize_bundle_bfgs`.
    x0 : array_like
        Starting point (finite ``f``).

    Returns
    -------
    BfgsResult
        ``iterations`` counts every cycle's; ``message`` the number of cycles and the last
        one's reason.
    """
    x = x_best = np.asarray(x0, dtype=float)
    f_best, used, history, evaluations, messages, kicks_left = None, 0, [], 0, [], kicks
    while used < max_iterations:
        res = minimize_bundle_bfgs(
            fun,
            x,
            regrad=regrad,
            max_iterations=min(restart_every, max_iterations - used),
            qp=qp,
        )
        used += res.iterations
        evaluations += res.evaluations
        messages.append(res.message)
        improved = f_best is None or res.f < f_best * (1.0 - restart_rtol)
        if f_best is None or res.f < f_best:
            history.extend(res.history if not history else (res.f,))
            x_best, f_best = res.x, res.f
        if improved and res.iterations > 0:
            x = x_best
            continue
        x = None
        while kicks_left > 0 and x is None:
            kicks_left -= 1
            rng = np.random.default_rng([used, kicks_left])
            trial = x_best + kick * np.abs(x_best).mean() * rng.normal(size=x_best.shape)
            evaluations += 1
            if np.isfinite(fun(trial)[0]):  # else it destabilized a loop
                x = trial
        if x is None:
            break
    if not history:  # no budget: the start point
        return BfgsResult(x_best, float(fun(x_best)[0]), 0, 1, (), "no iteration")
    return BfgsResult(
        x_best,
        history[-1],
        used,
        evaluations,
        tuple(history),
        f"{len(messages)} metric cycle(s); last: {messages[-1]}",
    )
