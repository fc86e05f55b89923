r"""Compiled (numba) per-matrix kernels of the mu lower bound (:mod:`oos_drake.robust.mu_lower`).

* :func:`power_iteration`: the mixed power iteration of the module docstring of ``mu_lower`` (its
  numpy version in ``tests/robust/oracles.py`` is the reference; tests check both agree to
  round-off), with real and imaginary parts
  in separate arrays, one pass over ``M`` per
  step for both ``M Delta a`` and ``M^* z`` (``M^* (c z) = c M^* z`` for the scalar ``c`` that
  normalizes and rotates ``z``), four rows of ``M`` at a time, reciprocals and ``sqrt`` instead
  of complex divisions and ``hypot``, helpers inlined (a numba call passes each array as seven
  arguments). Several starts per matrix read the same ``M`` (no replicated batch).
* :func:`eigen_polish`: ``oracles.polish_eigenvalue`` (shifted inverse iteration for the
  eigen-pair of ``M Delta``) and ``oracles.make_eigenvalue_real`` (its Newton steps on the
  real blocks and on the common phase of the complex blocks towards a real eigenvalue), matrix
  by matrix, with the same arithmetic and stopping rules. ``M Delta`` is formed block by block,
  the shifted systems are solved by a small complex LU with partial pivoting (split real and
  imaginary parts) and the left eigenvector's two solves with ``(M Delta - s I)^*`` share one
  factorization (numpy factors twice).
* :func:`rayleigh_quotients` (the score that picks the starts to polish) and
  :func:`vector_residual` (``oracles.vector_residual``, the certificate's first check).

Paper-sized problem (26 x 26, 16 blocks), one core: about 47 us per power-iteration start of 60
steps (the earlier per-matrix kernel: 88 us) and about 60 us per polished start (numpy: about
160 us).

Blocks are described by an integer array ``(5, n_blocks)``: kind (0 repeated real, 1 repeated
complex, 2 full), rows, columns, row offset and column offset.
"""

from __future__ import annotations

import math

import numba
import numpy as np

# numpy's error model: float division by zero gives inf/nan (no exception branches)
_opts = dict(cache=True, nogil=True, error_model="numpy")
_jit = numba.njit(**_opts)
# small helpers called in the inner loops: inlined by numba (a call passes every array as
# seven arguments, which costs more than the helper's own work)
_jit_inline = numba.njit(**_opts, inline="always")
# reassociation and FMA contraction let LLVM vectorize the split complex loops
_jit_fast = numba.njit(**_opts, fastmath={"reassoc", "contract"})

# --------------------------------------------------------------------------------------------
# power iteration


@_jit_inline
def _mv_pair(Mr, Mi, vr, vi, zr, zi, outr, outi, wr, wi):
    """``out = M v`` (length c) and ``w = M^* z`` (length rp) in one pass over ``M``.

    ``Mr``, ``Mi``: ``(c, rp)`` real and imaginary parts, zero-padded columns; ``vr``, ``vi``
    of length ``rp``, ``zr``, ``zi`` of length ``c``. Four rows at a time: each load of ``v``
    and each load and store of ``w`` serves four rows.
    """
    c, rp = Mr.shape
    for i in range(rp):
        wr[i] = 0.0
        wi[i] = 0.0
    q = 0
    while q + 4 <= c:
        a0 = Mr[q]
        b0 = Mi[q]
        a1 = Mr[q + 1]
        b1 = Mi[q + 1]
        a2 = Mr[q + 2]
        b2 = Mi[q + 2]
        a3 = Mr[q + 3]
        b3 = Mi[q + 3]
        z0r, z0i, z1r, z1i = zr[q], zi[q], zr[q + 1], zi[q + 1]
        z2r, z2i, z3r, z3i = zr[q + 2], zi[q + 2], zr[q + 3], zi[q + 3]
        s0r = s0i = s1r = s1i = s2r = s2i = s3r = s3i = 0.0
        for i in range(rp):
            xr = vr[i]
            xi = vi[i]
            s0r += a0[i] * xr - b0[i] * xi
            s0i += a0[i] * xi + b0[i] * xr
            s1r += a1[i] * xr - b1[i] * xi
            s1i += a1[i] * xi + b1[i] * xr
            s2r += a2[i] * xr - b2[i] * xi
            s2i += a2[i] * xi + b2[i] * xr
            s3r += a3[i] * xr - b3[i] * xi
            s3i += a3[i] * xi + b3[i] * xr
            wr[i] += (a0[i] * z0r + b0[i] * z0i + a1[i] * z1r + b1[i] * z1i) + (
                a2[i] * z2r + b2[i] * z2i + a3[i] * z3r + b3[i] * z3i
            )
            wi[i] += (a0[i] * z0i - b0[i] * z0r + a1[i] * z1i - b1[i] * z1r) + (
                a2[i] * z2i - b2[i] * z2r + a3[i] * z3i - b3[i] * z3r
            )
        outr[q], outi[q], outr[q + 1], outi[q + 1] = s0r, s0i, s1r, s1i
        outr[q + 2], outi[q + 2], outr[q + 3], outi[q + 3] = s2r, s2i, s3r, s3i
        q += 4
    while q < c:
        a0 = Mr[q]
        b0 = Mi[q]
        z0r = zr[q]
        z0i = zi[q]
        s0r = 0.0
        s0i = 0.0
        for i in range(rp):
            s0r += a0[i] * vr[i] - b0[i] * vi[i]
            s0i += a0[i] * vi[i] + b0[i] * vr[i]
            wr[i] += a0[i] * z0r + b0[i] * z0i
            wi[i] += a0[i] * z0i - b0[i] * z0r
        outr[q] = s0r
        outi[q] = s0i
        q += 1


