r"""Compiled (numba) per-matrix kernels of the mu upper bound: evaluation, layout, balancing.

The D-G optimizer itself is :func:`oos_drake.robust.mu_lanes.dg_minimize_lanes` (eight
matrices per evaluation, any batch size). This module holds what it and ``mu_upper`` share:
the layout's index arrays (:func:`pack_layout`), the Osborne balancing of the
start (:func:`osborne`), :func:`warm_up`, and the per-matrix evaluation :func:`dg_objective`
(the exact final evaluation of ``mu_upper``, its round-off cross-check against numpy, and the
fallback of a lane whose QR did not converge).

:func:`dg_objective` evaluates, for each matrix of a batch, the smoothed ``lambda_max`` of the
scaled D-G matrix of :mod:`oos_drake.robust.mu_upper` and its gradient. It is the same function
as the numpy oracle of the tests (``tests/robust/oracles.py``; tests check both agree to
round-off), written without
the batched fancy-indexing temporaries:

* the scalings are block diagonal with blocks of size <= 3: ``X = M T_r^{-1}``,
  ``Mh = T_l X`` and ``Y X = T_r^{-*} G X`` are formed block by block (``O(n^2)``), and
  ``H = Mh^* Mh + j (Y X - (Y X)^*)`` costs one dense product;
* ``H`` is formed as a lower triangle with real and imaginary parts apart, and reduced to a
  real tridiagonal by our own Householder loop (the arithmetic of LAPACK's ``zhetd2``; split
  parts vectorize, LAPACK's level-2 calls on 26 x 26 are dominated by call overheads); all
  eigenvalues by implicit QR on the tridiagonal with its rotations recorded, eigenvectors only
  for the few eigenvalues that carry the smoothed maximum (those rotations applied to unit
  vectors, then our own back-transformation, all vectors together). About 35-45 us per
  26 x 26 evaluation near the optimum, where the top eigenvalues cluster (with LAPACK's
  ``dsterf`` and ``dstein``: 35-55 us; a full ``eigh``: 60 us).

If the QR does not converge within its step budget (:data:`QR_STEP_BUDGET`) the kernel falls
back to LAPACK's ``zheevd`` for that matrix. Whatever the kernel returns only steers the
optimizer: every returned bound is proved at the final scalings by
``mu_upper.certified_upper`` (the LMI with an a priori bound on its own round-off).

The LAPACK routines are bound by symbol name (``llvmlite.binding.add_symbol``) so that the
compiled code can be cached on disk (``cache=True``): the first call in a fresh checkout
compiles (a few seconds, see ``benchmarks/bench_mussv.py``), later processes load the cache.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

try:  # numba is a dependency (pyproject): there is no slower copy to run without it
    import llvmlite.binding as _ll
    import numba
    from numba import types
    from numba.extending import get_cython_function_address
except ImportError as err:  # pragma: no cover - exercised only without numba
    raise ImportError(f"oos_drake.robust needs numba (pip install numba): {err}") from err

for _lib, _names in (("lapack", ("zheevd",)), ("blas", ("zherk", "zgemm"))):
    for _name in _names:
        _address = get_cython_function_address(f"scipy.linalg.cython_{_lib}", _name)
        _ll.add_symbol(f"oosd_{_name}", _address)
_P = types.voidptr
_zheevd = types.ExternalFunction("oosd_zheevd", types.void(*([_P] * 13)))
_zherk = types.ExternalFunction("oosd_zherk", types.void(*([_P] * 10)))
_zgemm = types.ExternalFunction("oosd_zgemm", types.void(*([_P] * 13)))
_jit = numba.njit(cache=True, nogil=True, fastmath=False)
# reassociation lets LLVM vectorize the real dot products of the split complex products
_jit_fast = numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})


#: Weight below which an eigenvalue is left out of the smoothed maximum's gradient.
WEIGHT_FLOOR = 1e-5
#: QR rotation steps allowed per tridiagonal eigenproblem, per row squared (about 1.1 n^2 are
#: needed; beyond the budget the evaluation falls back to ``zheevd``).
QR_STEP_BUDGET = 8


@_jit
def _scalings(x, lay, Tl, Tri, G):
    """Fill ``T_l`` (c x c), ``T_r^{-1}`` (r x r) and ``G`` (r x c) from the parameters ``x``.

    ``lay`` is the layout (``mu_lanes.LaneLayout``, from :func:`pack_layout`). Returns the
    entry values ``E`` of ``T``.
    """
    E = np.zeros(lay.n_entries, dtype=np.complex128)
    for k in range(lay.log_par.size):
        E[lay.log_ent[k]] = np.exp(min(max(x[lay.log_par[k]], -60.0), 60.0))
    for k in range(lay.lin_ent.size):
        E[lay.lin_ent[k]] = np.exp(min(max(x[lay.lin_row[k]], -60.0), 60.0)) * (
            x[lay.re_par[k]] + 1j * x[lay.im_par[k]]
        )
    Tl[:, :] = 0.0
    for k in range(lay.l_row.size):
        Tl[lay.l_row[k], lay.l_col[k]] = E[lay.l_ent[k]]
    Tr = np.zeros_like(Tri)
    for k in range(lay.r_row.size):
        Tr[lay.r_row[k], lay.r_col[k]] = E[lay.r_ent[k]]
    # T_r is block diagonal with lower-triangular blocks: invert each by forward substitution
    Tri[:, :] = 0.0
    for b in range(lay.rb_start.size):
        s, m = lay.rb_start[b], lay.rb_size[b]
        for j in range(s, s + m):
            Tri[j, j] = 1.0 / Tr[j, j]
            for i in range(j + 1, s + m):
                acc = 0.0j
                for q in range(j, i):
                    acc += Tr[i, q] * Tri[q, j]
                Tri[i, j] = -acc / Tr[i, i]
    G[:, :] = 0.0
    g_row, g_col = lay.g_row, lay.g_col
    for q in range(lay.gq_par.size):
        v = x[lay.gq_par[q]]
        k1 = lay.gq_pos1[q]
        G[g_row[k1], g_col[k1]] += v * lay.gq_coef1[q]
        k2 = lay.gq_pos2[q]
        if k2 >= 0:
            G[g_row[k2], g_col[k2]] += v * lay.gq_coef2[q]
    return E


@_jit
def _lower_tri_times(Tl, X, cb_start, cb_size, out):
    """``out = T X`` for ``T`` block diagonal with lower-triangular blocks."""
    ncol = X.shape[1]
    for b in range(cb_start.size):
        s, m = cb_start[b], cb_size[b]
        for i in range(s, s + m):  # row i of out: contiguous inner loops over the columns
            tij = Tl[i, s]
            for k in range(ncol):
                out[i, k] = tij * X[s, k]
            for j in range(s + 1, i + 1):
                tij = Tl[i, j]
                for k in range(ncol):
                    out[i, k] += tij * X[j, k]


@_jit
def _form_h(Mh, Tri, GX, realb, H, ints, reals):
    """``H = Mh^* Mh + j (Y X - (Y X)^*)`` with ``Y X = T_r^{-*} G X`` (``GX`` = ``G X``).

    Only the triangle LAPACK reads (``uplo = 'L'`` of the Fortran view) is exact: ``zherk``
    fills that one; the ``G`` term is added to both.
    """
    c, r = Mh.shape
    H[:, :] = 0.0
    ints[0] = r
    ints[3] = c
    reals[0] = 1.0
    reals[1] = 0.0
    # Fortran sees Mh (C order, c x r) as A = Mh^T (r x c): A A^H = (Mh^* Mh)^T, read back in
    # C order as Mh^* Mh
    _zherk(
        ints[4:5].ctypes, ints[7:8].ctypes, ints[0:1].ctypes, ints[3:4].ctypes,
        reals[0:1].ctypes, Mh.ctypes, ints[0:1].ctypes, reals[1:2].ctypes, H.ctypes,
        ints[0:1].ctypes,
    )  # fmt: skip
    yx = np.empty(r, dtype=np.complex128)
    for q in range(realb.shape[1]):
        ro, m = realb[0, q], realb[2, q]
        for a in range(m):  # row ro+a of Y X; (T_r^{-*})[ro+a, ro+bb] = conj(Tri[ro+bb, ro+a])
            for k in range(r):
                yx[k] = 0.0
            for bb in range(a, m):
                y = np.conj(Tri[ro + bb, ro + a])
                for k in range(r):
                    yx[k] += y * GX[ro + bb, k]
            for k in range(r):
                H[ro + a, k] += 1j * yx[k]
                H[k, ro + a] -= 1j * np.conj(yx[k])


@_jit_fast
def _form_h_split(Mh, Tri, GX, realb, Hr, Hi):
    """Lower triangle of ``H = Mh^* Mh + j (Y X - (Y X)^*)`` (``Y X = T_r^{-*} G X``, ``GX`` =
    ``G X``) with real and imaginary parts apart (``Hr``, ``Hi``; row ``i``: columns ``<= i``):
    the input of :func:`_tridiag_split`. Same value as :func:`_form_h`."""
    c, r = Mh.shape
    # column i of Mh as a contiguous row of its transpose, real and imaginary parts apart:
    # H[i, j] = sum_q conj(Mh[q, i]) Mh[q, j] is then a dot product that vectorizes
    tr_ = np.empty((r, c))
    ti_ = np.empty((r, c))
    for q in range(c):
        for i in range(r):
            tr_[i, q] = Mh[q, i].real
            ti_[i, q] = Mh[q, i].imag
    for i in range(r):
        ar = tr_[i]
        ai = ti_[i]
        for j in range(i + 1):
            br = tr_[j]
            bi = ti_[j]
            sr = 0.0
            si = 0.0
            for q in range(c):
                sr += ar[q] * br[q] + ai[q] * bi[q]
                si += ar[q] * bi[q] - ai[q] * br[q]
            Hr[i, j] = sr
            Hi[i, j] = si
    for q in range(realb.shape[1]):
        ro, m = realb[0, q], realb[2, q]
        for a in range(m):  # row i = ro + a of Y X; (T_r^{-*})[i, ro + bb] = conj(Tri[ro + bb, i])
            i = ro + a
            for k in range(r):
                yr = 0.0
                yi = 0.0
                for bb in range(a, m):
                    tr = Tri[ro + bb, i].real
                    ti = -Tri[ro + bb, i].imag
                    gr = GX[ro + bb, k].real
                    gi = GX[ro + bb, k].imag
                    yr += tr * gr - ti * gi
                    yi += tr * gi + ti * gr
                if k <= i:  # H[i, k] += j yx[k]
                    Hr[i, k] -= yi
                    Hi[i, k] += yr
                if k >= i:  # H[k, i] -= j conj(yx[k])
                    Hr[k, i] -= yi
                    Hi[k, i] -= yr


@_jit_fast
def _tridiag_split(Ar, Ai, d, e, taur, taui, pr, pi, vr, vi):
    """Householder tridiagonalization of a Hermitian matrix given by the lower triangle of
    ``Ar + j Ai`` (the arithmetic of LAPACK's ``zhetd2`` with ``uplo = 'L'``, in C order and
    with real and imaginary parts apart so that the loops vectorize).

    On return ``d``, ``e`` hold the real tridiagonal (``e[n-1] = 0``); the reflector
    ``H_k = I - tau_k v_k v_k^*`` (``v_k[k+1] = 1``) has its other entries below the subdiagonal
    of column ``k`` and ``tau_k`` in ``taur[k] + j taui[k]``: ``A = Q T Q^*``,
    ``Q = H_0 H_1 ... H_{n-2}``. ``pr, pi, vr, vi``: work vectors of length ``n``.
    """
    n = Ar.shape[0]
    for k in range(n - 1):
        o = k + 1
        m = n - o
        ar = Ar[o, k]
        ai = Ai[o, k]
        xn = 0.0
        for i in range(o + 1, n):
            xn += Ar[i, k] * Ar[i, k] + Ai[i, k] * Ai[i, k]
        d[k] = Ar[k, k]
        if xn == 0.0 and ai == 0.0:  # nothing to annihilate: H_k = I
            taur[k] = 0.0
            taui[k] = 0.0
            e[k] = ar
            for i in range(o + 1, n):
                Ar[i, k] = 0.0
                Ai[i, k] = 0.0
            continue
        beta = -np.copysign(np.sqrt(ar * ar + ai * ai + xn), ar)
        tr = (beta - ar) / beta
        ti = -ai / beta
        taur[k] = tr
        taui[k] = ti
        dr = ar - beta
        den = dr * dr + ai * ai
        sr = dr / den  # 1 / (alpha - beta)
        si = -ai / den
        vr[0] = 1.0
        vi[0] = 0.0
        for i in range(1, m):
            xr = Ar[o + i, k]
            xi = Ai[o + i, k]
            a_ = xr * sr - xi * si
            b_ = xr * si + xi * sr
            vr[i] = a_
            vi[i] = b_
            Ar[o + i, k] = a_
            Ai[o + i, k] = b_
        e[k] = beta
        # p = A22 v from the lower triangle (row i: a dot product and an axpy)
        for i in range(m):
            pr[i] = 0.0
            pi[i] = 0.0
        for i in range(m):
            rowr = Ar[o + i]
            rowi = Ai[o + i]
            v_r = vr[i]
            v_i = vi[i]
            s_r = rowr[o + i] * v_r
            s_i = rowr[o + i] * v_i
            for j in range(i):
                a_r = rowr[o + j]
                a_i = rowi[o + j]
                s_r += a_r * vr[j] - a_i * vi[j]
                s_i += a_r * vi[j] + a_i * vr[j]
                pr[j] += a_r * v_r + a_i * v_i
                pi[j] += a_r * v_i - a_i * v_r
            pr[i] += s_r
            pi[i] += s_i
        # p = tau p; w = p - tau (p^* v) v / 2
        hr = 0.0
        hi = 0.0
        for i in range(m):
            a_ = tr * pr[i] - ti * pi[i]
            b_ = tr * pi[i] + ti * pr[i]
            pr[i] = a_
            pi[i] = b_
            hr += a_ * vr[i] + b_ * vi[i]
            hi += a_ * vi[i] - b_ * vr[i]
        al_r = -0.5 * (tr * hr - ti * hi)
        al_i = -0.5 * (tr * hi + ti * hr)
        for i in range(m):
            pr[i] += al_r * vr[i] - al_i * vi[i]
            pi[i] += al_r * vi[i] + al_i * vr[i]
        # A22 -= v w^* + w v^* (lower triangle)
        for i in range(m):
            v_r = vr[i]
            v_i = vi[i]
            w_r = pr[i]
            w_i = pi[i]
            rowr = Ar[o + i]
            rowi = Ai[o + i]
            for j in range(i + 1):
                rowr[o + j] -= v_r * pr[j] + v_i * pi[j] + w_r * vr[j] + w_i * vi[j]
                rowi[o + j] -= v_i * pr[j] - v_r * pi[j] + w_i * vr[j] - w_r * vi[j]
    d[n - 1] = Ar[n - 1, n - 1]
    e[n - 1] = 0.0


@_jit
def _tridiag_qr(d, e, rot_k, rot_c, rot_s):
    """All eigenvalues of the symmetric tridiagonal ``(d, e)`` (``d`` receives them, unsorted;
    ``e`` is destroyed) by implicit QR with Wilkinson shifts, deflating at the bottom.

    The scalar form of ``mu_lanes._lane_qr`` (same steps and deflation test): step ``q``
    rotates rows ``rot_k[q]``, ``rot_k[q] + 1`` by ``(rot_c[q], rot_s[q])``. Returns the number
    of steps, or -1 when more than ``rot_k.size`` steps were needed.
    """
    n = d.shape[0]
    cap = rot_k.size
    nrm = 0.0
    for i in range(n):
        nrm = max(nrm, abs(d[i]) + abs(e[i]) + (abs(e[i - 1]) if i > 0 else 0.0))
    tol = 4.0 * 2.220446049250313e-16 * nrm
    nsteps = 0
    m = n - 1
    while True:
        while m > 0 and abs(e[m - 1]) <= tol:
            e[m - 1] = 0.0
            m -= 1
        if m == 0:
            return nsteps
        ll = m - 1
        while ll > 0 and abs(e[ll - 1]) > tol:
            ll -= 1
        if nsteps + (m - ll) > cap:
            return -1
        a, b, c_ = d[m - 1], e[m - 1], d[m]
        dd = 0.5 * (a - c_)
        den = dd + np.copysign(np.sqrt(dd * dd + b * b), dd)
        mu = c_ - b * b / den if den != 0.0 else c_
        x = d[ll] - mu
        z = e[ll]
        for k in range(ll, m):
            rr = np.sqrt(x * x + z * z)
            c = 1.0
            s = 0.0
            if rr > 0.0:
                c = x / rr
                s = z / rr
            if k > ll:
                e[k - 1] = rr
            dk = d[k]
            dk1 = d[k + 1]
            ek = e[k]
            cc = c * c
            ss = s * s
            cs = c * s
            d[k] = cc * dk + 2.0 * cs * ek + ss * dk1
            d[k + 1] = ss * dk - 2.0 * cs * ek + cc * dk1
            en = cs * (dk1 - dk) + (cc - ss) * ek
            e[k] = en
            bul = 0.0
            if k + 1 < n - 1:
                ek1 = e[k + 1]
                bul = s * ek1
                e[k + 1] = c * ek1
            x = en
            z = bul
            rot_k[nsteps] = k
            rot_c[nsteps] = c
            rot_s[nsteps] = s
            nsteps += 1


@_jit_fast
def _top_vectors(nsteps, rot_k, rot_c, rot_s, sel, K, Ar, Ai, taur, taui, Yr, Yi, sr, si):
    """Eigenvectors ``Y = Yr + j Yi`` (``(n, K)``, one per column) of the Hermitian matrix
    reduced by :func:`_tridiag_split` (reflectors in ``Ar``, ``Ai``, ``taur``, ``taui``) for
    the eigenvalues at the unsorted positions ``sel[:K]`` of :func:`_tridiag_qr`: the recorded
    rotations applied backwards to unit vectors, then the reflectors (``Y = Q Z``), the ``K``
    columns together (``mu_lanes._lane_vectors`` in scalar form). ``sr``, ``si``: work, ``>= K``.
    """
    n = Ar.shape[0]
    for i in range(n):
        for q in range(K):
            Yr[i, q] = 0.0
            Yi[i, q] = 0.0
    for q in range(K):
        Yr[sel[q], q] = 1.0
    for st in range(nsteps - 1, -1, -1):  # Z e_j = G_1 ... G_N e_j: G_N first
        k = rot_k[st]
        c = rot_c[st]
        s = rot_s[st]
        ya = Yr[k]
        yb = Yr[k + 1]
        for q in range(K):
            a = ya[q]
            b = yb[q]
            ya[q] = c * a - s * b
            yb[q] = s * a + c * b
    for k in range(n - 2, -1, -1):  # y = H_0 (H_1 (... H_{n-2} z))
        tr = taur[k]
        ti = taui[k]
        if tr == 0.0 and ti == 0.0:
            continue
        o = k + 1
        for q in range(K):  # s = v^* y (v[o] = 1)
            sr[q] = Yr[o, q]
            si[q] = Yi[o, q]
        for i in range(o + 1, n):
            a_r = Ar[i, k]
            a_i = Ai[i, k]
            yr = Yr[i]
            yi = Yi[i]
            for q in range(K):
                sr[q] += a_r * yr[q] + a_i * yi[q]
                si[q] += a_r * yi[q] - a_i * yr[q]
        for q in range(K):  # y -= tau s v
            cr = tr * sr[q] - ti * si[q]
            ci = tr * si[q] + ti * sr[q]
            sr[q] = cr
            si[q] = ci
            Yr[o, q] -= cr
            Yi[o, q] -= ci
        for i in range(o + 1, n):
            a_r = Ar[i, k]
            a_i = Ai[i, k]
            yr = Yr[i]
            yi = Yi[i]
            for q in range(K):
                yr[q] -= sr[q] * a_r - si[q] * a_i
                yi[q] -= sr[q] * a_i + si[q] * a_r


@_jit
def _eig_top_split(
    Hr, Hi, t, K_max, w_all, Vk, d, e, taur, taui, pr, pi, vr, vi, ev, rot_k, rot_c, rot_s,
    Yr, Yi, order,
):  # fmt: skip
    """Eigenvalues of the Hermitian matrix in the split lower triangle of
    :func:`_form_h_split` (overwritten) and eigenvectors of the top ones.

    Own tridiagonalization (:func:`_tridiag_split`), implicit QR on the tridiagonal
    (:func:`_tridiag_qr`: all eigenvalues, into ``w_all``, ascending) and eigenvectors from its
    recorded rotations and the reflectors (:func:`_top_vectors`): on the clustered top
    eigenvalues of the D-G optimum (4-11 within the smoothing) about 1.5 us per vector, where
    LAPACK's ``dstein`` (inverse iteration, reorthogonalized in clusters) took about 3.
    Returns ``(K, ok, t)``: ``Vk[:K]`` holds the eigenvectors of the ``K`` largest
    eigenvalues (ascending) whose smoothed-max weight at temperature ``t`` exceeds
    :data:`WEIGHT_FLOOR` (``K = 0`` when ``K_max = 0``: eigenvalues only); ``ok`` is False
    when the QR needed more than ``rot_k.size`` steps; a negative ``t`` is relative to the
    largest eigenvalue (``-t / lambda_max``) and the absolute one is returned.
    """
    n = Hr.shape[0]
    _tridiag_split(Hr, Hi, d, e, taur, taui, pr, pi, vr, vi)
    w_all[:] = d
    ev[:] = e
    ns = _tridiag_qr(w_all, ev, rot_k, rot_c, rot_s)
    if ns < 0:
        return 0, False, t
    for i in range(n):  # ascending, with the QR's positions (insertion sort: n is small)
        order[i] = i
    for i in range(1, n):
        v = w_all[i]
        o = order[i]
        j = i - 1
        while j >= 0 and w_all[j] > v:
            w_all[j + 1] = w_all[j]
            order[j + 1] = order[j]
            j -= 1
        w_all[j + 1] = v
        order[j + 1] = o
    if t < 0:  # relative to lambda_max
        t = -t / max(w_all[n - 1], 1e-12)
    if K_max == 0:
        return 0, True, t
    lmax = w_all[n - 1]
    K = 0
    ssum = 0.0
    for i in range(n):
        ssum += np.exp(t * (w_all[i] - lmax))
    for i in range(n - 1, -1, -1):
        if np.exp(t * (w_all[i] - lmax)) / ssum > WEIGHT_FLOOR and K < K_max:
            K += 1
        else:
            break
    _top_vectors(ns, rot_k, rot_c, rot_s, order[n - K :], K, Hr, Hi, taur, taui, Yr, Yi, pr, pi)
    for q in range(K):
        for i in range(n):
            Vk[q, i] = Yr[i, q] + 1j * Yi[i, q]
    return K, True, t


@_jit
def _eig_full(H, w_all, Vk, K_max, t, ints):
    """All eigenvalues and the top eigenvectors (weight > :data:`WEIGHT_FLOOR`) by ``zheevd``
    (the fallback of :func:`_eig_top_split`). Returns ``(K, ok, t)`` as that does."""
    n = H.shape[0]
    lwork = 2 * n + n * n
    lrwork = 1 + 5 * n + 2 * n * n
    liwork = 3 + 5 * n
    work = np.zeros(lwork, dtype=np.complex128)
    rwork = np.zeros(lrwork)
    iwork = np.zeros(liwork, dtype=np.int32)
    sizes = np.array([n, lwork, lrwork, liwork, 0, ord("V"), ord("L")], dtype=np.int32)
    _zheevd(
        sizes[5:6].ctypes, sizes[6:7].ctypes, sizes[0:1].ctypes, H.ctypes, sizes[0:1].ctypes,
        w_all.ctypes, work.ctypes, sizes[1:2].ctypes, rwork.ctypes, sizes[2:3].ctypes,
        iwork.ctypes, sizes[3:4].ctypes, sizes[4:5].ctypes,
    )  # fmt: skip
    if sizes[4] != 0:
        return 0, False, t
    if t < 0:  # relative to lambda_max
        t = -t / max(w_all[n - 1], 1e-12)
    if K_max == 0:
        return 0, True, t
    lm = w_all[n - 1]
    ss = 0.0
    for i in range(n):
        ss += np.exp(t * (w_all[i] - lm))
    K = 0
    for i in range(n - 1, -1, -1):
        if np.exp(t * (w_all[i] - lm)) / ss > WEIGHT_FLOOR and K < K_max:
            K += 1
        else:
            break
    # Fortran column j of the result = C row j, eigenvector of conj(H): conjugate back
    for k in range(K):
        for i in range(n):
            Vk[k, i] = np.conj(H[n - K + k, i])
    return K, True, t


#: Work arrays of the per-matrix evaluation (:func:`dg_objective_ws`), allocated once per
#: optimizer run by :func:`scalar_workspace` (an evaluation of one matrix then allocates
#: nothing: about 2.5 us of its 35 us on 26 x 26, paid 40-50 times per lone ``mussv`` call).
ScalarWorkspace = namedtuple(
    "ScalarWorkspace",
    [
        "Tl", "Tri", "G", "X", "Mh", "GX",  # the scalings and the scaled matrix
        "d", "e", "ev", "w_all",  # the tridiagonal, its QR copy, the eigenvalues
        "Vk",  # top eigenvectors (n, n)
        "rot_k", "rot_c", "rot_s",  # QR rotations, recorded (QR_STEP_BUDGET n^2 + n)
        "Yr", "Yi", "order",  # eigenvector work, eigenvalue order
        "ints", "Hr", "Hi",  # LAPACK/BLAS integer arguments; H (lower triangle, split)
        "taur", "taui", "pr", "pi", "vr", "vi",  # tridiagonalization
        "gT", "reals", "creals",  # gradient w.r.t. T's entries; BLAS scalars
        "tv", "xv", "mv", "pk",  # gradient work: T_r^{-1} V, M T_r^{-1} V, T_l M T_r^{-1} V
    ],
)  # fmt: skip


@_jit
def scalar_workspace(c, r, n_entries):
    """A :data:`ScalarWorkspace` for ``c x r`` matrices with ``n_entries`` entries of ``T``
    (contents: what :func:`dg_objective` allocated per call, zeros where it used zeros)."""
    n = r
    cap = QR_STEP_BUDGET * n * n + n
    ints = np.zeros(8, dtype=np.int32)
    ints[4] = ord("L")
    ints[7] = ord("N")
    return ScalarWorkspace(
        np.zeros((c, c), dtype=np.complex128), np.zeros((r, r), dtype=np.complex128),
        np.zeros((r, c), dtype=np.complex128), np.empty((c, r), dtype=np.complex128),
        np.empty((c, r), dtype=np.complex128), np.empty((r, r), dtype=np.complex128),
        np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n),
        np.empty((n, n), dtype=np.complex128),
        np.empty(cap, dtype=np.int64), np.empty(cap), np.empty(cap),
        np.empty((n, n)), np.empty((n, n)), np.zeros(n, dtype=np.int64),
        ints, np.empty((r, r)), np.empty((r, r)),
        np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n),
        np.zeros(n_entries, dtype=np.complex128), np.array([1.0, 0.0]),
        np.array([1.0 + 0.0j, 0.0j]),
        np.zeros(r * n, dtype=np.complex128), np.zeros(c * n, dtype=np.complex128),
        np.zeros(c * n, dtype=np.complex128), np.empty(n),
    )  # fmt: skip


@_jit
def dg_objective(M, x, t, need_grad, lay, f, grad, lmax, top, size=None):
    r"""Smoothed ``lambda_max`` of the scaled D-G matrix and its gradient, matrix by matrix.

    Parameters
    ----------
    M : complex array (B, c, r)
        The matrices (already gathered for the rows being evaluated).
    x : float array (B, p)
        Scaling parameters (layout of ``mu_upper._layout``).
    t : float array (B,)
        Smoothing temperatures (absolute):
        ``f = lambda_max + log(sum exp(t (lam - lambda_max))) / t``; a negative entry is
        relative to that matrix's ``lambda_max`` (``-t / lambda_max``) and is replaced by the
        absolute temperature used.
    need_grad : bool
        Also compute ``grad`` and ``top``.
    lay : mu_lanes.LaneLayout
        The layout (:func:`pack_layout`; the per-row maps of the lanes are not read here).
    f, grad, lmax, top : arrays (B,), (B, p), (B,), (B, r)
        Outputs (``top``: ``T_r^{-1} v`` for the top eigenvector ``v``).
    size : array (B,), optional
        Output: ``||M_hat||_F^2`` (``M_hat = T_l M T_r^{-1}``), the size of the LMI's terms
        by which the lane optimizer picks its best point (:mod:`mu_lanes`).

    Returns
    -------
    int
        Number of matrices whose eigenvectors needed the ``eigh`` fallback.
    """
    ws = scalar_workspace(M.shape[1], M.shape[2], lay.n_entries)
    return dg_objective_ws(M, x, t, need_grad, lay, f, grad, lmax, top, size, ws)


@_jit
def dg_objective_ws(M, x, t, need_grad, lay, f, grad, lmax, top, size, ws):
    """:func:`dg_objective` with its work arrays ``ws`` (:func:`scalar_workspace`) given: the
    same arithmetic (every work array is written before it is read, as from one matrix of a
    batch to the next), no allocation (but for the ``zheevd`` fallback)."""
    nb, c, r = M.shape
    cb_start, cb_size = lay.c_blocks[0], lay.c_blocks[1]
    rb_start, rb_size = lay.rb_start, lay.rb_size
    realb = lay.real_blocks
    n = r
    Tl, Tri, G, X, Mh, GX = ws.Tl, ws.Tri, ws.G, ws.X, ws.Mh, ws.GX
    d, e, ev, w_all, Vk = ws.d, ws.e, ws.ev, ws.w_all, ws.Vk
    K_max = n
    rot_k, rot_c, rot_s, Yr, Yi, order = ws.rot_k, ws.rot_c, ws.rot_s, ws.Yr, ws.Yi, ws.order
    ints, Hr, Hi = ws.ints, ws.Hr, ws.Hi
    taur, taui, pr, pi, vr, vi = ws.taur, ws.taui, ws.pr, ws.pi, ws.vr, ws.vi
    gT, reals, creals = ws.gT, ws.reals, ws.creals
    fallbacks = 0
    for b in range(nb):
        Mb = M[b]
        xb = x[b]
        E = _scalings(xb, lay, Tl, Tri, G)
        # X = M T_r^{-1} (T_r^{-1} block diagonal, lower triangular blocks)
        for i in range(c):
            for q in range(rb_start.size):
                s, m = rb_start[q], rb_size[q]
                for j in range(s, s + m):
                    acc = 0.0j
                    for k in range(j, s + m):
                        acc += Mb[i, k] * Tri[k, j]
                    X[i, j] = acc
        _lower_tri_times(Tl, X, cb_start, cb_size, Mh)
        if size is not None:
            acc_size = 0.0
            for i in range(c):
                for j in range(r):
                    acc_size += Mh[i, j].real ** 2 + Mh[i, j].imag ** 2
            size[b] = acc_size
        # G X: G is non-zero on the real blocks only
        for q in range(realb.shape[1]):
            ro, co, m = realb[0, q], realb[1, q], realb[2, q]
            for a in range(m):
                for k in range(r):
                    GX[ro + a, k] = 0.0
                for bb in range(m):
                    gab = G[ro + a, co + bb]
                    for k in range(r):
                        GX[ro + a, k] += gab * X[co + bb, k]
        _form_h_split(Mh, Tri, GX, realb, Hr, Hi)
        tb = t[b]
        K, ok, tb = _eig_top_split(
            Hr, Hi, tb, K_max if need_grad else 0, w_all, Vk, d, e, taur, taui, pr, pi, vr,
            vi, ev, rot_k, rot_c, rot_s, Yr, Yi, order,
        )  # fmt: skip
        if not ok:  # rebuild H (overwritten) and use a full eigendecomposition
            fallbacks += 1
            H = np.zeros((r, r), dtype=np.complex128)
            _form_h(Mh, Tri, GX, realb, H, ints, reals)
            K, ok, tb = _eig_full(H, w_all, Vk, K_max if need_grad else 0, t[b], ints)
            if not ok:  # not even zheevd: report an infinite objective (rejected step)
                f[b] = np.inf
                lmax[b] = np.inf
                if need_grad:
                    grad[b, :] = 0.0
                    top[b, :] = 0.0
                continue
        t[b] = tb
        lm = w_all[n - 1]
        lmax[b] = lm
        ssum = 0.0
        for i in range(n):
            ssum += np.exp(tb * (w_all[i] - lm))
        f[b] = lm + np.log(ssum) / tb
        if not need_grad:
            continue
        # gradient: with V_k the top eigenvectors, weights p_k, eigenvalues l_k:
        #   T_l entry (i, j): 2 sum_k XV[j,k] p_k conj(MV[i,k]),  XV = M T_r^{-1} V, MV = T_l XV
        #   T_r entry (i, j): -2 sum_k TV[j,k] p_k l_k conj(V[i,k]),  TV = T_r^{-1} V
        #   G entry (i, j):   2j sum_k XV[j,k] p_k conj(TV[i,k])
        TV = ws.tv[: r * K].reshape((r, K))  # every entry written below
        for q in range(rb_start.size):
            s, m = rb_start[q], rb_size[q]
            for i in range(s, s + m):
                for k in range(K):
                    acc = 0.0j
                    for j in range(s, i + 1):
                        acc += Tri[i, j] * Vk[k, j]
                    TV[i, k] = acc
        XV = ws.xv[: c * K].reshape((c, K))  # zgemm with beta = 0 writes it
        # C-order XV = Mb TV is, in Fortran's view, XV^T = TV^T Mb^T (K x c)
        ints[3] = K
        ints[5] = c
        ints[0] = r
        _zgemm(
            ints[7:8].ctypes, ints[7:8].ctypes, ints[3:4].ctypes, ints[5:6].ctypes,
            ints[0:1].ctypes, creals[0:1].ctypes, TV.ctypes, ints[3:4].ctypes, Mb.ctypes,
            ints[0:1].ctypes, creals[1:2].ctypes, XV.ctypes, ints[3:4].ctypes,
        )  # fmt: skip
        MV = ws.mv[: c * K].reshape((c, K))
        _lower_tri_times(Tl, XV, cb_start, cb_size, MV)
        pk = ws.pk
        for k in range(K):
            pk[k] = np.exp(tb * (w_all[n - K + k] - lm)) / ssum
        gT[:] = 0.0
        for q in range(lay.l_row.size):
            i, j = lay.l_row[q], lay.l_col[q]
            acc = 0.0j
            for k in range(K):
                acc += XV[j, k] * pk[k] * np.conj(MV[i, k])
            gT[lay.l_ent[q]] += 2.0 * acc
        for q in range(lay.r_row.size):
            i, j = lay.r_row[q], lay.r_col[q]
            acc = 0.0j
            for k in range(K):
                acc += TV[j, k] * (pk[k] * w_all[n - K + k]) * np.conj(Vk[k, i])
            gT[lay.r_ent[q]] -= 2.0 * acc
        gb = grad[b]
        gb[:] = 0.0
        for q in range(lay.log_par.size):
            gb[lay.log_par[q]] = (gT[lay.log_ent[q]] * E[lay.log_ent[q]]).real
        for q in range(lay.lin_ent.size):
            en = lay.lin_ent[q]
            gb[lay.lin_row[q]] += (gT[en] * E[en]).real
            rs = np.exp(min(max(xb[lay.lin_row[q]], -60.0), 60.0))
            gb[lay.re_par[q]] = gT[en].real * rs
            gb[lay.im_par[q]] = -gT[en].imag * rs
        for q in range(lay.gq_par.size):
            k1 = lay.gq_pos1[q]
            i, j = lay.g_row[k1], lay.g_col[k1]
            acc = 0.0j
            for k in range(K):
                acc += XV[j, k] * pk[k] * np.conj(TV[i, k])
            val = 2j * acc * lay.gq_coef1[q]
            k2 = lay.gq_pos2[q]
            if k2 >= 0:
                i, j = lay.g_row[k2], lay.g_col[k2]
                acc = 0.0j
                for k in range(K):
                    acc += XV[j, k] * pk[k] * np.conj(TV[i, k])
                val += 2j * acc * lay.gq_coef2[q]
            gb[lay.gq_par[q]] = val.real
        for i in range(r):
            top[b, i] = TV[i, K - 1]
    return fallbacks


def pack_layout(layout, c_groups) -> dict:
    """The index arrays of ``mu_upper._Layout`` as the kernels read them.

    Returns the fields of ``mu_lanes.LaneLayout`` up to ``gq_coef2`` (int64 index arrays,
    complex ``G`` coefficients), plus ``c_blocks``, the c-space diagonal blocks ``(2, n_blocks)``
    (start, size), and ``real_blocks``, the real blocks ``(3, n_real)`` (row offset, column
    offset, size); :func:`mu_lanes.lane_layout` adds the per-row maps of the lanes.
    """
    L = layout
    rb = _blocks_from_groups(L.inv_groups)
    # G parameters: each maps to one or two positions of G with complex coefficients
    gq_par, pos1, pos2, coef1, coef2 = [], [], [], [], []
    for q in range(L.g_map.shape[0]):
        nz = np.flatnonzero(L.g_map[q])
        gq_par.append(L.g_par[q])
        pos1.append(nz[0])
        coef1.append(L.g_map[q, nz[0]])
        if nz.size > 1:
            pos2.append(nz[1])
            coef2.append(L.g_map[q, nz[1]])
        else:
            pos2.append(-1)
            coef2.append(0.0)
    index = dict(
        log_par=L.log_par, log_ent=L.log_ent, re_par=L.lin_re_par, im_par=L.lin_im_par,
        lin_ent=L.lin_ent, lin_row=L.lin_row_par, l_row=L.l_row, l_col=L.l_col, l_ent=L.l_ent,
        r_row=L.r_row, r_col=L.r_col, r_ent=L.r_ent, rb_start=rb[0], rb_size=rb[1],
        g_row=L.g_row, g_col=L.g_col, gq_par=gq_par, gq_pos1=pos1, gq_pos2=pos2,
    )  # fmt: skip
    return dict(
        n_entries=int(L.n_entries),
        **{k: np.ascontiguousarray(v, dtype=np.int64) for k, v in index.items()},
        gq_coef1=np.array(coef1, dtype=np.complex128),
        gq_coef2=np.array(coef2, dtype=np.complex128),
        c_blocks=_blocks_from_groups(c_groups),
        # real blocks: G's diagonal blocks (r offset, c offset, size), read from the G positions
        real_blocks=_real_blocks(L),
    )


def _blocks_from_groups(groups) -> np.ndarray:
    starts, sizes = [], []
    for n, rows in groups:
        for row in rows:
            starts.append(int(row[0]))
            sizes.append(int(n))
    order = np.argsort(starts)
    return np.array([np.array(starts)[order], np.array(sizes)[order]], dtype=np.int64).reshape(
        2, -1
    )


def _real_blocks(L) -> np.ndarray:
    out = []
    if len(L.g_row):
        seen = set()
        rows, cols = np.asarray(L.g_row), np.asarray(L.g_col)
        # positions come block by block, n x n each, row-major from the block's corner
        k = 0
        while k < len(rows):
            ro, co = int(rows[k]), int(cols[k])
            m = 1
            while k + m < len(rows) and rows[k + m] == ro and cols[k + m] == co + m:
                m += 1
            if (ro, co) not in seen:
                seen.add((ro, co))
                out.append((ro, co, m))
            k += m * m
    return np.array(out, dtype=np.int64).reshape(-1, 3).T.copy()


@_jit
def osborne(P, iters, logd):
    """Osborne balancing sweeps of ``mu_upper._osborne_init`` (the same arithmetic and the same
    batch-wide stopping rule): ``P`` ``(B, k, k)`` coupling weights (zero diagonal, plus a tiny
    floor), ``logd`` ``(B, k)`` log-scalings, updated in place."""
    nb, k, _ = P.shape
    for _ in range(iters):
        biggest = 0.0
        for i in range(k):
            for b in range(nb):
                R = 0.0
                C = 0.0
                for j in range(k):
                    e = np.exp(logd[b, j] - logd[b, i])
                    R += P[b, i, j] / e
                    C += P[b, j, i] * e
                step = min(max(0.5 * (np.log(C) - np.log(R)), -5.0), 5.0)
                logd[b, i] += step
                biggest = max(biggest, abs(step))
        for b in range(nb):
            mean = 0.0
            for j in range(k):
                mean += logd[b, j]
            mean /= k
            for j in range(k):
                logd[b, j] = min(max(logd[b, j] - mean, -40.0), 40.0)
        if biggest < 1e-3:
            break


def warm_up() -> float:
    """Compile (or load from the on-disk cache) every kernel once; return the time taken [s].

    ``make`` calls it after installing, so that the one-time compilation (20-40 s on a fresh
    clone) is paid at setup, not inside the first analysis or inside several worker processes
    at once. It runs :func:`oos_drake.robust.mussv` on small matrices with the paper's block
    structure (repeated real, full complex and complex scalar blocks), on 3 and on 9 matrices
    (idle lanes and full ones), cold and with continuation, which reaches every compiled path.
    """
    import time

    from oos_drake.robust.mu import mussv

    start = time.perf_counter()
    blk = [[-3, 0], [-2, 0], [3, 3], [1, 0], [1, 0]]
    rng = np.random.default_rng(0)
    M = rng.standard_normal((9, 10, 10)) + 1j * rng.standard_normal((9, 10, 10))
    for part in (M[:3], M):  # the lane optimizer (mu_lanes) with idle lanes and with all busy
        mussv(part, blk)
        mussv(part, blk, continuation=True)
    for only in ([[-3, 0], [-2, 0], [-5, 0]], [[3, 3], [1, 0], [6, 0]]):  # real only, complex only
        mussv(M, only)
    return time.perf_counter() - start
