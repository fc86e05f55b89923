"""Work arrays reused across evaluations of the D-G optimizer (issue 29 item 6, mussv speed).

The per-matrix evaluator of the lane optimizer (a lone matrix, a batch's tail) keeps its work
arrays from one evaluation to the next (``mu_kernels.scalar_workspace``,
``mu_lanes._alone_workspace``), and the L-BFGS direction writes into work arrays. Checked
against independent computations: the numpy objective and the numpy two-loop recursion of
``oracles``, evaluation orders that leave the work arrays in other states, the numpy optimizer
in ``mussv`` on single matrices, and the LMI certificate, which must fail once the bound is
lowered by 1 %.
"""

import dataclasses

import numpy as np
import oracles  # tests/robust is on sys.path (rootdir imports)
import pytest
from numpy.testing import assert_allclose

from oos_drake.robust import mu_kernels, mu_lanes, mussv
from oos_drake.robust import mu_upper as mu
from oos_drake.robust.blocks import parse_blk

PAPER = [[-3, 0], [-3, 0]] + [[-2, 0]] * 4 + [[3, 3]] + [[1, 0]] * 9  # 26 x 26, 16 blocks
MIXED = [[-2, 0], [-1, 0], [2, 2], [2, 0], [1, 0], [1, 0]]  # 9 x 9
W = mu_lanes.W


def _crandn(rng, *shape):
    return rng.standard_normal(shape) + 1j * rng.standard_normal(shape)


@pytest.mark.parametrize("blk", [PAPER, MIXED])
def test_reused_work_arrays_give_the_numpy_objective_in_any_order(blk):
    """Eight matrices evaluated one after another through one set of work arrays (forwards,
    then backwards, at two temperatures: each evaluation finds the arrays as another matrix
    left them): value, lambda_max and ||M_hat||_F^2 equal numpy's (batched eigh) to 1e-12,
    the gradient to the weight floor, and every order gives the same numbers bit for bit."""
    s = parse_blk(blk)
    rng = np.random.default_rng(21)
    M = _crandn(rng, W, s.n_cols, s.n_rows)
    M /= np.linalg.norm(M, axis=(1, 2))[:, None, None]
    layout = mu._layout(s)
    ref = oracles.NumpyObjective(M, s, layout)
    x = mu._osborne_init(M, s, layout) + 0.3 * rng.standard_normal((W, layout.n_params))
    lay = mu._Objective(M, s, layout).lane_layout
    Mc, xq = np.ascontiguousarray(M), np.ascontiguousarray(x.T)
    aw = mu_lanes._alone_workspace(s.n_cols, s.n_rows, layout.n_params, lay.n_entries)
    idx = np.arange(W)
    _, _, lmax, _ = ref(x, idx, np.ones(W), need_grad=False)
    floor = s.n_rows * mu_kernels.WEIGHT_FLOOR  # eigenvalues of smaller weight are left out
    runs = {}
    for tau in (30.0, 300.0):
        f0, g0, l0, _ = ref(x, idx, tau / lmax)
        for order in (idx, idx[::-1]):
            f, l1, t1, size = np.zeros((4, W))
            g = np.zeros((layout.n_params, W))
            for w in order:
                mu_lanes._eval_lane_alone_ws(Mc, w, xq, np.full(W, -tau), lay, f, g, l1, t1, size,
                                             aw)  # fmt: skip
            assert_allclose(l1, l0, rtol=1e-12)
            assert_allclose(f, f0, rtol=1e-12)
            assert_allclose(size, ref.size(x, idx), rtol=1e-12)
            assert np.max(np.abs(g.T - g0)) <= 10 * floor * np.max(np.abs(g0))
            runs.setdefault(tau, []).append((f, g, l1, t1, size))
    for first, second in runs.values():  # forwards and backwards: bit for bit
        for a, b in zip(first, second, strict=True):
            assert np.array_equal(a, b)
    # and the same numbers as fresh work arrays (the allocating evaluator)
    f, l1, t1, size = np.zeros((4, W))
    g = np.zeros((layout.n_params, W))
    for w in idx:
        mu_lanes._eval_lane_alone(Mc, w, xq, np.full(W, -300.0), lay, f, g, l1, t1, size)
    for a, b in zip((f, g, l1, t1, size), runs[300.0][0], strict=True):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("count", [0, 3, 10])
