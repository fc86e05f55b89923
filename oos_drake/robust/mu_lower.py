r"""Lower bound of the mixed structured singular value by a power iteration, with a certificate.

Any ``Delta`` in the block structure with ``||Delta|| <= 1`` and a real eigenvalue ``lambda`` of
``M Delta`` gives ``mu(M) >= |lambda|``: ``delta = Delta / lambda`` makes ``I - M delta`` singular
and
has norm ``1 / |lambda|`` (for purely complex structures any eigenvalue works, its phase is absorbed
in the complex blocks). The search for a good ``Delta`` is a mixed power iteration in the spirit of
Young & Doyle (1997): with right/left eigenvectors ``a``, ``z`` of ``M Delta`` and ``w = M^* z``,
the first-order gain of ``Re(lambda)`` is ``Re(w_k^* dDelta_k a_k)``. Each step

* moves the complex blocks to the maximizer of that gain (the power-iteration fixed point):
  ``Delta_k = w_k a_k^* / (|w_k| |a_k|)`` (full), ``delta_k = conj(w_k^* a_k) / |w_k^* a_k|``
  (repeated complex),
* takes a saturated step ``delta_k <- sat(delta_k + kappa Re(w_k^* a_k) / (|w_k| |a_k|))`` on the
  real blocks,
* advances ``a`` and ``z`` by one power step on ``M Delta`` and ``(M Delta)^*``.

Several starts run at once (the worst direction of the upper bound and random vectors). The
returned ``delta`` is checked: ``sigma_min(I - M delta)`` must be at the round-off level,
otherwise that candidate is dropped (and the bound lowered, to 0 if no candidate passes).

The power iteration, the eigenvalue polish and the residual-vector check run compiled, start by
start (:mod:`oos_drake.robust.mu_lower_kernels`); a numpy implementation of the same algorithm is
the tests' oracle (``tests/robust/oracles.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.robust import mu_lower_kernels
from oos_drake.robust.blocks import FULL, REAL, BlockStructure
from oos_drake.robust.memory import in_chunks, reuse_freed_memory
from oos_drake.robust.mu_upper import _per_blk

#: Matrices per internal batch of :func:`mu_lower_bound` (bounds the memory of huge batches).
CHUNK = 1024

#: Relative tolerance on ``sigma_min(I - M delta)`` accepted as "singular".
CERTIFICATE_RTOL = 1e-7

# eigenvalue polish: inverse iteration steps (complex structures), and Newton rounds towards a
# real eigenvalue with their inverse iteration steps (structures with real blocks)
_POLISH_STEPS = 3
_REAL_ROUNDS = 8
_REAL_STEPS = 2


@dataclass(frozen=True)
class LowerBoundResult:
    """Raw result of :func:`mu_lower_bound` for a flat batch ``(B, c, r)``."""

    lower: np.ndarray  # (B,)
    delta: (
        np.ndarray
    )  # (B, r, c): destabilizing perturbation, ||delta|| = 1/lower (zeros if lower=0)
    residual: np.ndarray  # (B,) sigma_min(I - M delta) / (1 + ||M delta||)
    raw_delta: np.ndarray | None = (
        None  # (B, r, c) best unit perturbation, eigenvalue maybe complex
    )
    raw_lambda: np.ndarray | None = None  # (B,) its eigenvalue of M raw_delta
    vector: np.ndarray | None = None  # (B, c): eigenvector of M delta of the returned candidate


def _mv(A, v):
    """Batched matrix-vector product ``A v`` (``(B, m, n)`` by ``(B, n)``; matmul beats einsum)."""
    return (A @ v[..., None])[..., 0]


def _normalize(v):
    """Unit rows; a zero or non-finite row (e.g. the worst input of ``M = 0``) becomes zero."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    ok = np.isfinite(norm) & (norm > 1e-300)
    return np.where(ok, v / np.where(ok, norm, 1.0), 0.0)


def _max_block_norm(structure: BlockStructure, delta: np.ndarray) -> np.ndarray:
    """``max_k ||Delta_k||_2`` of each ``delta`` (``(N, r, c)`` -> ``(N,)``), i.e.
    ``np.max(structure.block_norms(delta), axis=1)``, cheaper.

    Compiled (:func:`mu_lower_kernels.max_block_norms`): the scalar blocks take their largest
    diagonal modulus; the full blocks of the power iteration are rank one (an outer product
    times phases), where ``||B||_2 = ||B||_F``: that holds to round-off when
    ``||B^* B||_F = ||B||_F^2`` to 1e-13 relative (``||B||_F`` is then at most 5e-14 relative
    above ``||B||_2``); the perturbations with another full block take an SVD here.
    """
    delta = np.ascontiguousarray(delta, dtype=complex)
    out = np.empty(delta.shape[0])
    inexact = np.empty(delta.shape[0], dtype=np.bool_)
    mu_lower_kernels.max_block_norms(delta, _kernel_blocks(structure), out, inexact)
    svd = np.flatnonzero(inexact)
    if svd.size:
        out[svd] = np.max(structure.block_norms(delta[svd]), axis=1)
    return out


