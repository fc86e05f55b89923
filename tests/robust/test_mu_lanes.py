"""The lock-step (SIMD lane) D-G optimizer, ``oos_drake.robust.mu_lanes`` (issue 5 speed work).

Checked against independent computations: the numpy objective (batched ``eigh``) and the numpy
optimizer (the same algorithm) of ``oracles``, fully
converged D-G bounds and the LMI certificate of every returned bound.
"""

import numpy as np
import oracles  # tests/robust is on sys.path (rootdir imports)
import pytest
from numpy.testing import assert_allclose

from oos_drake.robust import mu_kernels, mu_lanes, mussv
from oos_drake.robust import mu_upper as mu
from oos_drake.robust.blocks import parse_blk

PAPER = [[-3, 0], [-3, 0]] + [[-2, 0]] * 4 + [[3, 3]] + [[1, 0]] * 9  # 26 x 26, 16 blocks
MIXED = [[-2, 0], [-1, 0], [2, 2], [2, 0], [1, 0], [1, 0]]  # 9 x 9
RECT = [[-2, 0], [2, 3], [1, 1], [3, 0]]  # a full 2 x 3 block: M is 9 x 8
COMPLEX = [[2, 0], [3, 3], [1, 1]]  # no real block: no G
FULL = [[2, 3], [3, 2]]  # full blocks only
W = mu_lanes.W


