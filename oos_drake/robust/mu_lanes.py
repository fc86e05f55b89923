r"""The D-G upper bound optimizer, compiled, eight matrices in lock-step (one per SIMD lane).

The one compiled D-G optimizer of the product. :func:`dg_minimize_lanes` runs the algorithm of
``mu_upper.mu_upper_bound`` (smoothed ``lambda_max``, temperature stages, L-BFGS with Armijo
backtracking, patience stopping; its numpy version, ``tests/robust/oracles.py``, is the test
oracle) on every matrix
of a batch of any size, eight at a time (lanes without a matrix idle): each lane runs its own
optimizer (a small state machine that asks for the next point to evaluate) and one evaluation
serves the eight lanes.
The linear algebra of an evaluation then works on 8-vectors, one entry per matrix, which the
compiler maps onto SIMD registers (AVX-512: one register; AVX2: two) instead of the short,
latency-bound loops of one 26 x 26 problem:

* ``H = Mh^* Mh + j (Y X - (Y X)^*)`` (lower triangle, real and imaginary parts apart);
* Householder tridiagonalization of ``H`` (the arithmetic of LAPACK's ``zhetd2``);
* all eigenvalues by implicit symmetric QR with Wilkinson shifts, chasing the bulges of the
  eight tridiagonals in one loop (each lane deflates its own bottom rows; a lane that is done,
  or whose active block does not cover position ``k``, applies the identity). The rotations
  are recorded and applied afterwards only to the unit vectors of the top eigenvalues, then
  the Householder reflectors (eigenvectors of the top eigenvalues);
* the gradient of :func:`mu_kernels.dg_objective`.

Kernel arguments are grouped in named tuples (numba passes them to compiled code as structs):
the layout of the structure (:data:`LaneLayout`), the optimizer's options
(:data:`LaneOptions`) and the work arrays (:data:`LaneWorkspace`). The line-search constants
(:data:`ARMIJO`, ...) are defined here once.

An eight-lane evaluation costs the same whatever the number of busy lanes (about three
per-matrix evaluations inside the optimizer, four in isolation). With at most
``LaneOptions.per_matrix_lanes`` busy lanes (a lone matrix, a small batch, the tail of a
batch) the optimizer evaluates them one by one instead, with the
per-matrix kernel :func:`mu_kernels.dg_objective` (the same function, scalar code):
one optimizer, its state machine, line search and stopping rules unchanged, two evaluators.

The 8-vectors are tuples handled by the small helpers below (``_ld``, ``_fma``, ..., inlined):
tuples are values, not memory, so all loads of a step come before its stores and LLVM's SLP
vectorizer can pack them (numba leaves it off by default: :func:`compile_with_slp`). A lane
whose QR does not converge within the step budget (never seen) is evaluated again by the
per-matrix kernel :func:`mu_kernels.dg_objective` (``zheevd`` fallback). Whatever the
optimizer does, ``mu_upper.certified_upper`` proves the returned bound at the returned
scalings (an LMI check with a bounded round-off, raising the bound where needed).
"""

from __future__ import annotations

import contextlib
from collections import namedtuple

import numba
import numpy as np

from oos_drake.robust import mu_kernels
from oos_drake.robust.mu_kernels import QR_STEP_BUDGET, WEIGHT_FLOOR

#: Matrices evaluated together (8 doubles: one AVX-512 register).
W = 8
_FM = {"reassoc", "contract", "nsz", "arcp"}

# The line search of the D-G optimizer, defined once: the lanes here and the numpy oracle of
# the tests read these (numba freezes them into the compiled code: edit, then recompile).
#: Armijo sufficient-decrease constant.
ARMIJO = 1e-4
#: Factor by which a rejected step is shortened.
BACKTRACK = 0.3
#: Trial steps per line search (the unit step and its shortenings).
MAX_TRIALS = 12
#: Largest change of a log-scaling per iteration (``e^{+-2}``: larger steps never help).
MAX_LOG_STEP = 2.0
#: Failed line searches in a row after which a matrix's stage stops.
MAX_FAILED_SEARCHES = 3
#: A curvature pair ``(s, y)`` is kept if ``s.y > CURVATURE_FLOOR |s| |y|``.
CURVATURE_FLOOR = 1e-14
#: Stage budget: ``max(max_iter // n_stages, min(max_iter, MIN_STAGE_ITERATIONS))``.
MIN_STAGE_ITERATIONS = 5

# error_model="numpy": no zero-check branch on every division (it blocks vectorization)
_jit = numba.njit(cache=True, nogil=True, fastmath=_FM, error_model="numpy")
# helpers: LLVM inlines them (numba's own inline="always" compiles 1.5x slower, runs slower)
_vec = numba.njit(fastmath=_FM, error_model="numpy")
_jit_exact = numba.njit(cache=True, nogil=True, error_model="numpy")
# the L-BFGS recursion: exact arithmetic, dot products reassociated (vectorized)
_jit_lbfgs = numba.njit(cache=True, nogil=True)
_jit_dot = numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})


#: The parameter layout of one BLK for the lane kernels (built by :func:`lane_layout`; index
#: arrays are int64, one entry per item). ``T = diag(e^s) (I + N)`` per diagonal block.
LaneLayout = namedtuple(
    "LaneLayout",
    [
        "n_entries",  # number of distinct entries of T (int)
        "log_par",  # parameters that are the log of a diagonal entry of T ...
        "log_ent",  # ... and that entry
        "re_par",  # parameters that are Re / Im of an off-diagonal entry of N ...
        "im_par",
        "lin_ent",  # ... that entry
        "lin_row",  # ... and the log-parameter of its row
        "l_row",  # position (row, column) in T_l of each of its entries, and the entry
        "l_col",
        "l_ent",
        "r_row",  # the same in T_r
        "r_col",
        "r_ent",
        "rb_start",  # diagonal blocks of T_r: first row and size
        "rb_size",
        "g_row",  # positions of the entries of G (row in r-space, column in c-space)
        "g_col",
        "gq_par",  # each G parameter feeds one or two positions of G (index into g_row,
        "gq_pos1",  # g_col; -1: none) with complex coefficients
        "gq_pos2",
        "gq_coef1",
        "gq_coef2",
        "row_block_start",  # per r-space row: first row and size of its diagonal block
        "row_block_size",
        "col_block_start",  # per c-space row: first row of its diagonal block
        "row_g_col",  # per r-space row: first column of its real block's G (and its size;
        "row_g_size",  # 0: not a real block)
        "max_block",  # largest diagonal block (int): width of the row storage
        "c_blocks",  # diagonal blocks of T_l (2, n): start, size (mu_kernels.dg_objective)
        "real_blocks",  # real blocks (3, n): row offset, column offset, size (the same)
    ],
)

#: Options of :func:`dg_minimize_lanes` (see ``mu_upper.mu_upper_bound``).
LaneOptions = namedtuple(
    "LaneOptions",
    [
        "temperatures",  # (n_stages,) float: smoothing temperatures relative to the bound
        "max_iter",  # int: L-BFGS iterations in total
        "tol",  # (n_stages,) float: relative decrease counted as a stall, per stage
        "patience",  # int: stalls in a row that end a stage
        "memory",  # int: L-BFGS correction pairs
        "chain",  # bool: continuation along the batch
        "chain_temperatures",  # (n,) float: stages of a chained matrix
        "chain_patience",  # int
        "size_weight",  # float: weight of ||M_hat||_F^2 in the value that picks the best point
        "per_matrix_lanes",  # int: with at most this many busy lanes, evaluate them one by one
    ],
    # one eight-lane evaluation costs about three per-matrix ones in the optimizer (26 x 26,
    # AVX-512; benchmarks/bench_mussv.py): 3 is the break-even; 0: always the eight lanes
    defaults=(3,),
)

