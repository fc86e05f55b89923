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
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import (
    block_map,
    delta_channel_response,
    frequency_grid,
    worst_case_values,
)
from oos_drake.robust.mu_lower import mu_lower_bound
from oos_drake.robust.mu_upper import mu_upper_bound


@dataclass(frozen=True)
class WcGainResult:
    """Worst-case peak gain bounds.

    Attributes
    ----------
    lower : float
        Gain reached by ``worst_case`` (exact evaluation) at ``critical_frequency``.
    upper : float
        Guaranteed bound of the worst-case gain on the analyzed frequencies.
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

    Returns
    -------
    WcGainResult

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
        return WcGainResult(float("inf"), float("inf"), float("nan"), {}, {}, float("inf"))
    if omega is None:
        omega = np.concatenate([[0.0], frequency_grid(A, points_per_decade=points_per_decade)])
    omega = np.unique(np.asarray(omega, dtype=float))

    def evaluate(w):
        M = delta_channel_response(A, B, C, D, w)
        return skewed_gain_bounds(M, nz, nw, bmap.blk, tol=tol, upper_iterations=upper_iterations)

    lo, up, dl, nom = evaluate(omega)
    from oos_drake.robust.robstab import _refine

    for _ in range(refine_rounds):
        fin_up = np.where(np.isfinite(up), up, np.nanmax(np.where(np.isfinite(up), up, 0)) * 10 + 1)
        fin_lo = np.where(np.isfinite(lo), lo, np.nanmax(np.where(np.isfinite(lo), lo, 0)) * 10 + 1)
        new = np.setdiff1d(
            np.unique(np.concatenate([_refine(omega, fin_up), _refine(omega, fin_lo)])), omega
        )
        if new.size == 0:
            break
        l2, u2, d2, n2 = evaluate(new)
        omega = np.concatenate([omega, new])
        lo, up, dl, nom = (np.concatenate(x) for x in ((lo, l2), (up, u2), (dl, d2), (nom, n2)))
        order = np.argsort(omega)
        omega, lo, up, dl, nom = omega[order], lo[order], up[order], dl[order], nom[order]
    k = int(np.argmax(lo))
    structure = parse_blk(bmap.blk)
    worst = worst_case_values(bmap, structure, dl[k], float(omega[k]))
    worst_norm = {}
    for name, kind, rows in zip(bmap.names, bmap.kinds, bmap.blk_rows, strict=True):
        b = structure.blocks[rows[0]]
        sub = dl[k][b.r_slice, b.c_slice]
        worst_norm[name] = (
            float(sub[0, 0].real)
            if kind == "ureal"
            else (complex(sub[0, 0]) if kind == "ucomplex" else sub)
        )
    return WcGainResult(
        float(lo[k]),
        float(up.max()),
        float(omega[k]),
        worst,
        worst_norm,
        float(nom.max()),
        omega,
        lo,
        up,
    )
