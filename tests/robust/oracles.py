"""Numpy oracles of the compiled mu kernels: the same algorithms, batched over matrices.

The product runs only the compiled kernels (numba is a dependency): the D-G optimizer of
``oos_drake.robust.mu_lanes``, the evaluation and balancing of ``mu_kernels`` and the lower-bound
kernels of ``mu_lower_kernels``. These numpy versions of the same algorithms (the product's code
before issue 16 moved them here) are what the tests compare the kernels with:

* :class:`NumpyObjective`: the smoothed ``lambda_max`` of the scaled D-G matrix and its gradient
  (batched ``eigh``), :func:`osborne_init` (the balancing sweeps), :func:`mu_upper_bound` (the
  batched L-BFGS optimizer, then the product's certification ``mu_upper._conclude``);
* :func:`power_iteration`, :func:`polish_eigenvalue`, :func:`make_eigenvalue_real`,
  :func:`vector_residual` and :func:`mu_lower_bound` (then the product's ``mu_lower._conclude``).

Both sides read the same constants (``mu_lanes`` line search, ``mu_lower`` polish rounds).
"""

import numpy as np

from oos_drake.robust import mu_lanes
from oos_drake.robust import mu_lower as ml
from oos_drake.robust import mu_upper as mu
from oos_drake.robust.blocks import FULL, REAL, BlockStructure
from oos_drake.robust.mu_lower import _mv, _normalize

# -- upper bound ---------------------------------------------------------------------------


class NumpyObjective(mu._Objective):
    """``mu_upper._Objective`` evaluated in numpy (its :meth:`matrix`, batched ``eigh``)."""

    def __init__(self, M, structure, layout):
        super().__init__(M, structure, layout)
        # (positions, entries) indicators: the gradient of the entries of T_l and T_r
        self.sel_l = np.eye(layout.n_entries)[layout.l_ent]
        self.sel_r = np.eye(layout.n_entries)[layout.r_ent]

    def size(self, x, idx):
        """``||M_hat||_F^2`` (``M_hat = T_l M T_r^{-1}``) at ``x`` for the batch rows ``idx``."""
        _, Tl, Tr, _ = self.scalings(x, idx)
        tr = lambda A: np.swapaxes(A, -1, -2)  # noqa: E731
        X = tr(np.linalg.solve(tr(Tr), tr(self.M[idx])))  # M T_r^{-1}
        return np.linalg.norm(Tl @ X, axis=(1, 2)) ** 2

    def __call__(self, x, idx, t, need_grad=True):
        """Return ``(f, grad, lam_max, top_vec)`` for the batch rows ``idx``."""
        self.count[idx] += 1
        L = self.L
        M = self.M[idx]
        H, E, Tri, Mh = self.matrix(x, idx)
        if not need_grad:
            lam = np.linalg.eigvalsh(H)
            lmax = lam[:, -1]
            tt = t[:, None]
            f = lmax + np.log(np.sum(np.exp(tt * (lam - lmax[:, None])), axis=1)) / t
            return f, None, lmax, None
        lam, V = np.linalg.eigh(H)
        lmax = lam[:, -1]
        if need_grad == "top":  # the exact value and the top eigenvector only
            return lmax, None, lmax, (Tri @ V[:, :, -1:])[:, :, 0]
        with np.errstate(over="ignore"):  # t = 1e300: the top eigenvalue only (mu_upper._finish)
            z = np.exp(t[:, None] * (lam - lmax[:, None]))
        ssum = z.sum(axis=1)
        f = lmax + np.log(ssum) / t
        p = z / ssum[:, None]
        # W = df/dH = V diag(p) V^* has numerical rank K (eigenvalues near the top): with
        # H = T_r^{-*} A T_r^{-1}, A = M^* D_l M + j (G M - M^* G^*), the gradient is
        #   d/dT_l: 2 (X V) p (Mh V)^*,  d/dT_r: -2 (T_r^{-1} V) p lam V^*,
        #   d/dG: 2j (X V) p (T_r^{-1} V)^*
        K = int(np.max(np.sum(p > 1e-15, axis=1)))
        Vk = V[:, :, -K:]
        pk = p[:, -K:]
        lk = lam[:, -K:]
        TV = Tri @ Vk  # (B, r, K)
        XV = M @ TV  # X Vk
        MV = Mh @ Vk
        # coefficient matrices by batched products (K columns), then the structured entries
        XVp = XV * pk[:, None, :]
        coef_l = 2.0 * (XVp @ np.conj(np.swapaxes(MV, -1, -2)))[:, L.l_col, L.l_row]
        TVp = TV * (pk * lk)[:, None, :]
        coef_r = -2.0 * (TVp @ np.conj(np.swapaxes(Vk, -1, -2)))[:, L.r_col, L.r_row]
        gT = coef_l @ self.sel_l + coef_r @ self.sel_r
        grad = np.zeros_like(x)
        grad[:, L.log_par] = np.real(gT[:, L.log_ent] * E[:, L.log_ent])
        if len(L.lin_ent):
            gE = gT[:, L.lin_ent] * E[:, L.lin_ent]  # d/ds of the row scale
            np.add.at(grad, (slice(None), L.lin_row_par), np.real(gE))
            rowscale = np.exp(np.clip(x[:, L.lin_row_par], -60.0, 60.0))
            grad[:, L.lin_re_par] = np.real(gT[:, L.lin_ent]) * rowscale
            grad[:, L.lin_im_par] = -np.imag(gT[:, L.lin_ent]) * rowscale
        if len(L.g_par):
            coef_g = 2j * (XVp @ np.conj(np.swapaxes(TV, -1, -2)))[:, L.g_col, L.g_row]
            grad[:, L.g_par] = np.real(coef_g @ L.g_map.T)
        return f, grad, lmax, TV[:, :, -1]