#: Work arrays of :func:`_lane_eval` (eight lanes in the last axis; ``_re``/``_im``: real and
#: imaginary parts). Block-diagonal matrices are stored by rows (``T[i, j - start(i)]``).
LaneWorkspace = namedtuple(
    "LaneWorkspace",
    [
        "tl_re", "tl_im",  # T_l (c, max_block)
        "tri_re", "tri_im",  # T_r^{-1} (r, max_block)
        "tr_re", "tr_im",  # T_r (r, max_block)
        "g_re", "g_im",  # G (r, max_block)
        "ent_re", "ent_im",  # entries of T (n_entries)
        "x_re", "x_im",  # X = M T_r^{-1} (c, r)
        "mht_re", "mht_im",  # Mh = T_l X, transposed (r, c)
        "gx_re", "gx_im",  # G X on the rows of real blocks (r, r)
        "h_re", "h_im",  # H, then the Householder reflectors (n, n)
        "diag", "offdiag",  # the tridiagonal (n), then the eigenvalues in diag
        "tau_re", "tau_im",  # Householder scalars (n)
        "p_re", "p_im", "v_re", "v_im",  # tridiagonalization scratch (n)
        "rot_row", "rot_cos", "rot_sin",  # QR rotations, recorded (QR_STEP_BUDGET n^2 + n)
        "qr_lo", "qr_hi", "qr_x", "qr_z", "qr_ok",  # QR state per lane
        "top_index",  # indices of the top eigenvalues (n)
        "top_weight",  # their weights in the smoothed maximum (n)
        "top_lam",  # their values (n)
        "vec_re", "vec_im",  # their eigenvectors (n, n)
        "tv_re", "tv_im",  # T_r^{-1} V (n, r)
        "xv_re", "xv_im",  # M T_r^{-1} V (n, c)
        "mv_re", "mv_im",  # T_l M T_r^{-1} V (n, c)
        "grad_t_re", "grad_t_im",  # gradient with respect to the entries of T (n_entries)
        "size",  # ||M_hat||_F^2 per lane (8)
    ],
)  # fmt: skip


@contextlib.contextmanager
def compile_with_slp():
    """Turn on LLVM's SLP vectorizer while the lane kernels compile (numba's default is off;
    the cached machine code keeps it). Process-wide for the duration: other code compiled
    meanwhile only gets the same, semantics-preserving, optimization."""
    old = numba.config.SLP_VECTORIZE
    numba.config.SLP_VECTORIZE = 1
    try:
        yield
    finally:
        numba.config.SLP_VECTORIZE = old


# -- 8-vector helpers (tuples of 8 floats; inlined by LLVM) --------------------------------------


@_vec
def _ld(a):
    return (a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7])


@_vec
def _st(a, v):
    a[0] = v[0]
    a[1] = v[1]
    a[2] = v[2]
    a[3] = v[3]
    a[4] = v[4]
    a[5] = v[5]
    a[6] = v[6]
    a[7] = v[7]


@_vec
def _splat(s):
    return (s, s, s, s, s, s, s, s)


@_vec
def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2], a[3] + b[3],
            a[4] + b[4], a[5] + b[5], a[6] + b[6], a[7] + b[7])  # fmt: skip


@_vec
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2], a[3] - b[3],
            a[4] - b[4], a[5] - b[5], a[6] - b[6], a[7] - b[7])  # fmt: skip


@_vec
def _mul(a, b):
    return (a[0] * b[0], a[1] * b[1], a[2] * b[2], a[3] * b[3],
            a[4] * b[4], a[5] * b[5], a[6] * b[6], a[7] * b[7])  # fmt: skip


@_vec
def _div(a, b):
    return (a[0] / b[0], a[1] / b[1], a[2] / b[2], a[3] / b[3],
            a[4] / b[4], a[5] / b[5], a[6] / b[6], a[7] / b[7])  # fmt: skip


@_vec
def _fma(a, b, c):
    """``a b + c``."""
    return (a[0] * b[0] + c[0], a[1] * b[1] + c[1], a[2] * b[2] + c[2],
            a[3] * b[3] + c[3], a[4] * b[4] + c[4], a[5] * b[5] + c[5],
            a[6] * b[6] + c[6], a[7] * b[7] + c[7])  # fmt: skip


@_vec
def _fnma(a, b, c):
    """``c - a b``."""
    return (c[0] - a[0] * b[0], c[1] - a[1] * b[1], c[2] - a[2] * b[2],
            c[3] - a[3] * b[3], c[4] - a[4] * b[4], c[5] - a[5] * b[5],
            c[6] - a[6] * b[6], c[7] - a[7] * b[7])  # fmt: skip


@_vec
def _sqrt(a):
    return (np.sqrt(a[0]), np.sqrt(a[1]), np.sqrt(a[2]), np.sqrt(a[3]),
            np.sqrt(a[4]), np.sqrt(a[5]), np.sqrt(a[6]), np.sqrt(a[7]))  # fmt: skip


@_vec
def _sel(m, a, b):
    """``a`` where the mask ``m`` is true, else ``b``."""
    return (a[0] if m[0] else b[0], a[1] if m[1] else b[1], a[2] if m[2] else b[2],
            a[3] if m[3] else b[3], a[4] if m[4] else b[4], a[5] if m[5] else b[5],
            a[6] if m[6] else b[6], a[7] if m[7] else b[7])  # fmt: skip


@_vec
def _cmac(ar, ai, br, bi, cr, ci):
    """``c + a b`` (complex 8-vectors as real and imaginary tuples)."""
    return _fnma(ai, bi, _fma(ar, br, cr)), _fma(ai, br, _fma(ar, bi, ci))


@_vec
def _cjmac(ar, ai, br, bi, cr, ci):
    """``c + conj(a) b``."""
    return _fma(ai, bi, _fma(ar, br, cr)), _fnma(ai, br, _fma(ar, bi, ci))


@_vec
def _neg(a):
    return (-a[0], -a[1], -a[2], -a[3], -a[4], -a[5], -a[6], -a[7])


@_vec
def _mcopysign(a, b):
    """``-copysign(a, b)``."""
    return (-np.copysign(a[0], b[0]), -np.copysign(a[1], b[1]), -np.copysign(a[2], b[2]),
            -np.copysign(a[3], b[3]), -np.copysign(a[4], b[4]), -np.copysign(a[5], b[5]),
            -np.copysign(a[6], b[6]), -np.copysign(a[7], b[7]))  # fmt: skip


@_vec
def _both_zero(a, b):
    return (a[0] == 0.0 and b[0] == 0.0, a[1] == 0.0 and b[1] == 0.0,
            a[2] == 0.0 and b[2] == 0.0, a[3] == 0.0 and b[3] == 0.0,
            a[4] == 0.0 and b[4] == 0.0, a[5] == 0.0 and b[5] == 0.0,
            a[6] == 0.0 and b[6] == 0.0, a[7] == 0.0 and b[7] == 0.0)  # fmt: skip


@_vec
def _in_block(lo, hi, k):
    """Lanes whose active block ``[lo, hi]`` has a rotation at position ``k``."""
    return (lo[0] <= k < hi[0], lo[1] <= k < hi[1], lo[2] <= k < hi[2],
            lo[3] <= k < hi[3], lo[4] <= k < hi[4], lo[5] <= k < hi[5],
            lo[6] <= k < hi[6], lo[7] <= k < hi[7])  # fmt: skip


@_vec
def _past_start(act, lo, k):
    """Active lanes for which ``k`` is past the start of the block (a bulge is chased)."""
    return (act[0] and k > lo[0], act[1] and k > lo[1], act[2] and k > lo[2],
            act[3] and k > lo[3], act[4] and k > lo[4], act[5] and k > lo[5],
            act[6] and k > lo[6], act[7] and k > lo[7])  # fmt: skip


@_vec
def _positive(act, a):
    return (act[0] and a[0] > 0.0, act[1] and a[1] > 0.0, act[2] and a[2] > 0.0,
            act[3] and a[3] > 0.0, act[4] and a[4] > 0.0, act[5] and a[5] > 0.0,
            act[6] and a[6] > 0.0, act[7] and a[7] > 0.0)  # fmt: skip


# -- evaluation kernels ---------------------------------------------------------------------


@_jit
def _row_starts(n, starts, sizes):
    """Per row: the first row of its diagonal block (blocks given by ``starts``, ``sizes``)."""
    out = np.arange(n)
    for b in range(starts.size):
        for i in range(starts[b], starts[b] + sizes[b]):
            out[i] = starts[b]
    return out


@_jit
def _scatter_rows(rows, cols, ents, starts, Er, Ei, Tr_, Ti_):
    """Block-diagonal ``T`` stored by rows (``T[i, j] = T_[i, j - starts[i]]``) from its entry
    values ``E`` (n_ent, 8) and the positions ``(rows, cols, ents)`` of the layout."""
    Tr_[:] = 0.0
    Ti_[:] = 0.0
    for k in range(rows.size):
        i = rows[k]
        q = cols[k] - starts[i]
        _st(Tr_[i, q], _ld(Er[ents[k]]))
        _st(Ti_[i, q], _ld(Ei[ents[k]]))


