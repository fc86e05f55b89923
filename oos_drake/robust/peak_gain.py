"""Batched H-infinity norm (peak gain) of model arrays, vectorized over models and frequencies.

The synthesis inner loop evaluates ``||M_i||_inf`` for hundreds of closed loops at every step.
This is the package's one H-infinity norm; :func:`oos_drake.robust.hinfnorm` is its MATLAB-named
front end (input checks, any batch shape, certified upper bound).

Each model is diagonalized once (``A = V diag(lambda) V^-1``, batched LAPACK ``geev``), so its
frequency response on any grid is one matrix product of the resolvent ``1/(j w - lambda)``
with the residues ``(C V)_k (V^-1 B)_k``: no solve per frequency, no Python loop per model.
The grid holds ``w = 0``, a log grid spanning the model's poles and the damped frequencies
``|Im lambda|`` of every pole; the best local maxima are then refined (safeguarded secant on the
analytic slope ``d sigma / d omega``, or golden-section search), and the value at the peak is
recomputed with an LU solve (exact, independent of the modal basis).

The closed-loop eigendecomposition dominates the cost (2/3 of it for the paper's 81-state loops).
The synthesis therefore passes an ``evaluator`` (:class:`oos_drake.control.loop_response.
LoopSigma`) that samples the closed-loop gain from the plant's modal form, computed once per
plant array: each gamma evaluation then needs only the closed-loop *eigenvalues* (stability,
grid), and ``workers`` threads can share them (LAPACK runs without the GIL).

:func:`certify_peaks` certifies results with the Hamiltonian test of
Boyd-Balakrishnan-Bruinsma-Steinbuch (no imaginary eigenvalue above the reported gain), all
models together (:func:`oos_drake.robust.hinf.hinfnorm`, the one H-infinity norm, runs it).
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass

import numpy as np

from oos_drake.blas import with_single_threaded_blas
from oos_drake.processes import ThreadExecutor

#: Eigenvector basis condition number above which the exact (LU) response is used instead
#: (below it the modal response is accurate to ~cond * 1e-16, enough to locate peaks; the
#: reported gain is always recomputed exactly).
MODAL_CONDITION_LIMIT = 1e12
#: Local maxima of the sampled gain below this fraction of the model's largest sample are not
#: refined (they sit away from any lightly damped pole, whose damped frequency is sampled).
RELEVANT_FRACTION = 0.5


@dataclass(frozen=True)
class PeakGain:
    """Peak gains of a model array.

    Attributes
    ----------
    gamma : numpy.ndarray, shape (N,)
        ``||G_i||_inf`` (``inf`` for an unstable model).
    omega : numpy.ndarray, shape (N,)
        Peak frequency [rad/s] (``nan`` when unstable).
    spectral_abscissa : numpy.ndarray, shape (N,)
        ``max Re lambda(A_i)`` [1/s].
    peak_omega, peak_sigma : numpy.ndarray, shape (N, k), optional
        The refined local maxima of each model's gain curve (frequency [rad/s], modal-basis
        value); ``nan`` where not computed. Used to build the synthesis' active set.
    """

    gamma: np.ndarray
    omega: np.ndarray
    spectral_abscissa: np.ndarray
    peak_omega: np.ndarray | None = None
    peak_sigma: np.ndarray | None = None

    @property
    def worst(self) -> int:
        """Index of the model with the largest peak gain."""
        return int(np.argmax(self.gamma))


def sigma_max_exact(A, B, C, D, omega) -> np.ndarray:
    """Largest singular value of ``G_i(j omega_i)`` by LU solves (exact).

    Parameters
    ----------
    A, B, C, D : numpy.ndarray
        Batched matrices ``(N, n, n)``, ``(N, n, m)``, ``(N, p, n)``, ``(N, p, m)``.
    omega : numpy.ndarray, shape (N,) or (N, F)
        Frequencies [rad/s], one (or F) per model.

    Returns
    -------
    numpy.ndarray, shape like ``omega``
    """
    omega = np.asarray(omega, dtype=float)
    squeeze = omega.ndim == 1
    if squeeze:
        omega = omega[:, None]
    n = A.shape[-1]
    M = 1j * omega[..., None, None] * np.eye(n) - A[:, None]
    X = np.linalg.solve(M, np.broadcast_to(B[:, None], M.shape[:2] + B.shape[-2:]).astype(complex))
    H = C[:, None] @ X + D[:, None]
    s = np.linalg.svd(H, compute_uv=False)[..., 0]
    return s[:, 0] if squeeze else s


def pruned_sigma(H) -> np.ndarray:
    """``sigma_max`` of ``H`` (N, F, p, m) where it can be a model's maximum over F.

    Points whose Frobenius norm (an upper bound of sigma_max) is below a lower bound of the
    model's maximum -- sigma_max at its largest-Frobenius point -- get their Frobenius norm
    instead: they cannot hold the maximum. Returns (N, F).
    """
    fro = np.sqrt(np.sum(H.real**2 + H.imag**2, axis=(-2, -1)))
    N = H.shape[0]
    top = np.argmax(fro, axis=1)
    lower = _sigma_max(H[np.arange(N), top])[:, None]
    keep = fro >= lower
    values = fro.copy()
    values[keep] = _sigma_max(H[keep])
    return values


def _sigma_max(H) -> np.ndarray:
    """Largest singular values of a stack of complex matrices (via the smaller Gram matrix)."""
    p, m = H.shape[-2:]
    Hh = np.conj(np.swapaxes(H, -1, -2))
    G = H @ Hh if p <= m else Hh @ H
    return np.sqrt(np.maximum(np.linalg.eigvalsh(G)[..., -1], 0.0))


@functools.cache
def _executor(workers: int, pid: int) -> ThreadExecutor:
    """Threads kept for the process's life (``pid``: a forked worker makes its own; the
    parent's threads do not exist there)."""
    return ThreadExecutor(workers)


