"""The compiled kernels of the mu lower bound (``oos_drake.robust.mu_lower_kernels``).

Checked against the numpy implementation of the same algorithm (``oracles``); the certificate
of the lower bound (``sigma_min(I - M delta)`` at round-off level, ``||delta|| = 1 / lower``,
``delta`` in the block structure) is checked independently on random matrices with mixed structures.
"""

import numpy as np
import oracles  # tests/robust is on sys.path (rootdir imports)
import pytest
from numpy.testing import assert_allclose

from oos_drake.robust import mu_lower as ml
from oos_drake.robust import mu_lower_kernels as mlk
from oos_drake.robust.blocks import FULL, REAL, parse_blk

PAPER = [[-3, 0], [-3, 0]] + [[-2, 0]] * 4 + [[3, 3]] + [[1, 0]] * 9  # 26 x 26, 16 blocks
MIXED = [[-2, 0], [-1, 0], [2, 2], [2, 0], [1, 0], [1, 0]]  # 9 x 9
RECT = [[-2, 0], [2, 3], [1, 1], [3, 0]]  # a full 2 x 3 block: M is 9 x 8
COMPLEX = [[3, 3], [1, 0], [6, 0]]  # full and complex scalar blocks only
REAL_ONLY = [[-3, 0], [-2, 0], [-5, 0]]