@_jit_inline
def _mhv(Mr, Mi, zr, zi, wr, wi):
    """``w = M^* z`` (see :func:`_mv_pair`)."""
    c, rp = Mr.shape
    for i in range(rp):
        wr[i] = 0.0
        wi[i] = 0.0
    for q in range(c):
        mr = Mr[q]
        mi = Mi[q]
        zqr = zr[q]
        zqi = zi[q]
        for i in range(rp):
            wr[i] += mr[i] * zqr + mi[i] * zqi
            wi[i] += mr[i] * zqi - mi[i] * zqr


@_jit_inline
def _cabs(x, y):
    """``|x + j y|`` (``hypot``, several times slower, only where the squares could under- or
    overflow)."""
    s = x * x + y * y
    if 1e-280 < s < 1e280:
        return math.sqrt(s)
    return math.hypot(x, y)


@_jit_inline
def _scalar_maps(kind, rows, roff, coff, r, c):
    """Index maps of the scalar blocks: for each row ``i`` of ``Delta`` its column and block
    (``col_of``, ``blk_of``), for each column ``j`` its row and block (``row_of``,
    ``cblk_of``). Rows and columns of full blocks map to 0 and to the dummy block
    ``n_blocks`` (whose value stays 0)."""
    nblk = kind.size
    col_of = np.zeros(r, dtype=np.int64)
    blk_of = np.full(r, nblk, dtype=np.int64)
    row_of = np.zeros(c, dtype=np.int64)
    cblk_of = np.full(c, nblk, dtype=np.int64)
    for k in range(nblk):
        if kind[k] != 2:
            for i in range(rows[k]):
                col_of[roff[k] + i] = coff[k] + i
                blk_of[roff[k] + i] = k
                row_of[coff[k] + i] = roff[k] + i
                cblk_of[coff[k] + i] = k
    return col_of, blk_of, row_of, cblk_of


@_jit_inline
def _apply(maps, full, rows, cols, roff, coff, pr, pi, fr, fi, ar, ai, wr, wi, dar, dai, zur,
           zui):  # fmt: skip
    """``Delta a`` (r-space) and ``Delta^* w`` (c-space) for the block values ``pr + j pi``
    (scalar blocks, padded with the dummy 0) and ``fr + j fi`` (full blocks, listed in
    ``full``)."""
    col_of, blk_of, row_of, cblk_of = maps
    for i in range(blk_of.size):
        k = blk_of[i]
        j = col_of[i]
        dar[i] = pr[k] * ar[j] - pi[k] * ai[j]
        dai[i] = pr[k] * ai[j] + pi[k] * ar[j]
    for j in range(cblk_of.size):
        k = cblk_of[j]
        i = row_of[j]
        zur[j] = pr[k] * wr[i] + pi[k] * wi[i]
        zui[j] = pr[k] * wi[i] - pi[k] * wr[i]
    for k in full:
        for i in range(rows[k]):
            sr = 0.0
            si = 0.0
            for q in range(cols[k]):
                xr = ar[coff[k] + q]
                xi = ai[coff[k] + q]
                sr += fr[k, i, q] * xr - fi[k, i, q] * xi
                si += fr[k, i, q] * xi + fi[k, i, q] * xr
            dar[roff[k] + i] = sr
            dai[roff[k] + i] = si
        for q in range(cols[k]):
            sr = 0.0
            si = 0.0
            for i in range(rows[k]):
                xr = wr[roff[k] + i]
                xi = wi[roff[k] + i]
                sr += fr[k, i, q] * xr + fi[k, i, q] * xi
                si += fr[k, i, q] * xi - fi[k, i, q] * xr
            zur[coff[k] + q] = sr
            zui[coff[k] + q] = si


