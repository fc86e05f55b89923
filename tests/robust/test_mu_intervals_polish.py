"""The cover's solver polishes only points that could raise the level (``lazy_polish``).

A point whose bound is at or below the level already reached is not polished: its scalings are
tested at the level like any other's. These tests try to break that shortcut where it acts the
most: a floor far below mu, so that the level rises well above it and most solved points are
left as the first optimizer run found them. Every check is independent of the Hamiltonian
interval test: the LMI of the interval that claims a frequency, sampled densely
(``lmi_residual`` on ``M(j omega)`` computed directly), and certified mu lower bounds at the
same frequencies, which no proved level may be below.
"""

import control
import numpy as np
import pytest
from test_mu_intervals_cover import assert_lmi_holds_where_claimed, dense_frequencies

import oos_drake.robust.mu_intervals as mu_intervals
from oos_drake.lfr import as_lfr, feedback, ureal
from oos_drake.robust import mussv
from oos_drake.robust.lfr_analysis import block_map
from oos_drake.robust.mu_intervals import SLACK, Realization, cover_axis, mu_solver


def _two_modes():
    """Two lightly damped oscillators with real stiffness and damping (4 real blocks)."""

    def second_order(k, c):
        integ = as_lfr(control.tf(1, [1, 0]))
        return feedback(integ * feedback(integ, c), k)

    T = second_order(ureal("k1", 1, plusminus=0.3), ureal("c1", 0.01, plusminus=0.005))
    T = T + second_order(ureal("k2", 9, plusminus=3), ureal("c2", 0.03, plusminus=0.01))
    real = Realization(np.asarray(T.A), np.asarray(T.Bw), np.asarray(T.Cz), np.asarray(T.Dzw))
    return real, block_map(T).blk


@pytest.fixture(scope="module")
def covers(two_mass):
    """``{case: (real, blk, shortcut cover, reference cover, polish runs of each)}``: covers
    with a floor 100 times below the grid's peak of mu (seeds: the grid's peaks)."""
    out = {}
    _, real_2m, blk_2m, _ = two_mass
    for name, (real, blk) in {"two mass": (real_2m, blk_2m), "two modes": _two_modes()}.items():
        grid = np.geomspace(1e-2, 1e3, 200)
        res = mussv(real.response(grid), blk)
        floor = 0.01 * float(np.max(res.upper))
        seeds = grid[np.unique([np.argmax(res.upper), np.argmax(res.lower)])]
        runs = {}
        certs = {}
        for shortcut in (True, False):
            calls = []
            original = mu_intervals.mu_upper_bound

            def counted(M, structure, calls=calls, original=original, **options):
                calls.append(M.shape[0])
                return original(M, structure, **options)

            mu_intervals.mu_upper_bound = counted  # the polish runs (max_iter=0 ones: scalings)
            try:
                solve = mu_solver(
                    real,
                    blk,
                    slack=SLACK,
                    polish_above=floor / (1 + SLACK),
                    lazy_polish=shortcut,
                )
                certs[shortcut] = cover_axis(real, solve, seeds, floor=floor, slack=SLACK)
            finally:
                mu_intervals.mu_upper_bound = original
            runs[shortcut] = sum(calls)
        out[name] = (real, blk, certs[True], certs[False], runs)
    return out


@pytest.mark.parametrize("case", ["two mass", "two modes"])
def test_unpolished_points_still_prove_the_level_everywhere(covers, case):
    real, blk, cert, _, _ = covers[case]
    assert cert.covered and cert.reason == ""
    omega = dense_frequencies(cert, per_decade=60)
    assert assert_lmi_holds_where_claimed(real, cert, omega).size == 0
    lower = mussv(real.response(omega), blk).lower
    assert np.all(lower <= cert.upper), omega[np.argmax(lower)]
    again = cert.check()
    assert again["intervals_hold"] and again["covered"]


@pytest.mark.parametrize("case", ["two mass", "two modes"])
def test_shortcut_polishes_less_and_keeps_the_level(covers, case):
    """Fewer matrices polished than with every point above the floor polished, and the same
    guaranteed level up to the slack (both are proofs; the shortcut must not lose accuracy)."""
    _, _, cert, reference, runs = covers[case]
    assert reference.covered
    assert runs[True] < runs[False], runs
    assert cert.upper <= reference.upper * (1 + SLACK) * (1 + 1e-9)
    # the level is within the slack of the largest bound solved anywhere (the peak's own)
    solved = cert.optimal[np.isfinite(cert.optimal)]
    assert cert.upper <= (1 + SLACK) * float(np.max(solved)) * (1 + 1e-12)