def test_lbfgs_direction_equals_the_numpy_two_loop_recursion(count):
    """The compiled L-BFGS direction (circular buffers, newest pair at ``head``, work arrays
    holding garbage) against the numpy recursion of the tests' optimizer (pairs newest first,
    empty slots zero): equal to round-off, wrapping around the buffer's end."""
    rng = np.random.default_rng(count)
    p, m = 78, 10
    S, Y = rng.standard_normal((2, m, p))
    Y += 3.0 * S  # positive curvature s.y > 0
    rho = 1.0 / np.einsum("ki,ki->k", S, Y)
    g = rng.standard_normal(p)
    head = 2  # the newest pairs are slots 2, 1, 0, 9, 8, ...
    order = [(head - i) % m for i in range(count)]
    S_new, Y_new, rho_new = np.zeros((1, m, p)), np.zeros((1, m, p)), np.zeros((1, m))
    S_new[0, :count], Y_new[0, :count], rho_new[0, :count] = S[order], Y[order], rho[order]
    expected = -oracles.lbfgs_direction(g[None], S_new, Y_new, rho_new)[0]
    for _ in range(2):  # the second call finds the work arrays as the first left them
        out = np.full(p, np.nan)
        q, alpha = rng.standard_normal(p), rng.standard_normal(m)
        mu_lanes._lbfgs_dir(g, S, Y, rho, count, head, out, q, alpha)
        assert_allclose(out, expected, rtol=1e-12, atol=1e-12 * np.max(np.abs(expected)))
    if count == 0:  # no pairs: the steepest descent
        assert np.array_equal(out, -g)


def test_single_calls_match_the_numpy_optimizer_and_their_certificates_break_at_99_percent(
    monkeypatch,
):
    """mussv on lone paper-sized matrices (the per-matrix path with reused work arrays) against
    the same algorithm in numpy (``oracles``, batched ``eigh``): upper bounds equal within the
    stopping tolerance, lower bounds where the starts agree. Every returned bound is certified
    by the independent LMI check, and that check fails once the upper bound is lowered by 1 %
    (it proves something), as does the lower bound's once it is raised by 1 %."""
    import oos_drake.robust.mu as mu_module

    s = parse_blk(PAPER)
    M = _crandn(np.random.default_rng(8), 3, s.n_cols, s.n_rows) / 5
    fast = [mussv(m, PAPER) for m in M]
    monkeypatch.setattr(mu_module, "mu_upper_bound", oracles.mu_upper_bound)
    monkeypatch.setattr(mu_module, "mu_lower_bound", oracles.mu_lower_bound)
    slow = [mussv(m, PAPER) for m in M]
    rel = np.array([a.upper / b.upper - 1 for a, b in zip(fast, slow, strict=True)])
    assert np.max(np.abs(rel)) < 5e-3
    for m, res in zip(M, fast, strict=True):
        chk = res.check(m)
        assert chk["lmi_max_eig"] <= 0
        assert res.lower > 0 and chk["singularity"] < 1e-7
        assert abs(chk["delta_norm_error"]) < 1e-9
        low = dataclasses.replace(res, upper=0.99 * res.upper)
        assert low.check(m)["lmi_max_eig"] > 0
        high = dataclasses.replace(res, lower=1.01 * res.lower)
        assert abs(high.check(m)["delta_norm_error"]) > 1e-3


def _old_finish(obj, x, idx, scale):
    """``mu_upper._finish`` as it was before the single-call cuts (``eigvalsh`` on every group
    of ``D_r``'s diagonal blocks, 1 x 1 ones included): the oracle of the cut."""
    nb = len(idx)
    _, Tl, Tr, Gh = obj.scalings(x, idx)
    _, _, lmax, top = obj(x, idx, np.full(nb, 1e300))
    upper = scale * np.sqrt(np.maximum(lmax, 0.0))
    Dl = np.conj(np.swapaxes(Tl, -1, -2)) @ Tl
    Dr = np.conj(np.swapaxes(Tr, -1, -2)) @ Tr
    G = scale[:, None, None] * Gh
    dnorm = np.zeros(nb)
    d_min = np.full(nb, np.inf)
    for _n, rows in obj.L.inv_groups:
        ii, jj = rows[:, :, None], rows[:, None, :]
        ev = np.linalg.eigvalsh(Dr[:, ii, jj])
        dnorm = np.maximum(dnorm, ev.max(axis=(1, 2)))
        d_min = np.minimum(d_min, ev.min(axis=(1, 2)))
    Dl, Dr, G = Dl / dnorm[:, None, None], Dr / dnorm[:, None, None], G / dnorm[:, None, None]
    return upper, Dl, Dr, G, top, d_min / np.maximum(dnorm, 1e-300)