@_jit_inline
def _update(kind, rows, cols, roff, coff, pr, pi, fr, fi, phi, ar, ai, wr, wi, za, lam, eta, P, Q,
            free):  # fmt: skip
    """``mu_lower._update_blocks`` for one matrix (in place on the block values); returns phi.

    ``za = z^* a`` and ``lam`` are complex scalars; ``P``, ``Q``, ``free``: work arrays of
    length ``n_real + 1``.
    """
    nblk = kind.size
    cr = math.cos(phi)
    ci = math.sin(phi)
    zm = _cabs(za.real, za.imag)
    if zm <= 1e-300:
        za = 1e-300 + 0.0j
        zm = 1e-300
    izr = (za.real / zm) / zm  # 1 / za without overflow
    izi = (-za.imag / zm) / zm
    hr = 0.0
    hi = 0.0
    n_real = P.size - 1
    has_c = n_real < nblk
    j = 0
    for k in range(nblk):
        if kind[k] == 2:
            na = 0.0
            nw = 0.0
            for i in range(cols[k]):
                na += ar[coff[k] + i] ** 2 + ai[coff[k] + i] ** 2
            for i in range(rows[k]):
                nw += wr[roff[k] + i] ** 2 + wi[roff[k] + i] ** 2
            nn = math.sqrt(na) * math.sqrt(nw)
            if nn >= 1e-300:
                sr = cr / nn
                si = ci / nn
                for i in range(rows[k]):
                    # (rot / nn) w_i conj(a_q)
                    xr = sr * wr[roff[k] + i] - si * wi[roff[k] + i]
                    xi = sr * wi[roff[k] + i] + si * wr[roff[k] + i]
                    for q in range(cols[k]):
                        yr = ar[coff[k] + q]
                        yi = -ai[coff[k] + q]
                        fr[k, i, q] = xr * yr - xi * yi
                        fi[k, i, q] = xr * yi + xi * yr
            # h += rot nn / za
            hr += nn * (cr * izr - ci * izi)
            hi += nn * (cr * izi + ci * izr)
            continue
        ipr = 0.0  # w_k^* a_k
        ipi = 0.0
        for i in range(rows[k]):
            yr = wr[roff[k] + i]
            yi = wi[roff[k] + i]
            ipr += yr * ar[coff[k] + i] + yi * ai[coff[k] + i]
            ipi += yr * ai[coff[k] + i] - yi * ar[coff[k] + i]
        if kind[k] == 0:
            P[j] = ipr * izr - ipi * izi
            Q[j] = ipr * izi + ipi * izr
            free[j] = abs(pr[k]) < 1.0 - 1e-12
            j += 1
        else:
            mag = _cabs(ipr, ipi)
            if mag > 1e-300:  # rot conj(ip) / mag
                f = 1.0 / mag
                pr[k] = (cr * ipr + ci * ipi) * f
                pi[k] = (ci * ipr - cr * ipi) * f
            hr += mag * (cr * izr - ci * izi)
            hi += mag * (cr * izi + ci * izr)
    if n_real == 0:
        return phi
    m = n_real
    if has_c:
        P[m] = -hi
        Q[m] = hr
        free[m] = True
        m += 1
    q2 = 1e-300
    pq = 0.0
    for i in range(m):
        if not free[i]:
            Q[i] = 0.0
        q2 += Q[i] * Q[i]
    for i in range(m):
        pq += P[i] * Q[i]
    nasc = 0.0
    f = pq / q2
    for i in range(m):
        P[i] = P[i] - f * Q[i]
        nasc += P[i] * P[i]
    f = -lam.imag / q2
    g = eta / max(math.sqrt(nasc), 1e-300)
    nstep = 0.0
    for i in range(m):
        P[i] = f * Q[i] + g * P[i]  # the step
        nstep += P[i] * P[i]
    fac = min(1.0, 0.5 / max(math.sqrt(nstep), 1e-300))
    j = 0
    for k in range(nblk):
        if kind[k] == 0:
            pr[k] = min(max(pr[k] + fac * P[j], -1.0), 1.0)
            j += 1
    if has_c:
        dphi = fac * P[m - 1]
        phi += dphi
        er = math.cos(dphi)
        ei = math.sin(dphi)
        for k in range(nblk):
            if kind[k] == 1:
                xr = pr[k]
                pr[k] = xr * er - pi[k] * ei
                pi[k] = xr * ei + pi[k] * er
            elif kind[k] == 2:
                for i in range(rows[k]):
                    for q in range(cols[k]):
                        xr = fr[k, i, q]
                        fr[k, i, q] = xr * er - fi[k, i, q] * ei
                        fi[k, i, q] = xr * ei + fi[k, i, q] * er
    return phi


