"""Batched frequency response of LFRs and model arrays (no Python loop per frequency).

For every model the state matrix is diagonalized once, ``A = V diag(lambda) V^-1``, and

.. math:: G(j\\omega) = D + (C V) \\,
          \\mathrm{diag}\\big(1/(j\\omega - \\lambda)\\big) \\, (V^{-1} B)

is evaluated for all frequencies with one batched matrix product: one eigendecomposition plus
``O(F n ny nu)`` per model, with models processed in chunks to bound memory.

Two structures would spoil the modal sum and are handled exactly instead:

* Integrator tails. States that only feed later integrators (rigid-body ``1/(J s^2)`` outputs, the
  everyday case in spacecraft models) are found from the sparsity pattern of ``A`` over the whole
  batch: ``A = [[A11, 0], [A21, A22]]`` with ``A22`` nilpotent, so ``(sI - A22)^-1`` is a
  polynomial in ``1/s`` and only ``A11`` is diagonalized. The ``s^-(p+1)`` factors are folded into
  the modal residues by partial fractions when the poles of ``A11`` are not small.
* Ill-conditioned eigenvalues (defective or nearly defective, flagged by their condition number
  ``||v_i|| ||w_i||``, estimated with two random probes). With ``Q = [Q_g, Q_b]`` from a QR
  factorization of the well-conditioned eigenvectors, ``Q^H A Q`` is block upper triangular; the
  good block is diagonal in the projected eigenvectors and the small bad block is solved through
  its complex Schur form by back substitution for all frequencies at once.

Models where even this fails use an exact direct solve ``(j omega I - A) X = B``.

Real models whose state matrix is 2x2-block diagonal up to a low-rank coupling (flexible modes
on a hub: the Monte Carlo arrays of the paper) first try the eigendecomposition-free route of
:mod:`oos_drake.lfr.coupled_modes` (Woodbury identity, one real matrix product and closed-form
``r x r`` solves per model). The other real models take the modal route next: LAPACK ``dgeev``
returns the eigenvectors of a real ``A`` as a REAL basis ``T`` (real and imaginary parts of each
conjugate pair), so ``T^-1 B`` is a real solve, and the modal terms are summed two by two over
conjugate (or real) eigenvalue pairs,

.. math:: \\frac{r_1}{s - \\lambda_1} + \\frac{r_2}{s - \\lambda_2}
          = \\frac{s (r_1 + r_2) - (r_1 \\lambda_2 + r_2 \\lambda_1)}
                 {s^2 - (\\lambda_1 + \\lambda_2) s + \\lambda_1 \\lambda_2},

whose coefficients are all real: with ``1/d(j omega) = U + jV`` per pair, the whole response
(modal part, feedthrough and integrator-tail polynomial) is ONE real matrix product per model,
``[U, V, omega U, omega V, 1, omega^-r] @ R``, written straight into the complex output.
Models that this route cannot treat exactly (ill-conditioned or
defective eigenvalues, small poles next to an integrator tail, complex data) fall back to the
general path above, model by model. Chunks of models can be processed by ``workers``
threads (LAPACK and BLAS release the GIL); the result does not depend on the thread count.
"""

from __future__ import annotations

import functools
import threading

import numpy as np
import scipy.linalg
from scipy.linalg import lapack

from oos_drake.lfr.core import as_lfr
from oos_drake.lfr.coupled_modes import block_pairs, coupled_response, tail_terms
from oos_drake.lfr.workspace import Workspace
from oos_drake.processes import make_executor

#: Eigenvalues whose condition number ``||v|| ||w||`` exceeds this go to the clustered block.
EIG_COND_LIMIT = 1e5
#: A well-conditioned eigenvalue closer than this (relative) to a clustered one: direct solve.
CLUSTER_SEP_RTOL = 1e-6
#: Largest clustered block handled by the block method (larger: direct solve fallback).
MAX_CLUSTER = 24
#: Target size (complex entries) of temporary arrays per chunk.
CHUNK_ENTRIES = 1_500_000
#: Models per chunk on the block + low-rank route (at most; chunks come in even numbers).
COUPLED_CHUNK = 64