def _crandn(rng, *shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _unit(rng, n, c):
    a = _crandn(rng, n, c)
    return a / np.linalg.norm(a, axis=1, keepdims=True)


@pytest.mark.parametrize("blk", [MIXED, RECT, COMPLEX, [[2, 2], [3, 3]]])
def test_power_iteration_starts_share_matrices(blk):
    """Several starts per matrix (``M[s % nb]``) give the numpy iteration's results."""
    s = parse_blk(blk)
    rng = np.random.default_rng(2)
    M = _crandn(rng, 10, s.n_cols, s.n_rows)
    a = _unit(rng, 20, s.n_cols)
    fast = ml._power_iteration(M, s, a, a.copy(), 30, 0.5, np.random.default_rng(3))
    slow = oracles.power_iteration(M, s, a, a.copy(), 30, 0.5, np.random.default_rng(3))
    assert_allclose(fast[0], slow[0], atol=1e-8)
    assert_allclose(fast[1], slow[1], atol=1e-8)


def _iterates(blk, n_mat, seed):
    s = parse_blk(blk)
    rng = np.random.default_rng(seed)
    M = _crandn(rng, n_mat, s.n_cols, s.n_rows)
    a = _unit(rng, n_mat, s.n_cols)
    delta, a = ml._power_iteration(M, s, a, a.copy(), 60, 0.5, rng)
    return s, M, delta, a


@pytest.mark.parametrize("blk", [COMPLEX, [[2, 2], [3, 3], [1, 0]]])
def test_polish_equals_numpy(blk):
    """Complex structures: shifted inverse iteration, as ``polish_eigenvalue``."""
    s, M, delta, a = _iterates(blk, 40, 5)
    lam_np, a_np = oracles.polish_eigenvalue(M @ delta, a)
    lam = np.empty(len(M), dtype=complex)
    a_k = a.copy()
    mlk.eigen_polish(M, np.arange(len(M)), delta.copy(), a_k, ml._kernel_blocks(s), 0, 3, lam)
    assert_allclose(lam, lam_np, rtol=1e-10)
    assert_allclose(np.abs(np.sum(np.conj(a_k) * a_np, axis=1)), 1.0, atol=1e-8)


@pytest.mark.parametrize("blk", [PAPER, MIXED, RECT, REAL_ONLY])
def test_real_eigenvalue_search_equals_numpy(blk):
    """Structures with real blocks: the Newton rounds of ``make_eigenvalue_real``. Rounds that
    do not converge (a zero or clustered eigenvalue: round-off decides where they go) may end
    elsewhere on a few matrices; the others agree to round-off."""
    s, M, delta, a = _iterates(blk, 60, 6)
    d_np, lam_np, _ = oracles.make_eigenvalue_real(M, s, delta, a)
    d_k, a_k = delta.copy(), a.copy()
    lam = np.empty(len(M), dtype=complex)
    mlk.eigen_polish(M, np.arange(len(M)), d_k, a_k, ml._kernel_blocks(s), 8, 2, lam)
    close = (np.abs(lam - lam_np) <= 1e-9 * np.abs(lam_np)) & (np.abs(lam_np) > 1e-8)
    assert np.mean(close) >= 0.9
    assert_allclose(d_k[close], d_np[close], atol=1e-8)
    # the iterate stays in the structure: real blocks real and repeated
    for b in s.blocks:
        if b.kind == REAL:
            diag = d_k[:, b.row_offset + np.arange(b.rows), b.col_offset + np.arange(b.rows)]
            assert np.all(diag.imag == 0) and np.all(np.abs(diag.real) <= 1.0)
            assert np.all(diag == diag[:, :1])


@pytest.mark.parametrize("blk", [PAPER, RECT])
def test_residual_and_rayleigh_kernels(blk):
    s, M, delta, a = _iterates(blk, 20, 7)
    mat = np.arange(len(M))
    res = np.empty(len(M))
    mlk.vector_residual(M, mat, delta, a, ml._kernel_blocks(s), res)
    assert_allclose(res, oracles.vector_residual(M, delta, a), rtol=1e-12)
    rq = np.empty(len(M), dtype=complex)
    mlk.rayleigh_quotients(M, delta, a, ml._kernel_blocks(s), rq)
    assert_allclose(rq, np.sum(np.conj(a) * ml._mv(M, ml._mv(delta, a)), axis=1), rtol=1e-12)


def test_max_block_norm():
    """Rank-one full blocks by their Frobenius norm, others by an SVD: both as block_norms."""
    s = parse_blk(RECT)
    rng = np.random.default_rng(8)
    delta = np.zeros((30, s.n_rows, s.n_cols), dtype=complex)
    for b in s.blocks:
        if b.kind == FULL:
            u, v = _crandn(rng, 30, b.rows), _crandn(rng, 30, b.cols)
            delta[:, b.r_slice, b.c_slice] = u[:, :, None] * np.conj(v[:, None, :])
            delta[15:, b.r_slice, b.c_slice] = _crandn(rng, 15, b.rows, b.cols)  # full rank
        else:
            idx = np.arange(b.rows)
            delta[:, b.row_offset + idx, b.col_offset + idx] = _crandn(rng, 30)[:, None]
    assert_allclose(ml._max_block_norm(s, delta), np.max(s.block_norms(delta), axis=1), rtol=1e-13)


def _check_certificate(M, s, res):
    pos = res.lower > 0
    assert np.all(res.residual[pos] <= ml.CERTIFICATE_RTOL)
    assert np.all(ml.certificate_residual(M[pos], res.delta[pos]) <= ml.CERTIFICATE_RTOL)
    norms = np.linalg.norm(res.delta[pos], ord=2, axis=(1, 2))
    assert_allclose(norms * res.lower[pos], 1.0, rtol=1e-9)
    assert np.all(res.delta[~pos] == 0)
    # delta is in the block structure
    inside = np.zeros((s.n_rows, s.n_cols), dtype=bool)
    for b in s.blocks:
        if b.kind == FULL:
            inside[b.r_slice, b.c_slice] = True
        else:
            idx = np.arange(b.rows)
            diag = res.delta[:, b.row_offset + idx, b.col_offset + idx]
            assert_allclose(diag, np.repeat(diag[:, :1], b.rows, axis=1), rtol=0, atol=0)
            if b.kind == REAL:
                assert np.all(diag.imag == 0)
            inside[b.row_offset + idx, b.col_offset + idx] = True
    assert np.all(res.delta[:, ~inside] == 0)


@pytest.mark.parametrize("blk", [PAPER, MIXED, RECT, COMPLEX, REAL_ONLY])
@pytest.mark.parametrize("real_matrix", [False, True])
def test_lower_bound_certified(blk, real_matrix):
    s = parse_blk(blk)
    rng = np.random.default_rng(9)
    M = rng.standard_normal((40, s.n_cols, s.n_rows))
    if not real_matrix:
        M = M + 1j * rng.standard_normal(M.shape)
    res = ml.mu_lower_bound(M, s, restarts=3, rng=np.random.default_rng(1))
    _check_certificate(M, s, res)
    if blk == COMPLEX:
        assert np.all(res.lower > 0)  # complex blocks only: any eigenvalue is usable


@pytest.mark.parametrize("blk", [PAPER, MIXED, RECT, COMPLEX])
def test_lower_bound_compiled_equals_numpy(blk):
    """The whole lower bound, compiled and in numpy: equal to round-off (except the rare
    matrix whose real-eigenvalue search does not converge, where both stay certified)."""
    s = parse_blk(blk)
    rng = np.random.default_rng(10)
    M = _crandn(rng, 40, s.n_cols, s.n_rows)
    start = _crandn(rng, 40, s.n_rows)
    kwargs = dict(start_inputs=start, restarts=2, rng=None, polish_starts=1)
    fast = ml.mu_lower_bound(M, s, **kwargs)
    slow = oracles.mu_lower_bound(M, s, **kwargs)
    _check_certificate(M, s, fast)
    _check_certificate(M, s, slow)
    close = np.abs(fast.lower - slow.lower) <= 1e-10 * slow.lower
    assert np.mean(close) >= 0.95
    assert_allclose(fast.lower, slow.lower, rtol=0.05)


def test_real_only_lower_bound_close_to_numpy():
    """Real-only structures: the sign flips of the power iteration make it sensitive to
    round-off (the earlier compiled iteration differs from numpy as much); on average the
    bounds agree."""
    s = parse_blk(REAL_ONLY)
    rng = np.random.default_rng(12)
    M = rng.standard_normal((60, s.n_cols, s.n_rows))
    fast = ml.mu_lower_bound(M, s, restarts=3, rng=np.random.default_rng(0))
    slow = oracles.mu_lower_bound(M, s, restarts=3, rng=np.random.default_rng(0))
    _check_certificate(M, s, fast)
    close = np.abs(fast.lower - slow.lower) <= 1e-10 * np.maximum(slow.lower, 1e-300)
    assert np.mean(close) >= 0.8
    assert abs(np.mean(fast.lower) / np.mean(slow.lower) - 1) < 0.05