def osborne_init(M, structure: BlockStructure, layout, iters: int = 20):
    """``mu_upper._osborne_init`` with the sweeps in numpy (Gauss-Seidel, batch-wide stop)."""
    P, par = mu._osborne_problem(M, structure, layout)
    nb, k = P.shape[:2]
    logd = np.zeros((nb, k))  # log of d_e^2
    for _ in range(iters):
        biggest = 0.0
        for i in range(k):  # sequential (Gauss-Seidel) sweeps converge, simultaneous ones may not
            e = np.exp(logd - logd[:, [i]])
            R = (P[:, i, :] / e).sum(axis=1)
            C = (P[:, :, i] * e).sum(axis=1)
            step = np.clip(0.5 * (np.log(C) - np.log(R)), -5.0, 5.0)
            logd[:, i] += step
            biggest = max(biggest, float(np.max(np.abs(step))))
        logd = np.clip(logd - logd.mean(axis=1, keepdims=True), -40.0, 40.0)
        if biggest < 1e-3:
            break
    x = np.zeros((nb, layout.n_params))
    x[:, par] = 0.5 * logd
    return x


def lbfgs_direction(g, S, Y, rho):
    """Batched L-BFGS two-loop recursion: approximately ``H^{-1} g`` (empty slots are zeros)."""
    q = g.copy()
    m = S.shape[1]
    alpha = np.zeros((g.shape[0], m))
    for i in range(m):
        alpha[:, i] = rho[:, i] * np.einsum("bi,bi->b", S[:, i], q)
        q -= alpha[:, i, None] * Y[:, i]
    yy = np.einsum("bi,bi->b", Y[:, 0], Y[:, 0])
    sy = np.einsum("bi,bi->b", S[:, 0], Y[:, 0])
    gamma = np.where(yy > 0, sy / np.where(yy > 0, yy, 1.0), 1.0)
    r = gamma[:, None] * q
    for i in range(m - 1, -1, -1):
        beta = rho[:, i] * np.einsum("bi,bi->b", Y[:, i], r)
        r += S[:, i] * (alpha[:, i] - beta)[:, None]
    return r


