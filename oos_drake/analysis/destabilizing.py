r"""Destabilizing perturbations by a direct search: a lower bound of mu for real-parameter sets.

The power iteration of mussv's lower bound struggles with real parameters (mu is discontinuous
in frequency for them). Stability gives another route: for real blocks ``delta_r`` (normalized,
one scalar per block, repeated on its channels) the closed loop

.. math:: A(\Delta) = A + B_w \Delta (I - D_{zw} \Delta)^{-1} C_z

is unstable beyond the smallest ``alpha`` for which ``A(alpha diag(d))`` has a pole on the
imaginary axis. This module

1. searches the sign vertices ``d in {-1, 1}^n`` (all of them up to 2^10, else random ones),
   bisecting ``alpha`` on the spectral abscissa and polishing the crossing by the secant method,
   then moves off the vertex coordinate by coordinate (:func:`refine_direction`);
2. adds the complex blocks (``ultidyn``): at the real part ``alpha d`` it closes the real
   channels and asks the complex-mu power iteration for a complex perturbation of size
   ``<= alpha`` that makes ``I - M(j omega) Delta`` singular on a frequency grid, bisecting
   ``alpha`` again.

Whatever it returns is checked: ``sigma_min(I - M(j omega) delta)`` at round-off level, so
``1 / ||delta||`` is a certified lower bound of mu (``||delta|| = max block norm``).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from oos_drake.robust.blocks import REAL, parse_blk
from oos_drake.robust.lfr_analysis import delta_channel_response


@dataclass(frozen=True)
class Destabilizer:
    """A destabilizing structured perturbation.

    Attributes
    ----------
    mu_lower : float
        ``1 / ||delta||`` (0 when none was found within ``alpha_max``).
    omega : float
        Frequency [rad/s] at which ``det(I - M(j omega) delta) = 0`` (closed-loop pole ``j omega``).
    delta : numpy.ndarray
        Perturbation in the mussv layout of the structure.
    residual : float
        ``sigma_min(I - M delta) / (1 + ||M delta||)`` at ``omega``.
    """

    mu_lower: float
    omega: float
    delta: np.ndarray
    residual: float


def _expand(structure, real_values):
    """Perturbation matrix from one value per real block (the complex blocks at zero)."""
    delta = np.zeros((structure.n_rows, structure.n_cols), dtype=complex)
    for block, value in zip(_real_blocks(structure), real_values, strict=True):
        idx = np.arange(block.rows)
        delta[block.row_offset + idx, block.col_offset + idx] = value
    return delta


def _real_blocks(structure) -> list:
    return [b for b in structure.blocks if b.kind == REAL]


def _sign_vertices(n: int, max_vertices: int, rng: np.random.Generator | None = None):
    """Every sign vector of length ``n`` (``(2**n, n)``) if there are at most ``max_vertices``,
    else ``max_vertices`` random ones (``rng``, default seed 0)."""
    if 2**n <= max_vertices:
        return np.array(list(itertools.product([-1.0, 1.0], repeat=n)))
    return (rng or np.random.default_rng(0)).choice([-1.0, 1.0], size=(max_vertices, n))


def _closed_A(A, Bw, Cz, Dzw, delta):
    X = np.linalg.solve(np.eye(Dzw.shape[0]) - Dzw @ delta, Cz)
    return A + Bw @ delta @ X


def _abscissa(A, Bw, Cz, Dzw, delta):
    try:
        ev = np.linalg.eigvals(_closed_A(A, Bw, Cz, Dzw, delta))
    except np.linalg.LinAlgError:
        return np.inf, 0.0
    k = int(np.argmax(ev.real))
    return float(ev[k].real), float(abs(ev[k].imag))


def ill_posed_perturbation(Dzw, blk, *, max_vertices: int = 1024) -> Destabilizer:
    """Smallest real vertex perturbation that makes the loop ill-posed (``I - Dzw delta``
    singular: a closed-loop pole leaves through infinity, e.g. a mass matrix made singular).

    Along a sign vertex ``d`` of the real blocks (complex blocks at zero), ``det(I - alpha Dzw
    D(d)) = 0`` exactly when ``1 / alpha`` is a real eigenvalue of ``Dzw D(d)``: the smallest
    ``alpha`` is the reciprocal of its largest positive real eigenvalue. Exact per vertex, no
    search; the best vertex gives a certified lower bound of mu at infinite frequency.
    """
    structure = parse_blk(blk)
    Dzw = np.asarray(Dzw)
    n_real = len(_real_blocks(structure))
    none = Destabilizer(0.0, float("nan"), np.zeros((structure.n_rows, structure.n_cols)), np.nan)
    if n_real == 0 or Dzw.size == 0:
        return none
    best, best_lambda = None, 0.0
    for d in _sign_vertices(n_real, max_vertices):
        lam = np.linalg.eigvals(Dzw @ _expand(structure, d))
        real = lam[(np.abs(lam.imag) <= 1e-9 * max(1.0, np.abs(lam).max())) & (lam.real > 0)]
        if real.size and real.real.max() > best_lambda:
            best, best_lambda = d, float(real.real.max())
    if best is None:
        return none
    delta = _expand(structure, best / best_lambda).astype(complex)
    return Destabilizer(best_lambda, np.inf, delta, _residual(Dzw, delta))


def real_vertex_search(
    A,
    Bw,
    Cz,
    Dzw,
    blk,
    *,
    alpha_max: float = 8.0,
    max_vertices: int = 1024,
    rng: np.random.Generator | None = None,
):
    """Smallest ``alpha`` over sign vertices with a closed-loop pole on the imaginary axis.

    Only the real blocks of ``blk`` are perturbed (complex blocks at zero).

    Returns
    -------
    alpha : float
        ``inf`` if no vertex destabilizes within ``alpha_max``.
    signs : numpy.ndarray
        The vertex (one sign per real block).
    omega : float
        Crossing frequency [rad/s].
    """
    structure = parse_blk(blk)
    n_real = len(_real_blocks(structure))
    if n_real == 0:
        return np.inf, np.zeros(0), np.nan
    best = (np.inf, np.zeros(n_real), np.nan)
    for d in _sign_vertices(n_real, max_vertices, rng):
        hi = min(alpha_max, best[0])
        a_hi, _ = _abscissa(A, Bw, Cz, Dzw, _expand(structure, hi * d))
        if a_hi < 0:
            continue
        lo, a_lo = 0.0, _abscissa(A, Bw, Cz, Dzw, _expand(structure, 0 * d))[0]
        for _ in range(22):
            mid = 0.5 * (lo + hi)
            a_mid, _ = _abscissa(A, Bw, Cz, Dzw, _expand(structure, mid * d))
            if a_mid >= 0:
                hi, a_hi = mid, a_mid
            else:
                lo, a_lo = mid, a_mid
        # secant polish of the crossing: abscissa(alpha) = 0
        for _ in range(8):
            if not (np.isfinite(a_hi) and np.isfinite(a_lo)) or a_hi == a_lo:
                break
            mid = hi - a_hi * (hi - lo) / (a_hi - a_lo)
            if not lo < mid < hi:
                break
            a_mid, _ = _abscissa(A, Bw, Cz, Dzw, _expand(structure, mid * d))
            if a_mid >= 0:
                hi, a_hi = mid, a_mid
            else:
                lo, a_lo = mid, a_mid
            if abs(a_mid) < 1e-11:
                break
        _, w = _abscissa(A, Bw, Cz, Dzw, _expand(structure, hi * d))
        if hi < best[0]:
            best = (hi, d.copy(), w)
    return best


def _alpha_along(A, Bw, Cz, Dzw, structure, d, hi):
    """Smallest ``alpha <= hi`` with ``abscissa(A(alpha d)) >= 0`` (inf if none), bisection."""
    a_hi, _ = _abscissa(A, Bw, Cz, Dzw, _expand(structure, hi * d))
    if a_hi < 0:
        return np.inf
    lo = 0.0
    for _ in range(26):
        mid = 0.5 * (lo + hi)
        if _abscissa(A, Bw, Cz, Dzw, _expand(structure, mid * d))[0] >= 0:
            hi = mid
        else:
            lo = mid
    return hi


def refine_direction(
    A, Bw, Cz, Dzw, blk, alpha, signs, *, levels=(-1.0, -0.5, 0.0, 0.5, 1.0), passes: int = 2
):
    """Coordinate search off the vertices: the worst direction need not be a vertex.

    A direction ``d`` (``max |d_i| = 1``) with a smaller crossing ``alpha`` gives a larger lower
    bound ``1 / alpha``. Each coordinate is tried at ``levels`` in turn (the others fixed).

    Returns ``(alpha, d)``.
    """
    structure = parse_blk(blk)
    best_a, best_d = alpha, np.asarray(signs, dtype=float).copy()
    if not np.isfinite(best_a) or best_d.size < 2:
        return best_a, best_d
    for _ in range(passes):
        improved = False
        for i in range(best_d.size):
            for level in levels:
                if level == best_d[i]:
                    continue
                d = best_d.copy()
                d[i] = level
                norm = np.max(np.abs(d))
                if norm == 0:
                    continue
                d /= norm
                a = _alpha_along(A, Bw, Cz, Dzw, structure, d, best_a * 0.999)
                if a < best_a:
                    best_a, best_d, improved = a, d, True
        if not improved:
            break
    return best_a, best_d


def _residual(M, delta):
    from oos_drake.robust.mu_lower import certificate_residual

    return float(certificate_residual(M[None], delta[None])[0])


def _real_crossing_delta(A, Bw, Cz, Dzw, structure, alpha, signs):
    """Perturbation and frequency of a real crossing, with its singularity residual.

    A pole can also leave through infinity: when ``I - Dzw delta`` becomes singular (the loop
    is ill-posed there; e.g. a mass matrix made singular by negative masses) the abscissa jumps
    from negative to large positive values. The crossing frequency is then ``inf``, where
    ``M = Dzw`` is singular against ``delta``.
    """
    delta = _expand(structure, alpha * signs)
    try:
        ev = np.linalg.eigvals(_closed_A(A, Bw, Cz, Dzw, delta))
        k = int(np.argmax(ev.real))
        w = abs(ev[k].imag)
        residual = _residual(delta_channel_response(A, Bw, Cz, Dzw, [w])[0], delta)
    except np.linalg.LinAlgError:
        w, residual = np.nan, np.inf
    at_infinity = _residual(Dzw, delta)
    if at_infinity < residual:
        return delta, np.inf, at_infinity
    return delta, w, residual


def _complex_part(A, Bw, Cz, Dzw, structure, real_part, omega):
    """Complex-mu lower bound of the complex channels with the real ones closed at ``real_part``.

    Returns ``(mu_c (F,), complex blocks per frequency)``.
    """
    from oos_drake.robust.mu_lower import mu_lower_bound

    rows_r, cols_r, rows_c, cols_c, cblk = [], [], [], [], []
    for block in structure.blocks:
        r = list(range(block.row_offset, block.row_offset + block.rows))
        c = list(range(block.col_offset, block.col_offset + block.cols))
        if block.kind == REAL:
            rows_r += r
            cols_r += c
        else:
            rows_c += r
            cols_c += c
            cblk.append([block.rows, block.cols] if block.kind == "full" else [block.rows, 0])
    M = delta_channel_response(A, Bw, Cz, Dzw, omega)  # (F, c, r): z rows x w cols
    # w = Delta z, Delta rows = w channels (M columns), Delta cols = z channels (M rows)
    Mzz_cc = M[:, cols_c][:, :, rows_c]
    if rows_r:
        D_r = real_part[np.ix_(rows_r, cols_r)]
        M_rr = M[:, cols_r][:, :, rows_r]
        M_rc = M[:, cols_r][:, :, rows_c]
        M_cr = M[:, cols_c][:, :, rows_r]
        X = np.linalg.solve(np.eye(len(cols_r)) - M_rr @ D_r, M_rc)
        Mzz_cc = Mzz_cc + M_cr @ D_r @ X
    cstruct = parse_blk(cblk)
    res = mu_lower_bound(Mzz_cc, cstruct, restarts=3, iters=60)
    return res.lower, res.delta, (rows_c, cols_c)


def _pole_points(A, Bw, Cz, Dzw, real_part, lo_w, hi_w, max_damping: float = 0.2):
    """Frequencies [rad/s] on the lightly damped poles of the loop closed through ``real_part``.

    Three points per pole with damping ratio below ``max_damping`` and natural frequency within
    ``[lo_w / 1.5, 1.5 hi_w]``: the damped frequency and ``+-`` half its real part (the peak of
    a resonance of damping ``zeta`` is ``zeta omega_n`` wide).
    """
    try:
        ev = np.linalg.eigvals(_closed_A(A, Bw, Cz, Dzw, real_part))
    except np.linalg.LinAlgError:
        return np.zeros(0)
    wn = np.abs(ev)
    keep = (
        (ev.imag > 0)
        & (-ev.real < max_damping * np.maximum(wn, 1e-300))
        & (wn >= lo_w / 1.5)
        & (wn <= 1.5 * hi_w)
    )
    w, sigma = ev.imag[keep], np.abs(ev.real[keep])
    pts = np.concatenate([w, w - 0.5 * sigma, w + 0.5 * sigma])
    return pts[pts > 0]


def destabilizing_perturbation(
    A, Bw, Cz, Dzw, blk, omega_hint, *, alpha_max: float = 8.0, complex_points: int = 61
) -> Destabilizer:
    """Best destabilizing perturbation found by the vertex and complex searches.

    Parameters
    ----------
    A, Bw, Cz, Dzw : numpy.ndarray
        One closed-loop model restricted to the analyzed subset's Delta channels.
    blk : array_like
        BLK rows of the subset.
    omega_hint : array_like
        Frequencies [rad/s] around the mu peak (used for the complex blocks).
    alpha_max : float
        Largest perturbation size searched (mu lower bounds below ``1 / alpha_max`` are not found).
    complex_points : int
        Frequencies of the complex search (spread over ``omega_hint``'s span and the real crossing).
    """
    structure = parse_blk(blk)
    has_real = structure.has_real
    has_complex = any(b.kind != REAL for b in structure.blocks)
    best = Destabilizer(
        0.0, float("nan"), np.zeros((structure.n_rows, structure.n_cols), complex), float("nan")
    )
    signs = np.zeros(len(_real_blocks(structure)))
    alpha_r = np.inf
    if has_real:
        alpha_r, signs, w_r = real_vertex_search(A, Bw, Cz, Dzw, blk, alpha_max=alpha_max)
        alpha_r, signs = refine_direction(A, Bw, Cz, Dzw, blk, alpha_r, signs)
        if np.isfinite(alpha_r):
            delta, w, res = _real_crossing_delta(A, Bw, Cz, Dzw, structure, alpha_r, signs)
            best = Destabilizer(1.0 / alpha_r, float(w), delta, res)
    if not has_complex:
        return best
    omega_hint = np.asarray(omega_hint, dtype=float)
    lo_w, hi_w = omega_hint.min(), omega_hint.max()
    grid = np.geomspace(lo_w, hi_w, complex_points)
    if np.isfinite(best.omega):
        grid = np.unique(np.concatenate([grid, best.omega * np.geomspace(0.97, 1.03, 9)]))

    def trial(alpha):
        real_part = (
            _expand(structure, alpha * signs)
            if has_real
            else np.zeros((structure.n_rows, structure.n_cols), complex)
        )
        # the complex channels see the loop closed through the real part: its lightly damped
        # poles (just left of the axis when alpha nears the real crossing) make mu_c peak in
        # a band as narrow as their damping, which a fixed grid misses: add them
        trial_grid = np.unique(
            np.concatenate([grid, _pole_points(A, Bw, Cz, Dzw, real_part, lo_w, hi_w)])
        )
        mu_c, deltas, (rows_c, cols_c) = _complex_part(
            A, Bw, Cz, Dzw, structure, real_part, trial_grid
        )
        k = int(np.argmax(mu_c))
        if mu_c[k] <= 0:
            return False, None
        full = real_part.copy()
        full[np.ix_(rows_c, cols_c)] = deltas[k]
        return mu_c[k] * alpha >= 1.0, (full, trial_grid[k], 1.0 / mu_c[k])

    hi = alpha_r if np.isfinite(alpha_r) else alpha_max
    ok, found = trial(hi)
    if not ok and not np.isfinite(alpha_r):
        return best
    lo = 0.0
    cand = found if ok else None
    for _ in range(18):
        mid = 0.5 * (lo + hi)
        ok, f = trial(mid)
        if ok:
            hi, cand = mid, f
        else:
            lo = mid
    if cand is None:
        return best
    delta, w, cnorm = cand
    # complex blocks at size cnorm <= hi, real ones at hi: the perturbation's size is hi
    size = float(np.max(structure.block_norms(delta[None]))) if delta.size else hi
    M = delta_channel_response(A, Bw, Cz, Dzw, [w])[0]
    res = _residual(M, delta)
    if res <= 1e-6 and size > 0 and 1.0 / size > best.mu_lower:
        best = Destabilizer(1.0 / size, float(w), delta, res)
    return best