def test_one_by_one_hermitian_eigenvalue_is_the_real_part_bit_for_bit():
    """The cut of ``mu_upper._finish``: ``eigvalsh`` of a 1 x 1 Hermitian matrix (LAPACK's
    ``zheevd`` with ``N = 1``) is the real part of its entry plus ``0.0``, bit for bit, for any
    entry (both signs, subnormals, huge values, -0.0 (which it returns as 0.0), inf, NaN, an
    imaginary part that round-off left there)."""
    rng = np.random.default_rng(3)
    re = np.concatenate(
        [
            rng.standard_normal(2000) * 10.0 ** rng.integers(-320, 308, 2000),
            [0.0, -0.0, 5e-324, -5e-324, 1e308, -1e308, 1.0, np.inf, -np.inf, np.nan],
        ]
    )
    a = (re + 1j * rng.standard_normal(re.size) * 1e-17)[:, None, None]
    ev = np.linalg.eigvalsh(a)[:, 0]
    cut = a[:, 0, 0].real + 0.0
    assert np.array_equal(ev, cut, equal_nan=True)
    assert np.array_equal(np.signbit(ev), np.signbit(cut))


def _mussv_fields(res):
    return [res.upper, res.lower, res.delta, res.D_left, res.D_right, res.G]


def test_single_calls_equal_the_full_lane_workspace_and_the_old_finish_bit_for_bit(monkeypatch):
    """Single ``mussv`` calls (and batches of 2 and 3: still per matrix) with the thin lane
    workspace (``mu_lanes.thin_workspace``) and the cut ``_finish`` against the same calls with
    the full eight-lane workspace and the old ``_finish`` (:func:`_old_finish`): every bound,
    perturbation and scaling identical bit for bit (the cuts change no arithmetic)."""
    cases = []
    for blk, k in ((PAPER, 2), (MIXED, 3)):
        s = parse_blk(blk)
        rng = np.random.default_rng(21)
        cases += [(blk, _crandn(rng, s.n_cols, s.n_rows) / 5) for _ in range(k)]
        cases.append((blk, _crandn(rng, 3, s.n_cols, s.n_rows) / 5))
    new = [_mussv_fields(mussv(m, blk)) for blk, m in cases]
    thin_calls = []

    def full_workspace():  # what mu_upper_bound allocated before the cut (any lane count)
        thin_calls.append(1)
        c, r = current["shape"]
        return mu_lanes.lane_workspace(c, r, current["lay"])

    current = {}
    monkeypatch.setattr(mu_lanes, "thin_workspace", full_workspace)
    monkeypatch.setattr(mu, "_finish", _old_finish)
    old = []
    for blk, m in cases:
        s = parse_blk(blk)
        current["shape"] = (s.n_cols, s.n_rows)
        current["lay"] = mu._Objective(
            np.zeros((1, s.n_cols, s.n_rows), dtype=complex), s, mu._layout(s)
        ).lane_layout
        old.append(_mussv_fields(mussv(m, blk)))
    assert len(thin_calls) == len(cases)  # every case took the per-matrix path
    for a, b in zip(new, old, strict=True):
        for x, y in zip(a, b, strict=True):
            assert np.array_equal(x, y)


def test_per_structure_cache_follows_the_object_not_its_address():
    """``mu_upper._per_blk`` answers from the structure object (no BLK bytes per call): block
    structures built and dropped one after the other (whose ``id`` Python reuses) each get
    their own layout, the one built from scratch."""
    rng = np.random.default_rng(5)
    for _ in range(40):
        rows = rng.integers(1, 4, rng.integers(1, 5))
        blk = [[-int(n), 0] if rng.random() < 0.5 else [int(n), 0] for n in rows]
        s = parse_blk(np.array(blk))
        got = mu._layout(s)
        fresh = mu._build_layout(s)
        assert got.n_params == fresh.n_params
        assert np.array_equal(got.log_par, fresh.log_par)
        assert mu._layout(s) is got
        del s


@pytest.mark.parametrize("nb", [0, 1, 4])
def test_finish_equals_the_old_finish_bit_for_bit(nb):
    """``mu_upper._finish`` (1 x 1 blocks of ``D_r`` read off, larger ones by ``eigvalsh``)
    against :func:`_old_finish` at random scalings, for an empty batch too (robstab asks for
    one): every output identical."""
    s = parse_blk(PAPER)
    rng = np.random.default_rng(nb)
    M = _crandn(rng, max(nb, 1), s.n_cols, s.n_rows)[:nb] / 5
    obj = mu._Objective(M, s, mu._layout(s))
    x = rng.standard_normal((nb, obj.L.n_params))
    idx, scale = np.arange(nb), rng.uniform(0.5, 2.0, nb)
    for a, b in zip(mu._finish(obj, x, idx, scale), _old_finish(obj, x, idx, scale), strict=True):
        assert a.shape == b.shape
        assert np.array_equal(a, b)