def _over_chunks(function, A, workers: int) -> list:
    """``function`` of model chunks of ``A`` in ``workers`` threads: the chunks' results, in order.

    LAPACK's ``geev`` runs without the GIL, so threads use the cores without pickling; each
    ``function`` keeps one BLAS thread (many small problems: batching is the parallelism).
    """
    workers = int(workers)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if workers == 1 or A.shape[0] < 2 * workers:
        return [function(A)]
    chunks = np.array_split(np.arange(A.shape[0]), workers)
    return _executor(workers, os.getpid()).map(lambda idx: function(A[idx]), chunks)


@with_single_threaded_blas
def _eig_and_inverse(A):
    lam, V = np.linalg.eig(A)
    return lam, V, np.linalg.inv(V)


def eigendecompose(A, workers: int = 1):
    """``(lambda, V, V^-1)`` of a stack of matrices, in ``workers`` threads over model chunks."""
    parts = _over_chunks(_eig_and_inverse, A, workers)
    return tuple(np.concatenate([part[k] for part in parts]) for k in range(3))


@with_single_threaded_blas
def _eigvals(A):
    return np.linalg.eigvals(A) if A.shape[-1] else np.zeros((A.shape[0], 0), dtype=complex)


def eigenvalues(A, workers: int = 1) -> np.ndarray:
    """Eigenvalues of a stack of matrices (no vectors), in ``workers`` threads over chunks."""
    return np.concatenate(_over_chunks(_eigvals, A, workers))


