"""Every mu sweep of the package writes the one table, with the same numbers: a closed form.

For a scalar complex block ``c = 1 + 0.5 delta`` in the loop ``1 + c g P = 0`` (``g`` fixed per
model), ``mu(M11(j w)) = |0.5 g P(jw) / (1 + g P(jw))|`` exactly at every frequency (for a 1 x 1
complex block mu is the modulus): every row of :func:`~oos_drake.robust.robust_sweep`,
:meth:`~oos_drake.robust.RobStabResult.table` and the analysis's sweeps is checked against it.
"""

import control
import numpy as np

from oos_drake.analysis.stability import SweepOptions, certified_sweep, mu_sweep
from oos_drake.lfr import feedback, ucomplex, ureal, usubs
from oos_drake.robust import robstab, robust_sweep
from oos_drake.robust.tables import GUARANTEE_COLUMNS, SWEEP_COLUMNS

GAINS = np.array([0.8, 1.0, 1.25])


def complex_scalar_array():
    """Model array (one per ``GAINS``) and its exact mu as a function of (model, omega)."""
    P = control.tf([4.0], [1.0, 2.0, 1.0])
    c = ucomplex("c", 1.0, 0.5)
    g = ureal("g", 1.0, plusminus=0.5)
    arr = usubs(feedback(c * g * P, 1), {"g": GAINS})

    def exact(model, omega):
        Pjw = 4.0 / (1j * np.asarray(omega) + 1.0) ** 2
        gP = GAINS[np.asarray(model)] * Pjw
        return np.abs(0.5 * gP / (1.0 + gP))

    return arr, exact


def test_robust_sweep_and_robstab_tables_match_the_closed_form():
    arr, exact = complex_scalar_array()
    omega = np.geomspace(0.1, 10.0, 30)
    table = robust_sweep(
        arr, omega, times=[0.0, 5.0, 10.0], mode="full", warm_start=False, guaranteed=False
    )
    assert list(table.columns) == SWEEP_COLUMNS
    w = 2 * np.pi * table["frequency [Hz]"].to_numpy()
    mu = exact(table["model"].to_numpy(), w)
    np.testing.assert_allclose(table["mu upper [-]"], mu, rtol=1e-6)
    np.testing.assert_allclose(table["mu lower [-]"], mu, rtol=1e-6)
    np.testing.assert_allclose(table["time [s]"], 5.0 * table["model"])
    for j in range(GAINS.size):
        res = robstab(arr.model(j), omega, guaranteed=False)
        one = res.table(subset="total", time=5.0 * j)
        assert list(one.columns) == SWEEP_COLUMNS
        w = 2 * np.pi * one["frequency [Hz]"].to_numpy()
        np.testing.assert_allclose(one["mu upper [-]"], exact(j, w), rtol=1e-6)
        np.testing.assert_allclose(one["mu lower [-]"], exact(j, w), rtol=1e-6)
    guaranteed = robstab(arr.model(1), omega).table()
    assert list(guaranteed.columns) == SWEEP_COLUMNS + GUARANTEE_COLUMNS
    dense = np.linspace(0.0, 20.0, 200001)
    peak = exact(1, dense).max()
    assert peak <= guaranteed["mu upper guaranteed [-]"].iloc[0] <= 1.05 * peak


def test_analysis_sweeps_match_the_closed_form():
    arr, exact = complex_scalar_array()
    omega = np.geomspace(0.1, 10.0, 30)
    options = SweepOptions(n_jobs=1, converge_iterations=60, pole_points=0)
    for table in (
        mu_sweep(arr, omega, {"c": ["c"]}, times=[0.0, 5.0, 10.0], options=options, progress=False),
        certified_sweep(
            arr, omega, {"c": ["c"]}, times=[0.0, 5.0, 10.0], options=options, progress=False
        ).table,
    ):
        assert list(table.columns) == SWEEP_COLUMNS
        w = 2 * np.pi * table["frequency [Hz]"].to_numpy()
        mu = exact(table["model"].to_numpy(), w)
        np.testing.assert_allclose(table["mu upper [-]"], mu, rtol=1e-6)
        # lower bounds where computed (the highest points of each model), 0 elsewhere
        lower = table["mu lower [-]"].to_numpy()
        assert np.all(lower <= mu * (1 + 1e-9))
        top = table.groupby("model")["mu upper [-]"].idxmax()
        np.testing.assert_allclose(lower[top], mu[top], rtol=1e-6)
        np.testing.assert_allclose(table["time [s]"], 5.0 * table["model"])


def test_every_step_of_the_one_sweep_matches_the_closed_form():
    """``sweep_models`` with each grid method, refinement, polish and guarantee: every row is
    the closed form (upper and lower where computed), refinement points lie between grid
    points next to each model's peak, the best lower bound's perturbation makes
    ``I - M delta`` singular, and the guarantee holds the dense-grid peak within its slack."""
    from oos_drake.robust.lfr_analysis import (
        delta_channel_response,
        model_matrices,
        subset_parts,
    )
    from oos_drake.robust.sweep import SweepOptions as Options
    from oos_drake.robust.sweep import sweep_models

    arr, exact = complex_scalar_array()
    A, Bw, Cz, Dzw = model_matrices(arr)
    parts = subset_parts(arr, {"c": ["c"]})
    omega = np.geomspace(0.1, 10.0, 25)
    dense = np.linspace(0.0, 20.0, 200001)
    for grid in ("continued", "pruned", "warm", "cold"):
        options = Options(
            grid=grid,
            pole_points=0,
            converge_iterations=60,
            refine_points=5,
            refine_iterations=None if grid == "cold" else 60,
            polish_points=2,
            slack=0.02 if grid == "cold" else None,
            n_jobs=1,
        )
        pts = sweep_models(A, Bw, Cz, Dzw, omega, parts, options)["c"]
        mu = exact(pts.model, pts.omega)
        np.testing.assert_allclose(pts.upper, mu, rtol=1e-6, err_msg=grid)
        computed = pts.lower > 0
        np.testing.assert_allclose(pts.lower[computed], mu[computed], rtol=1e-6, err_msg=grid)
        assert np.all(np.diff(pts.omega[pts.model == 0]) > 0)
        for j in range(GAINS.size):
            mine = pts.model == j
            w_peak = pts.omega[mine][np.argmax(exact(j, pts.omega[mine]))]
            new = pts.omega[mine & pts.refined]
            assert new.size == 5 and np.all(np.abs(np.log(new / w_peak)) < 0.2), grid
            value, w_best, delta = pts.best[j]
            np.testing.assert_allclose(value, exact(j, dense).max(), rtol=2e-3)
            M = delta_channel_response(A[j], Bw[j], Cz[j], Dzw[j], [w_best])[0]
            assert abs(np.linalg.det(np.eye(M.shape[0]) - M @ delta)) < 1e-9
            if options.slack is not None:
                peak = exact(j, dense).max()
                assert peak <= pts.guarantees[j].upper <= 1.05 * peak
