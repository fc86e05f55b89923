"""The points that raise a cover's level get a converged bound (``mu_solver(converge=True)``).

Fixture ``data/mu_total_peak.npz``: ``M(j omega)`` of the mission's total subset (baseline PD,
configuration 6 of 8, ``omega`` 3.806 and 4.611 rad/s, near its peak; BLK of 18 blocks: a
3 x 3 complex block, nine complex scalars, real scalars and repeated reals). Perturbing ``M``
by a relative 1e-15 moved the bound of the cover's solver there by 8e-5 and 1.5e-3 (relative)
before the cold start and restarts of the points that raise the level (and, on the reduced
analysis of 8 configurations, the guaranteed level of the total subset by 1.7 %).

The bounds must stay valid (the LMI of the returned scalings checked directly, every bound
above a certified lower bound whose perturbation is checked by its determinant: a weak one,
0.01, the power iteration finds none on the full structure there) and never be worse than the
solver without the stage. Reproducibility: at 4.611 rad/s the stage brings the
spread of four round-off perturbations from 8e-5 to 2e-6; at 3.806 rad/s it does not (1.8e-3):
the optimizer stalls where the round-off sends it. The issue's target, 1e-6 relative, is not
reached at either point (marked ``xfail``).
"""

from pathlib import Path

import numpy as np
import pytest

from oos_drake.robust import mussv
from oos_drake.robust.blocks import parse_blk
from oos_drake.robust.mu_intervals import Realization, mu_solver

DATA = Path(__file__).parent / "data" / "mu_total_peak.npz"


def _fixture():
    f = np.load(DATA)
    return f["M"], f["omega"], f["blk"]


def _constant(M):
    """A realization without states whose response is ``M`` at every frequency."""
    c, r = M.shape
    return Realization(np.zeros((0, 0)), np.zeros((0, r)), np.zeros((c, 0)), M)


def _perturbed(M, seed):
    """``M`` times ``1 + 1e-15 R`` entry by entry (``R`` uniform in [-1, 1]); seed 0: ``M``."""
    if seed == 0:
        return M
    return M * (1 + 1e-15 * np.random.default_rng(seed).uniform(-1, 1, M.shape))


def _complex_part_lower(M, blk):
    """``(lower, delta)``: mussv's lower bound on the complex blocks of ``blk`` only, its
    perturbation embedded in the full structure (zero real blocks)."""
    s = parse_blk(blk)
    keep = [i for i, b in enumerate(np.asarray(blk)) if b[0] > 0]
    rows = np.concatenate(
        [np.arange(s.blocks[i].c_slice.start, s.blocks[i].c_slice.stop) for i in keep]
    )
    cols = np.concatenate(
        [np.arange(s.blocks[i].r_slice.start, s.blocks[i].r_slice.stop) for i in keep]
    )
    low = mussv(M[np.ix_(rows, cols)], np.asarray(blk)[keep])
    delta = np.zeros((M.shape[1], M.shape[0]), complex)
    delta[np.ix_(cols, rows)] = low.delta
    return float(low.lower), delta


def _solve(M, omega, blk, converge=True):
    upper, level, scalings = mu_solver(_constant(M), blk, converge=converge)([omega])
    return float(upper[0]), float(level[0]), scalings[0]


@pytest.mark.parametrize("k", [0, 1])
def test_converged_bound_is_valid_and_never_worse(k):
    M_all, omega, blk = _fixture()
    M, w = M_all[k], float(omega[k])
    for seed in (0, 1):
        Mx = _perturbed(M, seed)
        upper, level, sc = _solve(Mx, w, blk)
        plain, _, _ = _solve(Mx, w, blk, converge=False)
        assert upper <= plain * (1 + 1e-12), (upper, plain)  # the lowest bound is kept
        # the scalings prove the level: M^H Dl M + j (G M - M^H G^H) - level^2 Dr < 0, formed
        # here directly (not the package's scaled check)
        Dl, Dr, G = sc.D_left, sc.D_right, sc.G
        Phi = Mx.conj().T @ Dl @ Mx + 1j * (G @ Mx - Mx.conj().T @ G.conj().T) - level**2 * Dr
        Phi = 0.5 * (Phi + Phi.conj().T)
        # relative to the size of the terms (the round-off of forming Phi)
        size = np.linalg.norm(Mx, 2) ** 2 * np.linalg.norm(Dl, 2) + level**2 * np.linalg.norm(Dr, 2)
        assert np.linalg.eigvalsh(Phi)[-1] < -1e-12 * size
        # above a certified lower bound: the power iteration finds none on the full structure
        # here (0), so on its complex blocks alone (the real ones at 0: still a perturbation of
        # the full structure), checked by det(I - M delta) = 0 on the full M
        lower, delta = _complex_part_lower(Mx, blk)
        assert np.linalg.norm(delta, 2) == pytest.approx(1 / lower, rel=1e-8)
        sv = np.linalg.svd(np.eye(Mx.shape[0]) - Mx @ delta, compute_uv=False)
        assert sv[-1] <= 1e-8 * sv[0]
        assert upper >= lower


def _spread(k, converge=True, seeds=(0, 1, 2, 3)):
    M_all, omega, blk = _fixture()
    bounds = np.array(
        [_solve(_perturbed(M_all[k], s), float(omega[k]), blk, converge)[0] for s in seeds]
    )
    return float(bounds.max() / bounds.min() - 1)


def test_round_off_no_longer_moves_a_stalled_bound():
    """4.611 rad/s: without the stage the four bounds spread over 8e-5; with it 2e-6."""
    assert _spread(1, converge=False) > 4e-5  # the sensitivity is there without the stage
    assert _spread(1) < 2e-5


@pytest.mark.slow
@pytest.mark.xfail(
    strict=False,
    reason="the D-G optimizer's end point still moves with the round-off of M (2e-6 at "
    "4.611 rad/s, 1.8e-3 at 3.806 rad/s): reproducible to 1e-6 needs an exact solver of the "
    "D-G LMI at the points that raise the level",
)
@pytest.mark.parametrize("k", [0, 1])
def test_bound_reproducible_to_one_millionth(k):
    assert _spread(k) < 1e-6