def _kernel_blocks(structure: BlockStructure) -> np.ndarray:
    """Block description of the compiled kernels: ``(5, n_blocks)`` integers, kind (0 real,
    1 repeated complex, 2 full), rows, columns, row offset, column offset (cached per BLK:
    the kernels only read it)."""
    return _per_blk("kernel_blocks", structure, lambda: _build_kernel_blocks(structure))


def _build_kernel_blocks(structure: BlockStructure) -> np.ndarray:
    kinds = {REAL: 0, FULL: 2}
    return np.array(
        [
            [kinds.get(b.kind, 1), b.rows, b.cols, b.row_offset, b.col_offset]
            for b in structure.blocks
        ],
        dtype=np.int64,
    ).T.copy()


def _power_iteration(M, structure, a, z, iters, kappa, rng):
    """Run the mixed power iteration (:func:`mu_lower_kernels.power_iteration`) from vectors
    ``a`` (c-space) and ``z`` (c-space); return ``(delta, a)``.

    ``M`` is ``(nb, c, r)`` and ``a``, ``z`` are ``(N, c)`` with ``N`` a multiple of ``nb``:
    start ``s`` runs on ``M[s % nb]`` (several starts per matrix).
    """
    nb = a.shape[0]
    n_real = _per_blk("n_real", structure, lambda: sum(b.kind == REAL for b in structure.blocks))
    real0 = rng.uniform(-1.0, 1.0, (n_real, nb)).T.copy()  # one draw per block, in one
    delta = np.empty((nb, structure.n_rows, structure.n_cols), dtype=complex)
    a_out = np.empty((nb, structure.n_cols), dtype=complex)
    mu_lower_kernels.power_iteration(
        np.ascontiguousarray(M, dtype=complex),
        np.ascontiguousarray(a, dtype=complex),
        np.ascontiguousarray(z, dtype=complex),
        real0,
        _kernel_blocks(structure),
        int(iters),
        float(kappa),
        delta,
        a_out,
    )
    return delta, a_out


def certificate_residual(M, delta):
    """``sigma_min(I - M delta) / (1 + ||M delta||_2)`` for ``(..., c, r)`` and ``(..., r, c)``."""
    Md = np.asarray(M) @ np.asarray(delta)
    eye = np.eye(Md.shape[-1])
    sv = np.linalg.svd(eye - Md, compute_uv=False)
    return sv[..., -1] / (1.0 + np.linalg.norm(Md, ord=2, axis=(-2, -1)))