@_jit
def _lane_scalings(x, lay, ws):
    """``T_l``, ``T_r^{-1}`` and ``G`` of the eight lanes from the parameters ``x`` (p, 8), into
    the workspace ``ws`` (:data:`LaneWorkspace`; ``lay``: :data:`LaneLayout`).

    Block-diagonal matrices are stored by rows: ``T[i, j] = T_[i, j - start(i)]`` for ``j`` in
    the block of row ``i``; ``G`` likewise (from the first column of the row's real block).
    ``ent_re, ent_im`` receive the entries of ``T`` (n_ent, 8).
    """
    log_par, log_ent, lin_ent, lin_row = lay.log_par, lay.log_ent, lay.lin_ent, lay.lin_row
    re_par, im_par, rb_start, rb_size = lay.re_par, lay.im_par, lay.rb_start, lay.rb_size
    g_row, g_col, gq_par = lay.g_row, lay.g_col, lay.gq_par
    gq_pos1, gq_pos2 = lay.gq_pos1, lay.gq_pos2
    rs, cs, gco = lay.row_block_start, lay.col_block_start, lay.row_g_col
    Tlr, Tli, Tir, Tii, Trr, Tri = ws.tl_re, ws.tl_im, ws.tri_re, ws.tri_im, ws.tr_re, ws.tr_im
    Gr, Gi, Er, Ei = ws.g_re, ws.g_im, ws.ent_re, ws.ent_im
    n_gq = gq_par.size
    for k in range(log_par.size):
        for w in range(W):
            Er[log_ent[k], w] = np.exp(min(max(x[log_par[k], w], -60.0), 60.0))
            Ei[log_ent[k], w] = 0.0
    for k in range(lin_ent.size):
        for w in range(W):
            sc = np.exp(min(max(x[lin_row[k], w], -60.0), 60.0))
            Er[lin_ent[k], w] = sc * x[re_par[k], w]
            Ei[lin_ent[k], w] = sc * x[im_par[k], w]
    _scatter_rows(lay.l_row, lay.l_col, lay.l_ent, cs, Er, Ei, Tlr, Tli)
    _scatter_rows(lay.r_row, lay.r_col, lay.r_ent, rs, Er, Ei, Trr, Tri)
    # inverse of each lower-triangular diagonal block of T_r (real positive diagonal)
    Tir[:] = 0.0
    Tii[:] = 0.0
    one = _splat(1.0)
    zero = _splat(0.0)
    for b in range(rb_start.size):
        s, m = rb_start[b], rb_size[b]
        for j in range(s, s + m):
            _st(Tir[j, j - s], _div(one, _ld(Trr[j, j - s])))
            for i in range(j + 1, s + m):
                ar = zero
                ai = zero
                for q in range(j, i):
                    ar, ai = _cmac(
                        _ld(Trr[i, q - s]), _ld(Tri[i, q - s]), _ld(Tir[q, j - s]),
                        _ld(Tii[q, j - s]), ar, ai,
                    )  # fmt: skip
                inv = _div(one, _ld(Trr[i, i - s]))
                _st(Tir[i, j - s], _neg(_mul(ar, inv)))
                _st(Tii[i, j - s], _neg(_mul(ai, inv)))
    Gr[:] = 0.0
    Gi[:] = 0.0
    coef1 = lay.gq_coef1
    coef2 = lay.gq_coef2
    for q in range(n_gq):
        v = _ld(x[gq_par[q]])
        for kk in range(2):
            pos = gq_pos1[q] if kk == 0 else gq_pos2[q]
            if pos < 0:
                continue
            cf = coef1[q] if kk == 0 else coef2[q]
            i, j = g_row[pos], g_col[pos] - gco[g_row[pos]]
            _st(Gr[i, j], _fma(v, _splat(cf.real), _ld(Gr[i, j])))
            _st(Gi[i, j], _fma(v, _splat(cf.imag), _ld(Gi[i, j])))


@_jit
def _lane_form_h(Mr, Mi, lay, ws):
    """Lower triangle of ``H = Mh^* Mh + j (Y X - (Y X)^*)`` for the eight lanes (into
    ``ws.h_re, ws.h_im``), with ``X = M T_r^{-1}``, ``Mh = T_l X`` (kept transposed in
    ``ws.mht_*``) and ``Y = T_r^{-*} G``."""
    rs, rsz, cs = lay.row_block_start, lay.row_block_size, lay.col_block_start
    gco, rgsz = lay.row_g_col, lay.row_g_size
    Tlr, Tli, Tir, Tii, Gr, Gi = ws.tl_re, ws.tl_im, ws.tri_re, ws.tri_im, ws.g_re, ws.g_im
    Xr, Xi, MTr, MTi, GXr, GXi = ws.x_re, ws.x_im, ws.mht_re, ws.mht_im, ws.gx_re, ws.gx_im
    Hr, Hi = ws.h_re, ws.h_im
    c, r, _ = Mr.shape
    zero = _splat(0.0)
    for i in range(c):  # X[i, j] = sum_{k >= j in the block of j} M[i, k] Tinv[k, j]
        for j in range(r):
            s = rs[j]
            xr = zero
            xi = zero
            for k in range(j, s + rsz[j]):
                xr, xi = _cmac(
                    _ld(Mr[i, k]), _ld(Mi[i, k]), _ld(Tir[k, j - s]), _ld(Tii[k, j - s]), xr, xi
                )
            _st(Xr[i, j], xr)
            _st(Xi[i, j], xi)
    for i in range(c):  # Mh[i, j] = sum_{q = cs[i]}^{i} T_l[i, q] X[q, j], stored as MT[j, i]
        s = cs[i]
        for j in range(r):
            yr = zero
            yi = zero
            for q in range(s, i + 1):
                yr, yi = _cmac(
                    _ld(Tlr[i, q - s]), _ld(Tli[i, q - s]), _ld(Xr[q, j]), _ld(Xi[q, j]), yr, yi
                )
            _st(MTr[j, i], yr)
            _st(MTi[j, i], yi)
    for i in range(r):  # H[i, j] = sum_q conj(Mh[q, i]) Mh[q, j]
        for j in range(i + 1):
            sr = zero
            si = zero
            for q in range(c):
                sr, si = _cjmac(
                    _ld(MTr[i, q]), _ld(MTi[i, q]), _ld(MTr[j, q]), _ld(MTi[j, q]), sr, si
                )
            _st(Hr[i, j], sr)
            _st(Hi[i, j], si)
    for i in range(r):  # GX = G X on the rows of the real blocks
        if rgsz[i] == 0:
            continue
        co = gco[i]
        for j in range(r):
            gr = zero
            gi = zero
            for b in range(rgsz[i]):
                gr, gi = _cmac(
                    _ld(Gr[i, b]), _ld(Gi[i, b]), _ld(Xr[co + b, j]), _ld(Xi[co + b, j]), gr, gi
                )
            _st(GXr[i, j], gr)
            _st(GXi[i, j], gi)
    # (Y X)[i, j] = sum_{k >= i in the block} conj(Tinv[k, i]) GX[k, j]: j (Y X)[i, j] goes to
    # H[i, j] and -j conj((Y X)[i, j]) to H[j, i] (each in the stored lower triangle)
    for i in range(r):
        if rgsz[i] == 0:
            continue
        s = rs[i]
        for j in range(r):
            yr = zero
            yi = zero
            for k in range(i, s + rsz[i]):
                yr, yi = _cjmac(
                    _ld(Tir[k, i - s]), _ld(Tii[k, i - s]), _ld(GXr[k, j]), _ld(GXi[k, j]), yr, yi
                )
            if j <= i:
                _st(Hr[i, j], _sub(_ld(Hr[i, j]), yi))
                _st(Hi[i, j], _add(_ld(Hi[i, j]), yr))
            if j >= i:
                _st(Hr[j, i], _sub(_ld(Hr[j, i]), yi))
                _st(Hi[j, i], _sub(_ld(Hi[j, i]), yr))


