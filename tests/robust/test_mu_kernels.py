"""The compiled kernels of the mu bounds (``oos_drake.robust.mu_kernels``, issue 5 speed work).

Checked against independent computations: the numpy implementation of the same objective
(batched ``eigh``), optimizer, balancing and power iteration (``oracles``), central finite
differences of the smoothed objective, and fully converged D-G bounds.
"""

import subprocess
import sys

import numpy as np
import oracles  # tests/robust is on sys.path (rootdir imports)
import pytest
from numpy.testing import assert_allclose

from oos_drake.robust import mu_kernels, mussv
from oos_drake.robust import mu_lower as ml
from oos_drake.robust import mu_upper as mu
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.lfr_analysis import delta_channel_response

PAPER = [[-3, 0], [-3, 0]] + [[-2, 0]] * 4 + [[3, 3]] + [[1, 0]] * 9  # 26 x 26, 16 blocks
MIXED = [[-2, 0], [-1, 0], [2, 2], [2, 0], [1, 0], [1, 0]]  # 9 x 9
RECT = [[-2, 0], [2, 3], [1, 1], [3, 0]]  # a full 2 x 3 block: M is 9 x 8


def _crandn(rng, *shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


def _objective_pair(blk, seed, n_mat=12):
    s = parse_blk(blk)
    rng = np.random.default_rng(seed)
    M = _crandn(rng, n_mat, s.n_cols, s.n_rows)
    M /= np.linalg.norm(M, axis=(1, 2))[:, None, None]
    layout = mu._layout(s)
    numpy_obj = oracles.NumpyObjective(M, s, layout)
    compiled_obj = mu._Objective(M, s, layout)
    x = mu._osborne_init(M, s, layout) + 0.3 * rng.standard_normal((n_mat, layout.n_params))
    return s, M, x, numpy_obj, compiled_obj


COMPLEX = [[2, 0], [3, 3], [1, 1]]  # no real block: no G
FULL = [[2, 3], [3, 2]]  # full blocks only


@pytest.mark.parametrize("blk", [PAPER, MIXED, RECT, COMPLEX, FULL])
@pytest.mark.parametrize("tau", [3.0, 100.0, 3000.0])
def test_compiled_objective_equals_the_numpy_objective(blk, tau):
    s, M, x, ref, fast = _objective_pair(blk, seed=len(blk))
    idx = np.arange(len(M))
    _, _, lmax, _ = ref(x, idx, np.ones(len(M)), need_grad=False)
    t = tau / lmax
    f0, g0, l0, top0 = ref(x, idx, t)
    f1, g1, l1, top1 = fast(x, idx, t)
    assert_allclose(l1, l0, rtol=1e-12)
    assert_allclose(f1, f0, rtol=1e-12)
    # gradient: the compiled kernel leaves out eigenvalues of weight < WEIGHT_FLOOR (numpy:
    # 1e-15), at most n of them: an error of at most ~n * WEIGHT_FLOOR of the gradient's size
    floor = s.n_rows * mu_kernels.WEIGHT_FLOOR
    assert np.max(np.abs(g1 - g0)) <= 10 * max(floor, 1e-12) * np.max(np.abs(g0))
    # top direction T_r^{-1} v: equal up to a unit phase (and equal when the top is simple)
    overlap = np.abs(np.sum(np.conj(top0) * top1, axis=1))
    assert_allclose(overlap, np.linalg.norm(top0, axis=1) * np.linalg.norm(top1, axis=1), 1e-8)
    # eigenvalues only
    f2, g2, l2, _ = fast(x, idx, t, need_grad=False)
    assert g2 is None
    assert_allclose(l2, l0, rtol=1e-12)
    assert_allclose(f2, f0, rtol=1e-12)


@pytest.mark.parametrize("blk", [PAPER, RECT])
def test_compiled_gradient_matches_finite_differences(blk):
    s, M, x, _, fast = _objective_pair(blk, seed=3, n_mat=2)
    idx = np.arange(2)
    _, _, lmax, _ = fast(x, idx, np.ones(2), need_grad=False)
    t = 20.0 / lmax  # smooth enough for central differences
    _, g, _, _ = fast(x, idx, t)
    h = 1e-6
    rng = np.random.default_rng(0)
    for q in rng.choice(x.shape[1], size=12, replace=False):
        xp, xm = x.copy(), x.copy()
        xp[:, q] += h
        xm[:, q] -= h
        fp = fast(xp, idx, t, need_grad=False)[0]
        fm = fast(xm, idx, t, need_grad=False)[0]
        fd = (fp - fm) / (2 * h)
        tol = 10 * s.n_rows * mu_kernels.WEIGHT_FLOOR + 1e-7  # dropped weights (see above)
        assert_allclose(g[:, q], fd, rtol=1e-4, atol=tol * np.max(np.abs(g)))


def test_compiled_optimizer_reproduces_the_numpy_optimizer():
    # the same algorithm, eight matrices per lane evaluation instead of batched (and the
    # gradient without eigenvalues of weight < WEIGHT_FLOOR): bounds within the optimizer's
    # own stopping tolerance
    rng = np.random.default_rng(11)
    s = parse_blk(MIXED)
    M = _crandn(rng, 16, 9, 9)
    kw = dict(max_iter=60, tol=2e-4, temperatures=(50.0, 500.0), patience=3)
    fast = mu.mu_upper_bound(M, s, **kw)
    ref = oracles.mu_upper_bound(M, s, **kw)
    rel = fast.upper / ref.upper - 1
    assert np.median(np.abs(rel)) < 1e-5
    assert np.max(np.abs(rel)) < 5e-3
    assert np.all(
        mu.lmi_residual(M, fast.upper * (1 + 1e-7), fast.D_left, fast.D_right, fast.G) <= 0
    )
    assert np.all(fast.evaluations >= 1)


@pytest.mark.parametrize("blk", [MIXED, RECT, [[2, 0], [3, 3], [1, 1]]])
def test_compiled_power_iteration_equals_the_numpy_one(blk):
    s = parse_blk(blk)
    rng = np.random.default_rng(4)
    M = _crandn(rng, 30, s.n_cols, s.n_rows)
    a = _crandn(rng, 30, s.n_cols)
    out = []
    for power_iteration in (oracles.power_iteration, ml._power_iteration):
        rng5 = np.random.default_rng(5)
        out.append(power_iteration(M, s, a, a.copy(), 40, 0.5, rng5))
    assert_allclose(out[1][0], out[0][0], atol=1e-7)
    assert_allclose(out[1][1], out[0][1], atol=1e-7)


def _frequency_response(seed=0, n_freq=64):
    """A lightly damped closed loop with the MIXED structure (smooth in frequency)."""
    rng = np.random.default_rng(seed)
    n_modes, n = 5, 9
    wn = np.geomspace(0.5, 20.0, n_modes)
    A = np.zeros((2 * n_modes, 2 * n_modes))
    for i in range(n_modes):
        A[2 * i, 2 * i + 1] = wn[i]
        A[2 * i + 1, 2 * i] = -wn[i]
        A[2 * i + 1, 2 * i + 1] = -2 * 0.02 * wn[i]
    Bw = rng.standard_normal((2 * n_modes, n)) * 0.3
    Cz = rng.standard_normal((n, 2 * n_modes)) * 0.3
    Dzw = rng.standard_normal((n, n)) * 0.05
    return delta_channel_response(A, Bw, Cz, Dzw, np.geomspace(0.1, 50.0, n_freq))


def test_continuation_gives_certified_bounds_close_to_independent_ones():
    M = _frequency_response()
    s = parse_blk(MIXED)
    cold = mussv(M, MIXED)
    warm = mussv(M, MIXED, continuation=True)
    converged = mu.mu_upper_bound(
        M, s, max_iter=400, tol=1e-12, temperatures=(30.0, 300.0, 3000.0, 30000.0)
    ).upper
    for res in (cold, warm):
        chk = res.check(M)
        assert np.all(chk["lmi_max_eig"] <= 0)
        assert np.all(res.lower <= res.upper)
        ok = res.lower > 0
        assert np.all(chk["singularity"][ok] < 1e-7)
        assert np.all(res.upper <= converged * 1.01)
        assert np.all(res.upper >= converged * (1 - 1e-3))
    # on unrelated matrices continuation is merely useless, never wrong
    rng = np.random.default_rng(2)
    R = _crandn(rng, 20, 9, 9)
    res = mussv(R, MIXED, continuation=True)
    assert np.all(res.check(R)["lmi_max_eig"] <= 0)
    assert np.all(res.lower <= res.upper)


def test_real_matrices_run_with_one_blas_thread_whatever_the_process_setting(monkeypatch):
    # a multi-threaded OpenBLAS made each 26 x 26 LAPACK call ~1000x slower (72 ms): the
    # kernels run single-threaded whatever the process setting (speed: benchmarks/bench_mussv.py)
    import contextlib

    from oos_drake import blas

    def thread_counts():
        pairs = [blas._global_pair(lib) for lib in blas._libraries()]
        return [pair[1]() for pair in pairs if pair is not None]

    seen = []
    original = mu.single_threaded_blas

    @contextlib.contextmanager
    def spy():
        with original():
            seen.append(thread_counts())
            yield

    monkeypatch.setattr(mu, "single_threaded_blas", spy)
    before = thread_counts()
    rng = np.random.default_rng(0)
    M = rng.standard_normal((2, 26, 26)) + 0j
    try:
        blas.limit_blas_threads(2)
        res = mussv(M, PAPER)
    finally:
        if before:
            blas.limit_blas_threads(before[0])
    assert seen, "the upper bound did not run under single_threaded_blas"
    assert all(count == 1 for counts in seen for count in counts), seen
    assert np.all(res.check(M)["lmi_max_eig"] <= 0)


def test_numpy_oracles_in_mussv_give_the_same_bounds(monkeypatch):
    # mussv with the numpy oracles of both bounds in place of the kernels: same bounds
    import oos_drake.robust.mu as mu_module

    rng = np.random.default_rng(5)
    M = _crandn(rng, 10, 9, 9)
    fast = mussv(M, MIXED)
    monkeypatch.setattr(mu_module, "mu_upper_bound", oracles.mu_upper_bound)
    monkeypatch.setattr(mu_module, "mu_lower_bound", oracles.mu_lower_bound)
    slow = mussv(M, MIXED)
    assert np.median(np.abs(slow.upper / fast.upper - 1)) < 1e-5
    assert np.max(np.abs(slow.upper / fast.upper - 1)) < 5e-3
    # the lower bound starts from the upper bound's worst direction: equal where that agrees
    assert np.median(np.abs(slow.lower / fast.lower - 1)) < 1e-6
    assert np.max(np.abs(slow.lower / fast.lower - 1)) < 1e-2
    for res in (fast, slow):
        chk = res.check(M)
        assert np.all(chk["lmi_max_eig"] <= 0)
        assert np.all(chk["singularity"][res.lower > 0] < 1e-7)


def test_full_eigendecomposition_fallback_matches_numpy():
    # the kernel's fallback (zheevd) when the tridiagonal eigenvectors fail
    rng = np.random.default_rng(6)
    A = _crandn(rng, 26, 26)
    H = A + A.conj().T
    w_ref, V_ref = np.linalg.eigh(H)
    w = np.zeros(26)
    Vk = np.zeros((26, 26), dtype=complex)
    t = 1e3 / abs(w_ref[-1])
    K, ok, t_used = mu_kernels._eig_full(H.copy(), w, Vk, 26, t, np.zeros(8, dtype=np.int32))
    assert ok and K >= 1 and t_used == t
    assert_allclose(w, w_ref, atol=1e-12 * np.max(np.abs(w_ref)))
    for k in range(K):  # ascending: row k of Vk is the eigenvector of eigenvalue 26 - K + k
        v = Vk[k]
        assert_allclose(abs(np.vdot(V_ref[:, 26 - K + k], v)), 1.0, atol=1e-10)


def _eig_top(H, t, k_max):
    """``mu_kernels._eig_top_split`` on the Hermitian ``H``: ``(K, ok, t_used, w, Vk)``."""
    n = H.shape[0]
    Hr, Hi = np.ascontiguousarray(np.tril(H.real)), np.ascontiguousarray(np.tril(H.imag))
    w, Vk = np.zeros(n), np.zeros((n, n), dtype=complex)
    vecs = [np.zeros(n) for _ in range(9)]  # d, e, taur, taui, pr, pi, vr, vi, ev
    cap = mu_kernels.QR_STEP_BUDGET * n * n + n
    rot = np.zeros(cap, dtype=np.int64), np.zeros(cap), np.zeros(cap)
    work = np.zeros((n, n)), np.zeros((n, n)), np.zeros(n, dtype=np.int64)
    K, ok, t_used = mu_kernels._eig_top_split(Hr, Hi, t, k_max, w, Vk, *vecs, *rot, *work)
    return K, ok, t_used, w, Vk


def test_tridiagonal_qr_eigenpairs_match_numpy_on_clustered_top_eigenvalues():
    # the D-G optimum clusters the top eigenvalues (here five within 4 %, two 2e-9 apart): the
    # QR's eigenvalues and the eigenvectors from its rotations against numpy's eigh
    rng = np.random.default_rng(7)
    n = 26
    Q, _ = np.linalg.qr(_crandn(rng, n, n))
    lam = np.r_[np.linspace(-0.5, 0.9, n - 5), [0.96, 0.99, 0.995, 1.0 - 2e-9, 1.0]]
    H = (Q * lam) @ Q.conj().T
    H = 0.5 * (H + H.conj().T)
    w_ref = np.linalg.eigvalsh(H)
    t = 30.0  # weights above WEIGHT_FLOOR down to about 0.62: several eigenvectors
    K, ok, t_used, w, Vk = _eig_top(H, t, n)
    assert ok and t_used == t
    assert_allclose(w, w_ref, atol=1e-13)
    weights = np.exp(t * (w_ref - w_ref[-1]))
    assert K == np.sum(weights / weights.sum() > mu_kernels.WEIGHT_FLOOR) and K >= 5
    V = Vk[:K].T
    assert_allclose(V.conj().T @ V, np.eye(K), atol=1e-12)  # orthonormal within the cluster
    assert_allclose(H @ V, V * w[n - K :], atol=1e-12)
    # a negative temperature is relative to lambda_max: the same as its absolute value
    K2, ok2, t2, _, Vk2 = _eig_top(H, -t, n)
    assert ok2 and K2 == K and np.isclose(t2, t / w_ref[-1], rtol=1e-14, atol=0.0)
    assert_allclose(np.abs(np.sum(Vk2[:K].conj() * Vk[:K], axis=1)), 1.0, atol=1e-12)
    # eigenvalues only
    K0, ok0, _, w0, _ = _eig_top(H, t, 0)
    assert ok0 and K0 == 0
    assert_allclose(w0, w_ref, atol=1e-13)


@pytest.mark.parametrize("blk", [PAPER, MIXED, RECT])
def test_compiled_balancing_equals_the_numpy_sweeps(blk):
    s = parse_blk(blk)
    M = _crandn(np.random.default_rng(12), 20, s.n_cols, s.n_rows)
    M[:, :, 0] *= 1e3  # badly scaled: the sweeps have work to do
    layout = mu._layout(s)
    x = mu._osborne_init(M, s, layout)
    assert np.max(np.abs(x)) > 1.0
    assert_allclose(x, oracles.osborne_init(M, s, layout), rtol=1e-10, atol=1e-10)


def test_import_without_numba_fails_with_one_line_naming_numba():
    # numba is a dependency: no slower copy runs without it, the import says what is missing
    code = "import sys; sys.modules['numba'] = None; import oos_drake.robust"
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode != 0
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith(("ImportError", "ModuleNotFoundError")) and "numba" in last, last