def mu_lower_bound(
    M: np.ndarray,
    structure: BlockStructure,
    *,
    start_inputs: np.ndarray | None = None,
    start_vectors: np.ndarray | None = None,
    restarts: int = 4,
    iters: int = 60,
    kappa: float = 0.5,
    rng: np.random.Generator | None = None,
    polish_starts: int | None = 2,
) -> LowerBoundResult:
    """Certified lower bound of mixed mu for a flat batch of matrices.

    Parameters
    ----------
    M : numpy.ndarray
        ``(B, sum(c), sum(r))`` complex.
    structure : BlockStructure
    start_inputs : numpy.ndarray, optional
        ``(B, sum(r))`` starting directions in ``M``'s input space (e.g. the worst direction of
        the upper bound); used for the first start.
    start_vectors : numpy.ndarray, optional
        ``(B, k, sum(c))`` further starts in ``M``'s output space, e.g. the ``vector`` of the
        results at neighbouring frequencies (continuation).
    restarts : int
        Number of random starts besides ``start_inputs`` and ``start_vectors``.
    iters : int
        Power-iteration steps per start.
    kappa : float
        Step size of the real-block update.
    rng : numpy.random.Generator, optional
        Source of the random starts (default: ``numpy.random.default_rng(0)``, reproducible).
    polish_starts : int or None
        Starts per matrix (the best by their Rayleigh quotient after the power iteration) that
        get the eigenvalue polish and the certificate check; None: all.

    Returns
    -------
    LowerBoundResult
    """
    rng = np.random.default_rng(0) if rng is None else rng
    reuse_freed_memory()
    if M.shape[0] > CHUNK:  # bounded memory: (restarts + 1) copies of the batch are in flight
        starts = {"start_inputs": start_inputs, "start_vectors": start_vectors}
        options = dict(restarts=restarts, iters=iters, kappa=kappa, polish_starts=polish_starts)
        options.update(structure=structure, rng=rng)
        return in_chunks(mu_lower_bound, M, CHUNK, LowerBoundResult, starts, **options)
    nb = M.shape[0]
    a, z = _starts(M, start_inputs, start_vectors, restarts, rng)
    ns = a.shape[0] // nb
    mat = np.tile(np.arange(nb), ns)  # the matrix of each start
    delta_unit, a = _power_iteration(M, structure, a, z, iters, kappa, rng)
    M = np.ascontiguousarray(M, dtype=complex)
    blocks = _kernel_blocks(structure)
    if polish_starts is not None and 0 < polish_starts < ns:
        est = np.empty(a.shape[0], dtype=complex)
        mu_lower_kernels.rayleigh_quotients(M, delta_unit, a, blocks, est)
        keep = _best_starts(structure, np.abs(est), delta_unit, ns, polish_starts)
        ns = polish_starts
        mat, delta_unit, a = mat[keep], delta_unit[keep], a[keep]
    delta_unit = np.ascontiguousarray(delta_unit)
    a = np.ascontiguousarray(a)
    lam = np.empty(a.shape[0], dtype=complex)
    rounds, steps = (_REAL_ROUNDS, _REAL_STEPS) if structure.has_real else (0, _POLISH_STEPS)
    mu_lower_kernels.eigen_polish(M, mat, delta_unit, a, blocks, rounds, steps, lam)

    def residual(M, mat, delta, a, rows):
        out = np.empty(a.shape[0])
        mu_lower_kernels.vector_residual(M, mat, delta, a, blocks, out)
        return out[rows]

    return _conclude(M, structure, mat, delta_unit, a, lam, ns, residual)


def _starts(M, start_inputs, start_vectors, restarts, rng):
    """``(a, z)``: the starting vectors of the power iteration, ``(ns * B, c)`` each, start by
    start (``start_inputs``, ``start_vectors``, then ``restarts`` random ones)."""
    nb, c, _ = M.shape
    starts_a, starts_z = [], []
    if start_inputs is not None:
        a0 = _normalize(_mv(M, start_inputs))
        starts_a.append(a0)
        starts_z.append(a0)
    if start_vectors is not None:
        for k in range(start_vectors.shape[1]):
            a0 = _normalize(np.asarray(start_vectors[:, k], dtype=complex))
            starts_a.append(a0)
            starts_z.append(a0)
    if restarts > 0:  # one draw: the numbers of a draw per start and part, in that order
        g = rng.standard_normal((restarts, 2, 2, nb, c))
        g = _normalize((g[:, :, 0] + 1j * g[:, :, 1]).reshape(-1, c)).reshape(restarts, 2, nb, c)
        starts_a.extend(g[:, 0])
        starts_z.extend(g[:, 1])
    if not starts_a:
        starts_a.append(_normalize(np.ones((nb, c), dtype=complex)))
        starts_z.append(starts_a[0])
    return np.concatenate(starts_a, axis=0), np.concatenate(starts_z, axis=0)


def _best_starts(structure, est, delta_unit, ns, polish_starts):
    """Indices of the ``polish_starts`` most promising starts of each matrix (by the Rayleigh
    quotient estimate ``est`` relative to the perturbation's size): the eigenvalue polish and
    the certificate cost more than the power iteration itself."""
    nb = est.size // ns
    est = est / np.maximum(_max_block_norm(structure, delta_unit), 1e-300)
    order = np.argsort(-est.reshape(ns, nb), axis=0, kind="stable")[:polish_starts]
    return (order * nb + np.arange(nb)[None, :]).ravel()