def mu_upper_bound(
    M,
    structure: BlockStructure,
    *,
    max_iter: int = 200,
    tol=1e-7,
    temperatures=(30.0, 300.0, 3000.0),
    memory: int = 10,
    x0=None,
    patience: int = 2,
):
    """``mu_upper.mu_upper_bound`` (no chaining) with the optimizer in numpy: the same L-BFGS
    stages, line search and stopping rules, batched over matrices, then the product's exact
    evaluation and certification (``mu_upper._conclude``)."""
    nb, c, r = M.shape
    tols = mu._stage_tolerances(tol, temperatures)
    layout = mu._layout(structure)
    scale = np.linalg.norm(M, axis=(1, 2)) + 1e-300
    obj = NumpyObjective(M / scale[:, None, None], structure, layout)
    x = osborne_init(obj.M, structure, layout)
    p = layout.n_params
    if max_iter <= 0:
        if x0 is not None:
            x, _ = mu._warm_start(obj, x, np.array(x0, dtype=float).reshape(x.shape))
        return mu._conclude(M, obj, scale, x, x, iterations=0, optimized=False)
    coords = mu._Balanced(obj, x)
    balanced = NumpyObjective(coords.M, structure, layout)
    x = coords.to_balanced(x)
    allidx = np.arange(nb)
    _, _, lmax0, _ = balanced(x, allidx, np.ones(nb), need_grad=False)
    if x0 is not None:
        x, lmax0 = mu._warm_start(
            balanced, x, coords.to_balanced(np.array(x0, dtype=float).reshape(x.shape))
        )
    obj_final, obj = obj, balanced
    # the optimizer keeps the point with the smallest lambda_max + size_weight ||M_hat||_F^2
    size_weight = mu.CERT_SIZE_FACTOR * mu.check_roundoff(r)
    best_l = lmax0.copy()
    best_v = best_l + size_weight * obj.size(x, allidx)
    best_x = x.copy()
    start_x = x.copy()
    iters_done = 0
    per_stage = max(max_iter // len(temperatures), min(max_iter, mu_lanes.MIN_STAGE_ITERATIONS))
    for stage, tau in enumerate(temperatures):
        t = tau / np.maximum(best_l, 1e-12)
        f, g, lmax, _ = obj(x, allidx, t)
        val = lmax + size_weight * obj.size(x, allidx)
        better = val < best_v
        best_l[better], best_v[better], best_x[better] = lmax[better], val[better], x[better]
        if stage == 0:  # L-BFGS pairs, newest first (zeros = empty slots); kept across stages
            S = np.zeros((nb, memory, p))
            Y = np.zeros((nb, memory, p))
            rho = np.zeros((nb, memory))
        active = np.ones(nb, dtype=bool)
        stall = np.zeros(nb, dtype=int)
        fails = np.zeros(nb, dtype=int)
        for _ in range(per_stage):
            idx = np.flatnonzero(active)
            if idx.size == 0:
                break
            iters_done += 1
            d = -lbfgs_direction(g[idx], S[idx], Y[idx], rho[idx])
            slope = np.einsum("bi,bi->b", d, g[idx])
            bad = slope >= 0
            if np.any(bad):
                d[bad] = -g[idx][bad]
                slope[bad] = -np.einsum("bi,bi->b", g[idx][bad], g[idx][bad])
                S[idx[bad]] = 0.0
                Y[idx[bad]] = 0.0
                rho[idx[bad]] = 0.0
            # cap the step: log-scalings beyond e^{+-2} per iteration are never useful
            dmax = (
                np.max(np.abs(d[:, layout.log_par]), axis=1)
                if layout.log_par.size
                else np.zeros(len(d))
            )
            d *= np.minimum(1.0, mu_lanes.MAX_LOG_STEP / np.maximum(dmax, 1e-300))[:, None]
            alpha = np.ones(idx.size)
            pending = np.ones(idx.size, dtype=bool)
            f_new = f[idx].copy()
            g_new = g[idx].copy()
            l_new = np.full(idx.size, np.inf)
            x_new = x[idx].copy()
            accepted = np.zeros(idx.size, dtype=bool)
            for _ls in range(mu_lanes.MAX_TRIALS):
                sub = np.flatnonzero(pending)
                if sub.size == 0:
                    break
                xt = x[idx[sub]] + alpha[sub, None] * d[sub]
                ft, gt, lt, _ = obj(xt, idx[sub], t[idx[sub]])
                armijo = f[idx[sub]] + mu_lanes.ARMIJO * alpha[sub] * slope[sub]
                ok = np.isfinite(ft) & (ft <= armijo)
                acc = sub[ok]
                f_new[acc], g_new[acc], l_new[acc], x_new[acc] = ft[ok], gt[ok], lt[ok], xt[ok]
                accepted[acc] = True
                pending[acc] = False
                alpha[sub[~ok]] *= mu_lanes.BACKTRACK
            # L-BFGS memory update
            for_upd = np.flatnonzero(accepted)
            gi = idx[for_upd]
            s_ = x_new[for_upd] - x[gi]
            y_ = g_new[for_upd] - g[gi]
            sy = np.einsum("bi,bi->b", s_, y_)
            good = sy > mu_lanes.CURVATURE_FLOOR * np.maximum(
                np.linalg.norm(s_, axis=1) * np.linalg.norm(y_, axis=1), 1e-300
            )
            if np.any(good):
                gg = gi[good]
                S[gg] = np.roll(S[gg], 1, axis=1)
                Y[gg] = np.roll(Y[gg], 1, axis=1)
                rho[gg] = np.roll(rho[gg], 1, axis=1)
                S[gg, 0], Y[gg, 0], rho[gg, 0] = s_[good], y_[good], 1.0 / sy[good]
            rel = (f[gi] - f_new[for_upd]) / np.maximum(np.abs(f[gi]), 1e-300)
            x[gi], f[gi], g[gi] = x_new[for_upd], f_new[for_upd], g_new[for_upd]
            v_new = l_new[for_upd] + size_weight * obj.size(x_new[for_upd], gi)
            improved = v_new < best_v[gi]
            best_l[gi[improved]] = l_new[for_upd][improved]
            best_v[gi[improved]] = v_new[improved]
            best_x[gi[improved]] = x_new[for_upd][improved]
            small = rel < tols[stage]
            stall[gi[small]] += 1
            stall[gi[~small]] = 0
            active[gi[stall[gi] >= patience]] = False
            # a failed line search: forget the curvature pairs and retry along the gradient;
            # give up after MAX_FAILED_SEARCHES failures in a row
            failed = idx[~accepted]
            fails[failed] += 1
            fails[gi] = 0
            S[failed], Y[failed], rho[failed] = 0.0, 0.0, 0.0
            active[failed[fails[failed] >= mu_lanes.MAX_FAILED_SEARCHES]] = False
        if iters_done >= max_iter:
            break
    obj_final.count += obj.count
    return mu._conclude(
        M,
        obj_final,
        scale,
        coords.to_absolute(best_x),
        coords.to_absolute(start_x),
        iterations=iters_done,
        optimized=True,
    )


# -- lower bound ---------------------------------------------------------------------------


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


def power_iteration(M, structure, a, z, iters, kappa, rng):
    """Run the mixed power iteration from vectors ``a`` (c-space) and ``z`` (c-space).

    ``M`` is ``(nb, c, r)`` and ``a``, ``z`` are ``(N, c)`` with ``N`` a multiple of ``nb``:
    start ``s`` runs on ``M[s % nb]`` (several starts per matrix). Returns ``(delta, a)``.
    """
    nb = a.shape[0]
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


def polish_eigenvalue(MD, a, steps=ml._POLISH_STEPS):
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


def make_eigenvalue_real(M, structure, delta, a, steps=ml._REAL_ROUNDS):
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
        lam, aa = polish_eigenvalue(MD, a[act], steps=ml._REAL_STEPS)
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


def vector_residual(M, delta, a):
    """Upper bound of ``sigma_min(I - M delta) / (1 + ||M delta||_2)`` from a vector ``a``.

    ``sigma_min(I - M delta) <= ||(I - M delta) a|| / ||a||`` and ``||M delta||_2 >=
    ||M delta a|| / ||a||``: a small value proves near-singularity as the SVD would, at the cost
    of two matrix-vector products.
    """
    na = np.maximum(np.linalg.norm(a, axis=1), 1e-300)
    mda = _mv(M, _mv(delta, a))
    return (np.linalg.norm(a - mda, axis=1) / na) / (1.0 + np.linalg.norm(mda, axis=1) / na)


def mu_lower_bound(
    M,
    structure: BlockStructure,
    *,
    start_inputs=None,
    start_vectors=None,
    restarts: int = 4,
    iters: int = 60,
    kappa: float = 0.5,
    rng=None,
    polish_starts: int | None = 2,
):
    """``mu_lower.mu_lower_bound`` with the power iteration, the start selection, the eigenvalue
    polish and the residual check in numpy, then the product's ``mu_lower._conclude``."""
    rng = np.random.default_rng(0) if rng is None else rng
    nb = M.shape[0]
    a, z = ml._starts(M, start_inputs, start_vectors, restarts, rng)
    ns = a.shape[0] // nb
    mat = np.tile(np.arange(nb), ns)  # the matrix of each start
    delta_unit, a = power_iteration(M, structure, a, z, iters, kappa, rng)
    if polish_starts is not None and 0 < polish_starts < ns:
        est = np.abs(np.sum(np.conj(a) * _mv(M[mat], _mv(delta_unit, a)), axis=1))
        keep = ml._best_starts(structure, est, delta_unit, ns, polish_starts)
        ns = polish_starts
        mat, delta_unit, a = mat[keep], delta_unit[keep], a[keep]
    if structure.has_real:
        delta_unit, lam, a = make_eigenvalue_real(M[mat], structure, delta_unit, a)
    else:
        lam, a = polish_eigenvalue(M[mat] @ delta_unit, a)

    def residual(M, mat, delta, a, rows):
        return vector_residual(M[mat[rows]], delta[rows], a[rows])

    return ml._conclude(M, structure, mat, delta_unit, a, lam, ns, residual)