class ModalResponse:
    """Frequency response of a batch of stable models through their modal decomposition.

    Parameters
    ----------
    A, B, C, D : numpy.ndarray
        Batched matrices (leading dimension N).
    workers : int
        Threads for the eigendecompositions (see :func:`eigendecompose`).
    eigen : tuple of numpy.ndarray, optional
        ``(lambda, V, V^-1)`` of ``A`` when already computed (:func:`eigendecompose`; models
        that share ``A`` and differ in ``B, C, D``).
    """

    def __init__(self, A, B, C, D, workers: int = 1, eigen=None):
        self.A, self.B, self.C, self.D = (np.asarray(M, dtype=float) for M in (A, B, C, D))
        N, n = self.A.shape[0], self.A.shape[-1]
        self.p, self.m = self.D.shape[-2:]
        self.lam, V, Vinv = eigendecompose(self.A, workers) if eigen is None else eigen
        cond = np.linalg.norm(V, 1, axis=(-2, -1)) * np.linalg.norm(Vinv, 1, axis=(-2, -1))
        self.exact = ~np.isfinite(cond) | (cond > MODAL_CONDITION_LIMIT)
        CV = self.C @ V
        VB = Vinv @ self.B
        # residues R[i, k, p*m] = CV[i, :, k] outer VB[i, k, :]
        self.residues = (CV.transpose(0, 2, 1)[..., :, None] * VB[..., None, :]).reshape(
            N, n, self.p * self.m
        )
        self.spectral_abscissa = self.lam.real.max(axis=-1) if n else np.full(N, -np.inf)

    def take(self, index) -> ModalResponse:
        """Return the decomposition of the models ``index`` (no recomputation)."""
        sub = object.__new__(ModalResponse)
        for name in ("A", "B", "C", "D", "lam", "exact", "residues", "spectral_abscissa"):
            setattr(sub, name, getattr(self, name)[index])
        sub.p, sub.m = self.p, self.m
        return sub

    def response(self, omega) -> np.ndarray:
        """Return ``G_i(j omega_if)``, shape ``(N, F, p, m)``, for ``omega`` of shape (N, F)."""
        omega = np.asarray(omega, dtype=float)
        resolvent = 1.0 / (1j * omega[..., None] - self.lam[:, None, :])
        if omega.shape[1] > 16:
            # one zgemm per model: much faster than numpy's batched complex matmul
            flat = np.empty(omega.shape + (self.p * self.m,), dtype=complex)
            for i in range(omega.shape[0]):
                np.dot(resolvent[i], self.residues[i], out=flat[i])
        else:
            flat = resolvent @ self.residues
        H = flat.reshape(omega.shape + (self.p, self.m)) + self.D[:, None]
        if np.any(self.exact):
            idx = np.flatnonzero(self.exact)
            _, _, H[idx] = self._lu_response(idx, omega[idx])
        return H

    def _lu_response(self, idx, omega):
        """``(j omega I - A, X = (j omega I - A)^-1 B, G)`` of the models ``idx`` by LU solves."""
        A, B, C, D = self.A[idx], self.B[idx], self.C[idx], self.D[idx]
        M = 1j * omega[..., None, None] * np.eye(A.shape[-1]) - A[:, None]
        X = np.linalg.solve(M, np.broadcast_to(B[:, None], M.shape[:2] + B.shape[-2:]) + 0j)
        return M, X, C[:, None] @ X + D[:, None]

    def sigma_and_slope(self, omega):
        """Largest singular value and its derivative ``d sigma / d omega`` at ``omega`` (N, K).

        ``dG/d omega = sum_k -j R_k / (j omega - lambda_k)^2`` in the modal basis and, for a simple
        largest singular value with vectors ``u, v``, ``d sigma = Re(u^H dG v)``. Models flagged
        ``exact`` (ill-conditioned eigenvectors) use LU solves: ``dG = -j C X^2 B`` stacked.

        Returns
        -------
        tuple of numpy.ndarray
            ``(sigma, slope)`` [-, s/rad], shapes (N, K).
        """
        omega = np.asarray(omega, dtype=float)
        N, K = omega.shape
        resolvent = 1.0 / (1j * omega[..., None] - self.lam[:, None, :])
        stacked = np.concatenate([resolvent, -1j * resolvent * resolvent], axis=1)
        flat = stacked @ self.residues
        H = flat[:, :K].reshape(N, K, self.p, self.m) + self.D[:, None]
        dH = flat[:, K:].reshape(N, K, self.p, self.m)
        if np.any(self.exact):
            idx = np.flatnonzero(self.exact)
            M, X, H[idx] = self._lu_response(idx, omega[idx])
            dH[idx] = -1j * (self.C[idx][:, None] @ np.linalg.solve(M, X))
        if self.p > self.m:  # the smaller Gram matrix: that of the adjoint (same sigma, slope)
            H, dH = np.conj(np.swapaxes(H, -1, -2)), np.conj(np.swapaxes(dH, -1, -2))
        Hh = np.conj(np.swapaxes(H, -1, -2))
        w, U = np.linalg.eigh(H @ Hh)
        u = U[..., -1]  # left singular vector
        sigma = np.sqrt(np.maximum(w[..., -1], 0.0))
        # d sigma = Re(u^H dH H^H u) / sigma
        slope = np.real(np.einsum("...i,...ij,...j->...", np.conj(u), dH @ Hh, u)) / np.maximum(
            sigma, 1e-300
        )
        return sigma, slope

    def sigma(self, omega, *, prune: bool = False) -> np.ndarray:
        """Largest singular value of the response at ``omega`` (N, F).

        With ``prune`` see :func:`pruned_sigma`.
        """
        H = self.response(omega)
        return pruned_sigma(H) if prune else _sigma_max(H)


