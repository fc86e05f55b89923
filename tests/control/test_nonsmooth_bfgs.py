"""The bundle step's dual QP over the simplex: the active-set solver against brute force."""

import itertools

import numpy as np
import pytest

from oos_drake.control.nonsmooth_bfgs import simplex_qp, simplex_qp_slsqp


def _brute_force(Q, c):
    """Best point over every support: the equality-constrained minimizer on each face of the
    simplex (KKT system by least squares), kept when it lies in the face."""
    k = c.size
    best, best_value = None, np.inf
    for size in range(1, k + 1):
        for support in itertools.combinations(range(k), size):
            s = np.array(support)
            kkt = np.block([[Q[np.ix_(s, s)], np.ones((size, 1))], [np.ones((1, size)), 0.0]])
            sol = np.linalg.lstsq(kkt, np.append(c[s], 1.0), rcond=None)[0][:size]
            if np.any(sol < -1e-12) or abs(sol.sum() - 1) > 1e-9:
                continue
            lam = np.zeros(k)
            lam[s] = np.clip(sol, 0, None)
            value = 0.5 * lam @ Q @ lam - c @ lam
            if value < best_value:
                best, best_value = lam, value
    return best, best_value


@pytest.mark.parametrize("seed", range(12))
def test_simplex_qp_is_the_brute_force_optimum(seed):
    rng = np.random.default_rng(seed)
    k, n = int(rng.integers(2, 7)), int(rng.integers(2, 5))  # k > n: Q singular
    G = rng.normal(size=(k, n))
    if seed % 3 == 0:
        G[-1] = G[0]  # a repeated piece (the same peak twice)
    H = np.diag(rng.uniform(0.1, 2.0, n))
    Q, c = G @ H @ G.T, -np.abs(rng.normal(size=k))
    lam = simplex_qp(Q, c)
    _, best = _brute_force(Q, c)
    assert np.all(lam >= 0) and abs(lam.sum() - 1) < 1e-12
    assert 0.5 * lam @ Q @ lam - c @ lam <= best + 1e-12 * (1 + abs(best))
    # the primal step d = -H G^T lam is unique even where lam is not
    d_ref = -H @ G.T @ simplex_qp_slsqp(Q, c)
    np.testing.assert_allclose(-H @ G.T @ lam, d_ref, atol=1e-6 * (1 + np.abs(d_ref).max()))


def test_simplex_qp_single_piece_and_vertex():
    assert simplex_qp(np.eye(1), np.zeros(1)).tolist() == [1.0]
    # a dominant linear term: the optimum is the vertex of the largest c
    lam = simplex_qp(np.eye(3) * 1e-3, np.array([0.0, 5.0, 1.0]))
    np.testing.assert_allclose(lam, [0.0, 1.0, 0.0])