@_jit
def _lane_tridiag(Ar, Ai, d, e, taur, taui, pr, pi, vr, vi):
    """Householder tridiagonalization of the eight Hermitian matrices (lower triangles of
    ``Ar + j Ai``, (n, n, 8)): ``d``, ``e`` (n, 8; ``e[n-1] = 0``), the reflectors below the
    subdiagonal (``v[0] = 1`` implicit) and ``tau`` (the arithmetic of ``zhetd2``)."""
    n = Ar.shape[0]
    zero = _splat(0.0)
    one = _splat(1.0)
    mhalf = _splat(-0.5)
    for k in range(n - 1):
        o = k + 1
        m = n - o
        ar = _ld(Ar[o, k])
        ai = _ld(Ai[o, k])
        xn = zero
        for i in range(o + 1, n):
            a_r = _ld(Ar[i, k])
            a_i = _ld(Ai[i, k])
            xn = _fma(a_r, a_r, _fma(a_i, a_i, xn))
        _st(d[k], _ld(Ar[k, k]))
        nothing = _both_zero(xn, ai)  # nothing to annihilate: H_k = I
        beta = _mcopysign(_sqrt(_fma(ar, ar, _fma(ai, ai, xn))), ar)
        bs = _sel(nothing, one, beta)
        tr = _sel(nothing, zero, _div(_sub(beta, ar), bs))
        ti = _sel(nothing, zero, _div(_neg(ai), bs))
        _st(taur[k], tr)
        _st(taui[k], ti)
        _st(e[k], _sel(nothing, ar, beta))
        dr = _sub(ar, beta)
        den = _sel(nothing, one, _fma(dr, dr, _mul(ai, ai)))
        hr = _sel(nothing, zero, _div(dr, den))  # 1 / (alpha - beta)
        hi = _sel(nothing, zero, _div(_neg(ai), den))
        _st(vr[0], one)
        _st(vi[0], zero)
        for i in range(1, m):
            xr = _ld(Ar[o + i, k])
            xi = _ld(Ai[o + i, k])
            a_ = _fnma(xi, hi, _mul(xr, hr))
            b_ = _fma(xi, hr, _mul(xr, hi))
            _st(vr[i], a_)
            _st(vi[i], b_)
            _st(Ar[o + i, k], a_)
            _st(Ai[o + i, k], b_)
        for i in range(m):  # p = A22 v from the lower triangle
            _st(pr[i], zero)
            _st(pi[i], zero)
        for i in range(m):
            v_r = _ld(vr[i])
            v_i = _ld(vi[i])
            dg = _ld(Ar[o + i, o + i])
            sr = _mul(dg, v_r)
            si = _mul(dg, v_i)
            for j in range(i):
                a_r = _ld(Ar[o + i, o + j])
                a_i = _ld(Ai[o + i, o + j])
                sr, si = _cmac(a_r, a_i, _ld(vr[j]), _ld(vi[j]), sr, si)
                qr, qi = _cjmac(a_r, a_i, v_r, v_i, _ld(pr[j]), _ld(pi[j]))
                _st(pr[j], qr)
                _st(pi[j], qi)
            _st(pr[i], _add(_ld(pr[i]), sr))
            _st(pi[i], _add(_ld(pi[i]), si))
        hr = zero  # p = tau p, h = p^* v
        hi = zero
        for i in range(m):
            p_r = _ld(pr[i])
            p_i = _ld(pi[i])
            a_ = _fnma(ti, p_i, _mul(tr, p_r))
            b_ = _fma(ti, p_r, _mul(tr, p_i))
            _st(pr[i], a_)
            _st(pi[i], b_)
            hr, hi = _cjmac(a_, b_, _ld(vr[i]), _ld(vi[i]), hr, hi)
        alr = _mul(mhalf, _fnma(ti, hi, _mul(tr, hr)))  # alpha = -tau h / 2
        ali = _mul(mhalf, _fma(ti, hr, _mul(tr, hi)))
        for i in range(m):  # w = p + alpha v
            q_r, q_i = _cmac(alr, ali, _ld(vr[i]), _ld(vi[i]), _ld(pr[i]), _ld(pi[i]))
            _st(pr[i], q_r)
            _st(pi[i], q_i)
        for i in range(m):  # A22 -= v w^* + w v^*
            v_r = _ld(vr[i])
            v_i = _ld(vi[i])
            w_r = _ld(pr[i])
            w_i = _ld(pi[i])
            for j in range(i + 1):
                pjr = _ld(pr[j])
                pji = _ld(pi[j])
                vjr = _ld(vr[j])
                vji = _ld(vi[j])
                re = _fma(w_i, vji, _fma(w_r, vjr, _fma(v_i, pji, _mul(v_r, pjr))))
                im = _fnma(w_r, vji, _fma(w_i, vjr, _fnma(v_r, pji, _mul(v_i, pjr))))
                _st(Ar[o + i, o + j], _sub(_ld(Ar[o + i, o + j]), re))
                _st(Ai[o + i, o + j], _sub(_ld(Ai[o + i, o + j]), im))
    _st(d[n - 1], _ld(Ar[n - 1, n - 1]))
    _st(e[n - 1], zero)


@_jit
def _lane_qr(d, e, rot_k, rot_c, rot_s, lo, hi, x0, z0, ok):
    """All eigenvalues of the eight symmetric tridiagonals ``(d, e)`` (``d`` receives them,
    unsorted) by implicit QR with Wilkinson shifts, in lock-step.

    Step ``q`` rotates rows ``rot_k[q]``, ``rot_k[q] + 1`` of every lane by
    ``(rot_c[q], rot_s[q])`` (the identity where a lane is not active). Returns the number of
    steps; ``ok[w]`` is False for a lane that needed more than ``rot_k.size`` steps.
    """
    n = d.shape[0]
    cap = rot_k.size
    nsteps = 0
    tol = np.empty(W)
    for w in range(W):
        nrm = 0.0
        for i in range(n):
            nrm = max(nrm, abs(d[i, w]) + abs(e[i, w]) + (abs(e[i - 1, w]) if i > 0 else 0.0))
        tol[w] = 4.0 * 2.220446049250313e-16 * nrm
        hi[w] = n - 1
        ok[w] = True
    zero = _splat(0.0)
    one = _splat(1.0)
    two = _splat(2.0)
    while True:
        kmin = n
        kmax = 0
        for w in range(W):  # deflate at the bottom, find the unreduced block, Wilkinson shift
            m = hi[w]
            while m > 0 and abs(e[m - 1, w]) <= tol[w]:
                e[m - 1, w] = 0.0
                m -= 1
            hi[w] = m
            if m == 0 or not ok[w]:
                lo[w] = n  # no position k has lo <= k < hi
                continue
            ll = m - 1
            while ll > 0 and abs(e[ll - 1, w]) > tol[w]:
                ll -= 1
            lo[w] = ll
            a, b, c_ = d[m - 1, w], e[m - 1, w], d[m, w]
            dd = 0.5 * (a - c_)
            den = dd + np.copysign(np.sqrt(dd * dd + b * b), dd)
            mu = c_ - b * b / den if den != 0.0 else c_
            x0[w] = d[ll, w] - mu
            z0[w] = e[ll, w]
            kmin = min(kmin, ll)
            kmax = max(kmax, m)
        if kmax == 0:
            break
        if nsteps + (kmax - kmin) > cap:
            for w in range(W):
                if hi[w] > 0:
                    ok[w] = False
            break
        x = _ld(x0)
        z = _ld(z0)
        for k in range(kmin, kmax):
            act = _in_block(lo, hi, k)
            rr = _sqrt(_fma(x, x, _mul(z, z)))
            good = _positive(act, rr)
            c = _sel(good, _div(x, rr), one)
            s = _sel(good, _div(z, rr), zero)
            if k > kmin:
                _st(e[k - 1], _sel(_past_start(act, lo, k), rr, _ld(e[k - 1])))
            dk = _ld(d[k])
            dk1 = _ld(d[k + 1])
            ek = _ld(e[k])
            cc = _mul(c, c)
            ss = _mul(s, s)
            cs = _mul(c, s)
            cs2 = _mul(two, cs)
            _st(d[k], _fma(cc, dk, _fma(cs2, ek, _mul(ss, dk1))))
            _st(d[k + 1], _fma(ss, dk, _fnma(cs2, ek, _mul(cc, dk1))))
            en = _fma(cs, _sub(dk1, dk), _mul(_sub(cc, ss), ek))
            _st(e[k], en)
            bul = zero
            if k + 1 < n - 1:
                ek1 = _ld(e[k + 1])
                bul = _mul(s, ek1)
                _st(e[k + 1], _mul(c, ek1))
            x = _sel(act, en, x)
            z = _sel(act, bul, z)
            rot_k[nsteps] = k
            _st(rot_c[nsteps], c)
            _st(rot_s[nsteps], s)
            nsteps += 1
    return nsteps