def peak_search_grid(lam, points_per_decade: int = 12) -> np.ndarray:
    """Per-model starting points [rad/s] of the H-infinity peak search, shape (N, F), increasing.

    Not a general frequency grid (that is :func:`oos_drake.robust.lfr_analysis.frequency_grid`):
    the brackets of this peak search, one row per model.

    ``0``; a log grid from ``0.05 min|lambda|`` to ``2 max|lambda|`` (beyond, a stable
    model's gain tends to ``sigma(D)``: one far point covers it); the damped frequency
    ``|Im lambda|`` of every pole with damping below 0.5 and, for damping below 0.05,
    its half-power points ``|Im lambda| (1 -+ zeta)`` (tight brackets around sharp
    resonances). Rows are padded with their last point (flagged as repeats).

    Parameters
    ----------
    lam : numpy.ndarray, shape (N, n)
        Poles of each model [rad/s] (complex).
    """
    lam = np.asarray(lam)
    mag = np.abs(lam)
    mag = np.where(mag > 1e-12, mag, np.nan)
    low = np.nanmin(mag, axis=-1, initial=np.inf)
    high = np.nanmax(mag, axis=-1, initial=-np.inf)
    low = np.where(np.isfinite(low), low, 1.0)
    high = np.where(np.isfinite(high), high, 1.0)
    lo, hi = np.log10(0.05 * low).min(), np.log10(2.0 * high).max()
    count = int(np.ceil((hi - lo) * points_per_decade)) + 1
    log_grid = np.logspace(lo, hi, count)
    N = lam.shape[0]
    upper = lam.imag > 0
    zeta = -lam.real / np.maximum(np.abs(lam), 1e-300)
    damped = np.where(upper & (zeta < 0.5), lam.imag, np.nan)
    sharp = upper & (zeta < 0.05)
    below = np.where(sharp, lam.imag * (1.0 - zeta), np.nan)
    above = np.where(sharp, lam.imag * (1.0 + zeta), np.nan)
    far = np.full((N, 1), 1e3 * 10.0**hi)
    grid = np.sort(
        np.concatenate(
            [
                np.zeros((N, 1)),
                np.broadcast_to(log_grid, (N, count)),
                damped,
                below,
                above,
                far,
            ],
            axis=1,
        ),
        axis=1,
    )  # nan last
    repeated = np.zeros(grid.shape, dtype=bool)
    repeated[:, 1:] = grid[:, 1:] <= grid[:, :-1] * (1.0 + 1e-12)
    grid = np.sort(np.where(repeated, np.nan, grid), axis=1)
    width = int(np.max(np.sum(~np.isnan(grid), axis=1)))
    grid = grid[:, :width]
    return np.where(np.isnan(grid), np.nanmax(grid, axis=1, keepdims=True), grid)