def _crandn(rng, *shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _lane_problem(blk, seed):
    s = parse_blk(blk)
    rng = np.random.default_rng(seed)
    M = _crandn(rng, W, s.n_cols, s.n_rows)
    M /= np.linalg.norm(M, axis=(1, 2))[:, None, None]
    layout = mu._layout(s)
    ref = oracles.NumpyObjective(M, s, layout)
    x = mu._osborne_init(M, s, layout) + 0.3 * rng.standard_normal((W, layout.n_params))
    packed = mu._Objective(M, s, layout).packed
    return s, M, x, layout, ref, packed


def _lane_eval(s, M, x, layout, packed, tq, cap=None):
    lay = mu_lanes.lane_layout(packed, s)
    ws = mu_lanes.lane_workspace(s.n_cols, s.n_rows, lay)
    if cap is not None:  # a tiny QR step budget: every lane takes the per-matrix fallback
        ws = ws._replace(
            rot_row=np.zeros(cap, dtype=np.int64),
            rot_cos=np.zeros((cap, W)),
            rot_sin=np.zeros((cap, W)),
        )
    f, g, lmax = np.zeros(W), np.zeros((layout.n_params, W)), np.zeros(W)
    Mr = np.ascontiguousarray(M.real.transpose(1, 2, 0))
    Mi = np.ascontiguousarray(M.imag.transpose(1, 2, 0))
    with mu_lanes.compile_with_slp():
        t = mu_lanes._lane_eval(
            Mr, Mi, np.ascontiguousarray(M), np.ascontiguousarray(x.T), np.asarray(tq, float),
            lay, ws, f, g, lmax,
        )  # fmt: skip
    return f, g.T, lmax, t, ws.qr_ok


@pytest.mark.parametrize("blk", [PAPER, MIXED, RECT, COMPLEX, FULL])
@pytest.mark.parametrize("tau", [3.0, 100.0, 3000.0])
def test_lane_evaluation_equals_the_numpy_objective(blk, tau):
    s, M, x, layout, ref, packed = _lane_problem(blk, seed=len(blk))
    idx = np.arange(W)
    _, _, lmax, _ = ref(x, idx, np.ones(W), need_grad=False)
    t = tau / lmax
    f0, g0, l0, _ = ref(x, idx, t)
    floor = s.n_rows * mu_kernels.WEIGHT_FLOOR  # eigenvalues of smaller weight are left out
    for tq in (t, np.full(W, -tau)):  # absolute, and relative to each lane's own lambda_max
        f1, g1, l1, t1, ok = _lane_eval(s, M, x, layout, packed, tq)
        assert ok.all()
        assert_allclose(t1, t, rtol=1e-12)
        assert_allclose(l1, l0, rtol=1e-12)
        assert_allclose(f1, f0, rtol=1e-12)
        assert np.max(np.abs(g1 - g0)) <= 10 * max(floor, 1e-12) * np.max(np.abs(g0))


def test_lanes_whose_qr_exceeds_its_budget_fall_back_to_the_per_matrix_kernel():
    s, M, x, layout, ref, packed = _lane_problem(PAPER, seed=5)
    idx = np.arange(W)
    _, _, lmax, _ = ref(x, idx, np.ones(W), need_grad=False)
    f0, g0, l0, _ = ref(x, idx, 100.0 / lmax)
    f1, g1, l1, t1, ok = _lane_eval(s, M, x, layout, packed, np.full(W, -100.0), cap=10)
    assert not ok.any()
    assert_allclose(l1, l0, rtol=1e-12)
    assert_allclose(f1, f0, rtol=1e-12)
    assert_allclose(t1, 100.0 / lmax, rtol=1e-12)
    assert np.max(np.abs(g1 - g0)) <= 1e-3 * np.max(np.abs(g0))


def _upper(M, s, compiled, **kw):
    upper_bound = mu.mu_upper_bound if compiled else oracles.mu_upper_bound
    return upper_bound(
        M, s, max_iter=100, tol=2e-4, temperatures=(30.0, 300.0), patience=3, **kw
    )  # fmt: skip


@pytest.mark.parametrize("blk,nb", [(PAPER, 13), (MIXED, 21), (RECT, 5)])
def test_lane_optimizer_reproduces_the_numpy_optimizer(blk, nb):
    s = parse_blk(blk)
    M = _crandn(np.random.default_rng(nb), nb, s.n_cols, s.n_rows)
    lanes = _upper(M, s, True)
    oracle = _upper(M, s, False)
    # the same algorithm, but the lanes leave eigenvalues of weight < WEIGHT_FLOOR out of the
    # gradient and round-off in the eigen-solvers may flip a line-search decision: the two
    # stop at different points within the stopping tolerance (tol = 2e-4 per iteration)
    rel = np.abs(lanes.upper / oracle.upper - 1)
    assert np.median(rel) < 1e-4
    assert np.max(rel) < 5e-3
    converged = mu.mu_upper_bound(
        M, s, max_iter=600, tol=1e-12, temperatures=(30.0, 300.0, 3000.0, 30000.0)
    ).upper
    for res in (lanes, oracle):  # both valid (not below the converged bound) and close to it
        assert np.all(res.upper >= converged * (1 - 1e-9))
        assert np.max(res.upper / converged - 1) < 2e-2
    for res in (lanes, oracle):  # both certified by the independent LMI check
        assert np.all(mu.lmi_residual(M, res.upper * (1 + 1e-7), res.D_left, res.D_right, res.G)
                      <= mu.LMI_ROUNDOFF)  # fmt: skip


def test_lane_optimizer_lands_within_one_percent_of_a_converged_bound():
    s = parse_blk(PAPER)
    M = _crandn(np.random.default_rng(7), 16, s.n_cols, s.n_rows)
    got = mussv(M, PAPER).upper
    converged = mu.mu_upper_bound(
        M, s, max_iter=600, tol=1e-12, temperatures=(30.0, 300.0, 3000.0, 30000.0)
    ).upper
    assert np.all(got >= converged * (1 - 1e-9))  # both valid: the converged one is lower
    assert np.max(got / converged - 1) < 1e-2


def test_slp_switch_is_restored():
    import numba

    before = numba.config.SLP_VECTORIZE
    with mu_lanes.compile_with_slp():
        assert numba.config.SLP_VECTORIZE == 1
    assert numba.config.SLP_VECTORIZE == before


@pytest.mark.parametrize("batch", [1, 2, 3, 7])
def test_small_batches_run_on_the_lanes_with_the_values_of_a_full_batch(monkeypatch, batch):
    """DESIGN.md: every batch runs on the lane optimizer; lanes without a matrix idle. Lanes
    share only the length of the gradient's eigenvector sums (the largest over the lanes: the
    summation order), so a matrix gets the bound it gets inside a batch of eight up to
    round-off, which can flip a line-search decision: the two stop within the stopping
    tolerance (tol = 2e-4 per iteration) of each other."""
    calls = []
    lanes = mu_lanes.dg_minimize_lanes

    def spy_lanes(*args, **kwargs):
        calls.append(args[0].shape[0])
        return lanes(*args, **kwargs)

    s = parse_blk(MIXED)
    rng = np.random.default_rng(5)
    M = rng.standard_normal((W, 9, 9)) + 1j * rng.standard_normal((W, 9, 9))
    full = _upper(M, s, True)
    monkeypatch.setattr(mu_lanes, "dg_minimize_lanes", spy_lanes)
    part = _upper(M[:batch], s, True)
    assert calls == [batch]
    rel = np.abs(part.upper / full.upper[:batch] - 1)
    assert np.median(rel) < 1e-4
    assert np.max(rel) < 5e-3
    assert np.all(mu.lmi_residual(M[:batch], part.upper * (1 + 1e-7), part.D_left,
                                  part.D_right, part.G) <= mu.LMI_ROUNDOFF)  # fmt: skip


def test_a_lane_evaluated_alone_equals_the_numpy_objective():
    """The per-matrix evaluator of the lane optimizer (few busy lanes, QR fallback): value,
    gradient, lambda_max, temperature and ||M_hat||_F^2 against numpy (batched eigh, solve)."""
    s, M, x, layout, ref, packed = _lane_problem(PAPER, seed=11)
    lay = mu_lanes.lane_layout(packed, s)
    idx = np.arange(W)
    _, _, lmax, _ = ref(x, idx, np.ones(W), need_grad=False)
    t = 100.0 / lmax
    f0, g0, l0, _ = ref(x, idx, t)
    size0 = ref.size(x, idx)
    floor = s.n_rows * mu_kernels.WEIGHT_FLOOR  # eigenvalues of smaller weight are left out
    xq = np.ascontiguousarray(x.T)
    for tq in (t, np.full(W, -100.0)):  # absolute, and relative to each lane's own lambda_max
        f, l1, t1, size = np.zeros((4, W))
        g = np.zeros((layout.n_params, W))
        for w in range(W):
            mu_lanes._eval_lane_alone(np.ascontiguousarray(M), w, xq, tq, lay, f, g, l1, t1, size)
        assert_allclose(t1, t, rtol=1e-12)
        assert_allclose(l1, l0, rtol=1e-12)
        assert_allclose(f, f0, rtol=1e-12)
        assert_allclose(size, size0, rtol=1e-12)
        assert np.max(np.abs(g.T - g0)) <= 10 * floor * np.max(np.abs(g0))


@pytest.mark.parametrize("chain", [False, True])
def test_evaluating_lanes_one_by_one_gives_the_bounds_of_the_eight_lane_evaluation(
    monkeypatch, chain
):
    """LaneOptions.per_matrix_lanes picks the evaluator, not the optimizer: every evaluation
    one by one (per_matrix_lanes = W) and every one on the eight lanes (0) give the same bounds
    up to round-off flipping a line-search decision (within the stopping tolerance), all
    certified by the independent LMI check."""
    lanes = mu_lanes.dg_minimize_lanes
    s = parse_blk(PAPER)
    M = _crandn(np.random.default_rng(3), 13, s.n_cols, s.n_rows)
    got = {}
    for per_matrix in (0, W):

        def forced(M_, x0, opts, *args, per_matrix=per_matrix):
            return lanes(M_, x0, opts._replace(per_matrix_lanes=per_matrix), *args)

        monkeypatch.setattr(mu_lanes, "dg_minimize_lanes", forced)
        got[per_matrix] = res = _upper(M, s, True, chain=chain)
        assert np.all(mu.lmi_residual(M, res.upper * (1 + 1e-7), res.D_left, res.D_right, res.G)
                      <= mu.LMI_ROUNDOFF)  # fmt: skip
    rel = np.abs(got[W].upper / got[0].upper - 1)
    assert np.median(rel) < 1e-4
    assert np.max(rel) < 5e-3
