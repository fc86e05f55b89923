"""Frequency response of state matrices that are 2x2-block diagonal up to a low-rank coupling.

Flexible appendages in modal coordinates mounted on a rigid hub (the paper's spacecraft, and every
model assembled from TITOP blocks around a hub) have state matrices of the form

.. math:: A = D + U W^T,

``D`` block diagonal with one 2x2 block per mode (its position row ``q' = v`` and its velocity
row) and ``U W^T`` of small rank ``r`` (the hub degrees of freedom: every mode is driven by the
hub acceleration, which depends on all the modes). With ``R_0(s) = (sI - D)^{-1}`` and the
Woodbury identity,

.. math:: C (sI - A)^{-1} B = H_{cb} + H_{cu} K^{-1} H_{wb}, \\qquad K = I_r - H_{wu},

where ``H = [C; W^T] R_0 [B, U]``. Each 2x2 block contributes ``(s P_j + Q_j) / d_j(s)`` to
``H`` with ``d_j(s) = s^2 - t_j s + \\delta_j`` (trace and determinant of the block) and real
coefficients ``P_j = X_j Y_j``, ``Q_j = X_j N_j Y_j`` (``N_j = adj(sI - D_j) - sI``), so ``H`` at
all frequencies is ONE real matrix product per model, and the ``r x r`` solves are closed-form
(``r <= 3``) over all frequencies at once. No eigendecomposition is needed: ``O(F h (ny + r)
(nu + r))`` per model against a dense ``dgeev`` (``~25 m^3``) plus the modal sum.

Sensors and actuators on the coupling (hub torques in, hub angles out: ``B = U beta`` and
``C = Gamma W^T``) shrink this to the ``r x r`` matrix ``H_wu`` alone:
``G = Gamma (K^{-1} - I) beta`` (``K^{-1} - I = K^{-1} H_wu``), with the integrator-tail outputs
``C_p = Gamma_p W^T`` entering as ``Gamma(s) = sum_p s^-p Gamma_p``; with sensors only,
``G = Gamma(s) K^{-1} H_wb``. Otherwise integrator tails (see :mod:`oos_drake.lfr.frequency`) are
folded into the block denominators by partial fractions, ``(sP + Q) / (s d(s)) = alpha / s +
(-alpha s + P + alpha t) / d(s)`` with ``alpha = Q / delta``, like the modal route does with
eigenvalues.

The structure is detected, not assumed: the 2x2 blocks pair each "kinematic" row (a row of ``A``
with a single nonzero, off the diagonal, over the whole batch) with the state it integrates; the
other states are paired two by two (an odd one out gets a decoupled padding state). ``U`` and
``W`` are identified per model from the off-block entries of ``A`` (three interleaved groups of
blocks, a seeded random range finder for the rank, least squares; see :func:`_split_coupling`),
``D`` is what remains on the blocks, and ``D + U W^T`` must reproduce ``A`` to round-off
(checked on two random probe vectors). Models that fail any check (rank above
:data:`RANK_LIMIT`, too few modes per group to identify the coupling, a block pole on the
imaginary axis, a small block pole next to an integrator tail, non-finite values) are reported so
the caller can use the modal route.
"""

from __future__ import annotations

import functools

import numpy as np

from oos_drake.lfr.workspace import Workspace

#: Largest coupling rank handled by this route (closed-form ``r x r`` solves).
RANK_LIMIT = 3
#: A singular value of the coupling below this fraction of the largest is round-off.
RANK_RTOL = 1e-10
#: Accepted residual ``||(A - D - U W^T) X|| / (||A||_F ||X||)`` of the split (and of the
#: sensor / actuator reductions, relative to ``||C||`` and ``||B||``).
FACTOR_RTOL = 1e-13
#: A 2x2 block with damping ratio below this (a pole on the imaginary axis) is rejected.
POLE_ON_GRID_RTOL = 1e-8
#: Size (complex entries) of the frequency-dependent temporaries of one sub-chunk of models.
SUB_CHUNK_ENTRIES = 150_000
#: Limit on ``(omega_max / |lambda|_min)^q`` for the partial fractions of an integrator tail.
TAIL_SAFE_RATIO = 1e6


