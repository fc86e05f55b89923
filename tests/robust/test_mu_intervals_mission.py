"""The whole-axis guarantee on the mission case where the grid-only upper bound is broken.

Fixture ``data/mu_mechanical_crossing.npz``: the realization ``(A, B, C, D)`` of ``M`` seen by the
mechanical subset (three real scalars and a ``delta_m I3``) of the ``make run`` closed loop
(synthesized controller, gamma 0.3543) at t = 255 s, configuration 56 of 330; the analysis'
frequencies of that configuration (grid and refinement points), the D-G parameters its sweep
found there, and the subset's certified lower bound (0.03385, at infinite frequency).
``oos confirm`` found this loop crossing the imaginary axis near 0.356 Hz before alpha = 1
(docs/CLAIMS.md A11): between grid frequencies, mu is above the grid-only upper bound.
"""

import itertools
from pathlib import Path

import numpy as np
import pytest

from oos_drake.robust.mu_intervals import (
    SLACK,
    Realization,
    cover_axis,
    mu_solver,
    scalings_at,
)

DATA = Path(__file__).parent / "data" / "mu_mechanical_crossing.npz"


def _vertex_crossing(real, sizes):
    """Brute force, independent of mu: the smallest scale ``alpha`` of a vertex direction of the
    real parameter box at which the closed loop ``A + B Delta (I - D Delta)^{-1} C`` gets a pole
    on the imaginary axis (a sweep, then bisection); returns ``(1 / alpha, frequency [Hz])``,
    a lower bound of the peak of mu (every block is real: a real crossing)."""
    A, B, C, D = real.A, real.B, real.C, real.D
    n = D.shape[0]

    def pole(direction, alpha):
        Dl = np.diag(alpha * direction)
        ev = np.linalg.eigvals(A + B @ Dl @ np.linalg.solve(np.eye(n) - D @ Dl, C))
        return ev[np.argmax(ev.real)]

    best = (np.inf, np.nan)
    for signs in itertools.product((-1.0, 1.0), repeat=len(sizes)):
        direction = np.repeat(signs, sizes)
        alphas = np.linspace(0.0, 60.0, 61)
        unstable = np.flatnonzero([pole(direction, a).real >= 0 for a in alphas])
        if not unstable.size:
            continue
        lo, hi = alphas[unstable[0] - 1], alphas[unstable[0]]
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if pole(direction, mid).real >= 0 else (mid, hi)
        if hi < best[0]:
            best = (hi, abs(pole(direction, hi).imag) / (2 * np.pi))
    return 1.0 / best[0], best[1]


@pytest.mark.slow  # about 20 s of CPU (the cover: 50 points, 81 states)
def test_guarantee_covers_the_crossing_the_grid_misses():
    f = np.load(DATA)
    real = Realization(f["A"], f["B"], f["C"], f["D"])
    blk = f["blk"]
    sizes = np.abs(blk[:, 0])
    assert np.all(blk[:, 0] < 0)  # every block real: the vertex search is a real crossing
    mu_cross, f_cross = _vertex_crossing(real, sizes)
    assert 0.3 < f_cross < 0.4  # the crossing oos confirm saw near 0.356 Hz
    # the grid-only bound of this configuration (the analysis' frequencies) and the subset's
    # certified peak stay below it: the grid-only upper bound is broken
    assert f["upper"].max() < mu_cross
    assert float(f["subset_lower"]) * (1 + SLACK) < mu_cross
    # the analysis' cover (stability._axis_task) from the lowest level it may start at
    floor = (1.0 + SLACK) * float(f["subset_lower"])
    upper, scalings = scalings_at(real, blk, f["omega"], f["params"])
    cert = cover_axis(
        real,
        mu_solver(real, blk, slack=SLACK, polish_above=floor / (1 + SLACK)),
        [],
        floor=floor,
        known=(f["omega"], upper, scalings),
    )
    assert cert.covered
    assert mu_cross <= cert.upper <= 1.02 * mu_cross, (cert.upper, mu_cross)
    again = cert.check()
    assert again["intervals_hold"] and again["covered"]
    # the grid's scalings were used (not re-solved) where they prove the level
    assert np.sum(~cert.added) > 0
