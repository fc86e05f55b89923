r"""Worst-case peak gain of an uncertain LFR (MATLAB ``wcgain`` semantics), by skewed mu.

At each frequency, with ``M = [[M11, M12], [M21, M22]]`` the response from ``[w; u]`` to
``[z; y]``, the worst-case gain ``max_{||Delta|| <= 1} sigma_max(Fu(M, Delta))`` is bounded by

* upper: the smallest ``gamma`` with ``mu_upper([[M11, M12], [M21, M22] / gamma]) <= 1`` for the
  structure ``diag(Delta, Delta_perf)`` (``Delta`` kept at unit size, a full performance block:
  skewed mu), found by bisection on ``gamma``; ``inf`` when ``mu(M11) >= 1`` (not robustly
  stable);
* lower: ``sigma_max(Fu(M, Delta))`` evaluated exactly for the uncertainty part of the skewed-mu
  lower-bound perturbation, scaled to unit size (or the nominal gain if larger).

The peak over frequency is refined around the largest values; ``worst_case`` holds the named,
physical perturbation that achieves the lower bound at ``critical_frequency``.

With ``guaranteed=True`` (default) the upper bound holds on the whole frequency axis: the
skewed-mu scalings of a few frequencies prove the gain level on intervals computed exactly
(:mod:`oos_drake.robust.mu_intervals`, the performance outputs divided by the level, LMI at
``beta = 1``) and points are added until the intervals cover ``[0, inf)``. For models whose
analyzed blocks are all ``ureal``, the lower bound also searches the parameter box
(:func:`~oos_drake.robust.worst_search.real_worst_gain`: vertices, random points, a local
ascent), each candidate evaluated exactly by the H-infinity norm of the closed loop at those
values: a worst case far from the nominal poles (a corner of the box) is found, not a local
maximum near nominal. Where the gap stays above :data:`GAP_TARGET`, the lower bound gets more
search (a larger box search, more skewed-mu starts) and ``gap_note`` says why it remains.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import (
    block_map,
    delta_channel_response,
    frequency_grid,
    normalized_worst_case,
    worst_case_values,
)
from oos_drake.robust.mu_intervals import (
    POLISH_OPTIONS,
    SLACK,
    AxisCertificate,
    Realization,
    Scalings,
    cover_axis,
    proving_scalings,
)
from oos_drake.robust.mu_lower import mu_lower_bound
from oos_drake.robust.mu_upper import mu_upper_bound
from oos_drake.robust.sweep import peak_seeds, refined_grid
from oos_drake.robust.worst_search import real_worst_gain

#: Relative gap ``(upper - lower) / upper`` above which the lower bound gets more search.
GAP_TARGET = 0.05


@dataclass(frozen=True)
class WcGainResult:
    """Worst-case peak gain bounds.

    Attributes
    ----------
    lower : float
        Gain reached by ``worst_case`` (exact evaluation) at ``critical_frequency``.
    upper : float
        Guaranteed bound of the worst-case gain: on the whole frequency axis when
        ``guarantee`` is set, else on the analyzed frequencies only.
    critical_frequency : float
        Frequency [rad/s] of the lower bound.
    worst_case : dict
        Block name -> physical value (``ureal`` float, ``ucomplex`` complex, ``ultidyn``
        ``control.StateSpace``).
    worst_case_normalized : dict
        Block name -> normalized value at ``critical_frequency``.
    nominal : float
        Peak nominal gain over the analyzed frequencies.
    omega : numpy.ndarray
        Frequencies [rad/s].
    gain_lower, gain_upper : numpy.ndarray
        Bounds at each frequency.
    guarantee : AxisCertificate or None
        With ``guaranteed=True``: the intervals that prove ``upper`` on ``[0, inf)`` (levels of
        the gain; ``check()`` proves them again).
    covered : bool
        True when ``upper`` holds on the whole frequency axis (the cover closed).
    reason : str
        Why ``upper`` is not proved on the whole axis (empty when ``covered``).
    lower_source : str
        Which search attained ``lower``: ``"skewed mu"`` (the skewed-mu perturbation at a
        grid frequency), ``"restarts"`` (more starts of it), or the parameter-box search of
        :func:`~oos_drake.robust.worst_search.real_worst_gain` (``"vertex"``, ``"random"``,
        ``"center"``, ``"local"``).
    gap_note : str
        Empty when ``(upper - lower) / upper <=`` :data:`GAP_TARGET`; else why the gap stays
        (after the extra lower-bound searches).
    """

    lower: float
    upper: float
    critical_frequency: float
    worst_case: dict
    worst_case_normalized: dict = field(default_factory=dict)
    nominal: float = float("nan")
    omega: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gain_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gain_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    guarantee: AxisCertificate | None = None
    covered: bool = False
    reason: str = ""
    lower_source: str = "skewed mu"
    gap_note: str = ""

    def summary(self) -> str:
        """The bounds, the critical frequency and where the upper bound holds, one line."""
        where = (
            "proved on the whole frequency axis"
            if self.covered
            else f"NOT proved on the whole frequency axis ({self.reason})"
        )
        return (
            f"worst-case gain in [{self.lower:.6g}, {self.upper:.6g}], critical frequency "
            f"{self.critical_frequency:.6g} rad/s; upper bound {where}"
        )

    def __str__(self) -> str:
        return self.summary()


def _closed_gain(M11, M12, M21, M22, delta):
    """``sigma_max(M22 + M21 delta (I - M11 delta)^{-1} M12)`` (inf if singular), batched."""
    nz = M11.shape[-2]
    X = np.eye(nz) - M11 @ delta
    cond = np.linalg.cond(X)
    ok = np.isfinite(cond) & (cond < 1e12)
    G = np.array(M22, dtype=complex)
    if np.any(ok):
        G[ok] = M22[ok] + M21[ok] @ delta[ok] @ np.linalg.solve(X[ok], M12[ok])
    gain = np.linalg.norm(G, ord=2, axis=(-2, -1))
    return np.where(ok, gain, np.inf)


def skewed_gain_bounds(M, nz, nw, blk, *, tol=1e-3, upper_iterations=60, rng=None):
    """Worst-case gain bounds at each frequency for responses ``M`` ``(F, nz+ny, nw+nu)``.

    Returns
    -------
    lower, upper : arrays (F,)
    delta : array (F, nw, nz) normalized uncertainty reaching ``lower``
    """
    M = np.asarray(M, dtype=complex)
    F = M.shape[0]
    M11, M12 = M[:, :nz, :nw], M[:, :nz, nw:]
    M21, M22 = M[:, nz:, :nw], M[:, nz:, nw:]
    ny, nu = M22.shape[-2:]
    s_unc = parse_blk(blk)
    s_aug = parse_blk(np.vstack([np.asarray(blk).reshape(-1, 2), [[nu, ny]]]))
    nominal = np.linalg.norm(M22, ord=2, axis=(-2, -1))
    stab = mu_upper_bound(M11, s_unc, max_iter=upper_iterations).upper
    lower = nominal.copy()
    upper = np.full(F, np.inf)
    delta_best = np.zeros((F, nw, nz), dtype=complex)
    live = np.flatnonzero(stab < 1.0)

    def mu_at(idx, gamma):
        Mg = M[idx].copy()
        Mg[:, nz:, :] /= gamma[:, None, None]
        return mu_upper_bound(Mg, s_aug, max_iter=upper_iterations)

    if live.size:
        lo = np.maximum(nominal[live], 1e-300)
        hi = 2.0 * lo
        pending = np.ones(live.size, dtype=bool)
        for _ in range(60):  # grow the bracket until mu <= 1
            idx = np.flatnonzero(pending)
            if idx.size == 0:
                break
            ok = mu_at(live[idx], hi[idx]).upper <= 1.0
            lo[idx[~ok]] = hi[idx[~ok]]
            hi[idx[~ok]] *= 4.0
            pending[idx[ok]] = False
        while True:
            idx = np.flatnonzero(hi > lo * (1 + tol))
            if idx.size == 0:
                break
            mid = np.sqrt(lo[idx] * hi[idx])
            ok = mu_at(live[idx], mid).upper <= 1.0
            hi[idx[ok]] = mid[ok]
            lo[idx[~ok]] = mid[~ok]
        upper[live] = hi
        # lower bound: perturbation of the skewed problem at the upper level, evaluated exactly
        Mg = M[live].copy()
        Mg[:, nz:, :] /= hi[:, None, None]
        lb = mu_lower_bound(Mg, s_aug, rng=rng)
        d_unc = lb.delta[:, :nw, :nz]
        norms = np.linalg.norm(d_unc, ord=2, axis=(-2, -1))
        d_unit = np.where(
            (norms > 0)[:, None, None], d_unc / np.maximum(norms, 1e-300)[:, None, None], 0.0
        )
        gains = _closed_gain(M11[live], M12[live], M21[live], M22[live], d_unit)
        better = np.isfinite(gains) & (gains > lower[live])
        lower[live[better]] = gains[better]
        delta_best[live[better]] = d_unit[better]
    # not robustly stable at this frequency: a unit perturbation may make the loop singular
    dead = np.flatnonzero(stab >= 1.0)
    if dead.size:
        lb = mu_lower_bound(M11[dead], s_unc, rng=rng)
        destab = lb.lower >= 1.0
        lower[dead[destab]] = np.inf
        delta_best[dead[destab]] = lb.delta[destab]
    return lower, upper, delta_best, nominal


def wcgain(
    sys,
    omega=None,
    *,
    blocks=None,
    tol: float = 1e-3,
    points_per_decade: int = 30,
    refine_rounds: int = 1,
    upper_iterations: int = 60,
    guaranteed: bool = True,
    slack: float = SLACK,
) -> WcGainResult:
    """Worst-case peak gain of an uncertain LFR over its uncertainty (unit normalized size).

    Parameters
    ----------
    sys : LFR
        Uncertain model (one model); its inputs/outputs define the gain.
    omega : array_like, optional
        Frequencies [rad/s] (default: from the nominal poles, see :func:`frequency_grid`).
    blocks : sequence of str, optional
        Only these blocks vary; the others stay nominal.
    tol : float
        Relative accuracy of the bisection on the gain level.
    points_per_decade : int
        Density of the automatic grid.
    refine_rounds : int
        Rounds of refinement around the peaks of the lower and upper bounds.
    upper_iterations : int
        Iterations of each mu upper bound.
    guaranteed : bool
        Prove the upper bound on the whole frequency axis (and search the parameter box for
        the lower bound when all analyzed blocks are ``ureal``).
    slack : float
        Relative slack of the guaranteed bound above the level found at each point.

    Returns
    -------
    WcGainResult

    Raises
    ------
    ValueError
        For a model array, unknown blocks, or (``guaranteed=True``) a nominal pole within
        round-off of the imaginary axis.

    Examples
    --------
    >>> import control
    >>> from oos_drake.lfr import ureal
    >>> k = ureal("k", 1.0, plusminus=0.5)
    >>> res = wcgain(k * control.tf(1, [1, 1]))       # peak at omega = 0, k = 1.5
    >>> round(res.lower, 3), round(res.worst_case["k"], 3)
    (1.5, 1.5)
    """
    from oos_drake.lfr import as_lfr

    sys = as_lfr(sys)
    if sys.batch_shape:
        raise ValueError(f"wcgain: sys is a model array {sys.batch_shape}; loop over sys.model(k)")
    bmap = block_map(sys)
    A = np.asarray(sys.A)
    Bw, Bu, Cz, Cy = (np.asarray(x) for x in (sys.Bw, sys.Bu, sys.Cz, sys.Cy))
    Dzw, Dzu, Dyw, Dyu = (np.asarray(x) for x in (sys.Dzw, sys.Dzu, sys.Dyw, sys.Dyu))
    if blocks is not None:
        bmap, zrows, wcols = bmap.subset(list(blocks))
        Bw, Cz, Dzw = Bw[:, wcols], Cz[zrows, :], Dzw[np.ix_(zrows, wcols)]
        Dzu, Dyw = Dzu[zrows, :], Dyw[:, wcols]
    nz, nw = Dzw.shape
    B = np.concatenate([Bw, Bu], axis=1)
    C = np.concatenate([Cz, Cy], axis=0)
    D = np.block([[Dzw, Dzu], [Dyw, Dyu]])
    if A.size and np.any(np.linalg.eigvals(A).real >= 0):
        return WcGainResult(
            float("inf"), float("inf"), float("nan"), {}, {}, float("inf"), covered=True
        )
    if omega is None:
        omega = np.concatenate([[0.0], frequency_grid(A, points_per_decade=points_per_decade)])
    omega = np.unique(np.asarray(omega, dtype=float))

    def evaluate(w):
        M = delta_channel_response(A, B, C, D, w)
        return skewed_gain_bounds(M, nz, nw, bmap.blk, tol=tol, upper_iterations=upper_iterations)

    def finite(values):  # an infinite bound counts as a peak above every finite one
        big = np.nanmax(np.where(np.isfinite(values), values, 0)) * 10 + 1
        return np.where(np.isfinite(values), values, big)

    omega, (lo, up, dl, nom) = refined_grid(
        omega, evaluate(omega), evaluate, lambda a: (finite(a[1]), finite(a[0])), refine_rounds
    )
    k = int(np.argmax(lo))
    structure = parse_blk(bmap.blk)
    worst = worst_case_values(bmap, structure, dl[k], float(omega[k]))
    best_lower, critical = float(lo[k]), float(omega[k])
    guarantee, searched, search_source = None, None, "skewed mu"
    evaluations = 0
    all_real = all(kind == "ureal" for kind in bmap.kinds)
    seeds = np.union1d(peak_seeds(omega, np.where(np.isfinite(up), up, 0.0)), [critical])

    def box_search(effort):
        nonlocal best_lower, critical, searched, worst, search_source, evaluations
        if not (all_real and np.isfinite(best_lower)):
            return
        found = real_worst_gain(A, B, C, D, nz, nw, structure, seeds, **effort)
        if found is None:
            return
        evaluations += found.evaluations
        if found.gain > best_lower:
            best_lower, critical, search_source = found.gain, found.omega, found.source
            searched = dict(zip(bmap.names, found.x.tolist(), strict=True))
            worst = {
                name: float(spec.to_physical(searched[name]))
                for name, spec in zip(bmap.names, bmap.specs, strict=True)
            }

    box_search({})
    upper = float(up.max())
    covered, reason = False, "guaranteed=False: analyzed frequencies only"
    if guaranteed:
        real = Realization(A, B, C, D)
        ny = D.shape[0] - nz
        floor = (1.0 + slack) * best_lower if np.isfinite(best_lower) else np.inf
        if np.isfinite(floor):
            guarantee = cover_axis(
                real,
                _gain_solver(real, nz, nw, bmap.blk, slack, tol, upper_iterations, best_lower),
                seeds,
                floor=floor,
                slack=slack,
                performance_rows=ny,
            )
            covered = guarantee.covered
            if covered:
                upper, reason = guarantee.upper, ""
            else:  # the proved part and the grid, and why not the whole axis
                upper = max(upper, guarantee.upper_on_cover)
                reason = f"whole-axis cover open: {guarantee.reason}"
        else:
            upper, covered = np.inf, True
            reason = ""
    gap_note = ""
    if np.isfinite(upper) and upper > 0 and (upper - best_lower) / upper > GAP_TARGET:
        # more lower-bound work where the gap is: a larger box search (real parameters) or
        # the skewed-mu lower bound from more starts at the largest upper bounds
        before = best_lower
        if all_real:
            box_search(dict(random_points=4000, exact_points=200, local_starts=8))
        else:
            top = np.union1d(omega[np.argsort(-np.where(np.isfinite(up), up, 0.0))[:8]], [critical])
            M = delta_channel_response(A, B, C, D, top)
            for seed in range(1, 5):
                lo2, _, dl2, _ = skewed_gain_bounds(
                    M, nz, nw, bmap.blk, tol=tol, upper_iterations=upper_iterations,
                    rng=np.random.default_rng(seed),
                )  # fmt: skip
                evaluations += top.size
                j = int(np.argmax(lo2))
                if np.isfinite(lo2[j]) and lo2[j] > best_lower:
                    best_lower, critical, search_source = float(lo2[j]), float(top[j]), "restarts"
                    worst = worst_case_values(bmap, structure, dl2[j], critical)
                    searched = normalized_worst_case(bmap, structure, dl2[j])
        gap = (upper - best_lower) / upper
        if gap > GAP_TARGET:
            gap_note = (
                f"gap {100 * gap:.3g} % above {100 * GAP_TARGET:g} % after the extra lower-bound "
                f"searches (lower {before:.6g} -> {best_lower:.6g}, {evaluations} closed-loop "
                "evaluations): the lower bound is attained by worst_case; the upper bound (D-G "
                "scalings of skewed mu) may be conservative"
            )
    worst_norm = normalized_worst_case(bmap, structure, dl[k]) if searched is None else searched
    return WcGainResult(
        best_lower,
        max(float(upper), best_lower),
        critical,
        worst,
        worst_norm,
        float(nom.max()),
        omega,
        lo,
        up,
        guarantee,
        covered,
        reason,
        search_source,
        gap_note,
    )


def _gain_solver(real, nz, nw, blk, slack, tol, iterations, polish_above):
    """The ``solve`` of :func:`~oos_drake.robust.mu_intervals.cover_axis` for the worst-case gain.

    At each frequency: the skewed-mu bisection gives ``gamma`` (long optimizer runs where it
    exceeds ``polish_above``); the scalings are then computed for the problem whose performance
    rows are divided by ``L = (1 + slack) gamma`` and must prove ``mu < 1`` strictly there
    (else ``L`` grows by ``1 + slack``, at most five times; ``inf`` without a proof).
    """
    ny = real.D.shape[0] - nz
    s_aug = parse_blk(np.vstack([np.asarray(blk).reshape(-1, 2), [[real.D.shape[1] - nw, ny]]]))

    def solve(omega):
        M = real.response(omega)
        _, gamma, _, _ = skewed_gain_bounds(M, nz, nw, blk, tol=tol, upper_iterations=iterations)
        redo = np.flatnonzero(np.isfinite(gamma) & (gamma > polish_above))
        if redo.size:
            _, g2, _, _ = skewed_gain_bounds(
                M[redo], nz, nw, blk, tol=tol, upper_iterations=POLISH_OPTIONS["max_iter"]
            )
            gamma[redo] = np.minimum(gamma[redo], g2)
        level = (1.0 + slack) * gamma
        scalings = [None] * omega.size
        todo = np.flatnonzero(np.isfinite(level))
        for _ in range(5):
            if todo.size == 0:
                break
            Mg = M[todo].copy()
            Mg[:, nz:, :] /= level[todo, None, None]
            res = mu_upper_bound(Mg, s_aug, **POLISH_OPTIONS)
            ok = res.upper < 1.0 - 1e-9
            for j in np.flatnonzero(ok):
                i = todo[j]
                raw = Scalings(res.D_left[j], res.D_right[j], res.G[j])
                rows = slice(nz, real.D.shape[0])
                scalings[i] = proving_scalings(
                    real.scale_rows(rows, 1.0 / level[i]), raw, 1.0, omega[i]
                )
            level[todo[~ok]] *= 1.0 + slack
            todo = todo[~ok]
        level[todo] = np.inf
        return gamma, level, scalings

    return solve
