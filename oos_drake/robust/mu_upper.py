r"""Upper bound of the mixed structured singular value with D and G scalings.

The bound (Fan, Tits & Doyle 1991; Young, Newlin & Doyle 1995): :math:`\mu_\Delta(M) \le \beta` if
there are scalings ``D_l, D_r > 0`` that commute with the structure and a Hermitian ``G`` that
is non-zero only on the real blocks, with

.. math::

    M^* D_l M + j (G M - M^* G^*) - \beta^2 D_r \preceq 0 .

``D_l`` (``sum(c)`` square) and ``D_r`` (``sum(r)`` square) carry, for a repeated scalar block, the
same full Hermitian positive definite ``D_k`` (``r x r``), for a full block ``d_k I``. ``G`` is
``sum(r) x sum(c)`` with Hermitian ``G_k`` on the real blocks.

Method (no LMI solver): write ``D = T^* T`` with block lower-triangular ``T`` (``T = diag(e^s)
(I + N)`` per block); with ``Mh = T_l M T_r^{-1}`` the smallest feasible ``beta`` for given
scalings is

.. math::

    \beta^2(T, G) = \lambda_{\max}\big(T_r^{-*} [M^* D_l M + j (G M - M^* G^*)] T_r^{-1}\big),

which is minimized over ``(T, G)`` (``G`` itself, not scaled by ``T``: a scaled ``G`` couples
the two and stalls on ill-conditioned matrices). ``lambda_max`` is smoothed by the log-sum-exp of
the eigenvalues (temperature raised in stages) and minimized by L-BFGS, matrix by matrix (eight
in lock-step, see Speed); the gradient uses only the few eigenvectors that carry the smoothed
maximum.
Initialization: Osborne balancing of ``|M|`` (one scaling per full block and per channel of a
repeated block), or a warm start.

Certificate: whatever the optimizer reaches, every returned bound is proved by the returned
scalings (:func:`certified_upper`): the LMI is checked in the scaled coordinates of
:func:`lmi_residual` with an a priori bound of the check's own round-off
(:func:`check_roundoff`), and the bound is raised, in closed form, by what that check needs.
The value the optimizer reports comes from a compiled fastmath evaluation whose rounding can
change with the process' history (which copy of a cached kernel was loaded first); the
certificate does not depend on it. Where the optimizer's scalings are so ill-conditioned that
their LMI terms dwarf the bound (mu about 0 approached by scalings running off to infinity:
the cancellation is beyond double precision), the same scalings conditioned (``D + e I``), then
points back to its start and ``D = I, G = 0`` (the plain bound ``||M||_2``) are certified too
and the lowest bound is kept; the optimizers keep their best point by ``lambda_max`` plus what
certifying it would add (:data:`CERT_SIZE_FACTOR`).

Speed: the optimizer is the one compiled D-G optimizer,
:func:`oos_drake.robust.mu_lanes.dg_minimize_lanes`: eight matrices at a time, one per SIMD lane
(about 16-20 us per 26 x 26 matrix and evaluation), for batches of any size (a batch of fewer
than eight leaves lanes idle: slower per matrix, see ``benchmarks/bench_mussv.py``); the
balancing and the final exact evaluation run compiled too (:mod:`oos_drake.robust.mu_kernels`).
A numpy implementation of the same algorithm is the tests' oracle (``tests/robust/oracles.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from oos_drake.blas import single_threaded_blas
from oos_drake.robust import mu_kernels, mu_lanes
from oos_drake.robust.blocks import REAL, BlockStructure
from oos_drake.robust.memory import in_chunks, reuse_freed_memory

#: Matrices per internal batch of :func:`mu_upper_bound`: bounds the memory of huge batches, and
#: keeps the temporaries (~50 per matrix) in cache: 512 runs ~25 % faster per matrix than 2048.
CHUNK = 512


@dataclass(frozen=True)
class _Layout:
    """Index maps from the real parameter vector to ``T_l``, ``T_r`` and ``Gh``."""

    n_params: int
    n_entries: int
    log_par: np.ndarray  # params that are log of a diagonal entry of T
    log_ent: np.ndarray
    lin_re_par: np.ndarray  # params that are Re/Im of an off-diagonal entry of T
    lin_im_par: np.ndarray
    lin_ent: np.ndarray
    lin_row_par: np.ndarray  # T = diag(e^s) (I + N): the log-scale of each off-diagonal's row
    l_row: np.ndarray  # positions of T entries in T_l
    l_col: np.ndarray
    l_ent: np.ndarray
    r_row: np.ndarray  # positions in T_r
    r_col: np.ndarray
    r_ent: np.ndarray
    g_row: np.ndarray  # positions of Gh entries (row in r-space, column in c-space)
    g_col: np.ndarray
    g_map: np.ndarray  # (n_g_params, n_g_pos) complex: Gh[pos] = x_g @ g_map
    g_par: np.ndarray  # indices of G parameters in x
    block_log_par: tuple  # per block: log-params of its diagonal (for initialization)
    lrow_col: np.ndarray  # (c, k): T_l as padded rows (column, entry); pad entry = n_entries
    lrow_ent: np.ndarray
    grow_col: np.ndarray  # (r, k): Gh as padded rows (column, position); pad = n_g_positions
    grow_pos: np.ndarray
    inv_groups: tuple  # ((size, (n_blocks, size) indices), ...): diagonal blocks of T_r


_PER_BLK: dict = {}  # (what, BLK) -> what _per_blk built
_PER_OBJ: dict = {}  # (what, id(structure)) -> (structure, the same): no BLK bytes per call


def _per_blk(what: str, structure: BlockStructure, build):
    """``build()``, once per block structure and ``what`` (layouts and index maps: single-matrix
    calls repeat them; every entry is a function of the BLK alone)."""
    seen = _PER_OBJ.get((what, id(structure)))
    if seen is not None and seen[0] is structure:  # the same object (mussv's parsed BLKs)
        return seen[1]
    key = (what, structure.blk.shape, structure.blk.tobytes())
    if key not in _PER_BLK:
        if len(_PER_BLK) > 256:
            _PER_BLK.clear()
        _PER_BLK[key] = build()
    if len(_PER_OBJ) > 256:
        _PER_OBJ.clear()
    _PER_OBJ[(what, id(structure))] = (structure, _PER_BLK[key])
    return _PER_BLK[key]


def _layout(structure: BlockStructure) -> _Layout:
    """The parameter layout of ``structure``."""
    return _per_blk("layout", structure, lambda: _build_layout(structure))


def _build_layout(structure: BlockStructure) -> _Layout:
    log_par, log_ent, re_par, im_par, lin_ent, lin_row = [], [], [], [], [], []
    l_row, l_col, l_ent, r_row, r_col, r_ent = [], [], [], [], [], []
    block_log_par = []
    n_par = 0
    n_ent = 0
    for block in structure.blocks:
        if block.repeated:
            n = block.rows
            diag_pars = []
            for a in range(n):
                row_par = n_par
                for b in [a] + list(range(a)):  # diagonal first: its log-scale multiplies the row
                    e = n_ent
                    n_ent += 1
                    if a == b:
                        log_par.append(n_par)
                        log_ent.append(e)
                        diag_pars.append(n_par)
                        n_par += 1
                    else:
                        re_par.append(n_par)
                        im_par.append(n_par + 1)
                        lin_ent.append(e)
                        lin_row.append(row_par)
                        n_par += 2
                    l_row.append(block.col_offset + a)
                    l_col.append(block.col_offset + b)
                    l_ent.append(e)
                    r_row.append(block.row_offset + a)
                    r_col.append(block.row_offset + b)
                    r_ent.append(e)
            block_log_par.append(np.array(diag_pars))
        else:
            e = n_ent
            n_ent += 1
            log_par.append(n_par)
            log_ent.append(e)
            block_log_par.append(np.array([n_par]))
            n_par += 1
            for a in range(block.cols):
                l_row.append(block.col_offset + a)
                l_col.append(block.col_offset + a)
                l_ent.append(e)
            for a in range(block.rows):
                r_row.append(block.row_offset + a)
                r_col.append(block.row_offset + a)
                r_ent.append(e)
    g_row, g_col, g_cols = [], [], []
    g_pos = {}
    for block in structure.blocks:
        if block.kind != REAL:
            continue
        n = block.rows
        for a in range(n):
            for b in range(n):
                g_pos[(block.row_offset + a, block.col_offset + b)] = len(g_row)
                g_row.append(block.row_offset + a)
                g_col.append(block.col_offset + b)
        for a in range(n):
            for b in range(a + 1):
                pa, pb = block.row_offset + a, block.col_offset + b
                qa, qb = block.row_offset + b, block.col_offset + a
                if a == b:
                    g_cols.append({g_pos[(pa, pb)]: 1.0})
                else:
                    g_cols.append({g_pos[(pa, pb)]: 1.0, g_pos[(qa, qb)]: 1.0})
                    g_cols.append({g_pos[(pa, pb)]: 1.0j, g_pos[(qa, qb)]: -1.0j})
    g_map = np.zeros((len(g_cols), len(g_row)), dtype=complex)
    for q, col in enumerate(g_cols):
        for pos, coef in col.items():
            g_map[q, pos] = coef
    g_par = np.arange(n_par, n_par + len(g_cols))
    n_par += len(g_cols)

    def padded_rows(rows, cols, ents, n, pad):
        """Per row: the (column, entry) pairs, padded to equal length with ``pad`` entries."""
        per = [[] for _ in range(n)]
        for i, j, e in zip(rows, cols, ents, strict=True):
            per[i].append((j, e))
        k = max(1, max(len(v) for v in per))
        col = np.zeros((n, k), dtype=int)
        ent = np.full((n, k), pad, dtype=int)
        for i, v in enumerate(per):
            for q, (j, e) in enumerate(v):
                col[i, q], ent[i, q] = j, e
        return col, ent

    lrow_col, lrow_ent = padded_rows(l_row, l_col, l_ent, structure.n_cols, n_ent)
    inv_groups = _size_groups(structure, "rows")  # for batched small inverses
    grow_col, grow_pos = padded_rows(
        g_row, g_col, list(range(len(g_row))), structure.n_rows, len(g_row)
    )

    ints = lambda v: np.asarray(v, dtype=int)  # noqa: E731
    return _Layout(
        n_params=n_par,
        n_entries=n_ent,
        log_par=ints(log_par),
        log_ent=ints(log_ent),
        lin_re_par=ints(re_par),
        lin_im_par=ints(im_par),
        lin_ent=ints(lin_ent),
        lin_row_par=ints(lin_row),
        l_row=ints(l_row),
        l_col=ints(l_col),
        l_ent=ints(l_ent),
        r_row=ints(r_row),
        r_col=ints(r_col),
        r_ent=ints(r_ent),
        g_row=ints(g_row),
        g_col=ints(g_col),
        g_map=g_map,
        g_par=g_par,
        block_log_par=tuple(block_log_par),
        lrow_col=lrow_col,
        lrow_ent=lrow_ent,
        grow_col=grow_col,
        grow_pos=grow_pos,
        inv_groups=inv_groups,
    )


def _size_groups(structure: BlockStructure, side: str) -> tuple:
    """Diagonal blocks of ``T_r`` (``side="rows"``) or ``T_l`` (``"cols"``) grouped by size:
    ``((size, (n_blocks, size) channel indices), ...)``."""
    sizes = {}
    for block in structure.blocks:
        n = block.rows if side == "rows" else block.cols
        offset = block.row_offset if side == "rows" else block.col_offset
        if block.repeated:
            sizes.setdefault(n, []).append(offset + np.arange(n))
        else:
            for a in range(n):
                sizes.setdefault(1, []).append(np.array([offset + a]))
    return tuple((n, np.array(v)) for n, v in sorted(sizes.items()))


def _times_blockdiag(A, groups, blocks):
    """``A @ T`` for a block-diagonal ``T`` given by size groups (``(n, rows)``, blocks)."""
    out = np.empty_like(A)
    for (n, rows), b in zip(groups, blocks, strict=True):
        if n == 1:
            d = rows[:, 0]
            out[:, :, d] = A[:, :, d] * b[:, None, :]
        else:
            prod = np.swapaxes(A[:, :, rows], 1, 2) @ b  # (B, blocks, p, n)
            out[:, :, rows] = np.swapaxes(prod, 1, 2)
    return out


def _blockdiag_times(blocks, groups, A, adjoint=False):
    """``T @ A`` (or ``T^* @ A``) for a block-diagonal ``T`` given by size groups."""
    out = np.empty_like(A)
    for (n, rows), b in zip(groups, blocks, strict=True):
        if n == 1:
            d = rows[:, 0]
            out[:, d, :] = (np.conj(b) if adjoint else b)[:, :, None] * A[:, d, :]
        else:
            bb = np.conj(np.swapaxes(b, -1, -2)) if adjoint else b
            out[:, rows, :] = bb @ A[:, rows, :]
    return out


class _Objective:
    """Smoothed ``lambda_max`` of the scaled LMI matrix and its gradient, batched (compiled:
    :func:`mu_kernels.dg_objective`); :meth:`matrix` forms the matrix in numpy."""

    def __init__(self, M: np.ndarray, structure: BlockStructure, layout: _Layout):
        self.M = np.ascontiguousarray(M)
        self.count = np.zeros(M.shape[0], dtype=np.int64)  # evaluations per matrix
        self._mh = None  # M^H, formed by matrix() (the trust check) only
        self.s = structure
        self.L = layout
        self.c_groups = _per_blk("c_groups", structure, lambda: _size_groups(structure, "cols"))
        self.packed = _per_blk(
            "packed", structure, lambda: mu_kernels.pack_layout(layout, self.c_groups)
        )
        #: The layout of the compiled kernels (:func:`mu_lanes.lane_layout`).
        self.lane_layout = _per_blk(
            "lanes", structure, lambda: mu_lanes.lane_layout(self.packed, structure)
        )

    def __call__(self, x, idx, t, need_grad=True):
        """Return ``(f, grad, lam_max, top_vec)`` for the batch rows ``idx`` (``grad`` and
        ``top_vec`` None without ``need_grad``); ``t`` is the smoothing temperature."""
        self.count[idx] += 1
        nb = len(idx)
        M = self.M if nb == self.M.shape[0] else np.ascontiguousarray(self.M[idx])
        f = np.empty(nb)
        lmax = np.empty(nb)
        grad = np.empty((nb, self.L.n_params)) if need_grad else np.empty((0, self.L.n_params))
        top = np.empty((nb, self.s.n_rows), dtype=complex)
        x = np.ascontiguousarray(x, dtype=float)
        t = np.array(np.broadcast_to(t, (nb,)), dtype=float)  # writable (see dg_objective)
        with single_threaded_blas():  # threads on 26 x 26 LAPACK calls: 100x slower
            lay = self.lane_layout
            mu_kernels.dg_objective(M, x, t, bool(need_grad), lay, f, grad, lmax, top)
        if not need_grad:
            return f, None, lmax, None
        return f, grad, lmax, top

    def scalings(self, x, idx):
        L = self.L
        nb = len(idx)
        c, r = self.s.n_cols, self.s.n_rows
        E = np.zeros((nb, L.n_entries), dtype=complex)
        E[:, L.log_ent] = np.exp(np.minimum(np.maximum(x[:, L.log_par], -60.0), 60.0))
        if len(L.lin_ent):
            E[:, L.lin_ent] = np.exp(np.minimum(np.maximum(x[:, L.lin_row_par], -60.0), 60.0)) * (
                x[:, L.lin_re_par] + 1j * x[:, L.lin_im_par]
            )
        Tl = np.zeros((nb, c, c), dtype=complex)
        Tl[:, L.l_row, L.l_col] = E[:, L.l_ent]
        Tr = np.zeros((nb, r, r), dtype=complex)
        Tr[:, L.r_row, L.r_col] = E[:, L.r_ent]
        Gh = np.zeros((nb, r, c), dtype=complex)
        if len(L.g_par):
            Gh[:, L.g_row, L.g_col] = x[:, L.g_par] @ L.g_map
        return E, Tl, Tr, Gh

    def matrix(self, x, idx):
        """The scaled LMI matrix ``H`` (its largest eigenvalue is ``beta^2``) formed in numpy for
        the batch rows ``idx``, with ``(E, T_r^{-1}, M_hat)``: a second rounding of what
        :meth:`__call__` evaluates (:func:`_trusted`; the tests' oracle adds the gradient)."""
        L = self.L
        M = self.M[idx]
        E, Tl, Tr, Gh = self.scalings(x, idx)
        nb = len(idx)
        c, r = self.s.n_cols, self.s.n_rows
        # the scalings are block diagonal: products with them go block size by block size
        Tri = np.zeros_like(Tr)
        tri_b, tl_b = [], []
        for n, rows in L.inv_groups:  # r-space groups: invert the small blocks
            if n == 1:
                d = rows[:, 0]
                inv = 1.0 / Tr[:, d, d]
                Tri[:, d, d] = inv
            else:
                ii, jj = rows[:, :, None], rows[:, None, :]
                inv = np.linalg.inv(Tr[:, ii, jj])
                Tri[:, ii, jj] = inv
            tri_b.append(inv)
        for n, rows in self.c_groups:
            if n == 1:
                tl_b.append(Tl[:, rows[:, 0], rows[:, 0]])
            else:
                tl_b.append(Tl[:, rows[:, :, None], rows[:, None, :]])
        # H = X^* D_l X + j (Y X - X^* Y^*) with X = M T_r^{-1}, Y = T_r^{-*} G, written as
        # H = W + W^* with W = X^* Z, Z = T_l^* T_l X / 2 - j Y^*: one dense 26 x 26 product on
        # contiguous operands (numpy copies transposed operands, which costs as much as a product)
        rg, cg = L.inv_groups, self.c_groups
        X = _times_blockdiag(M, rg, tri_b)
        Mh = _blockdiag_times(tl_b, cg, X)
        Z = _blockdiag_times(tl_b, cg, 0.5 * Mh, adjoint=True)
        if len(L.g_par):
            GhH = np.zeros((nb, c, r), dtype=complex)
            GhH[:, L.g_col, L.g_row] = np.conj(Gh[:, L.g_row, L.g_col])
            Z -= 1j * _times_blockdiag(GhH, rg, tri_b)
        if self._mh is None:
            self._mh = np.ascontiguousarray(np.conj(np.swapaxes(self.M, -1, -2)))
        W = _blockdiag_times(tri_b, rg, self._mh[idx], adjoint=True) @ Z
        H = W + np.conj(np.swapaxes(W, -1, -2))
        return H, E, Tri, Mh


class _Balanced:
    """The optimization in balanced coordinates: ``M_b = T0_l M T0_r^{-1}`` with the diagonal
    starting scalings ``T0`` (Osborne balancing, parameters ``x_start``), and the affine change
    of parameters ``x = x_b / factor + shift`` under which ``lambda_max`` is the same function
    (``T = T' T0``, ``G = T0_r G' T0_l``: ``D = T0 D' T0``; ``T0`` commutes with the structure).

    It leaves the D scalings' start unchanged (``x_b = 0`` there) and puts ``G`` in the units of
    the balanced matrix: without it a repeated real block whose channels are scaled very
    differently (``diag(10, 0.1)``) leaves ``G`` so badly conditioned that the bound stops
    5 % (up to 15 %) above the converged one (``tests/robust/test_mu_speed_paths.py``).
    """

    def __init__(self, obj: _Objective, x_start: np.ndarray):
        L = obj.L
        # the diagonals of T_l and T_r: e^s of their log-parameters (what obj.scalings puts there)
        l_par, r_par = _per_blk("diag_params", obj.s, lambda: _diag_params(L))
        tl = np.exp(np.minimum(np.maximum(x_start[:, l_par], -60.0), 60.0))
        tr = np.exp(np.minimum(np.maximum(x_start[:, r_par], -60.0), 60.0))
        self.M = tl[:, :, None] * obj.M / tr[:, None, :]
        lin_col_par, g_row_par, g_col_par = _per_blk("balance", obj.s, lambda: _balance_maps(L))
        log_t = x_start  # the start's log-scalings (its other parameters are zero)
        self.shift = np.zeros_like(x_start)
        self.shift[:, L.log_par] = x_start[:, L.log_par]
        self.factor = np.ones_like(x_start)
        if len(L.lin_ent):  # N' = N t_a / t_b for the entry (a, b) of T = diag(e^s) (I + N)
            f = np.exp(log_t[:, L.lin_row_par] - log_t[:, lin_col_par])
            self.factor[:, L.lin_re_par] = f
            self.factor[:, L.lin_im_par] = f
        if len(L.g_par):  # G' = G / (t_a t_b) for the entry (a, b) of G
            self.factor[:, L.g_par] = np.exp(-(log_t[:, g_row_par] + log_t[:, g_col_par]))

    def to_balanced(self, x):
        return (x - self.shift) * self.factor

    def to_absolute(self, x_b):
        return x_b / self.factor + self.shift


def _diag_params(L: _Layout) -> tuple:
    """``(l_par, r_par)``: the log-parameter of each diagonal entry of ``T_l`` and of ``T_r``."""
    par_of_ent = np.full(L.n_entries, -1)
    par_of_ent[L.log_ent] = L.log_par
    out = []
    for rows, cols, ents in ((L.l_row, L.l_col, L.l_ent), (L.r_row, L.r_col, L.r_ent)):
        on_diag = rows == cols
        par = np.full(int(rows.max(initial=-1)) + 1, -1)
        par[rows[on_diag]] = par_of_ent[ents[on_diag]]
        if np.any(par < 0):  # every diagonal entry of T is e^s of a log-parameter
            raise AssertionError("mu_upper: a diagonal scaling without its log-parameter")
        out.append(par)
    return tuple(out)


def _balance_maps(L: _Layout):
    """For each off-diagonal ``T`` entry of the layout ``L``, the log-parameter of its column's
    channel; for each ``G`` parameter, the log-parameters of the r-space row and c-space column
    of its entry."""
    diag_par_r, diag_par_l = {}, {}
    ent_par = dict(zip(L.log_ent.tolist(), L.log_par.tolist(), strict=True))
    for i, j, e in zip(L.r_row, L.r_col, L.r_ent, strict=True):
        if i == j:
            diag_par_r[int(i)] = ent_par[int(e)]
    for i, j, e in zip(L.l_row, L.l_col, L.l_ent, strict=True):
        if i == j:
            diag_par_l[int(i)] = ent_par[int(e)]
    r_pos = {int(e): (int(i), int(j)) for i, j, e in zip(L.r_row, L.r_col, L.r_ent, strict=True)}
    lin_col = np.array([diag_par_r[r_pos[int(e)][1]] for e in L.lin_ent], dtype=int)
    # a position of each G parameter (none without real blocks)
    first = np.argmax(np.abs(L.g_map) > 0, axis=1) if L.g_map.size else np.zeros(0, int)
    g_row = np.array([diag_par_r[int(L.g_row[q])] for q in first], dtype=int)
    g_col = np.array([diag_par_l[int(L.g_col[q])] for q in first], dtype=int)
    return lin_col, g_row, g_col


def _osborne_init(M: np.ndarray, structure: BlockStructure, layout: _Layout, iters: int = 20):
    """Diagonal ``D`` from Osborne balancing of ``|M|`` (:func:`mu_kernels.osborne`): one scaling
    per full block and one per channel of a repeated block (a diagonal ``D_k`` is a valid start
    for the full Hermitian one). Returns ``(B, n_params)`` parameters."""
    P, par = _osborne_problem(M, structure, layout)
    logd = np.zeros(P.shape[:2])  # log of d_e^2
    mu_kernels.osborne(P, int(iters), logd)
    x = np.zeros((M.shape[0], layout.n_params))
    x[:, par] = 0.5 * logd
    return x


def _osborne_problem(M, structure, layout):
    """``(P, par)``: the ``(B, E, E)`` matrix of the balancing (``|M|^2`` summed over the channels
    of each scaling ``e``, zero diagonal) and the log-parameter of each scaling."""
    Sc, Sr, par = _per_blk("osborne", structure, lambda: _osborne_channels(structure, layout))
    k = Sc.shape[1]
    P = Sc.T @ (np.abs(M) ** 2) @ Sr  # (B, E, E) real
    P[:, np.eye(k, dtype=bool)] = 0.0
    P += 1e-300
    return np.ascontiguousarray(P), par


def _osborne_channels(structure, layout):
    """``(Sc, Sr, par)``: the 0/1 ``(c, E)`` and ``(r, E)`` channel sums of each scaling ``e`` of
    the balancing (one per full block, one per channel of a repeated block) and its
    log-parameter (:func:`_osborne_problem`; a function of the BLK alone)."""
    c, r = structure.n_cols, structure.n_rows
    Sc, Sr, par = [], [], []
    for block, pars in zip(structure.blocks, layout.block_log_par, strict=True):
        chans = range(block.rows) if block.repeated else [None]
        for a in chans:
            sc, sr = np.zeros(c), np.zeros(r)
            if a is None:
                sc[block.c_slice], sr[block.r_slice] = 1.0, 1.0
            else:
                sc[block.col_offset + a], sr[block.row_offset + a] = 1.0, 1.0
            Sc.append(sc)
            Sr.append(sr)
            par.append(pars[0 if a is None else a])
    return np.array(Sc).T, np.array(Sr).T, np.array(par, dtype=int)  # (c, E), (r, E), (E,)


@dataclass(frozen=True)
class UpperBoundResult:
    """Raw result of :func:`mu_upper_bound` for a flat batch ``(B, c, r)``."""

    upper: np.ndarray  # (B,)
    D_left: np.ndarray  # (B, c, c)
    D_right: np.ndarray  # (B, r, r)
    G: np.ndarray  # (B, r, c)
    worst_input: np.ndarray  # (B, r): direction in M's input space at the bound
    iterations: int
    params: np.ndarray  # (B, n_params): raw scalings, a warm start for a neighbouring problem
    evaluations: np.ndarray | None = None  # (B,): eigen-decompositions spent on each matrix


def mu_upper_bound(
    M: np.ndarray,
    structure: BlockStructure,
    *,
    max_iter: int = 200,
    tol: float | tuple = 1e-7,
    temperatures=(30.0, 300.0, 3000.0),
    memory: int = 10,
    x0: np.ndarray | None = None,
    patience: int = 2,
    chain: bool = False,
    chain_temperatures=(500.0,),
    chain_patience: int = 2,
) -> UpperBoundResult:
    """D-G upper bound of mixed mu for a flat batch of matrices.

    Parameters
    ----------
    M : numpy.ndarray
        ``(B, sum(c), sum(r))`` complex, finite (checked by the caller).
    structure : BlockStructure
        Parsed BLK.
    max_iter : int
        Maximum BFGS iterations in total over all temperature stages.
    tol : float or sequence of float
        Relative decrease of the smoothed objective per iteration below which (``patience``
        iterations in a row) a matrix stops its current stage; one per stage, or one for all.
    temperatures : sequence of float
        Smoothing temperatures relative to the current bound (``t * lambda_max``); the last
        one sets the final smoothing bias ``<= log(n) / t`` (relative, on ``beta^2``).
    memory : int
        Number of L-BFGS correction pairs.
    x0 : numpy.ndarray, optional
        ``(B, n_params)`` starting scalings (``params`` of a previous result, e.g. at the
        neighbouring frequency of a sweep) instead of Osborne balancing.
    patience : int
        Consecutive small decreases (see ``tol``) that stop a matrix's stage.
    chain : bool
        Continuation along the batch: the batch is cut into eight contiguous segments (one per lane)
        and each matrix after the first of its segment also tries the scalings reached on the
        previous one and, where they start lower than its own start, runs ``chain_temperatures``
        with ``chain_patience`` from there (a batch of eight or fewer: no chaining).
    chain_temperatures : sequence of float
        Stages of the chained matrices.
    chain_patience : int
        Patience of the chained matrices.

    Returns
    -------
    UpperBoundResult
    """
    reuse_freed_memory()  # ~30 % faster evaluations: no page faults on the temporaries
    if M.shape[0] > CHUNK:  # bounded memory: temporaries are ~50 matrices per input matrix
        options = dict(max_iter=max_iter, tol=tol, temperatures=temperatures, memory=memory)
        options.update(patience=patience, chain=chain, chain_temperatures=chain_temperatures)
        options.update(structure=structure, chain_patience=chain_patience)
        return in_chunks(mu_upper_bound, M, CHUNK, UpperBoundResult, {"x0": x0}, **options)
    nb, c, r = M.shape
    tols = _stage_tolerances(tol, temperatures)
    layout = _layout(structure)
    scale = np.linalg.norm(M, axis=(1, 2)) + 1e-300
    obj = _Objective(M / scale[:, None, None], structure, layout)  # the final, exact evaluation
    x = _osborne_init(obj.M, structure, layout)
    if layout.n_params == 0 or max_iter <= 0:  # the balancing (or a warm start) alone
        if x0 is not None:
            x, _ = _warm_start(obj, x, np.array(x0, dtype=float).reshape(x.shape))
        return _conclude(M, obj, scale, x, x, iterations=0, optimized=max_iter > 0)
    # optimize over the same function in balanced coordinates (see _Balanced)
    coords = _Balanced(obj, x)
    balanced = _Objective(coords.M, structure, layout)
    x = coords.to_balanced(x)
    lmax0 = np.full(nb, np.inf)  # the lane optimizer evaluates the start itself
    if x0 is not None:
        xw = coords.to_balanced(np.array(x0, dtype=float).reshape(x.shape))
        x, lmax0 = _warm_start(balanced, x, xw)
    # the compiled optimizer: eight matrices in lock-step (mu_lanes); it keeps the point with the
    # smallest lambda_max + size_weight ||M_hat||_F^2
    best_x = x.copy()
    its = np.zeros(nb, dtype=np.int64)
    n_evals = np.zeros(nb, dtype=np.int64)
    options = mu_lanes.LaneOptions(
        temperatures=np.asarray(temperatures, dtype=float),
        max_iter=int(max_iter),
        tol=tols,
        patience=int(patience),
        memory=int(memory),
        chain=bool(chain),
        chain_temperatures=np.asarray(chain_temperatures, dtype=float),
        chain_patience=int(chain_patience),
        size_weight=float(CERT_SIZE_FACTOR * check_roundoff(r)),
    )
    lay = balanced.lane_layout
    # at most per_matrix_lanes matrices: every evaluation per matrix, the lanes' arrays unused
    few = nb <= options.per_matrix_lanes
    work = mu_lanes.thin_workspace() if few else mu_lanes.lane_workspace(c, r, lay)
    # one BLAS thread: threads on 26 x 26 LAPACK calls are 100x slower
    with single_threaded_blas(), mu_lanes.compile_with_slp():
        mu_lanes.dg_minimize_lanes(
            balanced.M, np.ascontiguousarray(x), options, lay, work, best_x, lmax0, its, n_evals
        )
    obj.count += balanced.count + n_evals
    return _conclude(
        M,
        obj,
        scale,
        coords.to_absolute(best_x),
        coords.to_absolute(x),
        iterations=int(its.max(initial=0)),
        optimized=True,
    )


def _stage_tolerances(tol, temperatures) -> np.ndarray:
    """``tol`` of :func:`mu_upper_bound`, one per temperature stage."""
    tols = np.asarray(tol, dtype=float).reshape(-1)
    if tols.size == 1:
        tols = np.full(len(temperatures), tols[0])
    if tols.size != len(temperatures):
        raise ValueError(
            f"tol: {tols.size} values for {len(temperatures)} temperature stages (give one or one "
            "per stage)"
        )
    return tols


def _warm_start(obj, x, xw):
    """``(x, lambda_max)``: per matrix, the warm start ``xw`` where it beats ``x`` (it may not,
    e.g. across a resonance)."""
    allidx, one = np.arange(len(x)), np.ones(len(x))
    _, _, lmax0, _ = obj(x, allidx, one, need_grad=False)
    _, _, lw, _ = obj(xw, allidx, one, need_grad=False)
    use = lw < lmax0
    x, lmax0 = x.copy(), lmax0.copy()
    x[use], lmax0[use] = xw[use], lw[use]
    return x, lmax0


def _conclude(M, obj, scale, best_x, start_x, *, iterations, optimized):
    """The result at the optimizer's end point ``best_x`` (started at ``start_x``), certified.

    Parameters
    ----------
    M : numpy.ndarray
        ``(B, c, r)`` the matrices as given.
    obj : _Objective
        The evaluation of ``M / scale`` (its ``count``: evaluations spent so far).
    scale : numpy.ndarray
        ``(B,)`` ``||M||_F`` (plus a tiny floor).
    best_x, start_x : numpy.ndarray
        ``(B, n_params)`` end and start of the optimizer (scalings of ``M`` itself).
    iterations : int
        Iterations done (the result's ``iterations``).
    optimized : bool
        Whether an optimizer ran (``max_iter > 0``): only then is its end checked by
        :func:`_trusted`.
    """
    p = obj.L.n_params
    best_x = best_x.copy()
    allidx = np.arange(M.shape[0])
    # exact lambda_max at the best scalings, and the scalings themselves
    upper, Dl, Dr, G, top, d_min = _finish(obj, best_x, allidx, scale)
    # ill-conditioned scalings, or a bound above ||M||_F >= ||M||_2: was it round-off?
    risky = np.flatnonzero((d_min < TRUST_CONDITION) | (upper > scale)) if optimized else []
    if p > 0 and len(risky):
        best_x[risky] = _trusted(obj, best_x[risky], start_x[risky], risky)
        upper[risky], Dl[risky], Dr[risky], G[risky], top[risky], _ = _finish(
            obj, best_x[risky], risky, scale[risky]
        )
    # every bound is proved by its scalings: certified_upper raises it where its check needs
    # (the value above comes from a compiled, fastmath evaluation whose rounding, and with it
    # the optimizer's path on round-off-dominated matrices, may differ between processes)
    cert, Dl, Dr, G = certified_upper(M, upper, Dl, Dr, G)
    moved = np.flatnonzero(cert > upper * (1 + CERT_RAISE)) if p > 0 else []
    upper = cert
    if len(moved):
        # scalings so ill-conditioned that the LMI's terms dwarf the bound (their cancellation
        # is beyond double precision: mu about 0 approached by scalings running off to
        # infinity): certify the points back to the optimizer's start and to D = I, G = 0 (the
        # plain bound ||M||_2), and keep the lowest certified bound
        best = [upper[moved], Dl[moved], Dr[moved], G[moved], top[moved], best_x[moved]]
        for origin in (start_x[moved], np.zeros_like(start_x[moved])):
            for frac in TRUST_FRACTIONS:
                xs = origin + frac * (best_x[moved] - origin)
                u, dl, dr, g, tp, _ = _finish(obj, xs, moved, scale[moved])
                u, dl, dr, g = certified_upper(M[moved], u, dl, dr, g)
                take = u < best[0]
                for k, v in enumerate((u, dl, dr, g, tp, xs)):
                    best[k][take] = v[take]
        upper[moved], Dl[moved], Dr[moved], G[moved], top[moved], best_x[moved] = best
    return UpperBoundResult(upper, Dl, Dr, G, top, iterations, best_x, obj.count.copy())


#: Two evaluations of ``lambda_max`` (relative to ``||M||_F^2``) that differ by more than this
#: (relative, plus the same absolute amount) are round-off, not a value (:func:`_trusted`).
TRUST_RTOL = 1e-6
#: Scalings whose ``D_r`` has eigenvalues below this fraction of its largest (``cond(T_r)`` above
#: 1e4: the evaluation's round-off grows with ``cond(D_r) eps``) get the check of :func:`_trusted`.
TRUST_CONDITION = 1e-8
#: Fractions of the way from the optimizer's start to its end tried by :func:`_trusted` (and,
#: from the start and from ``D = I, G = 0``, for a bound the certificate check raised by more
#: than :data:`CERT_RAISE`).
TRUST_FRACTIONS = (0.9, 0.75, 0.5, 0.3, 0.15, 0.0)
#: The optimizers keep the point with the smallest ``lambda_max + w ||M_hat||_F^2``, ``w`` this
#: times :func:`check_roundoff`: about what certifying it adds (``R`` of :func:`certified_upper`
#: is ``||M_hat||^2 + 2 ||G_hat|| ||M_hat||``, and ``||G_hat||`` is about ``||M_hat||`` or less
#: at points with a low ``lambda_max``). Negligible unless the scalings are ill-conditioned.
CERT_SIZE_FACTOR = 3.0
#: Conditioning floors (relative to ``lambda_max(D_r)``) added to both ``D`` by
#: :func:`certified_upper` where the scalings as they are need a raise above :data:`CERT_RAISE`.
CERT_FLOORS = (1e-14, 1e-12, 1e-10, 1e-8, 1e-6)
#: A bound that :func:`certified_upper` raises by more than this (relative) was not proved by the
#: optimizer's scalings beyond round-off: other scalings are certified too (``mu_upper_bound``).
CERT_RAISE = 1e-6


def _trusted(obj, best_x, start_x, rows):
    """The optimizer's scalings where their ``lambda_max`` is a value, not round-off.

    The optimizer can follow round-off: near a bound reached only by singular scalings
    (``T_r`` with condition numbers of ``1e10`` and more: a repeated real block whose channels
    are nearly decoupled) the scaled matrix is formed from terms ``cond(T_r)^2`` times larger
    than itself, the computed ``lambda_max`` is noise, and a line search accepts the noise
    where it happens to be low. The exact evaluation at the end (a different rounding) then
    returns a bound far above mu, even above ``||M||`` (a spike: 400x mu on the mission's
    mechanical subset). Here each matrix's end point is evaluated twice (compiled, and formed in
    numpy by :meth:`_Objective.matrix`: different roundings); where they disagree by more than
    :data:`TRUST_RTOL`, the point is replaced by the lowest trusted one on the segment back to
    the start (:data:`TRUST_FRACTIONS`) or to ``D = I, G = 0`` (whose value is ``||M||_2^2``
    exactly: the last resort); so is an end above ``||M||_2^2``.

    Parameters
    ----------
    obj : _Objective
        The exact evaluation (compiled).
    best_x, start_x : numpy.ndarray
        ``(K, n_params)`` end and start of the optimizer for the rows ``rows`` of ``obj``.
    rows : numpy.ndarray
        ``(K,)`` rows of ``obj.M``.

    Returns
    -------
    numpy.ndarray
        ``(K, n_params)`` scalings (``best_x`` where trusted).
    """

    def values(x, rows):
        _, _, a, _ = obj(x, rows, np.ones(rows.size), need_grad=False)
        b = np.linalg.eigvalsh(obj.matrix(x, rows)[0])[:, -1]
        ok = np.abs(a - b) <= TRUST_RTOL * (np.maximum(np.abs(a), np.abs(b)) + 1e-3)
        return np.maximum(a, b), ok

    val, ok = values(best_x, rows)
    # D = I, G = 0 gives ||M||_2^2 exactly: an end above it is no progress either (a start
    # whose own evaluation was noise, e.g. balancing of a nearly decoupled |M|)
    plain = np.linalg.norm(obj.M[rows], ord=2, axis=(1, 2)) ** 2
    bad = np.flatnonzero(~ok | (val > plain * (1 + TRUST_RTOL)))
    if bad.size == 0:
        return best_x
    out = best_x.copy()
    chosen = np.full(bad.size, np.inf)
    zero = np.zeros_like(start_x[bad])
    for origin in (start_x[bad], zero):
        for frac in TRUST_FRACTIONS:
            xs = origin + frac * (best_x[bad] - origin)
            v, good = values(xs, rows[bad])
            take = good & (v < chosen)
            out[bad[take]], chosen[take] = xs[take], v[take]
    return out


def _finish(obj, x, idx, scale):
    """Exact bound, normalized scalings and top direction at ``x`` (rows ``idx`` of ``obj``).

    Returns ``(upper, D_l, D_r, G, top, d_min)``; ``d_min`` is the smallest eigenvalue of the
    normalized ``D_r`` (``1 / cond(D_r)``). ``upper`` is the evaluation's value, not yet
    certified (:func:`certified_upper`).
    """
    nb = len(idx)
    _, Tl, Tr, Gh = obj.scalings(x, idx)
    # infinite temperature: the top eigenvalue and its eigenvector only
    _, _, lmax, top = obj(x, idx, np.full(nb, 1e300))
    upper = scale * np.sqrt(np.maximum(lmax, 0.0))
    Dl = np.conj(np.swapaxes(Tl, -1, -2)) @ Tl
    Dr = np.conj(np.swapaxes(Tr, -1, -2)) @ Tr
    G = scale[:, None, None] * Gh  # the multiplier G itself (not scaled by T)
    # an eigenvalue of zero (mu = 0 bound) keeps its sign; normalize D so that max eig(D_r) = 1
    dnorm = np.zeros(nb)  # largest eigenvalue of the block-diagonal D_r, block size by size
    d_min = np.full(nb, np.inf)
    for n, rows in obj.L.inv_groups:
        if n == 1:  # 1 x 1 blocks: what eigvalsh (zheevd) returns, the entry's real part
            ev = Dr[:, rows[:, 0], rows[:, 0]].real + 0.0  # (-0.0 -> 0.0 as there)
        else:
            ii, jj = rows[:, :, None], rows[:, None, :]
            ev = np.linalg.eigvalsh(Dr[:, ii, jj]).reshape(nb, rows.size)
        dnorm = np.maximum(dnorm, ev.max(axis=1))
        d_min = np.minimum(d_min, ev.min(axis=1))
    Dl, Dr, G = Dl / dnorm[:, None, None], Dr / dnorm[:, None, None], G / dnorm[:, None, None]
    return upper, Dl, Dr, G, top, d_min / np.maximum(dnorm, 1e-300)


#: Floor of the round-off bound of the certificate check (:func:`check_roundoff`), relative to
#: the size of the LMI's terms. A piece of the frequency axis counts as proved where the scaled
#: LMI eigenvalue is below minus this (``mu_intervals.STRICT``).
LMI_ROUNDOFF = 1e-13
_EPS = float(np.finfo(float).eps)  # (np.finfo costs microseconds per call)


def check_roundoff(n: int) -> float:
    r"""Bound of the round-off of the certificate check for an ``n x n`` LMI, relative to the size
    of its terms (``beta^2 + ||M_hat||_F^2 + 2 ||G_hat||_F ||M_hat||_F``, see :func:`lmi_residual`).

    A priori bounds with unit constants: forming ``M_hat^* M_hat`` and ``G_hat M_hat`` (complex
    inner products of length ``<= n``: ``(n + 4) eps`` of the products of the absolute values,
    whose Frobenius norms are at most the terms above), the Householder tridiagonalization of
    LAPACK's ``zheevd`` (backward error ``n^2 eps`` in the Frobenius norm, the worst case of
    ``n - 1`` reflectors of ``n eps`` each) and its tridiagonal eigensolver (``n eps``):
    ``(n + 4)^2 eps`` in all, and never below :data:`LMI_ROUNDOFF` (2e-13 for ``n = 26``).
    """
    return max(LMI_ROUNDOFF, (n + 4.0) ** 2 * _EPS)


def certified_upper(M, beta, D_left, D_right, G):
    r"""The smallest bound ``>= beta`` that the scalings prove, with the scalings that prove it.

    The check is :func:`lmi_residual`'s scaled LMI: with ``lambda_0`` the computed largest
    eigenvalue of ``M_hat^* M_hat + j (G_hat M_hat - M_hat^* G_hat^*)`` and ``R`` the size of its
    terms, the LMI holds at ``beta'`` (its largest eigenvalue is ``lambda_0 - beta'^2`` in exact
    arithmetic: the congruence turns ``D_r`` into ``I``) if ``lambda_0 - beta'^2 + e (beta'^2 + R)
    <= 0`` with ``e`` = :func:`check_roundoff`: ``beta'^2 = (lambda_0 + e R) / (1 - e)``, in
    closed form (no bisection). Where that is below ``beta`` the bound stays; where it is above,
    the bound is raised to it (by round-off only, unless the bound came from an evaluation the
    check does not reproduce). Where that raise exceeds :data:`CERT_RAISE` (scalings so
    ill-conditioned that the LMI's terms dwarf the bound), the same scalings conditioned,
    ``D_l + e I`` and ``D_r + e I`` with ``e`` = :data:`CERT_FLOORS` times ``lambda_max(D_r)``
    (the structure is kept; the LMI changes by ``e (M^* M - beta^2 I)``, which the check
    sees), are certified too and the lowest bound kept. Where no ``D`` has a Cholesky factor
    (the check cannot run in scaled form) the plain bound ``||M||_2`` with ``D = I``, ``G = 0``
    is returned instead, certified the same way.

    What is proved: the LMI with the Cholesky factors and the products ``M_hat``, ``G_hat`` as
    computed; their own rounding (Cholesky and triangular solves, componentwise backward stable)
    amounts to relative perturbations of the scalings of order ``n eps``.

    Parameters
    ----------
    M : numpy.ndarray
        ``(B, c, r)`` complex.
    beta : numpy.ndarray
        ``(B,)`` bounds to certify.
    D_left, D_right, G : numpy.ndarray
        ``(B, c, c)``, ``(B, r, r)``, ``(B, r, c)`` scalings.

    Returns
    -------
    tuple of numpy.ndarray
        ``(beta', D_left, D_right, G)``: ``lmi_residual(M, beta', D_left, D_right, G) <=
        -check_roundoff(r)`` for every matrix.
    """
    M = np.asarray(M, dtype=complex)
    beta = np.array(beta, dtype=float)
    Dl, Dr, G = (np.array(a, dtype=complex) for a in (D_left, D_right, G))
    c, r = M.shape[1:]
    out = _certified_at(M, beta, Dl, Dr, G)
    moved = np.flatnonzero(~(out <= beta * (1 + CERT_RAISE)))  # NaN or inf included
    if moved.size:  # the same scalings conditioned: D + floor lambda_max(D_r) I
        with np.errstate(all="ignore"):
            top = np.max(np.abs(np.linalg.eigvals(_herm(Dr[moved]))), axis=1)
        for floor in CERT_FLOORS:
            e = (floor * top)[:, None, None]
            dl, dr = Dl[moved] + e * np.eye(c), Dr[moved] + e * np.eye(r)
            b = _certified_at(M[moved], beta[moved], dl, dr, G[moved])
            take = b < out[moved]
            rows = moved[take]
            out[rows], Dl[rows], Dr[rows] = b[take], dl[take], dr[take]
    bad = np.flatnonzero(~np.isfinite(out))
    if bad.size:  # no scaled form: the plain bound
        Dl[bad], Dr[bad], G[bad] = np.eye(c), np.eye(r), 0.0
        out[bad] = _certified_at(M[bad], np.zeros(bad.size), Dl[bad], Dr[bad], G[bad])
    return out, Dl, Dr, G


def _certified_at(M, beta, Dl, Dr, G):
    """:func:`certified_upper` at the given scalings only (inf where the check cannot run)."""
    sc = power_of_two_scale(M)
    lam, size = _scaled_lmi(M / sc[:, None, None], Dl, Dr, G / sc[:, None, None])
    e = check_roundoff(M.shape[2])
    need = (lam + e * size) / (1.0 - e) * (1.0 + 8.0 * _EPS)
    out = np.maximum(beta, sc * np.sqrt(np.maximum(need, 0.0)))
    return np.where(np.isfinite(lam) & np.isfinite(size), out, np.inf)


def power_of_two_scale(M):
    """Per matrix of ``(..., c, r)``, the power of two nearest its largest entry (1 for a zero
    matrix): mu and the LMI are homogeneous in ``(M, beta, G)``, dividing by it avoids overflow
    and underflow without rounding."""
    peak = np.max(np.abs(M), axis=(-2, -1))
    return np.where(peak > 0, np.exp2(np.round(np.log2(np.where(peak > 0, peak, 1.0)))), 1.0)


def _herm(A):
    return 0.5 * (A + np.conj(np.swapaxes(A, -1, -2)))


def _cholesky(D):
    """Lower Cholesky factors of a batch ``(B, n, n)``; NaN where one does not exist."""
    try:
        return np.linalg.cholesky(_herm(D))
    except np.linalg.LinAlgError:  # one failed: factor them one by one
        out = np.full(D.shape, np.nan, dtype=complex)
        for k in range(D.shape[0]):
            try:
                out[k] = np.linalg.cholesky(_herm(D[k]))
            except np.linalg.LinAlgError:
                pass
        return out


def _scaled_lmi(M, Dl, Dr, G):
    r"""``(lambda_0, R)`` of the scaled LMI of a batch (see :func:`lmi_residual`).

    ``lambda_0``: largest eigenvalue of ``M_hat^* M_hat + j (G_hat M_hat - M_hat^* G_hat^*)``
    with ``M_hat = L_l^* M L_r^{-*}``, ``G_hat = L_r^{-1} G L_l^{-*}`` (``D = L L^*``); ``R =
    ||M_hat||_F^2 + 2 ||G_hat||_F ||M_hat||_F``. NaN where a ``D`` has no Cholesky factor or
    the scaled matrices overflow.
    """
    B, c, r = M.shape
    lam = np.full(B, np.nan)
    size = np.full(B, np.nan)
    with np.errstate(all="ignore"):
        Ll, Lr = _cholesky(Dl), _cholesky(Dr)
        ok = np.all(np.isfinite(Ll), axis=(1, 2)) & np.all(np.isfinite(Lr), axis=(1, 2))
        if not np.any(ok):
            return lam, size
        Ll, Lr, M, G = Ll[ok], Lr[ok], M[ok], G[ok]
        adj = lambda A: np.conj(np.swapaxes(A, -1, -2))  # noqa: E731
        Mh = adj(Ll) @ adj(np.linalg.solve(Lr, adj(M)))  # L_l^* M L_r^{-*}
        Gh = np.linalg.solve(Lr, adj(np.linalg.solve(Ll, adj(G))))  # L_r^{-1} G L_l^{-*}
        GM = Gh @ Mh
        H = adj(Mh) @ Mh + 1j * (GM - adj(GM))
        nm = np.linalg.norm(Mh, axis=(1, 2))
        R = nm**2 + 2 * np.linalg.norm(Gh, axis=(1, 2)) * nm
        fin = np.all(np.isfinite(H), axis=(1, 2)) & np.isfinite(R)
        ev = np.full(H.shape[0], np.nan)
        if np.any(fin):
            ev[fin] = np.linalg.eigvalsh(_herm(H[fin]))[:, -1]
    lam[ok], size[ok] = ev, np.where(fin, R, np.nan)
    return lam, size


def lmi_residual(M, beta, D_left, D_right, G) -> np.ndarray:
    r"""Largest eigenvalue of ``M^* D_l M + j (G M - M^* G^*) - beta^2 D_r`` (``<= 0`` certifies).

    Evaluated after the congruence with ``L_r^{-1}`` (``D_r = L_r L_r^*``, ``D_l = L_l L_l^*``,
    Cholesky), which keeps the sign of every eigenvalue (Sylvester's law of inertia):

    .. math::

        \hat M^* \hat M + j (\hat G \hat M - \hat M^* \hat G^*) - \beta^2 I, \qquad
        \hat M = L_l^* M L_r^{-*}, \quad \hat G = L_r^{-1} G L_l^{-*},

    which stays accurate when the scalings are ill-conditioned (the unscaled matrix then loses
    the small directions to round-off). Where a ``D`` is not numerically positive definite the
    unscaled form is used. A value ``<= -check_roundoff(r)`` proves the bound beyond the
    check's own round-off (:func:`certified_upper` returns such bounds).

    Parameters
    ----------
    M : array (..., c, r)
    beta : array (...)
    D_left, D_right, G : arrays (..., c, c), (..., r, r), (..., r, c)

    Returns
    -------
    numpy.ndarray
        ``(...)`` largest eigenvalue relative to the size of the terms
        ``beta^2 + ||M_hat||_F^2 + 2 ||G_hat||_F ||M_hat||_F`` (a bound of zero reached by
        scalings running off to infinity then gets a round-off-level residual, not ``0 / 0``).
        Its sign is that of the largest eigenvalue of the LMI.
    """
    M = np.asarray(M, dtype=complex)
    beta = np.asarray(beta, dtype=float)
    shape = np.broadcast_shapes(M.shape[:-2], beta.shape)
    c, r = M.shape[-2:]
    flat = lambda A, tail: np.broadcast_to(np.asarray(A), shape + tail).reshape((-1,) + tail)  # noqa: E731
    M = flat(M, (c, r))
    beta = flat(beta, ())
    Dl, Dr, G = flat(D_left, (c, c)), flat(D_right, (r, r)), flat(G, (r, c))
    # the LMI is homogeneous in (M, beta, G): divide by a power of two to avoid overflow
    sc = power_of_two_scale(M)
    M, beta, G = M / sc[:, None, None], beta / sc, G.astype(complex) / sc[:, None, None]
    Dl, Dr = Dl.astype(complex), Dr.astype(complex)
    lam, size = _scaled_lmi(M, Dl, Dr, G)
    out = (lam - beta**2) / np.maximum(beta**2 + size, 1e-300)
    for k in np.flatnonzero(~np.isfinite(lam)):  # unscaled form
        out[k] = _lmi_residual_unscaled(M[k], beta[k], Dl[k], Dr[k], G[k])
    return out.reshape(shape)


def _lmi_residual_unscaled(M, beta, Dl, Dr, G) -> float:
    """:func:`lmi_residual` for one matrix whose ``D`` has no Cholesky factor."""
    GM = G @ M
    H = np.conj(M.T) @ Dl @ M + 1j * (GM - np.conj(GM.T)) - beta**2 * Dr
    ref = beta**2 * np.linalg.eigvalsh(_herm(Dr))[-1]
    ref += np.linalg.norm(M) ** 2 * np.linalg.eigvalsh(_herm(Dl))[-1]
    ref += 2 * np.linalg.norm(M) * np.linalg.norm(G)
    return float(np.linalg.eigvalsh(_herm(H))[-1] / max(ref, 1e-300))
