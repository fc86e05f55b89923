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
    for it in range(1, max_iterations + 1):
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
            rho = 1.0 / sy
            Hy = H @ y
            H = H - rho * (np.outer(s, Hy) + np.outer(Hy, s)) + (rho * rho * (y @ Hy) + rho) * np.outer(s, s)
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