def block_pairs(pattern: np.ndarray) -> np.ndarray | None:
    """Pair the states of a state matrix into 2x2 blocks from its sparsity ``pattern``.

    Parameters
    ----------
    pattern : numpy.ndarray
        Boolean ``(m, m)`` union of the nonzero patterns of the batch's state matrices.

    Returns
    -------
    numpy.ndarray or None
        ``(h, 2)`` state indices of the blocks; index ``m`` is a padding state (odd ``m``).
        ``None`` if ``m < 4`` (nothing to gain over the modal route).
    """
    m = pattern.shape[0]
    if m < 4:
        return None
    paired = np.zeros(m, dtype=bool)
    pairs = []
    counts = pattern.sum(axis=1)
    for i in range(m):
        if paired[i] or counts[i] != 1 or pattern[i, i]:
            continue
        j = int(np.flatnonzero(pattern[i])[0])
        if not paired[j]:
            pairs.append((i, j))
            paired[i] = paired[j] = True
    rest = list(np.flatnonzero(~paired))
    if len(rest) % 2:
        rest.append(m)
    pairs.extend(zip(rest[0::2], rest[1::2], strict=True))
    return np.array(pairs, dtype=int).reshape(-1, 2)


@functools.lru_cache(maxsize=16)
def _range_probes(m: int, k: int) -> np.ndarray:
    """Fixed Gaussian ``(m, k)`` probes of the random range finder (deterministic)."""
    probes = np.random.default_rng(20_251_122 + 31 * m + k).standard_normal((m, k))
    probes.flags.writeable = False
    return probes


def coupled_response(M, n, core, tail, powers, omega, pairs, out, ws=None):
    """``C (j omega I - A)^-1 B + D`` of a chunk of real models by the block + low-rank route.

    Parameters
    ----------
    M : numpy.ndarray
        Real ``(g, n + ny, n + nu)`` system matrices ``[[A, B], [C, D]]``.
    n : int
        Number of states.
    core, tail : numpy.ndarray
        State indices of the core and of the integrator tail (see
        :func:`oos_drake.lfr.frequency._integrator_tail`); ``powers`` is the tail's nilpotency
        index.
    powers : int
        Nilpotency index of the tail block.
    omega : numpy.ndarray
        Frequencies [rad/s], shape ``(F,)``, all nonzero if there is a tail.
    pairs : numpy.ndarray
        ``(h, 2)`` blocks of core positions from :func:`block_pairs` (``m`` = padding).
    out : numpy.ndarray
        Complex ``(g, F, ny, nu)`` output, written for the models that pass.
    ws : Workspace, optional
        Scratch buffers of the calling thread (:class:`oos_drake.lfr.workspace.Workspace`).

    Returns
    -------
    numpy.ndarray
        Boolean ``(g,)``: True where ``out[k]`` holds the response.
    """
    if omega.size == 0:
        return np.ones(M.shape[0], dtype=bool)  # nothing to evaluate
    with np.errstate(all="ignore"):  # rejected models may carry inf / NaN; they are flagged
        return _coupled_response(M, n, core, tail, powers, omega, pairs, out, ws)