@_jit
def _lane_vectors(nsteps, rot_k, rot_c, rot_s, sel, K, Ar, Ai, taur, taui, Vr, Vi):
    """Eigenvectors for the tridiagonal eigenvalues ``sel[q, w]`` (``q < K``): the recorded QR
    rotations applied backwards to unit vectors, then the Householder reflectors stored in
    ``Ar, Ai`` (``Vr, Vi``: (K, n, 8))."""
    n = Ar.shape[0]
    for q in range(K):
        for i in range(n):
            for w in range(W):
                Vr[q, i, w] = 1.0 if sel[q, w] == i else 0.0
                Vi[q, i, w] = 0.0
    for st in range(nsteps - 1, -1, -1):  # Z e_j = G_1^T ... G_N^T e_j: G_N^T first
        k = rot_k[st]
        c = _ld(rot_c[st])
        s = _ld(rot_s[st])
        for q in range(K):
            a = _ld(Vr[q, k])
            b = _ld(Vr[q, k + 1])
            _st(Vr[q, k], _fnma(s, b, _mul(c, a)))
            _st(Vr[q, k + 1], _fma(s, a, _mul(c, b)))
    for k in range(n - 2, -1, -1):  # y = H_0 (H_1 (... H_{n-2} z))
        o = k + 1
        tr = _ld(taur[k])
        ti = _ld(taui[k])
        for q in range(K):
            sr = _ld(Vr[q, o])  # s = v^* y
            si = _ld(Vi[q, o])
            for i in range(o + 1, n):
                sr, si = _cjmac(_ld(Ar[i, k]), _ld(Ai[i, k]), _ld(Vr[q, i]), _ld(Vi[q, i]), sr, si)
            cr = _fnma(ti, si, _mul(tr, sr))  # y -= tau s v
            ci = _fma(ti, sr, _mul(tr, si))
            _st(Vr[q, o], _sub(_ld(Vr[q, o]), cr))
            _st(Vi[q, o], _sub(_ld(Vi[q, o]), ci))
            for i in range(o + 1, n):
                a_r = _ld(Ar[i, k])
                a_i = _ld(Ai[i, k])
                _st(Vr[q, i], _sub(_ld(Vr[q, i]), _fnma(ci, a_i, _mul(cr, a_r))))
                _st(Vi[q, i], _sub(_ld(Vi[q, i]), _fma(ci, a_r, _mul(cr, a_i))))


@_jit
def _block_rows_times(Tr_, Ti_, starts, xr, xi, outr, outi):
    """``out = T x`` for the eight lanes, ``T`` block diagonal with lower-triangular blocks
    stored by rows (``T[i, j] = T_[i, j - starts[i]]``), ``x`` and ``out`` (n, 8)."""
    zero = _splat(0.0)
    for i in range(starts.size):
        s = starts[i]
        ar = zero
        ai = zero
        for j in range(s, i + 1):
            ar, ai = _cmac(_ld(Tr_[i, j - s]), _ld(Ti_[i, j - s]), _ld(xr[j]), _ld(xi[j]), ar, ai)
        _st(outr[i], ar)
        _st(outi[i], ai)


@_jit
def _weighted_cross(Ar, Ai, i, Br, Bi, j, wts, K):
    """``sum_q wts[q] conj(A[q, i]) B[q, j]`` over the ``K`` eigenvectors, for the eight lanes
    (``A``, ``B``: (K, n, 8) real and imaginary parts; returns the two 8-tuples)."""
    zero = _splat(0.0)
    ar = zero
    ai = zero
    for q in range(K):
        tr, ti = _cjmac(_ld(Ar[q, i]), _ld(Ai[q, i]), _ld(Br[q, j]), _ld(Bi[q, j]), zero, zero)
        wq = _ld(wts[q])
        ar = _fma(wq, tr, ar)
        ai = _fma(wq, ti, ai)
    return ar, ai


@_jit
def _lane_gradient(Mr, Mi, x, K, lay, ws, g):
    """Gradient ``g`` (p, 8) of the smoothed ``lambda_max`` from the ``K`` top eigenvectors
    ``ws.vec_*`` (K, n, 8), their weights ``ws.top_weight`` and eigenvalues ``ws.top_lam``
    (K, 8; overwritten), as in :func:`mu_kernels.dg_objective`."""
    log_par, log_ent, lin_ent, lin_row = lay.log_par, lay.log_ent, lay.lin_ent, lay.lin_row
    re_par, im_par, l_row, l_col, l_ent = lay.re_par, lay.im_par, lay.l_row, lay.l_col, lay.l_ent
    r_row, r_col, r_ent, g_row, g_col = lay.r_row, lay.r_col, lay.r_ent, lay.g_row, lay.g_col
    gq_par, gq_pos1, gq_pos2 = lay.gq_par, lay.gq_pos1, lay.gq_pos2
    rs, cs = lay.row_block_start, lay.col_block_start
    Tlr, Tli, Tir, Tii, Er, Ei = ws.tl_re, ws.tl_im, ws.tri_re, ws.tri_im, ws.ent_re, ws.ent_im
    Vr, Vi, TVr, TVi, XVr, XVi = ws.vec_re, ws.vec_im, ws.tv_re, ws.tv_im, ws.xv_re, ws.xv_im
    MVr, MVi, gTr, gTi = ws.mv_re, ws.mv_im, ws.grad_t_re, ws.grad_t_im
    lam, pk = ws.top_lam, ws.top_weight
    c, r, _ = Mr.shape
    n_gq = gq_par.size
    coef1 = lay.gq_coef1
    coef2 = lay.gq_coef2
    zero = _splat(0.0)
    for q in range(K):  # TV = T_r^{-1} V, XV = M TV, MV = T_l XV
        _block_rows_times(Tir, Tii, rs, Vr[q], Vi[q], TVr[q], TVi[q])
        for i in range(c):
            ar = zero
            ai = zero
            for j in range(r):
                ar, ai = _cmac(_ld(Mr[i, j]), _ld(Mi[i, j]), _ld(TVr[q, j]), _ld(TVi[q, j]), ar, ai)
            _st(XVr[q, i], ar)
            _st(XVi[q, i], ai)
        _block_rows_times(Tlr, Tli, cs, XVr[q], XVi[q], MVr[q], MVi[q])
    gTr[:] = 0.0
    gTi[:] = 0.0
    for k in range(l_row.size):  # T_l entry (i, j): 2 sum_q p_q XV[j, q] conj(MV[i, q])
        en = l_ent[k]
        ar, ai = _weighted_cross(MVr, MVi, l_row[k], XVr, XVi, l_col[k], pk, K)
        _st(gTr[en], _fma(_splat(2.0), ar, _ld(gTr[en])))
        _st(gTi[en], _fma(_splat(2.0), ai, _ld(gTi[en])))
    for q in range(K):  # scratch: lam becomes p_q l_q (not used after the gradient)
        _st(lam[q], _mul(_ld(pk[q]), _ld(lam[q])))
    for k in range(r_row.size):  # T_r entry (i, j): -2 sum_q p_q l_q TV[j, q] conj(V[i, q])
        en = r_ent[k]
        ar, ai = _weighted_cross(Vr, Vi, r_row[k], TVr, TVi, r_col[k], lam, K)
        _st(gTr[en], _fnma(_splat(2.0), ar, _ld(gTr[en])))
        _st(gTi[en], _fnma(_splat(2.0), ai, _ld(gTi[en])))
    for k in range(log_par.size):
        en = log_ent[k]
        for w in range(W):
            g[log_par[k], w] = gTr[en, w] * Er[en, w] - gTi[en, w] * Ei[en, w]
    for k in range(lin_ent.size):
        en = lin_ent[k]
        for w in range(W):
            g[lin_row[k], w] += gTr[en, w] * Er[en, w] - gTi[en, w] * Ei[en, w]
            sc = np.exp(min(max(x[lin_row[k], w], -60.0), 60.0))
            g[re_par[k], w] = gTr[en, w] * sc
            g[im_par[k], w] = -gTi[en, w] * sc
    for q in range(n_gq):  # G entry (i, j): 2j sum_k p_k XV[j, k] conj(TV[i, k]), times coef
        val = zero
        for kk in range(2):
            pos = gq_pos1[q] if kk == 0 else gq_pos2[q]
            if pos < 0:
                continue
            cf = coef1[q] if kk == 0 else coef2[q]
            ar, ai = _weighted_cross(TVr, TVi, g_row[pos], XVr, XVi, g_col[pos], pk, K)
            # Re(2j (ar + j ai) cf) = -2 (ai Re(cf) + ar Im(cf))
            val = _fnma(_splat(2.0), _fma(ai, _splat(cf.real), _mul(ar, _splat(cf.imag))), val)
        _st(g[gq_par[q]], val)