@_jit_fast
def power_iteration(M, a0, z0, real0, blocks, iters, kappa, delta, a_out):
    """The mixed power iteration (``oracles.power_iteration``), start by start.

    Parameters
    ----------
    M : complex array (nb, c, r)
        Matrices; start ``s`` runs on ``M[s % nb]`` (several starts per matrix without copies).
    a0, z0 : complex arrays (N, c)
        Starting right/left vectors (``N`` a multiple of ``nb``).
    real0 : float array (N, n_real)
        Starting values of the real blocks.
    blocks : int array (5, n_blocks)
        kind (0 real, 1 repeated complex, 2 full), rows, cols, row offset, column offset.
    iters : int
        Power-iteration steps.
    kappa : float
        Step size of the real-block update.
    delta, a_out : complex arrays (N, r, c), (N, c)
        Outputs: the unit-norm perturbation and the last right vector.
    """
    nb, c, r = M.shape
    N = a0.shape[0]
    kind, rows, cols, roff, coff = blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]
    nblk = kind.size
    rp = -(-r // 8) * 8
    maps = _scalar_maps(kind, rows, roff, coff, r, c)
    maxr = 1
    maxc = 1
    real_only = True
    n_real = 0
    n_full = 0
    for k in range(nblk):
        maxr = max(maxr, rows[k])
        maxc = max(maxc, cols[k])
        if kind[k] != 0:
            real_only = False
        else:
            n_real += 1
        if kind[k] == 2:
            n_full += 1
    full = np.empty(n_full, dtype=np.int64)
    n_full = 0
    for k in range(nblk):
        if kind[k] == 2:
            full[n_full] = k
            n_full += 1
    pr = np.zeros(nblk + 1)  # the last entry: dummy block of the full rows/columns (stays 0)
    pi = np.zeros(nblk + 1)
    fr = np.zeros((nblk, maxr, maxc))
    fi = np.zeros((nblk, maxr, maxc))
    ar = np.empty(c)
    ai = np.empty(c)
    zr = np.empty(c)
    zi = np.empty(c)
    zur = np.empty(c)
    zui = np.empty(c)
    wr = np.zeros(rp)
    wi = np.zeros(rp)
    wur = np.zeros(rp)
    wui = np.zeros(rp)
    dar = np.zeros(rp)
    dai = np.zeros(rp)
    mr = np.empty(c)
    mi = np.empty(c)
    Mr = np.zeros((c, rp))
    Mi = np.zeros((c, rp))
    P = np.empty(n_real + 1)
    Q = np.empty(n_real + 1)
    free = np.ones(n_real + 1, dtype=np.bool_)
    loaded = -1
    for s in range(N):
        b = s % nb
        if b != loaded:
            Mb = M[b]
            for q in range(c):
                for i in range(r):
                    Mr[q, i] = Mb[q, i].real
                    Mi[q, i] = Mb[q, i].imag
            loaded = b
        for q in range(c):
            ar[q] = a0[s, q].real
            ai[q] = a0[s, q].imag
            zr[q] = z0[s, q].real
            zi[q] = z0[s, q].imag
        _mhv(Mr, Mi, zr, zi, wr, wi)  # w = M^* z
        j = 0
        fr[:, :, :] = 0.0
        fi[:, :, :] = 0.0
        for k in range(nblk):
            pi[k] = 0.0
            if kind[k] == 0:
                pr[k] = real0[s, j]
                j += 1
            else:
                pr[k] = 1.0
        zar = 0.0
        zai = 0.0
        for q in range(c):
            zar += zr[q] * ar[q] + zi[q] * ai[q]
            zai += zr[q] * ai[q] - zi[q] * ar[q]
        za = zar + 1j * zai
        phi = _update(kind, rows, cols, roff, coff, pr, pi, fr, fi, 0.0, ar, ai, wr, wi, za, 0j,
                      0.0, P, Q, free)  # fmt: skip
        for it in range(iters):
            # Delta a, Delta^* w, then M Delta a and M^* Delta^* w in one pass over M
            _apply(maps, full, rows, cols, roff, coff, pr, pi, fr, fi, ar, ai, wr, wi, dar, dai,
                   zur, zui)  # fmt: skip
            _mv_pair(Mr, Mi, dar, dai, zur, zui, mr, mi, wur, wui)
            lr = 0.0
            li = 0.0
            for q in range(c):
                lr += zr[q] * mr[q] + zi[q] * mi[q]
                li += zr[q] * mi[q] - zi[q] * mr[q]
            if _cabs(za.real, za.imag) > 1e-300:
                lam = (lr + 1j * li) / za
            else:
                lam = (lr + 1j * li) / 1e-300
            sgn = 1.0
            if real_only and lam.real < 0:  # |lam| counts: flip the sign of delta
                for k in range(nblk):
                    pr[k] = -pr[k]
                lam = -lam
                sgn = -1.0
            nrm = 0.0
            for q in range(c):
                nrm += mr[q] * mr[q] + mi[q] * mi[q]
            inv = sgn / max(math.sqrt(nrm), 1e-300)
            for q in range(c):
                ar[q] = mr[q] * inv
                ai[q] = mi[q] * inv
            # z = Delta^* w normalized and rotated so that z^* a > 0 (the flip cancels here)
            nrm = 0.0
            for q in range(c):
                nrm += zur[q] * zur[q] + zui[q] * zui[q]
            inv = 1.0 / max(math.sqrt(nrm), 1e-300)
            zar = 0.0
            zai = 0.0
            for q in range(c):
                zr[q] = zur[q] * inv
                zi[q] = zui[q] * inv
                zar += zr[q] * ar[q] + zi[q] * ai[q]
                zai += zr[q] * ai[q] - zi[q] * ar[q]
            mag = _cabs(zar, zai)
            den = max(mag, 1e-300)
            rr = zar / den
            ri = zai / den
            for q in range(c):
                xr = zr[q]
                zr[q] = xr * rr - zi[q] * ri
                zi[q] = xr * ri + zi[q] * rr
            za = mag + 0.0j
            sr = rr * inv
            si = ri * inv
            for i in range(r):  # w = M^* z = (rot / ||Delta^* w||) M^* Delta^* w
                wr[i] = wur[i] * sr - wui[i] * si
                wi[i] = wur[i] * si + wui[i] * sr
            eta = kappa * max(0.0, 1.0 - it / (0.7 * iters))
            phi = _update(kind, rows, cols, roff, coff, pr, pi, fr, fi, phi, ar, ai, wr, wi, za,
                          lam, eta, P, Q, free)  # fmt: skip
        db = delta[s]
        db[:, :] = 0.0
        for k in range(nblk):
            if kind[k] == 2:
                for i in range(rows[k]):
                    for q in range(cols[k]):
                        db[roff[k] + i, coff[k] + q] = fr[k, i, q] + 1j * fi[k, i, q]
            else:
                for i in range(rows[k]):
                    db[roff[k] + i, coff[k] + i] = pr[k] + 1j * pi[k]
        for q in range(c):
            a_out[s, q] = ar[q] + 1j * ai[q]


# --------------------------------------------------------------------------------------------
# eigenvalue polish: shifted inverse iteration with a small complex LU


@_jit_inline
def _lu(Fr, Fi, n, piv, ur, ui):
    """LU factorization with partial pivoting (LAPACK's ``|re| + |im|`` pivot choice) in place.

    ``Fr + j Fi``: ``(n, m)`` row-major with ``m`` a multiple of 8 (padding columns are zero);
    ``ur``, ``ui``: work arrays of length ``m``. Returns False on an exactly zero pivot.
    (Inner loops run on 1-D row views: LLVM vectorizes those, not the 2-D indexing.)
    """
    m = Fr.shape[1]
    for k in range(n):
        p = k
        best = -1.0
        for i in range(k, n):
            v = abs(Fr[i, k]) + abs(Fi[i, k])
            if v > best:
                best = v
                p = i
        piv[k] = p
        if p != k:
            xr = Fr[k]
            xi = Fi[k]
            yr = Fr[p]
            yi = Fi[p]
            for j in range(m):
                t = xr[j]
                xr[j] = yr[j]
                yr[j] = t
                t = xi[j]
                xi[j] = yi[j]
                yi[j] = t
        dr = Fr[k, k]
        di = Fi[k, k]
        if dr == 0.0 and di == 0.0:
            return False
        # 1 / pivot, scaled against overflow and underflow
        s = max(abs(dr), abs(di))
        er = dr / s
        ei = di / s
        e2 = er * er + ei * ei
        ir = er / e2 / s
        ii = -ei / e2 / s
        j0 = ((k + 1) // 8) * 8  # aligned start: the pivot row copy is zero up to column k
        xr = Fr[k]
        xi = Fi[k]
        for j in range(j0, m):
            ur[j] = xr[j] if j > k else 0.0
            ui[j] = xi[j] if j > k else 0.0
        vr = ur[j0:]
        vi = ui[j0:]
        L = m - j0
        for i in range(k + 1, n):
            lr = Fr[i, k] * ir - Fi[i, k] * ii
            li = Fr[i, k] * ii + Fi[i, k] * ir
            rr = Fr[i, j0:]
            ri = Fi[i, j0:]
            for j in range(L):
                rr[j] -= lr * vr[j] - li * vi[j]
                ri[j] -= lr * vi[j] + li * vr[j]
            Fr[i, k] = lr
            Fi[i, k] = li
    return True


@_jit_inline
def _swap_pivots(piv, n, xr, xi, forward):
    """Apply the row interchanges of :func:`_lu` to ``x`` (``forward``: ``P^T x``)."""
    for kk in range(n):
        k = kk if forward else n - 1 - kk
        p = piv[k]
        if p != k:
            t = xr[k]
            xr[k] = xr[p]
            xr[p] = t
            t = xi[k]
            xi[k] = xi[p]
            xi[p] = t


@_jit_inline
def _lu_solve(Fr, Fi, n, piv, xr, xi):
    """Solve ``F x = b`` in place (``b`` in ``xr + j xi``) with the factors of :func:`_lu`."""
    _swap_pivots(piv, n, xr, xi, True)
    for i in range(n):  # L y = P^T b (unit diagonal)
        fr = Fr[i]
        fi = Fi[i]
        sr = xr[i]
        si = xi[i]
        for j in range(i):
            sr -= fr[j] * xr[j] - fi[j] * xi[j]
            si -= fr[j] * xi[j] + fi[j] * xr[j]
        xr[i] = sr
        xi[i] = si
    for i in range(n - 1, -1, -1):  # U x = y
        fr = Fr[i]
        fi = Fi[i]
        sr = xr[i]
        si = xi[i]
        for j in range(i + 1, n):
            sr -= fr[j] * xr[j] - fi[j] * xi[j]
            si -= fr[j] * xi[j] + fi[j] * xr[j]
        xr[i], xi[i] = _cdiv(sr, si, fr[i], fi[i])


@_jit_inline
def _lu_solve_h(Fr, Fi, n, piv, xr, xi, tr, ti):
    """Solve ``F^* x = b`` in place with the factors of :func:`_lu` (``tr``, ``ti``: work).

    ``F = P L U``: ``U^* y = b``, ``L^* v = y``, ``x = P v`` (both triangular solves by
    columns of ``U^*`` and ``L^*``, i.e. rows of ``U`` and ``L``).
    """
    for i in range(n):
        tr[i] = 0.0
        ti[i] = 0.0
    for i in range(n):  # U^* is lower triangular
        fr = Fr[i]
        fi = Fi[i]
        yr, yi = _cdiv(xr[i] - tr[i], xi[i] - ti[i], fr[i], -fi[i])
        xr[i] = yr
        xi[i] = yi
        for j in range(i + 1, n):  # t_j += conj(U_ij) y_i
            tr[j] += fr[j] * yr + fi[j] * yi
            ti[j] += fr[j] * yi - fi[j] * yr
    for i in range(n):
        tr[i] = 0.0
        ti[i] = 0.0
    for i in range(n - 1, -1, -1):  # L^* is unit upper triangular
        fr = Fr[i]
        fi = Fi[i]
        yr = xr[i] - tr[i]
        yi = xi[i] - ti[i]
        xr[i] = yr
        xi[i] = yi
        for j in range(i):  # t_j += conj(L_ij) y_i
            tr[j] += fr[j] * yr + fi[j] * yi
            ti[j] += fr[j] * yi - fi[j] * yr
    _swap_pivots(piv, n, xr, xi, False)


@_jit_inline
def _cdiv(ar, ai, br, bi):
    """``(ar + j ai) / (br + j bi)`` (Smith's scaling)."""
    if abs(br) >= abs(bi):
        if br == 0.0:
            return ar / br, ai / br  # inf or nan, as numpy
        t = bi / br
        d = br + bi * t
        return (ar + ai * t) / d, (ai - ar * t) / d
    t = br / bi
    d = br * t + bi
    return (ar * t + ai) / d, (ai * t - ar) / d


@_jit_inline
def _rayleigh(Dr, Di, n, ar, ai):
    """``a^* D a`` (``D``: ``(n, m)`` split and zero-padded, ``a`` of length ``m``)."""
    lr = 0.0
    li = 0.0
    m = Dr.shape[1]
    for q in range(n):
        dr = Dr[q]
        di = Di[q]
        sr = 0.0
        si = 0.0
        for i in range(m):
            sr += dr[i] * ar[i] - di[i] * ai[i]
            si += dr[i] * ai[i] + di[i] * ar[i]
        lr += ar[q] * sr + ai[q] * si
        li += ar[q] * si - ai[q] * sr
    return lr + 1j * li


@_jit_inline
def _shifted_lu(Dr, Di, n, lam, Fr, Fi, piv, ur, ui):
    """Factor ``D - s I`` with the shift ``s = lam (1 + 1e-10) + 1e-14`` of ``mu_lower``."""
    Fr[:, :] = Dr
    Fi[:, :] = Di
    for i in range(n):
        Fr[i, i] -= lam.real * (1 + 1e-10) + 1e-14
        Fi[i, i] -= lam.imag * (1 + 1e-10)
    return _lu(Fr, Fi, n, piv, ur, ui)


@_jit_inline
def _finite_normalize(xr, xi, ar, ai, n):
    """``a = x / ||x||`` with the entries of ``x`` that are not finite taken from ``a``."""
    nrm = 0.0
    for i in range(n):
        if not (math.isfinite(xr[i]) and math.isfinite(xi[i])):
            xr[i] = ar[i]
            xi[i] = ai[i]
        nrm += xr[i] * xr[i] + xi[i] * xi[i]
    nrm = max(math.sqrt(nrm), 1e-300)
    for i in range(n):
        ar[i] = xr[i] / nrm
        ai[i] = xi[i] / nrm


@_jit_inline
def _inverse_iteration(Dr, Di, n, ar, ai, steps, Fr, Fi, piv, ur, ui, xr, xi):
    """``oracles.polish_eigenvalue`` for one matrix (in place on ``a``); returns ``lam``."""
    lam = _rayleigh(Dr, Di, n, ar, ai)
    for _ in range(steps):
        if not _shifted_lu(Dr, Di, n, lam, Fr, Fi, piv, ur, ui):
            break
        xr[:n] = ar[:n]
        xi[:n] = ai[:n]
        _lu_solve(Fr, Fi, n, piv, xr, xi)
        _finite_normalize(xr, xi, ar, ai, n)
        lam = _rayleigh(Dr, Di, n, ar, ai)
    return lam


@_jit_inline
def _form_md(Mr, Mi, db, kind, rows, cols, roff, coff, row_of, cblk_of, vr, vi, Dr, Di):
    """``D = M delta`` block by block (``Dr + j Di``: ``(c, m)``, padding left at zero).

    ``row_of``, ``cblk_of``: see :func:`_scalar_maps`; ``vr``, ``vi``: work arrays of length
    ``c`` (the diagonal of the scalar blocks).
    """
    n = Dr.shape[0]
    nblk = kind.size
    for j in range(n):
        if cblk_of[j] < nblk:
            v = db[row_of[j], j]
            vr[j] = v.real
            vi[j] = v.imag
        else:
            vr[j] = 0.0
            vi[j] = 0.0
    for p in range(n):
        mr = Mr[p]
        mi = Mi[p]
        dr = Dr[p]
        di = Di[p]
        for j in range(n):
            xr = mr[row_of[j]]
            xi = mi[row_of[j]]
            dr[j] = xr * vr[j] - xi * vi[j]
            di[j] = xr * vi[j] + xi * vr[j]
        for k in range(kind.size):
            if kind[k] == 2:
                for q in range(cols[k]):
                    sr = 0.0
                    si = 0.0
                    for i in range(rows[k]):
                        v = db[roff[k] + i, coff[k] + q]
                        xr = mr[roff[k] + i]
                        xi = mi[roff[k] + i]
                        sr += xr * v.real - xi * v.imag
                        si += xr * v.imag + xi * v.real
                    dr[coff[k] + q] = sr
                    di[coff[k] + q] = si


@_jit_fast
def eigen_polish(M, mat, delta, a, blocks, rounds, steps, lam):
    """Eigenvalue polish of ``M delta`` (``oracles.polish_eigenvalue``) and, with
    ``rounds > 0``, the search for a real eigenvalue (``oracles.make_eigenvalue_real``).

    Parameters
    ----------
    M : complex array (nb, c, r)
    mat : int array (N,)
        The matrix ``M[mat[s]]`` of each candidate ``s``.
    delta : complex array (N, r, c)
        Perturbations in the block structure; with ``rounds > 0`` updated in place.
    a : complex array (N, c)
        Eigenvector estimates of ``M delta``; replaced by the polished right eigenvectors.
    blocks : int array (5, n_blocks)
        kind (0 real, 1 repeated complex, 2 full), rows, cols, row offset, column offset.
    rounds : int
        0: inverse iteration only (``polish_eigenvalue(M delta, a, steps)``); otherwise the
        Newton rounds of ``make_eigenvalue_real(..., steps=rounds)`` (each with ``steps``
        inverse iteration steps).
    steps : int
        Inverse iteration steps per polish.
    lam : complex array (N,)
        Output: the eigenvalue of ``M delta`` tracked from ``a``.
    """
    N = delta.shape[0]
    c, r = M.shape[1], M.shape[2]
    kind, rows, cols, roff, coff = blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]
    nblk = kind.size
    n = c
    mp = -(-n // 8) * 8
    rp = -(-r // 8) * 8
    row_of, cblk_of = _scalar_maps(kind, rows, roff, coff, r, c)[2:]
    Mr = np.zeros((n, rp))
    Mi = np.zeros((n, rp))
    Dr = np.zeros((n, mp))
    Di = np.zeros((n, mp))
    Fr = np.zeros((n, mp))
    Fi = np.zeros((n, mp))
    piv = np.zeros(n, dtype=np.int64)
    ur = np.zeros(mp)
    ui = np.zeros(mp)
    ar = np.zeros(mp)
    ai = np.zeros(mp)
    zr = np.zeros(mp)
    zi = np.zeros(mp)
    xr = np.zeros(mp)
    xi = np.zeros(mp)
    wr = np.zeros(rp)
    wi = np.zeros(rp)
    C = np.zeros(nblk + 1)
    loaded = -1
    for b in range(N):
        Mb = M[mat[b]]
        db = delta[b]
        for q in range(n):
            ar[q] = a[b, q].real
            ai[q] = a[b, q].imag
            zr[q] = ar[q]  # the left vector starts from the input vector
            zi[q] = ai[q]
        if mat[b] != loaded:
            loaded = mat[b]
            for q in range(n):
                mr = Mr[q]
                mi = Mi[q]
                for i in range(r):
                    mr[i] = Mb[q, i].real
                    mi[i] = Mb[q, i].imag
        for rnd in range(max(rounds, 0) + 1):
            _form_md(Mr, Mi, db, kind, rows, cols, roff, coff, row_of, cblk_of, xr, xi, Dr, Di)
            lb = _inverse_iteration(Dr, Di, n, ar, ai, steps, Fr, Fi, piv, ur, ui, xr, xi)
            lam[b] = lb
            if rounds <= 0 or rnd == rounds or abs(lb.imag) <= 1e-13 * abs(lb):
                break
            # left eigenvector: inverse iteration on (M delta)^*, one factorization
            if _shifted_lu(Dr, Di, n, lb, Fr, Fi, piv, ur, ui):
                for _k in range(2):
                    xr[:n] = zr[:n]
                    xi[:n] = zi[:n]
                    _lu_solve_h(Fr, Fi, n, piv, xr, xi, ur, ui)
                    _finite_normalize(xr, xi, zr, zi, n)
            zar = 0.0
            zai = 0.0
            for q in range(n):
                zar += zr[q] * ar[q] + zi[q] * ai[q]
                zai += zr[q] * ai[q] - zi[q] * ar[q]
            za = zar + 1j * zai
            if not abs(za) > 1e-300:
                za = 1e-300 + 0.0j
            _mhv(Mr, Mi, zr, zi, wr, wi)  # w = M^* z
            nc = 0
            h = 0.0j
            has_c = False
            for k in range(nblk):
                ipr = 0.0
                ipi = 0.0
                for i in range(rows[k]):  # w_k^* (delta_k a_k) (real blocks: w_k^* a_k)
                    if kind[k] == 0:
                        dar = ar[coff[k] + i]
                        dai = ai[coff[k] + i]
                    else:
                        dar = 0.0
                        dai = 0.0
                        q0 = 0 if kind[k] == 2 else i
                        q1 = cols[k] if kind[k] == 2 else i + 1
                        for q in range(q0, q1):
                            v = db[roff[k] + i, coff[k] + q]
                            dar += v.real * ar[coff[k] + q] - v.imag * ai[coff[k] + q]
                            dai += v.real * ai[coff[k] + q] + v.imag * ar[coff[k] + q]
                    ipr += wr[roff[k] + i] * dar + wi[roff[k] + i] * dai
                    ipi += wr[roff[k] + i] * dai - wi[roff[k] + i] * dar
                g = (ipr + 1j * ipi) / za
                if kind[k] == 0:
                    C[nc] = g.imag if abs(db[roff[k], coff[k]].real) < 1.0 - 1e-12 else 0.0
                    nc += 1
                else:
                    has_c = True
                    h += g
            if has_c:
                C[nc] = h.real  # Im(j h): d lam / d phase = j h
                nc += 1
            c2 = 1e-300
            for j in range(nc):
                c2 += C[j] * C[j]
            fac = -lb.imag / c2
            nstep = 0.0
            for j in range(nc):
                C[j] = fac * C[j]
                nstep += C[j] * C[j]
            sc = min(1.0, 0.2 / max(math.sqrt(nstep), 1e-300))
            j = 0
            for k in range(nblk):
                if kind[k] == 0:
                    dn = min(max(db[roff[k], coff[k]].real + sc * C[j], -1.0), 1.0)
                    for i in range(rows[k]):
                        db[roff[k] + i, coff[k] + i] = dn
                    j += 1
            if has_c:
                t = sc * C[nc - 1]
                rot = math.cos(t) + 1j * math.sin(t)
                for k in range(nblk):
                    if kind[k] != 0:
                        for i in range(rows[k]):
                            for q in range(cols[k]):
                                db[roff[k] + i, coff[k] + q] *= rot
        for q in range(n):
            a[b, q] = ar[q] + 1j * ai[q]


# --------------------------------------------------------------------------------------------
# certificate and start selection


@_jit
def _delta_times(db, kind, rows, cols, roff, coff, x, out):
    """``out = delta x`` for a dense ``delta`` (r x c) in the block structure."""
    for k in range(kind.size):
        for i in range(rows[k]):
            if kind[k] == 2:
                acc = 0.0j
                for q in range(cols[k]):
                    acc += db[roff[k] + i, coff[k] + q] * x[coff[k] + q]
                out[roff[k] + i] = acc
            else:
                out[roff[k] + i] = db[roff[k] + i, coff[k] + i] * x[coff[k] + i]


@_jit
def rayleigh_quotients(M, delta, a, blocks, out):
    """``a^* M delta a`` for each start (``M[s % nb]``, see :func:`power_iteration`).

    Parameters
    ----------
    M : complex array (nb, c, r)
    delta : complex array (N, r, c)
        Perturbations in the block structure.
    a : complex array (N, c)
    blocks : int array (5, n_blocks)
    out : complex array (N,)
    """
    nb, c, r = M.shape
    kind, rows, cols, roff, coff = blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]
    da = np.empty(r, dtype=np.complex128)
    for s in range(delta.shape[0]):
        Mb = M[s % nb]
        _delta_times(delta[s], kind, rows, cols, roff, coff, a[s], da)
        acc = 0.0j
        for q in range(c):
            mda = 0.0j
            for i in range(r):
                mda += Mb[q, i] * da[i]
            acc += np.conj(a[s, q]) * mda
        out[s] = acc


@_jit
def vector_residual(M, mat, delta, a, blocks, out):
    """``oracles.vector_residual``: ``||a - M delta a|| / ||a|| / (1 + ||M delta a|| / ||a||)``,
    an upper bound of ``sigma_min(I - M delta) / (1 + ||M delta||_2)``.

    Parameters
    ----------
    M : complex array (nb, c, r)
    mat : int array (N,)
        The matrix ``M[mat[s]]`` of each candidate.
    delta : complex array (N, r, c)
        Perturbations in the block structure.
    a : complex array (N, c)
    blocks : int array (5, n_blocks)
    out : float array (N,)
    """
    c, r = M.shape[1], M.shape[2]
    kind, rows, cols, roff, coff = blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]
    da = np.empty(r, dtype=np.complex128)
    for s in range(delta.shape[0]):
        Mb = M[mat[s]]
        _delta_times(delta[s], kind, rows, cols, roff, coff, a[s], da)
        na = 0.0
        nm = 0.0
        nd = 0.0
        for q in range(c):
            mda = 0.0j
            for i in range(r):
                mda += Mb[q, i] * da[i]
            x = a[s, q]
            na += x.real * x.real + x.imag * x.imag
            nm += mda.real * mda.real + mda.imag * mda.imag
            e = x - mda
            nd += e.real * e.real + e.imag * e.imag
        na = max(math.sqrt(na), 1e-300)
        out[s] = (math.sqrt(nd) / na) / (1.0 + math.sqrt(nm) / na)


@_jit
def max_block_norms(delta, blocks, out, inexact):
    """``max_k ||Delta_k||_2`` of each perturbation (``mu_lower._max_block_norm``).

    Repeated blocks: the largest modulus on their diagonal. Full blocks: ``||B||_F``, exact
    for the rank-one blocks of the power iteration (``||B||_2 = ||B||_F`` there); a block
    with ``||B||_F^2 - ||B^* B||_F > 1e-13 ||B||_F^2`` is not rank one to round-off and marks
    its perturbation in ``inexact`` (the caller takes an SVD there).

    Parameters
    ----------
    delta : complex array (N, r, c)
    blocks : int array (5, n_blocks)
    out : float array (N,)
    inexact : bool array (N,)
    """
    kind, rows, cols, roff, coff = blocks[0], blocks[1], blocks[2], blocks[3], blocks[4]
    for s in range(delta.shape[0]):
        d = delta[s]
        best = 0.0
        seen = 0.0  # NaN if any entry is (propagated as np.max does)
        bad = False
        for k in range(kind.size):
            ro, co = roff[k], coff[k]
            if kind[k] != 2:
                for i in range(rows[k]):
                    v = abs(d[ro + i, co + i])
                    seen += v
                    best = max(best, v)
                continue
            m, n = rows[k], cols[k]
            fro2 = 0.0
            for i in range(m):
                for q in range(n):
                    x = d[ro + i, co + q]
                    fro2 += x.real * x.real + x.imag * x.imag
            g2 = 0.0  # ||B^* B||_F^2
            for p in range(n):
                for q in range(n):
                    acc = 0.0j
                    for i in range(m):
                        acc += np.conj(d[ro + i, co + p]) * d[ro + i, co + q]
                    g2 += acc.real * acc.real + acc.imag * acc.imag
            if fro2 - math.sqrt(g2) > 1e-13 * fro2:
                bad = True
            seen += fro2
            best = max(best, math.sqrt(fro2))
        out[s] = best if seen == seen else np.nan
        inexact[s] = bad
