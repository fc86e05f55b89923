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

With numba installed the power iteration, the eigenvalue polish and the residual-vector check
run compiled, start by start (:mod:`oos_drake.robust.mu_lower_kernels`, the same arithmetic up to
round-off): that is the product's one lower-bound path. The numpy code here
(``compiled=False``) is the oracle of the tests, and what runs when numba is not installed.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from oos_drake.robust import mu_kernels, mu_lower_kernels
from oos_drake.robust.blocks import FULL, REAL, BlockStructure
from oos_drake.robust.memory import reuse_freed_memory

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


def _assemble(structure: BlockStructure, params, nb):
    delta = np.zeros((nb, structure.n_rows, structure.n_cols), dtype=complex)
    for block, value in zip(structure.blocks, params, strict=True):
        if block.kind == FULL:
            delta[:, block.r_slice, block.c_slice] = value
        else:
            idx = np.arange(block.rows)
            delta[:, block.row_offset + idx, block.col_offset + idx] = value[:, None]
    return delta


def _update_blocks(structure, params, phi, a, w, za, lam, eta):
    """One update of every block from the eigen-pair estimate (``za = z^* a``, ``lam``).

    The complex blocks are aligned so that each adds ``e^{j phi}`` times a positive number to
    ``lam``; the real blocks and the common phase ``phi`` take a Newton step towards
    ``Im(lam) = 0`` plus an ascent step on ``Re(lam)`` that leaves ``Im(lam)`` unchanged to first
    order (``phi`` plays the part of Young's multiplier ``x = tan(phi)`` in the rank-one formula).
    Returns ``(params, phi)``.
    """
    nb = a.shape[0]
    new = []
    real_idx = []
    g_real = []
    h = np.zeros(nb, dtype=complex)
    rot = np.exp(1j * phi)
    zas = np.where(np.abs(za) > 1e-300, za, 1e-300)
    for k, (block, value) in enumerate(zip(structure.blocks, params, strict=True)):
        ak = a[:, block.c_slice]
        wk = w[:, block.r_slice]
        if block.kind == FULL:
            na = np.linalg.norm(ak, axis=1)
            nw = np.linalg.norm(wk, axis=1)
            den = np.maximum(na * nw, 1e-300)
            upd = (rot / den)[:, None, None] * wk[:, :, None] * np.conj(ak)[:, None, :]
            keep = (na * nw) < 1e-300
            upd[keep] = value[keep]
            new.append(upd)
            h += rot * na * nw / zas
        else:
            ip = np.sum(np.conj(wk) * ak, axis=1)
            if block.kind == REAL:
                real_idx.append(k)
                g_real.append(ip / zas)
                new.append(value)
            else:
                mag = np.abs(ip)
                upd = np.where(mag > 1e-300, rot * np.conj(ip) / np.maximum(mag, 1e-300), value)
                new.append(upd)
                h += rot * mag / zas
    cols_p, cols_q = [], []
    for g in g_real:
        cols_p.append(g.real)
        cols_q.append(g.imag)
    has_c = len(real_idx) < len(structure.blocks)
    if has_c:
        cols_p.append(-h.imag)  # d lam / d phi = j h
        cols_q.append(h.real)
    if real_idx and cols_p:
        P = np.stack(cols_p, axis=1)
        Q = np.stack(cols_q, axis=1)
        # real parameters at a bound only move inwards
        free = np.ones_like(P, dtype=bool)
        for j, k in enumerate(real_idx):
            free[:, j] = np.abs(params[k]) < 1.0 - 1e-12
        Qf = np.where(free, Q, 0.0)
        q2 = np.sum(Qf * Qf, axis=1) + 1e-300
        corr = (-lam.imag / q2)[:, None] * Qf
        asc = P - (np.sum(P * Qf, axis=1) / q2)[:, None] * Qf
        asc = asc / np.maximum(np.linalg.norm(asc, axis=1, keepdims=True), 1e-300)
        step = corr + eta * asc
        nstep = np.linalg.norm(step, axis=1, keepdims=True)
        step = step * np.minimum(1.0, 0.5 / np.maximum(nstep, 1e-300))
        for j, k in enumerate(real_idx):
            new[k] = np.clip(params[k] + step[:, j], -1.0, 1.0)
        if has_c:
            phi = phi + step[:, -1]
            rot = np.exp(1j * step[:, -1])
            for k, block in enumerate(structure.blocks):
                if block.kind == FULL:
                    new[k] = new[k] * rot[:, None, None]
                elif block.kind != REAL:
                    new[k] = new[k] * rot
    return new, phi


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

    The scalar blocks take one gather. The full blocks of the power iteration are rank one (an
    outer product times phases), where ``||B||_2 = ||B||_F``: that holds to round-off when
    ``||B^* B||_F = ||B||_F^2`` to 1e-13 relative (``||B||_F`` is then at most 5e-14 relative
    above ``||B||_2``); the other blocks take an SVD.
    """
    rep = [b for b in structure.blocks if b.repeated]
    out = np.zeros(delta.shape[0])
    if rep:
        rows = np.concatenate([np.arange(b.rows) + b.row_offset for b in rep])
        cols = np.concatenate([np.arange(b.cols) + b.col_offset for b in rep])
        out = np.max(np.abs(delta[:, rows, cols]), axis=1)
    for b in structure.blocks:
        if b.kind != FULL:
            continue
        B = delta[:, b.r_slice, b.c_slice]
        fro2 = np.sum(B.real**2 + B.imag**2, axis=(1, 2))
        G = np.conj(np.swapaxes(B, 1, 2)) @ B
        g = np.sqrt(np.sum(G.real**2 + G.imag**2, axis=(1, 2)))
        norm = np.sqrt(fro2)
        svd = np.flatnonzero(fro2 - g > 1e-13 * fro2)
        if svd.size:
            norm[svd] = np.linalg.norm(B[svd], ord=2, axis=(1, 2))
        out = np.maximum(out, norm)
    return out


class _BlockDiag:
    """Apply a block-diagonal ``Delta`` given per block (no dense ``(B, r, c)`` assembly)."""

    def __init__(self, structure: BlockStructure):
        rep = [(k, b) for k, b in enumerate(structure.blocks) if b.repeated]
        self.rep_k = [k for k, _ in rep]
        self.rep_of = np.concatenate([np.full(b.rows, j) for j, (_, b) in enumerate(rep)] or [[]])
        self.rep_of = self.rep_of.astype(int)
        self.rep_rows = np.concatenate([np.arange(b.rows) + b.row_offset for _, b in rep] or [[]])
        self.rep_rows = self.rep_rows.astype(int)
        self.rep_cols = np.concatenate([np.arange(b.cols) + b.col_offset for _, b in rep] or [[]])
        self.rep_cols = self.rep_cols.astype(int)
        self.full = [(k, b) for k, b in enumerate(structure.blocks) if b.kind == FULL]
        self.r, self.c = structure.n_rows, structure.n_cols

    def apply(self, params, a, adjoint=False):
        """``Delta a`` (``a`` in c-space) or, with ``adjoint``, ``Delta^* z`` (``z`` in r-space)."""
        nb = a.shape[0]
        out = np.zeros((nb, self.c if adjoint else self.r), dtype=complex)
        src, dst = (self.rep_rows, self.rep_cols) if adjoint else (self.rep_cols, self.rep_rows)
        if self.rep_k:
            vals = np.stack([params[k] for k in self.rep_k], axis=1)[:, self.rep_of]
            out[:, dst] = (np.conj(vals) if adjoint else vals) * a[:, src]
        for k, b in self.full:
            if adjoint:
                out[:, b.c_slice] = _mv(np.conj(np.swapaxes(params[k], -1, -2)), a[:, b.r_slice])
            else:
                out[:, b.r_slice] = _mv(params[k], a[:, b.c_slice])
        return out


def _kernel_blocks(structure: BlockStructure) -> np.ndarray:
    """Block description of the compiled kernels: ``(5, n_blocks)`` integers, kind (0 real,
    1 repeated complex, 2 full), rows, columns, row offset, column offset."""
    kinds = {REAL: 0, FULL: 2}
    return np.array(
        [
            [kinds.get(b.kind, 1), b.rows, b.cols, b.row_offset, b.col_offset]
            for b in structure.blocks
        ],
        dtype=np.int64,
    ).T.copy()


def _power_iteration(M, structure, a, z, iters, kappa, rng, compiled=True):
    """Run the mixed power iteration from vectors ``a`` (c-space) and ``z`` (c-space).

    ``M`` is ``(nb, c, r)`` and ``a``, ``z`` are ``(N, c)`` with ``N`` a multiple of ``nb``:
    start ``s`` runs on ``M[s % nb]`` (several starts per matrix). ``compiled``: by
    :func:`mu_lower_kernels.power_iteration` when numba is installed.
    """
    nb = a.shape[0]
    if compiled and mu_kernels.HAVE_NUMBA:  # the same iteration, compiled per start
        real0 = [rng.uniform(-1.0, 1.0, nb) for b in structure.blocks if b.kind == REAL]
        real0 = np.stack(real0, axis=1) if real0 else np.zeros((nb, 0))
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
    if M.shape[0] != nb:
        M = np.broadcast_to(M[None], (nb // M.shape[0],) + M.shape).reshape((nb,) + M.shape[1:])
    MH = np.ascontiguousarray(np.conj(np.swapaxes(M, -1, -2)))
    w = _mv(MH, z)
    bd = _BlockDiag(structure)
    params = []
    for block in structure.blocks:  # complex blocks start aligned, real ones at a random point
        if block.kind == FULL:
            params.append(np.zeros((nb, block.rows, block.cols), dtype=complex))
        elif block.kind == REAL:
            params.append(rng.uniform(-1.0, 1.0, nb))
        else:
            params.append(np.ones(nb, dtype=complex))
    za = np.sum(np.conj(z) * a, axis=1)
    phi = np.zeros(nb)
    params, phi = _update_blocks(structure, params, phi, a, w, za, np.zeros(nb, dtype=complex), 0.0)
    real_only = all(b.kind == REAL for b in structure.blocks)
    real_pos = [k for k, b in enumerate(structure.blocks) if b.kind == REAL]
    for it in range(iters):
        MDa = _mv(M, bd.apply(params, a))
        lam = np.sum(np.conj(z) * MDa, axis=1) / np.where(np.abs(za) > 1e-300, za, 1e-300)
        if real_only:  # |lam| is what counts: make Re(lam) >= 0 by flipping the sign of delta
            flip = lam.real < 0
            if np.any(flip):
                for k in real_pos:
                    params[k] = np.where(flip, -params[k], params[k])
                lam = np.where(flip, -lam, lam)
                MDa = np.where(flip[:, None], -MDa, MDa)
        a = _normalize(MDa)
        z = _normalize(bd.apply(params, w, adjoint=True))  # w = M^* z of the previous z
        za = np.sum(np.conj(z) * a, axis=1)
        z = z * (za / np.maximum(np.abs(za), 1e-300))[:, None]
        za = np.abs(za)
        w = _mv(MH, z)
        eta = kappa * max(0.0, 1.0 - it / (0.7 * iters))
        params, phi = _update_blocks(structure, params, phi, a, w, za, lam, eta)
    return _assemble(structure, params, nb), a


def _polish_eigenvalue(MD, a, steps=_POLISH_STEPS):
    """Eigenvalue of ``MD`` nearest the Rayleigh quotient of ``a`` (shifted inverse iteration)."""
    n = MD.shape[-1]
    lam = np.sum(np.conj(a) * _mv(MD, a), axis=1)
    eye = np.eye(n)
    for _ in range(steps):
        shift = lam * (1 + 1e-10) + 1e-14
        try:
            x = np.linalg.solve(MD - shift[:, None, None] * eye, a[:, :, None])[:, :, 0]
        except np.linalg.LinAlgError:
            break
        a = _normalize(np.where(np.isfinite(x), x, a))
        lam = np.sum(np.conj(a) * _mv(MD, a), axis=1)
    return lam, a


def _make_eigenvalue_real(M, structure, delta, a, steps=_REAL_ROUNDS):
    """Newton steps on the real blocks (and a common phase of the complex blocks) to Im(lam) = 0.

    Returns ``(delta, lam)`` with ``lam`` the eigenvalue of ``M delta`` tracked from ``a``.
    """
    nb, c, r = M.shape
    real_blocks = [b for b in structure.blocks if b.kind == REAL]
    cplx_blocks = [b for b in structure.blocks if b.kind != REAL]
    eye = np.eye(c)
    delta = delta.copy()
    a = a.copy()
    z_all = a.copy()
    lam_all = np.zeros(nb, dtype=complex)
    act = np.arange(nb)  # rows whose eigenvalue is not yet real: the others stop early
    for rnd in range(steps + 1):
        Ma = M[act]
        da = delta[act]
        MD = Ma @ da
        lam, aa = _polish_eigenvalue(MD, a[act], steps=_REAL_STEPS)
        a[act], lam_all[act] = aa, lam
        done = np.abs(lam.imag) <= 1e-13 * np.abs(lam)
        if rnd == steps or np.all(done):
            break
        # left eigenvector by inverse iteration on (M delta)^*
        MDH = np.conj(np.swapaxes(MD, -1, -2))
        z = z_all[act]
        for _k in range(2):
            shift = np.conj(lam) * (1 + 1e-10) + 1e-14
            try:
                zz = np.linalg.solve(MDH - shift[:, None, None] * eye, z[:, :, None])[:, :, 0]
            except np.linalg.LinAlgError:
                break
            z = _normalize(np.where(np.isfinite(zz), zz, z))
        z_all[act] = z
        za = np.sum(np.conj(z) * aa, axis=1)
        za = np.where(np.abs(za) > 1e-300, za, 1e-300)
        w = _mv(np.conj(np.swapaxes(Ma, -1, -2)), z)
        coeffs, targets = [], []
        for b in real_blocks:
            g = np.sum(np.conj(w[:, b.r_slice]) * aa[:, b.c_slice], axis=1) / za
            d = da[:, b.row_offset, b.col_offset].real
            free = np.abs(d) < 1.0 - 1e-12
            coeffs.append(np.where(free, g.imag, 0.0))
            targets.append(("real", b))
        if cplx_blocks:
            h = np.zeros(act.size, dtype=complex)
            for b in cplx_blocks:
                Da = _mv(da[:, b.r_slice, b.c_slice], aa[:, b.c_slice])
                h += np.sum(np.conj(w[:, b.r_slice]) * Da, axis=1) / za
            coeffs.append((1j * h).imag)
            targets.append(("phase", None))
        if not coeffs:
            break
        C = np.stack(coeffs, axis=1)
        c2 = np.sum(C * C, axis=1) + 1e-300
        step = (-lam.imag / c2)[:, None] * C
        nstep = np.linalg.norm(step, axis=1, keepdims=True)
        step = step * np.minimum(1.0, 0.2 / np.maximum(nstep, 1e-300))
        step[done] = 0.0
        for j, (kind, b) in enumerate(targets):
            if kind == "real":
                idx = np.arange(b.rows)
                d = da[:, b.row_offset, b.col_offset].real
                dn = np.clip(d + step[:, j], -1.0, 1.0)
                da[:, b.row_offset + idx, b.col_offset + idx] = dn[:, None]
            else:
                rot = np.exp(1j * step[:, j])[:, None, None]
                for bc in cplx_blocks:
                    da[:, bc.r_slice, bc.c_slice] *= rot
        delta[act] = da
        act = act[~done]
    return delta, lam_all, a


def _vector_residual(M, delta, a):
    """Upper bound of ``sigma_min(I - M delta) / (1 + ||M delta||_2)`` from a vector ``a``.

    ``sigma_min(I - M delta) <= ||(I - M delta) a|| / ||a||`` and ``||M delta||_2 >=
    ||M delta a|| / ||a||``: a small value proves near-singularity as the SVD would, at the cost
    of two matrix-vector products.
    """
    na = np.maximum(np.linalg.norm(a, axis=1), 1e-300)
    mda = _mv(M, _mv(delta, a))
    return (np.linalg.norm(a - mda, axis=1) / na) / (1.0 + np.linalg.norm(mda, axis=1) / na)


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
    compiled: bool = True,
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
    compiled : bool
        Run the compiled kernels (:mod:`mu_lower_kernels`) when numba is installed (the
        default). False runs the numpy implementation of the same algorithm (the oracle of the
        tests; also what runs without numba).

    Returns
    -------
    LowerBoundResult
    """
    rng = np.random.default_rng(0) if rng is None else rng
    reuse_freed_memory()
    if M.shape[0] > CHUNK:  # bounded memory: (restarts + 1) copies of the batch are in flight
        parts = [
            mu_lower_bound(
                M[i : i + CHUNK],
                structure,
                start_inputs=None if start_inputs is None else start_inputs[i : i + CHUNK],
                start_vectors=None if start_vectors is None else start_vectors[i : i + CHUNK],
                restarts=restarts,
                iters=iters,
                kappa=kappa,
                rng=rng,
                polish_starts=polish_starts,
                compiled=compiled,
            )
            for i in range(0, M.shape[0], CHUNK)
        ]
        return LowerBoundResult(
            *(np.concatenate([getattr(q, f.name) for q in parts]) for f in fields(LowerBoundResult))
        )
    nb, c, r = M.shape
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
    for _ in range(max(restarts, 0)):
        starts_a.append(
            _normalize(rng.standard_normal((nb, c)) + 1j * rng.standard_normal((nb, c)))
        )
        starts_z.append(
            _normalize(rng.standard_normal((nb, c)) + 1j * rng.standard_normal((nb, c)))
        )
    if not starts_a:
        starts_a.append(_normalize(np.ones((nb, c), dtype=complex)))
        starts_z.append(starts_a[0])
    ns = len(starts_a)
    mat = np.tile(np.arange(nb), ns)  # the matrix of each start
    a = np.concatenate(starts_a, axis=0)
    z = np.concatenate(starts_z, axis=0)
    delta_unit, a = _power_iteration(M, structure, a, z, iters, kappa, rng, compiled)
    compiled = compiled and mu_kernels.HAVE_NUMBA
    if compiled:
        M = np.ascontiguousarray(M, dtype=complex)
        blocks = _kernel_blocks(structure)
    if polish_starts is not None and 0 < polish_starts < ns:
        # the eigenvalue polish and the certificate cost more than the power iteration itself:
        # keep only the most promising starts of each matrix (Rayleigh quotient estimate)
        if compiled:
            est = np.empty(a.shape[0], dtype=complex)
            mu_lower_kernels.rayleigh_quotients(M, delta_unit, a, blocks, est)
            est = np.abs(est)
        else:
            est = np.abs(np.sum(np.conj(a) * _mv(M[mat], _mv(delta_unit, a)), axis=1))
        est = est / np.maximum(_max_block_norm(structure, delta_unit), 1e-300)
        order = np.argsort(-est.reshape(ns, nb), axis=0, kind="stable")[:polish_starts]
        keep = (order * nb + np.arange(nb)[None, :]).ravel()
        ns = polish_starts
        mat, delta_unit, a = mat[keep], delta_unit[keep], a[keep]
    if compiled:  # the same polish, compiled per matrix
        delta_unit = np.ascontiguousarray(delta_unit)
        a = np.ascontiguousarray(a)
        lam = np.empty(a.shape[0], dtype=complex)
        mu_lower_kernels.eigen_polish(
            M,
            mat,
            delta_unit,
            a,
            blocks,
            _REAL_ROUNDS if structure.has_real else 0,
            _REAL_STEPS if structure.has_real else _POLISH_STEPS,
            lam,
        )
    elif structure.has_real:
        delta_unit, lam, a = _make_eigenvalue_real(M[mat], structure, delta_unit, a)
    else:
        lam, a = _polish_eigenvalue(M[mat] @ delta_unit, a)
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
        if compiled:
            vres = np.empty(a.shape[0])
            mu_lower_kernels.vector_residual(M, mat, delta, a, blocks, vres)
            resid[usable] = vres[usable]
        else:
            resid[usable] = _vector_residual(M[mat[usable]], delta[usable], a[usable])
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
        vertex = delta_unit[retry].copy()
        for block in structure.blocks:
            if block.kind == REAL:
                idx = np.arange(block.rows)
                d = vertex[:, block.row_offset, block.col_offset].real
                vertex[:, block.row_offset + idx, block.col_offset + idx] = np.where(
                    d < 0, -1.0, 1.0
                )[:, None]
        for trial in (delta_unit[retry], vertex):
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
    raw = delta_unit[best_raw].copy()
    for block in structure.blocks:  # real parameters pushed to the vertex of their sign
        if block.kind == REAL:
            idx = np.arange(block.rows)
            d = raw[:, block.row_offset, block.col_offset].real
            raw[:, block.row_offset + idx, block.col_offset + idx] = np.where(d < 0, -1.0, 1.0)[
                :, None
            ]
    return LowerBoundResult(lower, out_delta, out_resid, raw, lam_raw[best_raw], a[pick])