@_jit
def _lane_eval(Mr, Mi, Mc, x, tq, lay, ws, f, g, lmax):
    """Objective ``f``, gradient ``g`` (p, 8) and exact ``lambda_max`` at the eight points
    ``x`` (p, 8) for the lane matrices ``Mr + j Mi`` (c, r, 8; ``Mc``: the same, (8, c, r)
    complex), with the layout ``lay`` (:data:`LaneLayout`) and the work arrays ``ws``
    (:data:`LaneWorkspace`).

    ``tq[w] > 0`` is lane ``w``'s temperature; ``tq[w] < 0`` means ``t = -tq[w] / lambda_max``
    (relative to the lane's own ``lambda_max``). Returns the temperatures used (8,).
    """
    Hr, Hi, d, taur, taui = ws.h_re, ws.h_im, ws.diag, ws.tau_re, ws.tau_im
    rot_k, rot_c, rot_s, okq = ws.rot_row, ws.rot_cos, ws.rot_sin, ws.qr_ok
    sel, pk, lam = ws.top_index, ws.top_weight, ws.top_lam
    n = Hr.shape[0]
    _lane_scalings(x, lay, ws)
    _lane_form_h(Mr, Mi, lay, ws)
    _lane_tridiag(Hr, Hi, d, ws.offdiag, taur, taui, ws.p_re, ws.p_im, ws.v_re, ws.v_im)
    nsteps = _lane_qr(d, ws.offdiag, rot_k, rot_c, rot_s, ws.qr_lo, ws.qr_hi, ws.qr_x, ws.qr_z, okq)
    t = np.empty(W)
    kw = np.zeros(W, dtype=np.int64)
    K = 1
    for w in range(W):
        lm = -np.inf
        for i in range(n):
            lm = max(lm, d[i, w])
        tw = tq[w] if tq[w] > 0 else -tq[w] / max(lm, 1e-12)
        t[w] = tw
        ssum = 0.0
        for i in range(n):
            ssum += np.exp(tw * (d[i, w] - lm))
        lmax[w] = lm
        f[w] = lm + np.log(ssum) / tw
        for i in range(n):  # eigenvalues that carry the smoothed maximum
            if np.exp(tw * (d[i, w] - lm)) / ssum > WEIGHT_FLOOR:
                kw[w] += 1
        K = max(K, kw[w])
        # the K largest by repeated arg-max (ties by index); lanes with fewer get zero weights
        prev = np.inf
        prev_i = -1
        for q in range(n):
            best = -np.inf
            bi = 0
            for i in range(n):
                v = d[i, w]
                if (v < prev or (v == prev and i > prev_i)) and v > best:
                    best = v
                    bi = i
            sel[q, w] = bi
            lam[q, w] = best
            pk[q, w] = np.exp(tw * (best - lm)) / ssum if q < kw[w] else 0.0
            prev = best
            prev_i = bi
            if q + 1 >= kw[w] and q + 1 >= K:
                break
    for w in range(W):  # lanes that stopped early: fill the remaining slots with weight 0
        for q in range(kw[w], K):
            sel[q, w] = sel[max(kw[w] - 1, 0), w]
            lam[q, w] = 0.0
            pk[q, w] = 0.0
    _lane_vectors(nsteps, rot_k, rot_c, rot_s, sel, K, Hr, Hi, taur, taui, ws.vec_re, ws.vec_im)
    _lane_gradient(Mr, Mi, x, K, lay, ws, g)
    for w in range(W):  # the size of the LMI's terms, for the choice of the best point
        acc = 0.0
        for i in range(ws.mht_re.shape[0]):
            for j in range(ws.mht_re.shape[1]):
                acc += ws.mht_re[i, j, w] ** 2 + ws.mht_im[i, j, w] ** 2
        ws.size[w] = acc
    for w in range(W):  # a lane whose QR did not converge: the per-matrix kernel
        if not okq[w]:
            _eval_lane_alone(Mc, w, x, tq, lay, f, g, lmax, t, ws.size)
    return t


@_jit_exact
def _eval_lane_alone(Mc, w, x, tq, lay, f, g, lmax, t, size):
    """What :func:`_lane_eval` computes, for lane ``w`` only, by the per-matrix kernel
    :func:`mu_kernels.dg_objective` (scalar code): ``f[w]``, ``g[:, w]``,
    ``lmax[w]``, the temperature used ``t[w]`` and ``size[w]`` (``||M_hat||_F^2``).

    The evaluation of a lane whose QR did not converge, and of every busy lane when so few are
    busy that one eight-lane evaluation costs more than theirs one by one
    (``LaneOptions.per_matrix_lanes``). A temperature relative to the lane's own
    ``lambda_max`` (``tq[w] < 0``) is resolved inside that evaluation. Allocates its work
    arrays; :func:`_eval_lane_alone_ws` takes them from :func:`_alone_workspace`.
    """
    aw = _alone_workspace(Mc.shape[1], Mc.shape[2], x.shape[0], lay.n_entries)
    _eval_lane_alone_ws(Mc, w, x, tq, lay, f, g, lmax, t, size, aw)


@_jit_exact
def _alone_workspace(c, r, p, n_entries):
    """Work arrays of :func:`_eval_lane_alone_ws`: the one-matrix inputs and outputs of
    :func:`mu_kernels.dg_objective_ws` and its :data:`mu_kernels.ScalarWorkspace`."""
    return (
        np.empty((1, p)), np.empty(1), np.empty(1), np.empty((1, p)), np.empty(1),
        np.empty((1, r), dtype=np.complex128), np.empty(1),
        mu_kernels.scalar_workspace(c, r, n_entries),
    )  # fmt: skip


@_jit_exact
def _eval_lane_alone_ws(Mc, w, x, tq, lay, f, g, lmax, t, size, aw):
    """:func:`_eval_lane_alone` with its work arrays ``aw`` (:func:`_alone_workspace`, reused
    from evaluation to evaluation: the same arithmetic, no allocation)."""
    xw, f1, l1, g1, s1, top1, t1, sws = aw
    p = x.shape[0]
    for i in range(p):
        xw[0, i] = x[i, w]
    t1[0] = tq[w]  # negative: relative, dg_objective puts the absolute one there
    mu_kernels.dg_objective_ws(Mc[w : w + 1], xw, t1, True, lay, f1, g1, l1, top1, s1, sws)
    f[w] = f1[0]
    lmax[w] = l1[0]
    t[w] = t1[0]
    size[w] = s1[0]
    for i in range(p):
        g[i, w] = g1[0, i]


def lane_layout(packed, structure) -> LaneLayout:
    """The :data:`LaneLayout` of ``structure`` from ``mu_kernels.pack_layout``'s arrays
    ``packed`` (the per-row maps are derived here)."""
    cb, realb = packed["c_blocks"], packed["real_blocks"]
    rb = (packed["rb_start"], packed["rb_size"])
    c, r = structure.n_cols, structure.n_rows
    rs = _row_starts(r, rb[0], rb[1]).astype(np.int64)
    rsz = np.ones(r, dtype=np.int64)
    for s0, m in zip(rb[0], rb[1], strict=True):
        rsz[s0 : s0 + m] = m
    cs = _row_starts(c, cb[0], cb[1]).astype(np.int64)
    gco = np.zeros(r, dtype=np.int64)
    rgsz = np.zeros(r, dtype=np.int64)
    for ro, co, m in realb.T:
        gco[ro : ro + m] = co
        rgsz[ro : ro + m] = m
    bw = int(max(1, rb[1].max(initial=1), cb[1].max(initial=1)))
    return LaneLayout(
        **packed,
        row_block_start=rs,
        row_block_size=rsz,
        col_block_start=cs,
        row_g_col=gco,
        row_g_size=rgsz,
        max_block=bw,
    )


