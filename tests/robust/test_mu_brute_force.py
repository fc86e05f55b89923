"""mussv's upper bound against brute force on small mixed structures (issue 29: try to break it).

Two real scalars and one complex scalar on a 3 x 3 matrix: ``det(I - M diag(d1, d2, d3))`` is
affine in ``d3``, so for every real ``(d1, d2)`` of a grid the complex ``d3`` that makes it
singular is closed form. Each grid point is a singular perturbation in the structure, so
``1 / min max(|d1|, |d2|, |d3|)`` over the grid is a lower bound of mu found without the code
under test (``numpy.linalg.det`` only); every upper bound must lie above it, and the certified
lower bound of mussv below the upper bound.
"""

import numpy as np
import pytest

from oos_drake.robust import mussv

BLK = [[-1, 0], [-1, 0], [1, 0]]


def _brute_force_mu(M, radius, n=201):
    """``(mu_grid, d)``: ``1 / min max |d_i|`` over ``d1, d2`` on an ``n x n`` grid of
    ``[-radius, radius]`` with the complex ``d3`` that makes ``I - M diag(d)`` singular."""
    g = np.linspace(-radius, radius, n)
    d1, d2 = (a.ravel() for a in np.meshgrid(g, g))
    eye = np.eye(3)

    def det(d3):
        D = np.zeros((d1.size, 3, 3), dtype=complex)
        D[:, 0, 0], D[:, 1, 1], D[:, 2, 2] = d1, d2, d3
        return np.linalg.det(eye - M @ D)

    a = det(0.0)
    b = det(1.0) - a  # det is affine in d3
    with np.errstate(all="ignore"):
        d3 = np.where(np.abs(b) > 1e-12, -a / b, np.inf)
    size = np.maximum(np.maximum(np.abs(d1), np.abs(d2)), np.abs(d3))
    k = int(np.argmin(size))
    return 1.0 / size[k], np.array([d1[k], d2[k], d3[k]])


@pytest.mark.parametrize("seed", [0, 1, 5])  # 5: a lower bound of 0, a 74 % D-G gap
@pytest.mark.parametrize("real_matrix", [True, False])
def test_upper_bound_above_a_brute_force_lower_bound(seed, real_matrix):
    rng = np.random.default_rng(seed)
    M = rng.standard_normal((4, 3, 3))
    if not real_matrix:
        M = M + 1j * rng.standard_normal((4, 3, 3))
    res = mussv(M, BLK)
    for k in range(len(M)):
        # the minimizer has max |d_i| = 1 / mu <= 1 / mu_grid: each pass zooms the grid on
        # [-1.05 / mu_grid, 1.05 / mu_grid] (found without mussv's lower bound)
        mu_grid, d = _brute_force_mu(M[k], 1e3 / res.upper[k])
        for _ in range(4):
            mu_grid, d = max(
                _brute_force_mu(M[k], 1.05 / mu_grid), (mu_grid, d), key=lambda t: t[0]
            )
        # the grid point is singular (independent check of the oracle itself)
        sv = np.linalg.svd(np.eye(3) - M[k] @ np.diag(d), compute_uv=False)
        assert sv[-1] <= 1e-9 * sv[0]
        assert res.upper[k] >= mu_grid * (1 - 1e-9)
        assert res.lower[k] <= res.upper[k]
        # the zoomed grids (spacing 2 radius / 200) find mu to within about 1 %: the certified
        # lower bound of mussv cannot exceed it by more than that
        assert res.lower[k] <= mu_grid * 1.02 or mu_grid == 0