def _golden_refine(modal: ModalResponse, lo, hi, iterations: int):
    """Maximize sigma(w) on the brackets ``[lo, hi]`` (N, K) by golden-section search."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo.copy(), hi.copy()
    c = b - ratio * (b - a)
    d = a + ratio * (b - a)
    fc, fd = modal.sigma(c), modal.sigma(d)
    for _ in range(iterations):
        left = fc > fd  # maximum in [a, d]
        b = np.where(left, d, b)
        a = np.where(left, a, c)
        new_c, new_d = b - ratio * (b - a), a + ratio * (b - a)
        c_next = np.where(left, new_c, d)
        d_next = np.where(left, c, new_d)
        to_eval = np.where(left, c_next, d_next)
        f_new = modal.sigma(to_eval)
        fc, fd = np.where(left, f_new, fd), np.where(left, fc, f_new)
        c, d = c_next, d_next
    mid = 0.5 * (a + b)
    return mid


def _slope_refine(modal: ModalResponse, lo, hi, at_grid, iterations: int, rtol: float = 1e-10):
    """Maximize sigma(w) on the brackets ``[lo, hi]`` (N, K) by a safeguarded secant on the slope.

    The derivative ``d sigma / d omega`` (analytic, :meth:`ModalResponse.sigma_and_slope`) is
    positive at the left end and negative at the right end of a bracket around a local maximum;
    each step takes the false-position root of the slope (Illinois variant: superlinear) when it
    falls well inside the bracket, the midpoint otherwise, and keeps the sub-bracket where the
    slope changes sign. Brackets whose end slopes do not change sign fall back to bisection on the
    slope sign. Stops when every bracket is narrower than ``rtol`` (relative) or after
    ``iterations`` steps. Returns the best point seen per bracket and its (modal) value.
    """
    a, b = lo.copy(), hi.copy()
    x = np.clip(at_grid, a, b)
    fx, gx = modal.sigma_and_slope(x)
    best_w, best_s = x.copy(), fx.copy()
    # bracket ends: use the slope sign at the grid maximum to halve the bracket at once
    a = np.where(gx > 0, x, a)
    b = np.where(gx > 0, b, x)
    fa_, ga = modal.sigma_and_slope(a)
    fb_, gb = modal.sigma_and_slope(b)
    for values, points in ((fa_, a), (fb_, b)):
        better = values > best_s
        best_w, best_s = np.where(better, points, best_w), np.where(better, values, best_s)
    side = np.zeros(a.shape, dtype=int)
    for _ in range(iterations):
        width = b - a
        active = width > rtol * np.maximum(b, 1e-300)
        if not np.any(active):
            break
        valid = (ga > 0) & (gb < 0)
        t = np.where(valid, ga / np.where(valid, ga - gb, 1.0), 0.5)
        t = np.where((t > 0.02) & (t < 0.98), t, 0.5)
        m = a + t * width
        m = np.where(active, m, x)
        fm, gm = modal.sigma_and_slope(m)
        better = active & (fm > best_s)
        best_w, best_s = np.where(better, m, best_w), np.where(better, fm, best_s)
        right = gm > 0  # maximum to the right of m
        # Illinois: halve the retained end's slope when the same end is kept twice in a row
        ga_new = np.where(right, gm, np.where(side == -1, 0.5 * ga, ga))
        gb_new = np.where(right, np.where(side == 1, 0.5 * gb, gb), gm)
        a = np.where(active & right, m, a)
        b = np.where(active & ~right, m, b)
        ga = np.where(active, ga_new, ga)
        gb = np.where(active, gb_new, gb)
        side = np.where(active, np.where(right, 1, -1), side)
        x = m
    return best_w, best_s


@with_single_threaded_blas
def peak_gain(
    A,
    B,
    C,
    D,
    *,
    points_per_decade: int = 12,
    candidates: int = 3,
    iterations: int | None = None,
    modal: ModalResponse | None = None,
    focus: float | None = None,
    certify: bool = False,
    refine: str = "slope",
    workers: int = 1,
    evaluator=None,
) -> PeakGain:
    """H-infinity norms of a model array ``(A_i, B_i, C_i, D_i)``, vectorized.

    Parameters
    ----------
    A, B, C, D : numpy.ndarray
        Batched state-space matrices, leading dimension N.
    points_per_decade : int
        Density of the log part of the frequency grid (:func:`peak_search_grid`: the grid also
        holds the damped frequency and the half-power points of every lightly damped pole).
    candidates : int
        Number of grid local maxima refined per model.
    iterations : int, optional
        Largest number of refinement steps per candidate (default 16 for ``"slope"``, 25 for
        ``"golden"``; ``0``: grid values only).
    modal : ModalResponse, optional
        A precomputed modal decomposition of the same models.
    focus : float, optional
        Objective mode: only models whose sampled peak is within the relative margin ``focus``
        of the largest one are refined (the others keep their sampled peak, a lower bound), and
        nothing is computed when a model is unstable. ``None`` (default) refines all models.
    certify : bool
        Check every stable model with the Hamiltonian test (:func:`certify_peaks`, started
        from the grid estimate) and correct it: catches peaks that fall between grid
        points (one 2n x 2n eigenvalue problem per model and iteration).
    refine : str
        ``"slope"`` (default): safeguarded secant on the analytic slope ``d sigma / d omega``
        (superlinear, stops when every bracket is below 1e-10 relative); ``"golden"``:
        golden-section search on sigma (linear, 0.618 per step).
    workers : int
        Threads for the per-model eigendecompositions (the dominant cost; 2 on a 2-core
        machine halves it when the cores are free).
    evaluator : object, optional
        A cheaper sampler of ``sigma_max(G_i(j omega))`` with ``sigma(omega, prune=)`` and
        ``take(index)`` (e.g. :class:`oos_drake.control.loop_response.LoopSigma`, built from
        the plant's modal form): then only the eigenvalues of ``A_i`` are computed (no
        eigenvectors), the refinement is golden-section and the reported gains are the
        evaluator's at the refined frequencies (without it they are recomputed from
        ``(A, B, C, D)`` by LU solves).

    Returns
    -------
    PeakGain
        ``gamma`` is ``inf`` for models whose spectral abscissa is >= 0.
    """
    if refine not in ("slope", "golden"):
        raise ValueError(f"peak_gain: refine must be 'slope' or 'golden', got {refine!r}")
    default_iterations = iterations is None
    if default_iterations:
        iterations = 16 if refine == "slope" else 25
    A = np.asarray(A, dtype=float)
    if A.ndim == 2:
        A, B, C, D = (np.asarray(M, dtype=float)[None] for M in (A, B, C, D))
    N = A.shape[0]
    if evaluator is None:
        sampler = modal or ModalResponse(A, B, C, D, workers=workers)
        lam, abscissa = sampler.lam, sampler.spectral_abscissa
    else:
        sampler = evaluator
        lam = eigenvalues(A, workers)
        abscissa = lam.real.max(axis=-1) if lam.shape[-1] else np.full(N, -np.inf)
        if refine == "slope" and not hasattr(evaluator, "sigma_and_slope"):
            # golden steps on sigma: 20 shrink a bracket to 6.6e-5 (value error ~ 1e-9)
            refine, iterations = "golden", 20 if default_iterations else iterations
    unstable = abscissa >= 0
    if focus is not None and np.any(unstable):
        return PeakGain(np.where(unstable, np.inf, np.nan), np.full(N, np.nan), abscissa)
    grid = peak_search_grid(lam, points_per_decade)
    values = sampler.sigma(grid, prune=True)
    if focus is None:
        near = np.arange(N)
        gamma, omega = np.empty(N), np.empty(N)
    else:
        sampled = values.max(axis=1)
        near = np.flatnonzero(sampled >= (1.0 - focus) * sampled.max())
        gamma, omega = sampled, grid[np.arange(N), np.argmax(values, axis=1)]
    sub_omega, cand_w, cand_s = _refine_peaks(
        sampler.take(near), grid[near], values[near], candidates, iterations, refine
    )
    if evaluator is None:
        gamma[near] = sigma_max_exact(A[near], B[near], C[near], D[near], sub_omega)
    else:  # the evaluator is exact (no closed-loop modal basis): no LU recomputation needed
        gamma[near] = sampler.take(near).sigma(sub_omega[:, None])[:, 0]
    omega[near] = sub_omega
    peak_omega = np.full((N, cand_w.shape[1]), np.nan)
    peak_sigma = np.full((N, cand_w.shape[1]), np.nan)
    peak_omega[near], peak_sigma[near] = cand_w, cand_s
    if certify:
        stable = np.flatnonzero(~unstable)
        gamma[stable], omega[stable], _ = certify_peaks(
            A[stable], B[stable], C[stable], D[stable], gamma[stable], omega[stable]
        )
    gamma = np.where(unstable, np.inf, gamma)
    omega = np.where(unstable, np.nan, omega)
    return PeakGain(gamma, omega, abscissa, peak_omega, peak_sigma)


def _refine_peaks(
    modal: ModalResponse, grid, values, candidates: int, iterations: int, method: str = "slope"
):
    """Peak frequency per model: best of the refined top local maxima of the sampled curve."""
    N, F = grid.shape
    # local maxima of the sampled curve (endpoints included; repeated grid points skipped)
    padded = np.concatenate([np.full((N, 1), -np.inf), values, np.full((N, 1), -np.inf)], axis=1)
    is_peak = (values >= padded[:, :-2]) & (values >= padded[:, 2:])
    duplicate = np.zeros_like(is_peak)
    duplicate[:, 1:] = grid[:, 1:] <= grid[:, :-1] * (1.0 + 1e-12)
    score = np.where(is_peak & ~duplicate, values, -np.inf)
    k = min(candidates, F)
    top = np.argsort(-score, axis=1)[:, :k]
    lo = np.take_along_axis(grid, np.maximum(top - 1, 0), axis=1)
    hi = np.take_along_axis(grid, np.minimum(top + 1, F - 1), axis=1)
    at_grid = np.take_along_axis(grid, top, axis=1)
    at_values = np.take_along_axis(values, top, axis=1)
    peak_w, peak_s = at_grid.copy(), at_values.copy()
    # refine the candidates that can matter: the grid samples the damped frequency of every
    # lightly damped pole, so a local maximum sampled below half the model's best is no peak
    finite = np.isfinite(np.take_along_axis(score, top, axis=1))
    rows, cols = np.nonzero(finite & (at_values >= RELEVANT_FRACTION * at_values[:, :1]))
    if iterations > 0 and rows.size:
        sub = modal.take(rows)
        lo_, hi_, x_ = (M[rows, cols][:, None] for M in (lo, hi, at_grid))
        if method == "slope":
            refined, refined_values = _slope_refine(sub, lo_, hi_, x_, iterations)
        else:
            refined = _golden_refine(sub, lo_, hi_, iterations)
            refined_values = sub.sigma(refined)
        # keep the better of the refined point and its grid point, per candidate
        better = refined_values[:, 0] >= at_values[rows, cols]
        peak_w[rows, cols] = np.where(better, refined[:, 0], at_grid[rows, cols])
        peak_s[rows, cols] = np.where(better, refined_values[:, 0], at_values[rows, cols])
    peak_s = np.where(np.isfinite(np.take_along_axis(score, top, axis=1)), peak_s, np.nan)
    best = np.nanargmax(np.where(np.isnan(peak_s), -np.inf, peak_s), axis=1)
    return peak_w[np.arange(N), best], peak_w, peak_s


def certify_peaks(A, B, C, D, gamma, omega, *, rtol: float = 1e-7, max_iterations: int = 30):
    """Exact H-infinity norms of stable models from lower bounds, with certified upper bounds.

    Boyd-Balakrishnan / Bruinsma-Steinbuch level sets, all models together (stacked eigenvalue
    problems): each step takes the imaginary-axis eigenvalues of the Hamiltonian at
    ``(1 + 2 rtol)`` times the current lower bound, evaluates ``sigma_max`` at them and at the
    midpoints of the intervals they bound, and raises the lower bound; a level with no
    imaginary eigenvalue is a certified upper bound. Convergence is quadratic: from a good
    start (:func:`peak_gain`) one or two steps.

    Parameters
    ----------
    A, B, C, D : numpy.ndarray
        Stable models, leading dimension N.
    gamma, omega : numpy.ndarray, shape (N,)
        Lower bounds of the norms and their frequencies [rad/s]; raised to ``sigma_max(D)``
        (the gain at infinite frequency, ``omega = inf``) where below it.
    rtol : float
        Relative accuracy.
    max_iterations : int
        Largest number of steps (an unfinished model keeps ``upper = (1 + 2 rtol) gamma``,
        not certified).

    Returns
    -------
    tuple of numpy.ndarray
        ``(gamma, omega, upper)``, each (N,).
    """
    p, m = C.shape[-2], B.shape[-1]
    glb = np.asarray(gamma, dtype=float).copy()
    wpk = np.asarray(omega, dtype=float).copy()
    sigD = np.linalg.norm(D, ord=2, axis=(-2, -1)) if min(p, m) > 0 else np.zeros(glb.size)
    at_inf = sigD >= glb
    glb, wpk = np.where(at_inf, sigD, glb), np.where(at_inf, np.inf, wpk)
    gub = np.full(glb.size, np.inf)
    active = glb > 0
    gub[~active] = 0.0
    for _ in range(max_iterations):
        idx = np.flatnonzero(active)
        if idx.size == 0:
            break
        level = (1 + 2 * rtol) * glb[idx]
        ev = np.linalg.eigvals(_hamiltonian(A[idx], B[idx], C[idx], D[idx], level))
        scale = np.maximum(np.max(np.abs(ev), axis=1, keepdims=True), 1e-300)
        imag_axis = np.abs(ev.real) <= 1e-7 * scale
        for j, i in enumerate(idx):
            w = np.sort(np.abs(ev[j].imag[imag_axis[j]]))
            w = np.unique(np.round(w / scale[j, 0], 12)) * scale[j, 0] if w.size else w
            if w.size == 0:
                gub[i], active[i] = level[j], False
                continue
            mids = np.concatenate([0.5 * (w[:-1] + w[1:]) if w.size > 1 else w, w])
            sm = sigma_max_exact(A[i : i + 1], B[i : i + 1], C[i : i + 1], D[i : i + 1], mids[None])
            k = int(np.argmax(sm[0]))
            if sm[0, k] <= glb[i] * (1 + rtol):
                gub[i], active[i] = level[j], False
                continue
            glb[i], wpk[i] = sm[0, k], mids[k]
    gub = np.where(np.isinf(gub), glb * (1 + 2 * rtol), gub)
    return glb, wpk, gub


def _hamiltonian(A, B, C, D, gamma):
    """Stacked Hamiltonians of the level sets ``gamma`` (N,) (scaled form, ``gamma > sigma(D)``)."""
    m = B.shape[-1]
    p = C.shape[-2]
    g2 = (gamma**2)[:, None, None]
    DT = np.swapaxes(D, -1, -2)
    Ri = np.linalg.inv(g2 * np.eye(m) - DT @ D)
    Si = np.linalg.inv(g2 * np.eye(p) - D @ DT)
    BT = np.swapaxes(B, -1, -2)
    CT = np.swapaxes(C, -1, -2)
    F = A + B @ Ri @ DT @ C
    g = gamma[:, None, None]
    top = np.concatenate([F, g * (B @ Ri @ BT)], axis=-1)
    bot = np.concatenate([-g * (CT @ Si @ C), -np.swapaxes(F, -1, -2)], axis=-1)
    return np.concatenate([top, bot], axis=-2)