def lane_workspace(c: int, r: int, lay: LaneLayout) -> LaneWorkspace:
    """Work arrays of :func:`_lane_eval` for ``c x r`` matrices with the layout ``lay`` (zeroed,
    but for the QR's rotation records: written before they are read, and the largest)."""
    n, bw, ne = r, lay.max_block, lay.n_entries
    cap = QR_STEP_BUDGET * n * n + n
    z = np.zeros
    e = np.empty
    return LaneWorkspace(
        z((c, bw, W)), z((c, bw, W)), z((r, bw, W)), z((r, bw, W)), z((r, bw, W)),
        z((r, bw, W)), z((r, bw, W)), z((r, bw, W)), z((ne, W)), z((ne, W)),
        z((c, r, W)), z((c, r, W)), z((r, c, W)), z((r, c, W)), z((r, r, W)), z((r, r, W)),
        z((n, n, W)), z((n, n, W)), z((n, W)), z((n, W)), z((n, W)), z((n, W)),
        z((n, W)), z((n, W)), z((n, W)), z((n, W)),
        e(cap, dtype=np.int64), e((cap, W)), e((cap, W)), z(W, dtype=np.int64),
        z(W, dtype=np.int64), z(W), z(W), np.ones(W, dtype=np.bool_),
        z((n, W), dtype=np.int64), z((n, W)), z((n, W)), z((n, n, W)), z((n, n, W)),
        z((n, r, W)), z((n, r, W)), z((n, c, W)), z((n, c, W)), z((n, c, W)), z((n, c, W)),
        z((ne, W)), z((ne, W)), z(W),
    )  # fmt: skip


def thin_workspace() -> LaneWorkspace:
    """A :data:`LaneWorkspace` for :func:`dg_minimize_lanes` on batches of at most
    ``LaneOptions.per_matrix_lanes`` matrices: those never run :func:`_lane_eval` (every
    evaluation is per matrix, :func:`_eval_lane_alone_ws`), which alone reads the work arrays;
    the optimizer itself writes and reads only ``size``. Empty arrays of the same types (the
    same compiled optimizer) and a ``size`` of eight lanes: about 40 us less than
    :func:`lane_workspace` per single ``mussv`` call, the same arithmetic."""
    f1, f2, f3 = np.empty(0), np.empty((0, 0)), np.empty((0, 0, 0))
    i1, b1 = np.empty(0, dtype=np.int64), np.empty(0, dtype=np.bool_)
    i2 = np.empty((0, 0), dtype=np.int64)
    return LaneWorkspace(
        f3, f3, f3, f3, f3, f3, f3, f3, f2, f2,
        f3, f3, f3, f3, f3, f3, f3, f3, f2, f2, f2, f2,
        f2, f2, f2, f2,
        i1, f2, f2, i1,
        i1, f1, f1, b1,
        i2, f2, f2, f3, f3,
        f3, f3, f3, f3, f3, f3,
        f2, f2, np.zeros(W),
    )  # fmt: skip


# -- the lock-step optimizer ----------------------------------------------------------------

_INIT, _CHAIN, _START, _SEARCH, _IDLE = 0, 1, 2, 3, 4


@_jit_exact
def _load_lane(w, b, M, x0, Mr, Mi, Mc, xc, xq, tq, temps):
    """Put matrix ``b`` in lane ``w`` and ask for its first evaluation (at its balancing start,
    temperature relative to its own ``lambda_max``)."""
    c, r = M.shape[1], M.shape[2]
    for i in range(c):
        for j in range(r):
            Mr[i, j, w] = M[b, i, j].real
            Mi[i, j, w] = M[b, i, j].imag
            Mc[w, i, j] = M[b, i, j]
    for i in range(x0.shape[1]):
        xc[w, i] = x0[b, i]
        xq[i, w] = x0[b, i]
    tq[w] = -temps[0]


@_jit_exact
def _cap_step(dvec, log_par):
    """Cap the log-scale steps at :data:`MAX_LOG_STEP` per iteration."""
    dmax = 0.0
    for k in range(log_par.size):
        dmax = max(dmax, abs(dvec[log_par[k]]))
    if log_par.size:
        fac = min(1.0, MAX_LOG_STEP / max(dmax, 1e-300))
        for i in range(dvec.size):
            dvec[i] *= fac


@_jit_dot
def _dot(a, b):
    """Real dot product (a loop: no BLAS call for 80-element vectors)."""
    acc = 0.0
    for i in range(a.size):
        acc += a[i] * b[i]
    return acc


@_jit_lbfgs
def _lbfgs_dir(g, S, Y, rho, count, head, out, q, alpha):
    """``out = -H g`` by the L-BFGS two-loop recursion over the ``count`` newest pairs
    (circular buffers ``S``, ``Y``, ``rho`` with the newest at ``head``). ``q`` (like ``g``)
    and ``alpha`` (like ``rho``): work arrays (element loops, no temporaries: the arithmetic
    of the array expressions, in the same order)."""
    m = S.shape[0]
    n = g.size
    for i in range(n):
        q[i] = g[i]
    for i in range(count):
        k = (head - i) % m
        alpha[k] = rho[k] * _dot(S[k], q)
        a = alpha[k]
        Yk = Y[k]
        for j in range(n):
            q[j] -= a * Yk[j]
    gamma = 1.0
    if count > 0:
        yy = _dot(Y[head], Y[head])
        if yy > 0:
            gamma = _dot(S[head], Y[head]) / yy
    for j in range(n):  # r = gamma q, in place
        q[j] = gamma * q[j]
    for i in range(count - 1, -1, -1):
        k = (head - i) % m
        beta = rho[k] * _dot(Y[k], q)
        c = alpha[k] - beta
        Sk = S[k]
        for j in range(n):
            q[j] += Sk[j] * c
    for i in range(n):
        out[i] = -q[i]


