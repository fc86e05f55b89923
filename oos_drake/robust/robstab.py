r"""Robust stability margin of an uncertain LFR (MATLAB ``robstab`` semantics).

The stability margin is the factor by which the normalized uncertainty can grow before the loop
goes unstable: ``margin = 1 / max_omega mu(M11(j omega))``. A margin above 1 means the loop is
stable for the whole modeled uncertainty. The bounds:

* ``lower = 1 / max mu_upper``: with ``guaranteed=True`` (default) over the whole frequency
  axis (:mod:`oos_drake.robust.mu_intervals`: the D-G scalings of a few frequencies prove the
  bound on intervals computed exactly from a Hamiltonian, points are added until the intervals
  cover ``[0, inf)``; ``guarantee`` holds them); with ``guaranteed=False`` over the (refined)
  frequency grid only,
* ``upper = 1 / max mu_lower``: a perturbation of that size, returned in ``worst_case`` (named,
  physical values), puts a closed-loop pole on the imaginary axis at ``critical_frequency``.

Frequencies are chosen from the system's poles (log grid, dense clusters around lightly damped
poles, ``omega = 0``) and refined around the peaks of both bounds.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from oos_drake.robust.lfr_analysis import (
    block_map,
    delta_channel_response,
    frequency_grid,
    normalized_worst_case,
    worst_case_values,
)
from oos_drake.robust.mu import mussv
from oos_drake.robust.mu_intervals import SLACK, AxisCertificate, Realization, cover_axis, mu_solver
from oos_drake.robust.tables import sweep_table


@dataclass(frozen=True)
class RobStabResult:
    """Robust stability margin bounds.

    Attributes
    ----------
    lower : float
        Guaranteed margin (``1 / peak mu_upper``; ``inf`` if mu = 0): on the whole frequency
        axis when ``guarantee`` is set, else on the analyzed frequencies only.
    upper : float
        Margin of the destabilizing perturbation ``worst_case`` (``1 / peak mu_lower``).
    critical_frequency : float
        Frequency [rad/s] at which ``worst_case`` destabilizes (closed-loop pole ``j omega``).
    worst_case : dict
        Block name -> destabilizing value: physical value (float) for ``ureal``, complex for
        ``ucomplex``, a stable ``control.StateSpace`` for ``ultidyn`` (norm = bound * upper).
    worst_case_normalized : dict
        Block name -> normalized value (scalar or matrix at ``critical_frequency``).
    nominal_stable : bool
        False when the nominal closed loop is already unstable (margins 0).
    omega : numpy.ndarray
        Analyzed frequencies [rad/s] (sorted).
    mu_upper, mu_lower : numpy.ndarray
        Bounds of mu at ``omega``.
    guarantee : AxisCertificate or None
        The intervals that prove ``mu <= 1 / lower`` on ``[0, inf)`` (``guaranteed=True``):
        which points were solved (``added`` where the cover added them), at which level, on
        which interval; ``guarantee.check()`` proves it again.
    """

    lower: float
    upper: float
    critical_frequency: float
    worst_case: dict
    worst_case_normalized: dict = field(default_factory=dict)
    nominal_stable: bool = True
    omega: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    mu_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    guarantee: AxisCertificate | None = None

    def table(self, subset: str = "total", time: float = float("nan")):
        """The analyzed frequencies as a mu sweep table (:func:`~.tables.sweep_table`).

        Parameters
        ----------
        subset : str
            Label of the analyzed blocks (``subset`` column).
        time : float
            Mission time [s] (or scheduling value) of the model.

        Returns
        -------
        pandas.DataFrame
            One row per analyzed frequency (model 0, ``tightened`` everywhere), plus
            :data:`~oos_drake.robust.tables.GUARANTEE_COLUMNS` when ``guarantee`` is set.
        """
        return sweep_table(
            subset=subset,
            model=0,
            time=time,
            omega=self.omega,
            upper=self.mu_upper,
            lower=self.mu_lower,
            guaranteed=None if self.guarantee is None else self.guarantee.upper,
            guarantee_points=None if self.guarantee is None else self.guarantee.omega.size,
        )


def _refine(omega, values, count=4, points=12):
    """New frequencies next to the ``count`` highest local maxima of ``values``."""
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


def _merged(omega, arrays, new, new_arrays):
    """``omega`` and its per-frequency ``arrays`` with the points ``new`` added, sorted (stable)."""
    omega = np.concatenate([omega, new])
    order = np.argsort(omega, kind="stable")
    merged = (np.concatenate(pair)[order] for pair in zip(arrays, new_arrays, strict=True))
    return omega[order], tuple(merged)


def _refined_grid(omega, arrays, evaluate, curves, rounds):
    """Per-frequency ``arrays`` on a grid refined ``rounds`` times next to the highest peaks of
    ``curves(arrays)``; ``evaluate(new)`` returns the arrays at new frequencies."""
    for _ in range(rounds):
        new = np.concatenate([_refine(omega, values) for values in curves(arrays)])
        new = np.setdiff1d(np.unique(new), omega)
        if new.size == 0:
            break
        omega, arrays = _merged(omega, arrays, new, evaluate(new))
    return omega, arrays


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

    if omega.size < 2:
        return np.zeros(0), np.zeros(0), np.zeros((0, structure.n_rows, structure.n_cols))

    def top_peaks(values):
        interior = np.r_[True, values[1:] >= values[:-1]] & np.r_[values[:-1] >= values[1:], True]
        peaks = np.flatnonzero(interior)
        return peaks[np.argsort(values[peaks])[::-1][:count]]

    # candidates: peaks of the upper bound, and peaks of |lambda| of the best unit perturbation
    # (real parameters at a vertex) whatever its phase: continuous in omega where mu is not
    Mall = delta_channel_response(A, Bw, Cz, Dzw, omega)
    raw = mu_lower_bound(Mall, structure, restarts=2, iters=40)
    dn_all = np.max(structure.block_norms(raw.raw_delta), axis=1)
    score = np.where(dn_all > 0, np.abs(raw.raw_lambda) / np.maximum(dn_all, 1e-300), 0.0)
    score = np.where(np.isfinite(score), score, 0.0)
    peaks = np.unique(np.concatenate([top_peaks(up), top_peaks(score)]))
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
    if not out_w:
        return np.zeros(0), np.zeros(0), np.zeros((0, structure.n_rows, structure.n_cols))
    return np.array(out_w), np.array(out_lo), np.array(out_d)


def _polish_peaks(A, Bw, Cz, Dzw, structure, omega, up, lo, count=4, rounds=2):
    """Long runs of the upper bound at the highest peaks (the margin depends on the max only).

    Ill-conditioned matrices (lightly damped modes with repeated real parameters) need hundreds
    of iterations; spending them on a few frequencies keeps the sweep fast.
    """
    from oos_drake.robust.mu_upper import mu_upper_bound

    up = up.copy()
    done = set()
    for _ in range(rounds):
        order = [int(i) for i in np.argsort(up)[::-1] if int(i) not in done][:count]
        if not order:
            break
        Mk = delta_channel_response(A, Bw, Cz, Dzw, omega[order])
        better = mu_upper_bound(
            Mk, structure, max_iter=600, temperatures=(30.0, 300.0, 3000.0)
        ).upper
        for i, value in zip(order, better, strict=True):
            up[i] = max(min(up[i], value), lo[i])
            done.add(i)
        if int(np.argmax(up)) in done:
            break
    return up


def _refined_sweep(A, Bw, Cz, Dzw, blk, omega, *, refine_rounds=2, mu_options=None):
    """mu bounds of ``M11(j omega)`` on a grid refined around the peaks (single model).

    Returns
    -------
    omega, upper, lower, deltas : arrays (sorted by frequency); ``deltas`` ``(F, r, c)``.
    """
    mu_options = mu_options or {}
    omega = np.unique(np.asarray(omega, dtype=float))
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)
    res = mussv(M, blk, **mu_options)

    def evaluate(new):
        rn = mussv(delta_channel_response(A, Bw, Cz, Dzw, new), blk, **mu_options)
        return np.atleast_1d(rn.upper), np.atleast_1d(rn.lower), rn.delta

    first = (np.atleast_1d(res.upper), np.atleast_1d(res.lower), res.delta)
    omega, (up, lo, dl) = _refined_grid(omega, first, evaluate, lambda a: a[:2], refine_rounds)
    up = _polish_peaks(A, Bw, Cz, Dzw, res.structure, omega, up, lo)
    if res.structure.has_real:
        wx, lx, dx = _frequency_crossings(A, Bw, Cz, Dzw, res.structure, omega, up, lo)
        if wx.size:
            # mu_upper at the crossing frequencies too, so that lower <= upper holds pointwise
            ux = np.atleast_1d(
                mussv(delta_channel_response(A, Bw, Cz, Dzw, wx), res.structure, **mu_options).upper
            )
            omega, (up, lo, dl) = _merged(omega, (up, lo, dl), wx, (np.maximum(ux, lx), lx, dx))
    return omega, up, lo, dl, res.structure


def robstab(
    sys,
    omega=None,
    *,
    blocks=None,
    points_per_decade: int = 40,
    refine_rounds: int = 2,
    mu_options: dict | None = None,
    guaranteed: bool = True,
    slack: float = SLACK,
) -> RobStabResult:
    """Robust stability margin of an uncertain LFR.

    Parameters
    ----------
    sys : LFR
        Closed-loop uncertain model (one model; use :func:`robust_sweep` for model arrays). Its
        inputs and outputs play no part.
    omega : array_like, optional
        Frequencies [rad/s]; default: chosen from the poles of the nominal model.
    blocks : sequence of str, optional
        Analyze only these uncertain blocks (the others stay at their nominal value).
    points_per_decade : int
        Density of the automatic logarithmic grid.
    refine_rounds : int
        Rounds of local refinement around the peaks of the bounds.
    mu_options : dict, optional
        Options passed to :func:`~oos_drake.robust.mussv`.
    guaranteed : bool
        Prove the upper bound of mu (so the margin ``lower``) on the whole frequency axis, not
        only on the grid (see :func:`~oos_drake.robust.mu_intervals.cover_axis`).
    slack : float
        Relative slack of the guaranteed bound above the bound found at each point
        (``lower`` is about ``1 / (1 + slack)`` times the exact D-G margin at best).

    Returns
    -------
    RobStabResult

    Raises
    ------
    ValueError
        If ``sys`` is a model array, has no uncertain blocks, or names unknown blocks; with
        ``guaranteed=True``, if the nominal model has a pole within round-off of the
        imaginary axis (no frequency-axis certificate exists).

    Examples
    --------
    >>> import control
    >>> from oos_drake.lfr import ureal, feedback
    >>> k = ureal("k", 40.0, plusminus=10.0)                     # stable for -6 < k < 60
    >>> loop = feedback(k * control.tf(1, [1, 6, 11, 6]), 1)
    >>> res = robstab(loop)
    >>> round(res.upper, 3), round(res.worst_case["k"], 2), round(res.critical_frequency, 3)
    (2.0, 60.0, 3.317)
    """
    from oos_drake.lfr import as_lfr

    sys = as_lfr(sys)
    if sys.batch_shape:
        raise ValueError(f"robstab: sys is a model array {sys.batch_shape}; use robust_sweep")
    bmap = block_map(sys)
    A, Bw, Cz, Dzw = (np.asarray(x) for x in (sys.A, sys.Bw, sys.Cz, sys.Dzw))
    if blocks is not None:
        bmap, zrows, wcols = bmap.subset(list(blocks))
        Bw, Cz, Dzw = Bw[:, wcols], Cz[zrows, :], Dzw[np.ix_(zrows, wcols)]
    poles = np.linalg.eigvals(A) if A.size else np.zeros(0)
    if np.any(poles.real >= 0):
        return RobStabResult(0.0, 0.0, float("nan"), {}, {}, nominal_stable=False)
    if omega is None:
        omega = np.concatenate([[0.0], frequency_grid(A, points_per_decade=points_per_decade)])
    omega = np.asarray(omega, dtype=float)
    if omega.ndim != 1 or omega.size == 0 or np.any(omega < 0) or not np.all(np.isfinite(omega)):
        raise ValueError("robstab: omega must be a non-empty 1-D array of frequencies >= 0 [rad/s]")
    omega, up, lo, dl, structure = _refined_sweep(
        A, Bw, Cz, Dzw, bmap.blk, omega, refine_rounds=refine_rounds, mu_options=mu_options
    )
    guarantee = None
    if guaranteed:
        guarantee = _guarantee(Realization(A, Bw, Cz, Dzw), structure, omega, up, lo, slack)
        peak_up = guarantee.upper
    else:
        peak_up = float(up.max())
    k = int(np.argmax(lo))
    peak_lo = float(lo[k])
    lower = 1.0 / peak_up if peak_up > 0 else float("inf")
    upper = 1.0 / peak_lo if peak_lo > 0 else float("inf")
    worst, worst_norm, wc = {}, {}, float("nan")
    if peak_lo > 0:
        wc = float(omega[k])
        worst = worst_case_values(bmap, structure, dl[k], wc)
        worst_norm = normalized_worst_case(bmap, structure, dl[k])
    return RobStabResult(lower, upper, wc, worst, worst_norm, True, omega, up, lo, guarantee)


def peak_seeds(omega, values, count: int = 6) -> np.ndarray:
    """Frequencies of the ``count`` highest local maxima of ``values`` (plus 0): where a cover
    of the frequency axis starts."""
    interior = np.r_[True, values[1:] >= values[:-1]] & np.r_[values[:-1] >= values[1:], True]
    peaks = np.flatnonzero(interior)
    peaks = peaks[np.argsort(values[peaks])[::-1][:count]]
    return np.unique(np.concatenate([[0.0], omega[peaks]]))


def _guarantee(real, structure, omega, up, lo, slack) -> AxisCertificate:
    """Cover ``[0, inf)`` starting from the peaks of the grid's bounds, at a level no lower than
    ``(1 + slack)`` times the best certified lower bound (a common level widens the intervals;
    the points whose bound exceeds it get long optimizer runs, so that an optimizer stall does
    not raise the level)."""
    best = float(lo.max())
    return cover_axis(
        real,
        mu_solver(real, structure, slack=slack, polish_above=best),
        np.union1d(peak_seeds(omega, up), peak_seeds(omega, lo)),
        floor=(1.0 + slack) * best,
        slack=slack,
    )