def freqresp(
    sys, omega, *, workers: int = 1, coupled: bool = True, real_pairs: bool = True
) -> np.ndarray:
    """Frequency response ``G(j omega)`` of an LFR or model array.

    Parameters
    ----------
    sys : LFR or convertible
        A model or model array. Uncertain blocks still present are taken at their NOMINAL value
        (like MATLAB's ``freqresp`` of an uncertain model); substitute them first with ``usubs``.
    omega : array_like
        Frequencies [rad/s], shape ``(F,)``.
    workers : int
        Threads evaluating chunks of a model array in parallel (1: single-threaded; e.g.
        ``os.cpu_count()`` for large arrays). Results are bitwise independent of it; each
        worker runs its BLAS calls single-threaded.
    coupled : bool
        Try the eigendecomposition-free route of :mod:`oos_drake.lfr.coupled_modes` first for
        real models whose state matrix is 2x2-block diagonal up to a low-rank coupling (the
        default); False skips it (for tests and benchmarks: the same response).
    real_pairs : bool
        Use the real-arithmetic pairwise modal route for real models (the default); False: the
        general path only (for tests).

    Returns
    -------
    numpy.ndarray
        Complex array of shape ``batch_shape + (F, ny, nu)``.
    """
    sys = as_lfr(sys)
    if not sys.is_certain:
        sys = sys.nominal
    omega = np.atleast_1d(np.asarray(omega, dtype=float))
    if omega.ndim != 1:
        raise ValueError(f"freqresp: omega must be 1-D, got shape {omega.shape}")
    n = sys.nstates
    batch = sys.batch_shape
    ny, nu = sys.shape
    M = sys.M.reshape((-1,) + sys.M.shape[-2:])
    nb = M.shape[0]
    out = np.empty((nb, omega.size, ny, nu), dtype=complex)
    if n == 0:
        out[:] = M[:, None, :, :]
        return out.reshape(batch + out.shape[1:])
    pattern = np.logical_or.reduce(M[:, :n, :n], axis=0)  # nonzero anywhere in the batch
    core, tail, powers = _integrator_tail(M[:, :n, :n], pattern)
    pairs = None
    if coupled and core.size and not np.iscomplexobj(M):
        pairs = block_pairs(pattern[np.ix_(core, core)])
    n_core = core.size
    per_model = omega.size * (n_core + 4 * ny * nu * (1 + powers)) + 6 * n * n
    sub = max(1, CHUNK_ENTRIES // per_model)
    # the block + low-rank route has small per-model temporaries (it sub-chunks its frequency
    # part itself): larger chunks amortize its per-chunk work; the fallback routes keep ``sub``
    chunk = sub
    if pairs is not None:
        # an even number of equal chunks (balanced on two worker threads; the chunking must
        # not depend on workers, so that results are bitwise independent of it)
        pieces = 2 * max(1, -(-nb // (2 * max(sub, COUPLED_CHUNK))))
        chunk = max(1, -(-nb // pieces))
    starts = range(0, nb, chunk)
    local = threading.local()

    def work(start):
        stop = min(nb, start + chunk)
        if not hasattr(local, "ws"):
            local.ws = Workspace()
        _block_response(
            M[start:stop], n, core, tail, powers, omega, out[start:stop], local.ws, pairs, sub,
            real_pairs,
        )  # fmt: skip

    with make_executor(workers, "threads") as threads:
        threads.map(work, starts)
    return out.reshape(batch + out.shape[1:])


def _block_response(
    M, n, core, tail, powers, omega, out, ws=None, pairs=None, sub=None, real_pairs=True
):
    """Response of one chunk of models into ``out``: the block + low-rank route
    (:mod:`oos_drake.lfr.coupled_modes`, when ``pairs`` is given), then the real pairwise modal
    route (if ``real_pairs``), then the general path (:func:`_tail_response` /
    :func:`_chunk_response`), each for the models the previous one could not treat (in pieces
    of at most ``sub`` models)."""
    todo = np.arange(M.shape[0])
    if pairs is not None and core.size and not np.iscomplexobj(M):
        ok = coupled_response(M, n, core, tail, powers, omega, pairs, out, ws)
        todo = np.flatnonzero(~ok)
    sub = M.shape[0] if sub is None else max(1, int(sub))
    for start in range(0, todo.size, sub):
        idx = todo[start : start + sub]
        if idx.size == M.shape[0]:
            _fallback_response(M, n, core, tail, powers, omega, out, ws, real_pairs)
        else:
            part = np.empty((idx.size,) + out.shape[1:], dtype=complex)
            _fallback_response(M[idx], n, core, tail, powers, omega, part, ws, real_pairs)
            out[idx] = part


def _fallback_response(M, n, core, tail, powers, omega, out, ws=None, real_pairs=True):
    """The real pairwise modal route where it applies (if ``real_pairs``), the general path for
    the other models."""
    s = 1j * omega
    if real_pairs and core.size and not np.iscomplexobj(M):
        _, ok = _real_pair_response(M, n, core, tail, powers, omega, out, ws)
        rest = np.flatnonzero(~ok)
        if rest.size:
            out[rest] = _general_response(M[rest], n, core, tail, powers, s)
    else:
        out[:] = _general_response(M, n, core, tail, powers, s)


def _general_response(M, n, core, tail, powers, s):
    if tail.size:
        return _tail_response(M, n, core, tail, powers, s)
    return _chunk_response(M, n, s)


def _real_eig(A, ws=None):
    """``dgeev`` of every real ``A[k]``: eigenvalues ``(g, m)`` (complex) and the real basis ``T``
    ``(g, m, m)`` (columns ``j, j+1`` are the real and imaginary parts of the eigenvector of a
    conjugate pair, positive imaginary part first). ``ok[k]`` is False if ``A[k]`` is not finite
    or LAPACK failed (the caller then uses the general path)."""
    g, m = A.shape[0], A.shape[-1]
    ws = Workspace() if ws is None else ws
    lam = np.empty((g, m), dtype=complex)
    T = ws.get("eig_T", (g, m, m))
    ok = np.all(np.isfinite(A), axis=(1, 2))
    for k in range(g):
        info = 1
        if ok[k]:
            a = np.array(A[k], order="F")
            wr, wi, _, vr, info = lapack.dgeev(a, compute_vl=0, compute_vr=1, overwrite_a=1)
        if info != 0:
            ok[k] = False
            lam[k] = 1.0
            T[k] = np.eye(m)
            continue
        lam[k].real = wr
        lam[k].imag = wi
        T[k] = vr
    return lam, T, ok


def _real_pair_response(
    M, n, core, tail, powers, omega, out=None, ws=None, safe_ratio: float = 1e6
):
    """Real-arithmetic modal response of real models (see the module notes).

    Returns ``(out, ok)`` (``out`` is filled in place when given, C-contiguous of shape
    ``(g, F, ny, nu)``): ``out[k]`` is valid where ``ok[k]``; the other models need the general
    path (failed or ill-conditioned eigendecomposition, or small poles beside an integrator tail
    that would make the partial fractions inaccurate).
    """
    g = M.shape[0]
    ny, nu = M.shape[1] - n, M.shape[2] - n
    m = core.size
    nf = omega.size
    ws = Workspace() if ws is None else ws
    A11 = M[:, core[:, None], core[None, :]]
    B1, C1, D = M[:, core, n:], M[:, n:, core], M[:, n:, n:]
    tail_C, tail_B = tail_terms(M, M[:, tail[:, None], core[None, :]], tail, n, powers)
    lam, T, ok = _real_eig(A11, ws)
    with np.errstate(all="ignore"):
        # reals first (stable sort keeps each conjugate pair adjacent, positive part first);
        # an odd count of reals gets a zero-residue companion so that slots pair up evenly
        is_cplx = lam.imag != 0
        order = np.argsort(is_cplx, axis=1, kind="stable")
        lam = np.take_along_axis(lam, order, axis=1)
        T = np.take_along_axis(T, order[:, None, :], axis=2)
        is_cplx = np.take_along_axis(is_cplx, order, axis=1)
        X, singular = _safe_solve(
            T, np.concatenate([B1, np.broadcast_to(_probes(m, real=True), (g, m, 2))], axis=2)
        )
        ok &= ~singular
        first = is_cplx & (lam.imag > 0)
        second = is_cplx & (lam.imag < 0)
        # complex right eigenvector projections C v_j and left projections w_j^H B
        CT = [C1 @ T] + [Cp @ T for Cp in tail_C]
        cv = [_pair_columns(Y, first, second, sign=1.0) for Y in CT]
        XB = np.swapaxes(X[:, :, :nu], 1, 2)  # (g, nu, m)
        wb = (
            np.swapaxes(_pair_columns(XB, first, second, sign=-1.0), 1, 2)
            * np.where(is_cplx, 0.5, 1.0)[:, :, None]
        )  # (g, m, nu)
        # eigenvalue condition estimate ||v_j|| ||w_j|| (probes estimate the rows of T^-1)
        rows = np.sqrt(m) * np.max(np.abs(X[:, :, nu:]), axis=2)
        cols = np.linalg.norm(T, axis=1)
        partner_rows = _partner(rows, first, second)
        partner_cols = _partner(cols, first, second)
        kappa = np.hypot(rows, partner_rows) * np.hypot(cols, partner_cols)
        kappa = np.where(is_cplx, 0.5 * kappa, kappa)
        ok &= np.all(np.isfinite(kappa) & (kappa <= EIG_COND_LIMIT), axis=1)
        lam_min = np.min(np.abs(lam), axis=1)
        # slots pair up as (real, real) or (lambda, conj(lambda)): the number of real eigenvalues
        # has the parity of m, so an odd m gets one leading zero-residue real companion
        if m % 2:
            lam = np.concatenate([np.full((g, 1), -1.0 + 0j), lam], axis=1)
            cv = [np.concatenate([np.zeros((g, ny, 1)), c], axis=2) for c in cv]
            wb = np.concatenate([np.zeros((g, 1, nu)), wb], axis=1)
        l1, l2 = lam[:, 0::2], lam[:, 1::2]
        paired = ((l1.imag == 0) & (l2.imag == 0)) | ((l1.imag > 0) & (l2 == np.conj(l1)))
        ok &= np.all(paired, axis=1)
        # tail: fold s^-(p+1) into the residues by partial fractions (poles must not be small)
        q = len(tail_C)
        inv_lam = 1.0 / lam
        if q:
            smax = float(np.max(omega)) if nf else 0.0
            ok &= (lam_min > 0) & ((smax / lam_min) ** q < safe_ratio)
            eff = cv[0].copy()
            for p in range(q):
                eff += cv[p + 1] * (inv_lam ** (p + 1))[:, None, :]
        else:
            eff = cv[0]
        # residues r_j = (C v_j)(w_j^H B), flattened (ny*nu); pair slots -> real coefficients
        r = (np.swapaxes(eff, 1, 2)[:, :, :, None] * wb[:, :, None, :]).reshape(g, -1, ny * nu)
        # pair slots (lambda_1, lambda_2): r_1/(s - l_1) + r_2/(s - l_2) = (s P + Q) / d(s)
        r1, r2 = r[:, 0::2], r[:, 1::2]
        P = (r1 + r2).real
        Q = -(r1 * l2[:, :, None] + r2 * l1[:, :, None]).real
        tr = (l1 + l2).real  # (g, h)
        det = (l1 * l2).real
        k = ny * nu
        h = tr.shape[1]
        q = len(tail_B)
        # polynomial part sum_r K_r s^-r of the tail: C2 A22^(r-1) B2 minus the partial-fraction
        # terms (real up to rounding)
        K = np.zeros((g, q, ny, nu))
        for p in range(q):
            K[:, p] += tail_B[p]
            for rr in range(1, p + 2):
                weighted = cv[p + 1] * (inv_lam ** (p + 2 - rr))[:, None, :]
                K[:, rr - 1] -= (weighted @ wb).real
        # One real product per model gives G(jw) in complex storage. With d(jw) = (det - w^2)
        # - j tr w = 1/(U + jV) per pair slot: G = sum (jw P + Q)(U + jV) + D + sum K_r (jw)^-r,
        # i.e. Re G = Q U - P wV + D + ..., Im G = Q V + P wU + ...; the left factor is
        # L = [U, V, wU, wV, 1, w^-1 .. w^-q] and the right factor interleaves Re/Im columns.
        L = ws.get("L", (g, nf, 4 * h + 1 + q))
        re = np.subtract(
            det[:, None, :], (omega * omega)[None, :, None], out=ws.get("re", (g, nf, h))
        )
        im = np.multiply(tr[:, None, :], omega[None, :, None], out=ws.get("im", (g, nf, h)))
        den = np.multiply(re, re, out=ws.get("den", (g, nf, h)))
        den += np.multiply(im, im, out=L[:, :, :h])  # scratch, overwritten below
        np.reciprocal(den, out=den)
        U = np.multiply(re, den, out=L[:, :, :h])
        V = np.multiply(im, den, out=L[:, :, h : 2 * h])
        wcol = omega[None, :, None]
        np.multiply(U, wcol, out=L[:, :, 2 * h : 3 * h])
        np.multiply(V, wcol, out=L[:, :, 3 * h : 4 * h])
        L[:, :, 4 * h] = 1.0
        for r in range(1, q + 1):
            L[:, :, 4 * h + r] = omega ** (-r)
        Rm = ws.get("Rm", (g, 4 * h + 1 + q, k, 2))
        Rm[...] = 0.0
        Rm[:, :h, :, 0] = Q
        Rm[:, h : 2 * h, :, 1] = Q
        Rm[:, 2 * h : 3 * h, :, 1] = P
        Rm[:, 3 * h : 4 * h, :, 0] = -P
        Rm[:, 4 * h, :, 0] = D.reshape(g, k)
        for r in range(1, q + 1):  # (jw)^-r = (-j)^r w^-r
            part, sign = ((1, -1.0), (0, -1.0), (1, 1.0), (0, 1.0))[(r - 1) % 4]
            Rm[:, 4 * h + r, :, part] = sign * K[:, r - 1].reshape(g, k)
        out = np.empty((g, nf, ny, nu), dtype=complex) if out is None else out
        np.matmul(L, Rm.reshape(g, -1, 2 * k), out=out.view(float).reshape(g, nf, 2 * k))
        ok &= np.all(np.isfinite(Rm), axis=(1, 2, 3)) & np.isfinite(
            out.view(float).reshape(g, -1).sum(axis=1)
        )
    return out, ok


def _partner(x, first, second):
    """Value of the other member of each conjugate pair along axis 1 (0 for real eigenvalues)."""
    return np.where(first, np.roll(x, -1, 1), np.where(second, np.roll(x, 1, 1), 0.0))


def _pair_columns(Y, first, second, sign):
    """Complex columns from the real pair storage along the last axis of ``Y``:
    ``Y_j + i sign Y_{j+1}`` for the first member of a pair, ``Y_{j-1} - i sign Y_j`` for the
    second, ``Y_j`` for a real eigenvalue (``first``/``second``: ``(g, m)`` masks)."""
    nxt = np.roll(Y, -1, axis=-1)
    prv = np.roll(Y, 1, axis=-1)
    fm, sm = first[:, None, :], second[:, None, :]
    out = Y.astype(complex)
    out.imag = np.where(fm, sign * nxt, np.where(sm, -sign * Y, 0.0))
    out.real = np.where(sm, prv, Y)
    return out


def _tail_response(M, n, core, tail, powers, s):
    """Response when the states split into a core and a nilpotent integrator tail."""
    nb = M.shape[0]
    ny, nu = M.shape[1] - n, M.shape[2] - n
    A11 = M[:, core[:, None], core[None, :]]
    B1, C1 = M[:, core, n:], M[:, n:, core]
    # C2 (sI - A22)^-1 = sum_p s^-(p+1) C2 A22^p  (A22 nilpotent)
    tail_C, tail_B = tail_terms(M, M[:, tail[:, None], core[None, :]], tail, n, powers)
    with np.errstate(all="ignore"):
        if core.size:
            core_M = np.block([[A11, B1], [C1, np.zeros((nb, ny, nu), dtype=M.dtype)]])
            out = _chunk_response(core_M, core.size, s, tail_C)  # C1 X1 + sum s^-(p+1) C_p X1
        else:
            out = np.zeros((nb, s.size, ny, nu), dtype=complex)
        out += M[:, None, n:, n:]
        for p, KB in enumerate(tail_B):
            out += KB[:, None] * (s ** -(p + 1))[None, :, None, None]
    return out


def _integrator_tail(A: np.ndarray, pattern: np.ndarray | None = None):
    """Split states into a core and a downstream chain of pure integrators (structurally, over
    the whole batch): tail states feed only later tail states, so ``A = [[A11, 0], [A21, A22]]``
    with ``A22`` strictly lower triangular (nilpotent). Rigid-body ``1/s^2`` outputs are the typical
    tail; removing them keeps the eigendecomposition free of their defective zero eigenvalues.

    ``pattern`` (optional) is the precomputed boolean ``(n, n)`` union of the nonzero patterns.
    Returns ``(core, tail, q)`` index arrays and the nilpotency index ``q`` of ``A22``.
    """
    if pattern is None:
        pattern = np.any(A != 0, axis=0)
    n = pattern.shape[0]
    in_tail = np.zeros(n, dtype=bool)
    added = []
    while True:
        rows_free = ~in_tail
        feeds_core = np.any(pattern[rows_free, :], axis=0)
        new = np.flatnonzero(~feeds_core & ~in_tail)
        if new.size == 0:
            break
        added.append(new)
        in_tail[new] = True
    if not added:
        return np.arange(n), np.zeros(0, dtype=int), 0
    tail = np.concatenate(added[::-1])
    core = np.flatnonzero(~in_tail)
    return core, tail, len(added)


def _modal_sum(Ct, lam, Bt, s) -> np.ndarray:
    """``sum_i Ct[:, i] Bt[i, :] / (s - lam_i)`` for all models and frequencies."""
    g, ny, m = Ct.shape
    nu = Bt.shape[-1]
    resolvent = np.reciprocal(s[None, :, None] - lam[:, None, :])  # (g, F, m)
    if ny * nu <= m:
        residues = Ct.transpose(0, 2, 1)[:, :, :, None] * Bt[:, :, None, :]  # (g, m, ny, nu)
        return (resolvent @ residues.reshape(g, m, ny * nu)).reshape(g, s.size, ny, nu)
    return np.einsum("gin,gfn,gnj->gfij", Ct, resolvent, Bt, optimize=True)


def _chunk_response(M: np.ndarray, n: int, s: np.ndarray, tail_C=None) -> np.ndarray:
    """``C (sI - A)^-1 B + D`` for a chunk of models; with ``tail_C = [C_0, C_1, ...]`` the
    result is ``C X + sum_p s^-(p+1) C_p X + D``, ``X = (sI - A)^-1 B`` (integrator tail)."""
    if tail_C:
        return _chunk_response_tail(M, n, s, tail_C)
    A = M[:, :n, :n]
    B = M[:, :n, n:]
    C = M[:, n:, :n]
    D = M[:, n:, n:]
    nb, ny, nu = M.shape[0], C.shape[1], B.shape[2]
    result = np.empty((nb, s.size, ny, nu), dtype=complex)
    direct = np.zeros(nb, dtype=bool)
    with np.errstate(all="ignore"):
        lam, V, X, kappa, singular = _modal_basis(A, B)
        bad = ~np.isfinite(kappa) | (kappa > EIG_COND_LIMIT)
        bad[singular] = True
        nbad = bad.sum(axis=1)
        plain = np.flatnonzero(nbad == 0)
        if plain.size:
            result[plain] = _modal_sum(C[plain] @ V[plain], lam[plain], X[plain], s)
            result[plain] += D[plain][:, None, :, :]
        for k in np.unique(nbad[nbad > 0]):
            group = np.flatnonzero(nbad == k)
            if k > MAX_CLUSTER or k >= n:
                direct[group] = True
                continue
            ok, resp = _clustered_response(
                A[group], B[group], C[group], lam[group], V[group], bad[group], int(k), s
            )
            result[group[ok]] = resp[ok] + D[group[ok]][:, None, :, :]
            direct[group[~ok]] = True
    for k in np.flatnonzero(direct):
        result[k] = _direct_response(A[k], B[k], C[k], D[k], s)
    return result


def _chunk_response_tail(M, n, s, tail_C, safe_ratio: float = 1e6):
    """Tail version of :func:`_chunk_response`. Models whose eigenvalues are all well conditioned
    and not small fold the ``s^-(p+1)`` factors into the modal residues by partial fractions,

    ``s^-(p+1) / (s - l) = l^-(p+1) / (s - l) - sum_{r=1}^{p+1} l^-(p+2-r) s^-r``,

    so one modal sum of ``ny x nu`` residues suffices; the others use an augmented output."""
    q = len(tail_C)
    nb, ny, nu = M.shape[0], M.shape[1] - n, M.shape[2] - n
    A, B, C = M[:, :n, :n], M[:, :n, n:], M[:, n:, :n]
    result = np.empty((nb, s.size, ny, nu), dtype=complex)
    lam, V, X, kappa, singular = _modal_basis(A, B)
    well = np.all(np.isfinite(kappa) & (kappa <= EIG_COND_LIMIT), axis=1) & ~singular
    lam_min = np.min(np.abs(lam), axis=1)
    smax = np.max(np.abs(s)) if s.size else 0.0
    with np.errstate(all="ignore"):
        fast = well & (lam_min > 0) & ((smax / lam_min) ** q < safe_ratio)
    idx = np.flatnonzero(fast)
    if idx.size:
        Vf, lamf, Bt = V[idx], lam[idx], X[idx]
        CpV = [Cp[idx] @ Vf for Cp in tail_C]
        inv_lam = 1.0 / lamf
        Ct = C[idx] @ Vf
        for p, cpv in enumerate(CpV):
            Ct = Ct + cpv * (inv_lam ** (p + 1))[:, None, :]
        resp = _modal_sum(Ct, lamf, Bt, s) + M[idx, None, n:, n:]
        for p, cpv in enumerate(CpV):
            for r in range(1, p + 2):
                coef = (cpv * (inv_lam ** (p + 2 - r))[:, None, :]) @ Bt
                resp -= coef[:, None] * (s**-r)[None, :, None, None]
        result[idx] = resp
    rest = np.flatnonzero(~fast)
    if rest.size:
        C_aug = np.concatenate([C[rest]] + [Cp[rest] for Cp in tail_C], axis=1)
        M_aug = np.block([[A[rest], B[rest]], [C_aug, np.zeros((rest.size, C_aug.shape[1], nu))]])
        aug = _chunk_response(M_aug, n, s)
        out = aug[:, :, :ny, :] + M[rest, None, n:, n:]
        for p in range(q):
            out += aug[:, :, ny * (p + 1) : ny * (p + 2), :] * (s ** -(p + 1))[None, :, None, None]
        result[rest] = out
    return result


def _modal_basis(A, B):
    """``A V = V diag(lam)``, ``X = V^-1 B``, eigenvalue condition estimates ``kappa`` (random
    probes estimate the norms of the rows of ``V^-1`` without forming it) and ``singular``."""
    nb, n, nu = B.shape
    lam, V = np.linalg.eig(A)
    probes = np.broadcast_to(_probes(n), (nb, n, 2))
    X, singular = _safe_solve(V, np.concatenate([B.astype(complex), probes], axis=2))
    kappa = np.sqrt(n) * np.max(np.abs(X[:, :, nu:]), axis=2) * np.linalg.norm(V, axis=-2)
    return lam, V, X[:, :, :nu], kappa, singular


@functools.lru_cache(maxsize=128)
def _probes(n: int, real: bool = False) -> np.ndarray:
    """Two fixed unit-norm complex (or real) Gaussian probe vectors (deterministic, by ``n``)."""
    if real:
        probe = np.random.default_rng(20_240_602 + n).standard_normal((n, 2))
    else:
        rng = np.random.default_rng(20_240_601 + n)
        probe = rng.standard_normal((n, 2)) + 1j * rng.standard_normal((n, 2))
    probe = probe / np.linalg.norm(probe, axis=0)
    probe.flags.writeable = False
    return probe


def _safe_solve(V, rhs):
    """Batched ``V^-1 rhs``; exactly singular ``V`` give ``inf`` and are flagged."""
    try:
        return np.linalg.solve(V, rhs), np.zeros(V.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        out = np.empty(rhs.shape, dtype=np.result_type(V, rhs))
        singular = np.zeros(V.shape[0], dtype=bool)
        for k in range(V.shape[0]):
            try:
                out[k] = np.linalg.solve(V[k], rhs[k])
            except np.linalg.LinAlgError:
                out[k] = np.inf
                singular[k] = True
        return out, singular


def _ctranspose(X):
    return np.conj(np.swapaxes(X, -1, -2))


def _clustered_response(A, B, C, lam, V, bad, k, s):
    """Response of models whose ``k`` flagged eigenvalues are kept as one triangular block.

    With ``Q = [Q_g, Q_b]`` from a QR factorization of the well-conditioned eigenvectors
    ``V_g = Q_g W`` (``W`` triangular), ``Q^H A Q = [[A_gg, A_gb], [0, A_bb]]`` because the span of
    ``V_g`` is invariant, and ``A_gg = W diag(lambda_g) W^-1``. With ``Ct = C Q_g W``,
    ``Bt = W^-1 Q_g^H B``, ``Gt = W^-1 A_gb`` and ``Y(s) = (sI - A_bb)^-1 Q_b^H B``,

    ``G(s) - D = Ct R(s) (Bt + Gt Y(s)) + C Q_b Y(s)``,  ``R(s) = diag(1/(s - lambda_g))``.

    The coupling is split by partial fractions, ``(s - l)^-1 (sI - A_bb)^-1 =
    [(s - l)^-1 I - (sI - A_bb)^-1] (l I - A_bb)^-1``, so that

    ``G(s) - D = Ct R(s) (Bt + X Q_b^H B) + (C Q_b - Ct X) Y(s)``, row ``n`` of ``X`` being
    ``Gt[n] (lambda_n I - A_bb)^-1``: a modal sum plus a ``k``-state block, both O(F) per model.
    ``A_bb = Z T Z^H`` (complex Schur) makes every small solve a triangular substitution.
    """
    g, n = A.shape[0], A.shape[-1]
    m = n - k
    order = np.argsort(bad, axis=1, kind="stable")  # well-conditioned first
    lam_g = np.take_along_axis(lam, order, axis=1)[:, :m]
    V_g = np.take_along_axis(V, order[:, None, :], axis=2)[:, :, :m]
    Q, R = np.linalg.qr(V_g, mode="complete")
    W = R[:, :m, :m]
    diag = np.abs(np.diagonal(W, axis1=-2, axis2=-1))
    ok = np.min(diag, axis=1) > 1e-10 * np.max(diag, axis=1)
    Q_g, Q_b = Q[:, :, :m], Q[:, :, m:]
    Q_gH, Q_bH = _ctranspose(Q_g), _ctranspose(Q_b)
    AQ_g = A @ Q_g
    AQ_b = A @ Q_b
    residual = np.linalg.norm(Q_bH @ AQ_g, axis=(-2, -1)) / np.maximum(
        np.linalg.norm(A, axis=(-2, -1)), 1e-300
    )
    ok &= np.isfinite(residual) & (residual < 1e-10)
    W = np.where(ok[:, None, None], W, np.eye(m))  # keep the solves regular
    A_bb = Q_bH @ AQ_b
    Bt = np.linalg.solve(W, Q_gH @ B)  # (g, m, nu)
    Ct = (C @ Q_g) @ W  # (g, ny, m)
    T = np.empty((g, k, k), dtype=complex)
    Z = np.empty((g, k, k), dtype=complex)
    for i in range(g):
        T[i], Z[i] = scipy.linalg.schur(A_bb[i], output="complex")
    # the partial fractions divide by lambda_good - lambda_bad: a good eigenvalue (nearly) equal
    # to a clustered one (repeated eigenvalues of duplicated subsystems) needs the direct solve
    diag_T = np.diagonal(T, axis1=1, axis2=2)  # (g, k)
    sep = np.min(np.abs(lam_g[:, :, None] - diag_T[:, None, :]), axis=(1, 2))
    scale = np.maximum(np.max(np.abs(lam_g), axis=1), np.max(np.abs(diag_T), axis=1))
    ok &= sep > CLUSTER_SEP_RTOL * np.maximum(scale, 1e-300)
    GtZ = np.linalg.solve(W, Q_gH @ AQ_b) @ Z  # (g, m, k)
    # X_z[n] = GtZ[n] (lambda_n I - T)^-1  (row vectors: forward substitution)
    X_z = np.empty((g, m, k), dtype=complex)
    for col in range(k):
        acc = GtZ[:, :, col].copy()
        if col:
            acc += np.einsum("gmi,gi->gm", X_z[:, :, :col], T[:, :col, col])
        X_z[:, :, col] = acc / (lam_g - T[:, col, col, None])
    Bz = _ctranspose(Z) @ (Q_bH @ B)  # (g, k, nu)
    resp = _modal_sum(Ct, lam_g, Bt + X_z @ Bz, s)  # (g, F, ny, nu)
    # k-state block (C Q_b Z - Ct X_z) (sI - T)^-1 Bz: back substitution for all frequencies
    nf, nu, ny = s.size, B.shape[-1], C.shape[1]
    Yt = np.empty((g, k, nf, nu), dtype=complex)
    for row in range(k - 1, -1, -1):
        acc = np.broadcast_to(Bz[:, row, None, :], (g, nf, nu)).copy()
        if row + 1 < k:
            acc += np.einsum("gj,gjfu->gfu", T[:, row, row + 1 :], Yt[:, row + 1 :])
        Yt[:, row] = acc / (s[None, :, None] - T[:, row, row, None, None])
    C_blk = (C @ Q_b) @ Z - Ct @ X_z  # (g, ny, k)
    resp += np.swapaxes((C_blk @ Yt.reshape(g, k, nf * nu)).reshape(g, ny, nf, nu), 1, 2)
    return ok, resp


def _direct_response(A, B, C, D, s, chunk: int = 64) -> np.ndarray:
    """Exact ``C (sI - A)^-1 B + D`` by batched complex solves (any ``A``)."""
    n = A.shape[0]
    out = np.empty((s.size,) + D.shape, dtype=complex)
    eye = np.eye(n)
    with np.errstate(all="ignore"):
        for start in range(0, s.size, chunk):
            sl = slice(start, min(s.size, start + chunk))
            pencil = s[sl, None, None] * eye - A
            try:
                X = np.linalg.solve(pencil, np.broadcast_to(B, (pencil.shape[0],) + B.shape))
                out[sl] = C @ X + D
            except np.linalg.LinAlgError:
                for k, sk in enumerate(s[sl]):
                    try:
                        out[start + k] = C @ np.linalg.solve(sk * eye - A, B) + D
                    except np.linalg.LinAlgError:
                        out[start + k] = np.inf  # s is a pole
    return out