@_jit_exact
def dg_minimize_lanes(M, x0, opts, lay, ws, best_x, best_l, iters, evals):
    """Minimize the smoothed ``lambda_max`` of each matrix of ``M`` (B, c, r), eight matrices
    at a time (any ``B >= 1``: lanes without a matrix idle).

    For each matrix: temperature stages ``t = tau / lambda_best``; in each stage an L-BFGS
    (``opts.memory`` pairs, Armijo backtracking from the unit step, log-scale steps capped at
    :data:`MAX_LOG_STEP`) stops after ``opts.patience`` consecutive relative decreases below
    ``opts.tol[stage]`` (the last entry for later stages and chained matrices),
    :data:`MAX_FAILED_SEARCHES` failed line searches, or its share of ``opts.max_iter``.

    ``x0`` (B, p) are the starting scalings, ``opts`` a :data:`LaneOptions`, ``lay`` the
    :data:`LaneLayout`, ``ws`` a :data:`LaneWorkspace` (:func:`lane_workspace`). Outputs:
    ``best_x``/``best_l`` the best scalings met (below) and their exact ``lambda_max``, ``iters``
    the iterations and ``evals`` the evaluations (one per lane and eigen-decomposition) used.
    An evaluation runs on the eight lanes (:func:`_lane_eval`) while more than
    ``opts.per_matrix_lanes`` lanes are busy, else lane by lane (:func:`_eval_lane_alone`).
    The best point is the one with the smallest ``lambda_max + opts.size_weight ||M_hat||_F^2``
    (``M_hat = T_l M T_r^{-1}``): the round-off of the certificate check grows with the size
    of the LMI's terms, so a point lower by less than what its certification adds is not
    better (``mu_upper.certified_upper``). Lanes take the next matrix as soon as theirs is
    done. With ``opts.chain`` (continuation along the batch, e.g. a frequency grid) the batch
    is cut into 8 contiguous segments, one per lane, and each matrix after the first of its
    segment also tries the scalings reached on the previous one: where they beat its own
    start, it starts there and runs the ``opts.chain_temperatures`` stages with
    ``opts.chain_patience`` instead.
    """
    nb, c, r = M.shape
    p = x0.shape[1]
    temps, max_iter, tol, patience = opts.temperatures, opts.max_iter, opts.tol, opts.patience
    memory, chain = opts.memory, opts.chain
    chain_temps, chain_patience = opts.chain_temperatures, opts.chain_patience
    log_par = lay.log_par
    Mr = np.zeros((c, r, W))
    Mi = np.zeros((c, r, W))
    Mc = np.zeros((W, c, r), dtype=np.complex128)
    xq = np.zeros((p, W))
    tq = np.zeros(W)
    f = np.zeros(W)
    g = np.zeros((p, W))
    lm = np.zeros(W)
    # lane state
    mat = np.full(W, -1, dtype=np.int64)
    phase = np.full(W, _IDLE, dtype=np.int64)
    seg_next = np.zeros(W, dtype=np.int64)
    seg_end = np.zeros(W, dtype=np.int64)
    xc = np.zeros((W, p))
    fc = np.zeros(W)
    gc = np.zeros((W, p))
    dv = np.zeros((W, p))
    slope = np.zeros(W)
    alpha = np.zeros(W)
    tcur = np.zeros(W)
    f_init = np.zeros(W)
    g_init = np.zeros((W, p))
    ls = np.zeros(W, dtype=np.int64)
    stage = np.zeros(W, dtype=np.int64)
    it_total = np.zeros(W, dtype=np.int64)
    it_stage = np.zeros(W, dtype=np.int64)
    stall = np.zeros(W, dtype=np.int64)
    fails = np.zeros(W, dtype=np.int64)
    n_eval = np.zeros(W, dtype=np.int64)
    chained = np.zeros(W, dtype=np.bool_)
    S = np.zeros((W, memory, p))
    Y = np.zeros((W, memory, p))
    rho = np.zeros((W, memory))
    count = np.zeros(W, dtype=np.int64)
    head = np.full(W, memory - 1, dtype=np.int64)
    dtmp = np.zeros(p)
    lq = np.zeros(p)  # work of _lbfgs_dir
    la = np.zeros(memory)
    best_v = np.zeros(nb)  # the value that picks the best point (lambda_max + size)
    sw = opts.size_weight
    # which matrices each lane takes
    seg = (nb + W - 1) // W
    for w in range(W):
        if chain:
            seg_next[w] = min(nb, w * seg)
            seg_end[w] = min(nb, (w + 1) * seg)
        _load_lane(w, 0, M, x0, Mr, Mi, Mc, xc, xq, tq, temps)  # valid data in idle lanes
    next_global = 0
    active = 0
    for w in range(W):
        b = -1
        if chain:
            if seg_next[w] < seg_end[w]:
                b = seg_next[w]
                seg_next[w] += 1
        elif next_global < nb:
            b = next_global
            next_global += 1
        if b >= 0:
            mat[w] = b
            phase[w] = _INIT
            _load_lane(w, b, M, x0, Mr, Mi, Mc, xc, xq, tq, temps)
            active += 1
    tused = np.zeros(W)
    aw = _alone_workspace(c, r, p, lay.n_entries)  # the per-matrix path's work arrays
    while active > 0:
        if active > opts.per_matrix_lanes:
            tused = _lane_eval(Mr, Mi, Mc, xq, tq, lay, ws, f, g, lm)
        else:  # few busy lanes (a lone matrix, a batch's tail): cheaper one by one
            for w in range(W):
                if mat[w] >= 0:
                    _eval_lane_alone_ws(Mc, w, xq, tq, lay, f, g, lm, tused, ws.size, aw)
        for w in range(W):
            b = mat[w]
            if b < 0:
                continue
            n_eval[w] += 1
            ph = phase[w]
            begin = False  # start an L-BFGS iteration from (xc, fc, gc)
            end_stage = False
            val = lm[w] + sw * ws.size[w]
            if ph == _INIT:
                best_l[b] = lm[w]
                best_v[b] = val
                for i in range(p):
                    best_x[b, i] = xc[w, i]
                stage[w] = 0
                it_total[w] = 0
                chained[w] = False
                count[w] = 0
                head[w] = memory - 1
                tcur[w] = tused[w]
                if chain and b > 0 and (b - 1) >= w * seg:  # previous matrix of this segment
                    f_init[w] = f[w]
                    for i in range(p):
                        g_init[w, i] = g[i, w]
                        xq[i, w] = best_x[b - 1, i]
                    tq[w] = -chain_temps[0]
                    phase[w] = _CHAIN
                    continue
                fc[w] = f[w]
                for i in range(p):
                    gc[w, i] = g[i, w]
                stall[w] = 0
                fails[w] = 0
                it_stage[w] = 0
                begin = True
            elif ph == _CHAIN:
                if val < best_v[b]:  # the neighbour's scalings start lower
                    best_l[b] = lm[w]
                    best_v[b] = val
                    for i in range(p):
                        xc[w, i] = best_x[b - 1, i]
                        best_x[b, i] = xc[w, i]
                        gc[w, i] = g[i, w]
                    fc[w] = f[w]
                    tcur[w] = tused[w]
                    chained[w] = True
                else:
                    fc[w] = f_init[w]
                    for i in range(p):
                        gc[w, i] = g_init[w, i]
                stall[w] = 0
                fails[w] = 0
                it_stage[w] = 0
                begin = True
            elif ph == _START:
                fc[w] = f[w]
                for i in range(p):
                    gc[w, i] = g[i, w]
                if val < best_v[b]:
                    best_l[b] = lm[w]
                    best_v[b] = val
                    for i in range(p):
                        best_x[b, i] = xc[w, i]
                stall[w] = 0
                fails[w] = 0
                it_stage[w] = 0
                begin = True
            elif ph == _SEARCH:
                pat = chain_patience if chained[w] else patience
                nst = chain_temps.size if chained[w] else temps.size
                per_stage = max(max_iter // nst, min(max_iter, MIN_STAGE_ITERATIONS))
                if np.isfinite(f[w]) and f[w] <= fc[w] + ARMIJO * alpha[w] * slope[w]:
                    sy = 0.0
                    ss_ = 0.0
                    yy = 0.0
                    for i in range(p):
                        si = xq[i, w] - xc[w, i]
                        yi = g[i, w] - gc[w, i]
                        sy += si * yi
                        ss_ += si * si
                        yy += yi * yi
                    if sy > CURVATURE_FLOOR * max(np.sqrt(ss_ * yy), 1e-300):
                        h = (head[w] + 1) % memory
                        head[w] = h
                        for i in range(p):
                            S[w, h, i] = xq[i, w] - xc[w, i]
                            Y[w, h, i] = g[i, w] - gc[w, i]
                        rho[w, h] = 1.0 / sy
                        count[w] = min(count[w] + 1, memory)
                    rel = (fc[w] - f[w]) / max(abs(fc[w]), 1e-300)
                    for i in range(p):
                        xc[w, i] = xq[i, w]
                        gc[w, i] = g[i, w]
                    fc[w] = f[w]
                    if val < best_v[b]:
                        best_l[b] = lm[w]
                        best_v[b] = val
                        for i in range(p):
                            best_x[b, i] = xc[w, i]
                    fails[w] = 0
                    st_tol = tol[min(stage[w], tol.size - 1)]
                    stall[w] = stall[w] + 1 if rel < st_tol else 0
                    if stall[w] >= pat or it_stage[w] >= per_stage:
                        end_stage = True
                    else:
                        begin = True
                else:
                    alpha[w] *= BACKTRACK
                    ls[w] += 1
                    if ls[w] < MAX_TRIALS:
                        for i in range(p):
                            xq[i, w] = xc[w, i] + alpha[w] * dv[w, i]
                        continue
                    count[w] = 0  # forget the curvature pairs, retry along the gradient
                    fails[w] += 1
                    if fails[w] >= MAX_FAILED_SEARCHES or it_stage[w] >= per_stage:
                        end_stage = True
                    else:
                        begin = True
            if end_stage:
                stages = chain_temps if chained[w] else temps
                if it_total[w] >= max_iter or stage[w] + 1 >= stages.size:
                    iters[b] = it_total[w]
                    evals[b] = n_eval[w]
                    n_eval[w] = 0
                    nb_ = -1
                    if chain:
                        if seg_next[w] < seg_end[w]:
                            nb_ = seg_next[w]
                            seg_next[w] += 1
                    elif next_global < nb:
                        nb_ = next_global
                        next_global += 1
                    if nb_ < 0:
                        mat[w] = -1
                        phase[w] = _IDLE
                        active -= 1
                    else:
                        mat[w] = nb_
                        phase[w] = _INIT
                        _load_lane(w, nb_, M, x0, Mr, Mi, Mc, xc, xq, tq, temps)
                    continue
                stage[w] += 1
                tcur[w] = stages[stage[w]] / max(best_l[b], 1e-12)
                for i in range(p):
                    xq[i, w] = xc[w, i]
                tq[w] = tcur[w]
                phase[w] = _START
                continue
            if begin:
                it_total[w] += 1
                it_stage[w] += 1
                for i in range(p):
                    dtmp[i] = gc[w, i]
                _lbfgs_dir(dtmp, S[w], Y[w], rho[w], count[w], head[w], dv[w], lq, la)
                sl = 0.0
                for i in range(p):
                    sl += dv[w, i] * gc[w, i]
                if sl >= 0:
                    sl = 0.0
                    for i in range(p):
                        dv[w, i] = -gc[w, i]
                        sl -= gc[w, i] * gc[w, i]
                    count[w] = 0
                slope[w] = sl  # before the cap (as the numpy oracle of the tests)
                _cap_step(dv[w], log_par)
                alpha[w] = 1.0
                ls[w] = 0
                for i in range(p):
                    xq[i, w] = xc[w, i] + dv[w, i]
                tq[w] = tcur[w]
                phase[w] = _SEARCH