def _conclude(M, structure, mat, delta_unit, a, lam, ns, residual):
    """The certified lower bound from the polished candidates (``ns`` per matrix, start ``s`` on
    ``M[mat[s]]``, eigenvalue ``lam`` of ``M delta_unit`` with eigenvector ``a``).

    ``residual(M, mat, delta, a, rows)`` bounds ``sigma_min(I - M delta)`` from the vectors (the
    certificate's first check) on the candidates ``rows``; those it leaves above
    :data:`CERTIFICATE_RTOL` get the SVD, then a full ``eig`` retry.
    """
    nb = M.shape[0]
    lam_raw = lam.copy()
    mag = np.abs(lam)
    if structure.has_real:
        is_real = np.abs(lam.imag) <= 1e-9 * np.maximum(mag, 1e-300)
        lam = np.where(is_real, lam.real, 0.0)
        mag = np.abs(lam)
    norm_unit = _max_block_norm(structure, delta_unit)
    # eigenvalues at round-off level of ||M|| carry no information (and overflow delta)
    floor = (1e-13 * np.linalg.norm(M, axis=(1, 2)) + 1e-300)[mat]
    usable = (mag > floor) & (norm_unit > 1e-12) & np.isfinite(mag)
    candidate = np.where(usable, mag / np.maximum(norm_unit, 1e-300), 0.0)
    delta = np.where(
        usable[:, None, None], delta_unit / np.where(usable, lam, 1.0)[:, None, None], 0.0
    )
    resid = np.full(candidate.shape, np.inf)
    if np.any(usable):
        resid[usable] = residual(M, mat, delta, a, usable)
        exact = np.flatnonzero(usable & (resid > CERTIFICATE_RTOL))  # inconclusive: SVD
        if exact.size:
            resid[exact] = certificate_residual(M[mat[exact]], delta[exact])
    valid = (candidate > 0) & (resid <= CERTIFICATE_RTOL)
    retry = np.flatnonzero(~valid)
    if retry.size:
        # inverse iteration may stall on clustered eigenvalues, and the real-eigenvalue search
        # may shrink the real parameters: take the largest admissible eigenvalue of a full eig,
        # for the iterate and for its real parameters pushed to the vertex of their sign
        M_retry = M[mat[retry]]
        for trial in (delta_unit[retry], _at_vertex(structure, delta_unit[retry])):
            tn = _max_block_norm(structure, trial)
            ev = np.linalg.eigvals(M_retry @ trial)
            if structure.has_real:
                ev = np.where(np.abs(ev.imag) <= 1e-9 * np.abs(ev), ev.real, 0.0)
            pick_ev = ev[np.arange(retry.size), np.argmax(np.abs(ev), axis=1)]
            ok = (np.abs(pick_ev) > floor[retry]) & (tn > 1e-12)
            d_new = trial / np.where(ok, pick_ev, 1.0)[:, None, None]
            res_new = np.full(retry.size, np.inf)
            if np.any(ok):
                res_new[ok] = certificate_residual(M_retry[ok], d_new[ok])
            value = np.where(ok, np.abs(pick_ev) / np.maximum(tn, 1e-300), 0.0)
            good = ok & (res_new <= CERTIFICATE_RTOL) & (value > candidate[retry] * valid[retry])
            fix = retry[good]
            delta[fix] = d_new[good]
            resid[fix] = res_new[good]
            candidate[fix] = value[good]
            valid[fix] = True
    candidate = np.where(valid, candidate, 0.0).reshape(ns, nb)
    best = np.argmax(candidate, axis=0)
    pick = best * nb + np.arange(nb)
    lower = candidate[best, np.arange(nb)]
    out_delta = np.where((lower > 0)[:, None, None], delta[pick], 0.0)
    out_resid = np.where(lower > 0, resid[pick], np.nan)
    # best candidate whatever its eigenvalue (for searches that also move the frequency)
    score = (np.abs(lam_raw) / np.maximum(norm_unit, 1e-300)).reshape(ns, nb)
    best_raw = np.argmax(score, axis=0) * nb + np.arange(nb)
    raw = _at_vertex(structure, delta_unit[best_raw])
    return LowerBoundResult(lower, out_delta, out_resid, raw, lam_raw[best_raw], a[pick])


def _at_vertex(structure, delta):
    """A copy of the perturbations ``delta`` ``(B, r, c)`` with their real parameters pushed
    to the vertex of their sign (``+-1``)."""
    out = delta.copy()
    first, rows, cols, owner = _per_blk("real_entries", structure, lambda: _real_entries(structure))
    if first.size:
        sign = np.where(out[:, rows[first], cols[first]].real < 0, -1.0, 1.0)
        out[:, rows, cols] = sign[:, owner]
    return out


def _real_entries(structure: BlockStructure) -> tuple:
    """``(first, rows, cols, owner)``: the diagonal entries ``(rows, cols)`` of the real blocks
    in ``delta``, the position of each block's first entry among them and the block of each
    entry (:func:`_at_vertex`; a function of the BLK alone)."""
    real = [b for b in structure.blocks if b.kind == REAL]
    if not real:
        empty = np.zeros(0, dtype=int)
        return empty, empty, empty, empty
    rows = np.concatenate([np.arange(b.rows) + b.row_offset for b in real])
    cols = np.concatenate([np.arange(b.rows) + b.col_offset for b in real])
    owner = np.concatenate([np.full(b.rows, k) for k, b in enumerate(real)])
    first = np.cumsum([0] + [b.rows for b in real[:-1]])
    return first, rows, cols, owner