def _coupled_response(M, n, core, tail, powers, omega, pairs, out, ws):
    g = M.shape[0]
    ny, nu = M.shape[1] - n, M.shape[2] - n
    m = core.size
    h = pairs.shape[0]
    ws = Workspace() if ws is None else ws
    nf = omega.size
    # padded core (a decoupled state at -1 when m is odd), states in block order
    idx = np.concatenate([core, [n]]) if 2 * h > m else core
    order = idx[pairs.reshape(-1)]
    Mp = M
    if 2 * h > m:  # pad: row/column n of [[A, B], [C, D]] is replaced below
        Mp = np.zeros((g, n + ny + 1, n + nu + 1))
        Mp[:, : n + ny, : n + nu] = M
        Mp[:, n + ny, n + nu] = -1.0
        order = np.where(order == n, n + ny, order)
        pad_col = n + nu
        col_order = np.where(order == n + ny, pad_col, order)
        out_rows = np.arange(n, n + ny)
        in_cols = np.arange(n, n + nu)
    else:
        col_order = order
        out_rows = np.arange(n, n + ny)
        in_cols = np.arange(n, n + nu)
    # A in block order, gathered into a reused buffer (fresh large arrays cost page faults)
    A = ws.get("cm_A", (g, 2 * h, 2 * h))
    flat = (order[:, None] * Mp.shape[2] + col_order[None, :]).reshape(-1)
    np.take(Mp.reshape(g, -1), flat, axis=1, out=A.reshape(g, -1))
    B = Mp[:, order[:, None], in_cols[None, :]]  # (g, 2h, nu)
    C = Mp[:, out_rows[:, None], col_order[None, :]]  # (g, ny, 2h)
    Dm = M[:, n:, n:]
    jj = np.arange(h)
    i0, i1 = 2 * jj, 2 * jj + 1
    with np.errstate(all="ignore"):
        U, Wt, ok = _split_coupling(A, h)
    if not ok.any():
        return ok
    # the blocks of D: A's diagonal blocks minus those of U W^T
    ublk = U.reshape(g, h, 2, -1)
    wblk = np.swapaxes(Wt, 1, 2).reshape(g, h, 2, -1)
    Dblk = A.reshape(g, h, 2, h, 2)[:, jj, :, jj, :]  # (h, g, 2, 2)
    Dblk = np.moveaxis(Dblk, 0, 1)
    for i in range(ublk.shape[3]):  # minus the blocks of U W^T (r outer products)
        Dblk -= ublk[:, :, :, None, i] * wblk[:, :, None, :, i]
    # D + U W^T must reproduce A to round-off; checked on two fixed random probe vectors x:
    # ||(A - U W^T - D) x|| <= FACTOR_RTOL ||A|| ||x|| (a mismatch anywhere shows up in A x)
    with np.errstate(all="ignore"):
        probe = _range_probes(2 * h, 2)
        resid = A @ probe - U @ (Wt @ probe)
        resid -= (Dblk @ probe.reshape(h, 2, 2)).reshape(g, 2 * h, 2)
        ok &= _sq_norm(resid) <= FACTOR_RTOL**2 * _sq_norm(A) * float(np.sum(probe * probe))
    a, b = Dblk[:, :, 0, 0], Dblk[:, :, 0, 1]
    c, d = Dblk[:, :, 1, 0], Dblk[:, :, 1, 1]
    tr = a + d
    det = a * d - b * c
    # a block pole on (or within round-off of) the imaginary axis: d_j(j w) may vanish on the grid
    ok &= np.all(np.isfinite(det) & np.isfinite(tr), axis=1)
    ok &= np.all((det <= 0) | (np.abs(tr) > POLE_ON_GRID_RTOL * np.sqrt(np.abs(det))), axis=1)
    if not ok.any():
        return ok
    r = U.shape[2]
    # tail: C_p = C2 A22^p A21 (rows weighted by s^-(p+1)) and C2 A22^p B2 (polynomial part)
    tail_C, tail_B = tail_terms(M, Mp[:, tail[:, None], col_order[None, :]], tail, n, powers)
    q = len(tail_C)
    crows = np.concatenate([C] + tail_C, axis=1)  # (g, ny (1 + q), 2h)
    with np.errstate(all="ignore"):
        # sensors on the coupling: C1 and every C_p in the row space of W^T (C = Gamma W^T)
        gamma = _lstsq_right(crows, Wt) if r else np.zeros((g, crows.shape[1], 0))
        c_norm = np.linalg.norm(crows, axis=(1, 2))
        reduced = np.linalg.norm(crows - gamma @ Wt, axis=(1, 2)) <= FACTOR_RTOL * c_norm
        reduced = bool(np.all(reduced[ok]))
        # actuators on the coupling too: B = U beta; then only W^T R0 U is frequency dependent
        hub = False
        if reduced and r:
            beta_t = _lstsq_right(np.swapaxes(B, 1, 2), np.swapaxes(U, 1, 2))  # (g, nu, r)
            b_res = np.linalg.norm(B - U @ np.swapaxes(beta_t, 1, 2), axis=(1, 2))
            hub = bool(np.all((b_res <= FACTOR_RTOL * np.linalg.norm(B, axis=(1, 2)))[ok]))
        X = Wt if reduced else np.concatenate([crows, Wt], axis=1)  # (g, rows, 2h)
        Y = U if hub else np.concatenate([B, U], axis=2)  # (g, 2h, cols)
        x0, x1 = X[:, :, i0, None], X[:, :, i1, None]  # (g, rows, h, 1)
        xn0 = c[:, None, :, None] * x1 - d[:, None, :, None] * x0
        xn1 = b[:, None, :, None] * x0 - a[:, None, :, None] * x1
        y0, y1 = Y[:, None, i0, :], Y[:, None, i1, :]  # (g, 1, h, cols)
        # per-block coefficients of (s P + Q) / d_j(s), (g, rows, h, cols)
        P = x0 * y0 + x1 * y1
        Q = xn0 * y0 + xn1 * y1
        cols = Y.shape[2]
        # polynomial part: D + sum_k s^-k poly_k, entries (ny, nu) of G, or (ny, cols) of H
        poly = np.zeros((g, q + 1, ny, nu if reduced else cols))
        poly[:, 0, :, :nu] = Dm
        for p in range(q):
            poly[:, p + 1, :, :nu] = tail_B[p]
        if q and not reduced:
            lam_min = np.abs(det) / (np.abs(tr) + np.sqrt(np.abs(det)))
            smax = float(np.max(omega)) if nf else 0.0
            ok &= np.all(lam_min > 0, axis=1) & np.all((smax / lam_min) ** q < TAIL_SAFE_RATIO, 1)
            inv_det = (1.0 / det)[:, None, :, None]
            trc = tr[:, None, :, None]
            for p in range(q):
                rows = slice(ny * (p + 1), ny * (p + 2))
                Pc, Qc = P[:, rows], Q[:, rows]
                for i in range(1, p + 2):  # s^-k (sP + Q)/d, k = p + 1, one power at a time
                    alpha = Qc * inv_det
                    poly[:, p + 2 - i] += alpha.sum(axis=2)
                    Pc, Qc = -alpha, Pc + alpha * trc
                P[:, :ny] += Pc
                Q[:, :ny] += Qc
            keep = np.r_[0:ny, ny * (q + 1) : ny * (q + 1) + r]
            P, Q = P[:, keep], Q[:, keep]
        rows = P.shape[1]
        k = rows * cols
        coef = np.empty((g, 2 * k, h))
        coef[:, :k] = Q.transpose(0, 1, 3, 2).reshape(g, k, h)
        coef[:, k:] = P.transpose(0, 1, 3, 2).reshape(g, k, h)
        # s^-k basis of the polynomial part (complex, as a float view for real products)
        basis = (1j * omega)[None, :] ** -np.arange(q + 1)[:, None]
        poly = poly.reshape(g, q + 1, -1).transpose(0, 2, 1)  # (g, entries, q + 1)
        gam = gamma.reshape(g, q + 1, ny, r) if reduced else None
        if hub:
            # G_modal = sum_p s^-p Gamma_p (K^-1 - I) beta: Phi_p[(i, l), (a, b)] = Gamma_p[i, a]
            # beta[b, l] for the powers p with a nonzero Gamma_p
            pows = [p for p in range(q + 1) if np.any(gam[:, p])]
            gam = np.einsum("gpia,glb->gpilab", gam[:, pows], beta_t).reshape(
                g, len(pows) * ny * nu, r * r
            )
            gam = (gam, pows)
        sub = max(1, SUB_CHUNK_ENTRIES // (nf * (h + 2 * k)))
        for st in range(0, g, sub):
            sl = slice(st, st + sub)
            if hub:
                part = (gam[0][sl], gam[1])
            else:
                part = gam[sl] if reduced else None
            _evaluate(
                coef[sl], det[sl], tr[sl], poly[sl], basis, part, hub, omega, ny, nu, r, out[sl], ws
            )
        ok &= np.isfinite(out.view(float).reshape(g, -1).sum(axis=1))
    return ok


def _evaluate(coef, det, tr, poly, basis, gam, hub, omega, ny, nu, r, out, ws):
    """Frequency part of :func:`coupled_response` for a few models (cache-sized arrays).

    ``gam`` is ``None`` (general case), ``Gamma`` ``(g, q + 1, ny, r)`` (sensors on the
    coupling) or, with ``hub``, ``(Phi, powers)`` (sensors and actuators on the coupling)."""
    g, h = det.shape
    nf = omega.size
    k = coef.shape[1] // 2
    cols = r if hub else nu + r
    rows = k // cols
    # E = 1 / d_j(j w) = 1 / ((delta - w^2) - j t w)
    E = ws.get("cm_E", (g, h, nf), complex)
    re, im = E.real, E.imag
    den = ws.get("cm_den", (g, h, nf))
    tmp = ws.get("cm_tmp", (g, h, nf))
    np.subtract(det[:, :, None], (omega * omega)[None, None, :], out=re)
    np.multiply(tr[:, :, None], omega[None, None, :], out=im)
    np.multiply(re, re, out=den)
    den += np.multiply(im, im, out=tmp)
    np.divide(re, den, out=re)
    np.divide(im, den, out=im)
    H = ws.get("cm_H", (g, 2 * k, 2 * nf))
    np.matmul(coef, E.view(float), out=H)  # [sum_j Q_j E_j, sum_j P_j E_j]
    H = H.view(complex)
    Hq = H[:, :k]
    Hq += np.multiply(H[:, k:], 1j * omega, out=H[:, k:])
    Hq = Hq.reshape(g, rows, cols, nf)
    # polynomial part (D and the integrator tail), one real product: (g, entries, 2F)
    Gp = ws.get("cm_Gp", (g, poly.shape[1], 2 * nf))
    np.matmul(poly, basis.view(float), out=Gp)
    Gp = Gp.view(complex).reshape(g, ny, -1, nf)
    if hub:  # G = sum_p s^-p Phi_p vec(K^-1 - I) + polynomial part
        G = Gp
        phi, pows = gam
        if r and pows:
            Y = _inverse_minus_identity(Hq, ws.get("cm_Y", (g, r, r, nf), complex))
            T = ws.get("cm_T", (g, phi.shape[1], 2 * nf))
            np.matmul(phi, Y.reshape(g, r * r, nf).view(float), out=T)
            T = T.view(complex).reshape(g, len(pows), ny, nu, nf)
            for i, p in enumerate(pows):
                if p:
                    T[:, i] *= basis[p]
                G += T[:, i]
        out[...] = np.moveaxis(G, -1, 1)
        return
    Hw = Hq[:, rows - r :]  # W^T R0 [B, U]
    Z = ws.get("cm_Z", (g, r, nu, nf), complex)
    if r:
        _solve_small(Hw[:, :, nu:], Hw[:, :, :nu], Z, ws)  # K^-1 W^T R0 B
    if gam is not None:  # G = Gamma(s) K^-1 W^T R0 B + polynomial part
        G = Gp
        if r:
            zf = Z.reshape(g, r, nu * nf).view(float)
            term = ws.get("cm_term", (g, ny, 2 * nu * nf))
            for p in range(gam.shape[1]):
                if not np.any(gam[:, p]):
                    continue
                np.matmul(gam[:, p], zf, out=term)
                tc = term.view(complex).reshape(g, ny, nu, nf)
                if p:
                    tc *= basis[p]
                G += tc
    else:  # G = H_cb + H_cu K^-1 H_wb + polynomial part
        G = Hq[:, :ny, :nu]
        G += Gp[:, :, :nu]
        if r:
            Hcu = Hq[:, :ny, nu:]
            Hcu += Gp[:, :, nu:]
            for i in range(r):
                G += Hcu[:, :, i, None, :] * Z[:, None, i]
    out[...] = np.moveaxis(G, -1, 1)


def _split_coupling(A, h):
    """``A = D + U W^T`` per model with ``D`` 2x2-block diagonal (blocks ``2j, 2j + 1``).

    The off-block entries of ``A`` are those of ``U W^T``; the blocks are split in three
    interleaved groups ``S1, S2, S3`` whose cross terms are fully known: the range of
    ``A[S1, S2 + S3]`` (random range finder, rank to round-off) gives ``U1`` and ``W2, W3``,
    then ``U2 = A[S2, S3] W3^{+T}``, ``U3 = A[S3, S2] W2^{+T}``, ``W1^T = U2^+ A[S2, S1]``. The
    split is offered where its rank is at most :data:`RANK_LIMIT`; the caller checks that
    ``D + U W^T`` reproduces ``A``.

    Returns ``U (g, 2h, r)``, ``W^T (g, r, 2h)`` and the boolean ``(g,)`` acceptance.
    """
    g, m = A.shape[0], A.shape[1]
    fail = (np.zeros((g, m, 0)), np.zeros((g, 0, m)), np.zeros(g, dtype=bool))
    if h < 3:
        return fail
    S1, S2, S3 = (np.flatnonzero(np.arange(m) // 2 % 3 == k) for k in range(3))
    S23 = np.concatenate([S2, S3])
    A1 = A[:, S1[:, None], S23[None, :]]
    Qf, Rf = np.linalg.qr(A1 @ _range_probes(S23.size, RANK_LIMIT + 2))
    diag = np.abs(np.diagonal(Rf, axis1=1, axis2=2))
    top = np.max(diag, axis=1, keepdims=True)
    r = int(np.max(np.sum(diag > RANK_RTOL * top, axis=1), initial=0))
    ok = np.isfinite(_sq_norm(A))
    if r > RANK_LIMIT or min(S1.size, S2.size, S3.size) < r or not ok.any():
        return fail
    if r == 0:  # A is already 2x2-block diagonal
        return np.zeros((g, m, 0)), np.zeros((g, 0, m)), ok
    U1 = Qf[:, :, :r]
    W23t = np.swapaxes(U1, 1, 2) @ A1  # (g, r, |S23|)
    W2t, W3t = W23t[:, :, : S2.size], W23t[:, :, S2.size :]
    U2 = _lstsq_right(A[:, S2[:, None], S3[None, :]], W3t)
    U3 = _lstsq_right(A[:, S3[:, None], S2[None, :]], W2t)
    W1 = _lstsq_right(np.swapaxes(A[:, S2[:, None], S1[None, :]], 1, 2), np.swapaxes(U2, 1, 2))
    U = np.empty((g, m, r))
    Wt = np.empty((g, r, m))
    U[:, S1], U[:, S2], U[:, S3] = U1, U2, U3
    Wt[:, :, S1], Wt[:, :, S2], Wt[:, :, S3] = np.swapaxes(W1, 1, 2), W2t, W3t
    return U, Wt, ok


def _sq_norm(X):
    """Squared Frobenius norm of each matrix of a ``(g, p, q)`` batch."""
    return np.einsum("gij,gij->g", X, X)


def _lstsq_right(Y, Zt):
    """Least-squares ``X`` with ``X Z^T = Y`` for ``Z^T (g, r, k)`` of full row rank
    (``Z = Q R``, ``X = Y Q R^{-T}``; non-finite where ``Z`` is rank deficient)."""
    Qz, Rz = np.linalg.qr(np.swapaxes(Zt, 1, 2))  # thin QR, batched
    T = Y @ Qz  # X R^T = T, R upper triangular: back substitution over the columns
    r = Rz.shape[1]
    X = np.empty_like(T)
    for j in range(r - 1, -1, -1):
        acc = T[:, :, j]
        if j + 1 < r:
            acc = acc - np.einsum("gpi,gi->gp", X[:, :, j + 1 :], Rz[:, j, j + 1 :])
        X[:, :, j] = acc / Rz[:, j, j, None]
    return X


def _minus_k(Hwu):
    """Entries of ``-K = Hwu - I`` as ``(g, F)`` arrays (views off the diagonal)."""
    r = Hwu.shape[1]
    return [[Hwu[:, i, j] - 1.0 if i == j else Hwu[:, i, j] for j in range(r)] for i in range(r)]


def _cofactors(k):
    """Cofactor matrix and determinant of a 2x2 or 3x3 matrix of ``(g, F)`` entries."""
    r = len(k)
    if r == 2:
        return [[k[1][1], -k[1][0]], [-k[0][1], k[0][0]]], k[0][0] * k[1][1] - k[0][1] * k[1][0]
    cof = [[None] * 3 for _ in range(3)]
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            cof[i][j] = k[i1][j1] * k[i2][j2] - k[i1][j2] * k[i2][j1]
    return cof, k[0][0] * cof[0][0] + k[0][1] * cof[0][1] + k[0][2] * cof[0][2]


def _inverse_minus_identity(Hwu, out):
    """``out = K^-1 - I`` with ``K = I - Hwu`` (``(g, r, r, F)``); closed form for ``r <= 3``.

    With ``-K = Hwu - I``: ``K^-1 = -(-K)^-1 = -cof(-K)^T / det(-K)``."""
    r = Hwu.shape[1]
    if r > 3:
        K = np.moveaxis(-Hwu, -1, 1).copy()
        K[:, :, np.arange(r), np.arange(r)] += 1.0
        out[...] = np.moveaxis(np.linalg.inv(K), 1, -1)
    elif r == 1:
        np.divide(1.0, 1.0 - Hwu, out=out)
    else:
        cof, det = _cofactors(_minus_k(Hwu))
        scale = -1.0 / det
        for i in range(r):
            for j in range(r):
                np.multiply(cof[j][i], scale, out=out[:, i, j])
    for i in range(r):
        out[:, i, i] -= 1.0
    return out


def _solve_small(Hwu, rhs, out, ws):
    """``out = K^-1 rhs`` with ``K = I - Hwu``, for ``Hwu (g, r, r, F)`` and ``rhs (g, r, c, F)``:
    closed form for ``r <= 3`` (adjugate of ``-K = Hwu - I``), batched LAPACK solves beyond."""
    g, r, c, nf = rhs.shape
    if r == 1:
        np.divide(rhs, 1.0 - Hwu, out=out)
        return out
    if r > 3:
        K = np.moveaxis(-Hwu, -1, 1).copy()
        K[:, :, np.arange(r), np.arange(r)] += 1.0
        out[...] = np.moveaxis(np.linalg.solve(K, np.moveaxis(rhs, -1, 1)), 1, -1)
        return out
    cof, det = _cofactors(_minus_k(Hwu))
    inv_det = -1.0 / det  # K^-1 = cof(-K)^T / (-det(-K))
    acc = ws.get("cm_acc", (g, c, nf), complex)
    prod = ws.get("cm_prod", (g, c, nf), complex)
    for i in range(r):  # row i of K^-1 is column i of the cofactors of K over det(K)
        np.multiply(cof[0][i][:, None, :], rhs[:, 0], out=acc)
        for j in range(1, r):
            acc += np.multiply(cof[j][i][:, None, :], rhs[:, j], out=prod)
        np.multiply(acc, inv_det[:, None, :], out=out[:, i])
    return out


def tail_terms(M, A21, tail, n, powers):
    """Markov-like terms of the nilpotent tail: ``C2 A22^p A21`` and ``C2 A22^p B2``, p < powers.

    ``M`` is the batch of ``[[A, B], [C, D]]`` (``n`` states), ``tail`` the tail's state indices and
    ``A21`` the tail rows of ``A`` restricted to the core columns.
    Empty lists when there is no tail.
    """
    tail_C, tail_B = [], []
    if tail.size:
        A22 = M[:, tail[:, None], tail[None, :]]
        Ep = M[:, n:, tail]
        B2 = M[:, tail, n:]
        for _ in range(powers):
            tail_C.append(Ep @ A21)
            tail_B.append(Ep @ B2)
            Ep = Ep @ A22
    return tail_C, tail_B
