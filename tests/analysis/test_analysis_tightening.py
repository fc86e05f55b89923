"""Certified sweeps: neighbours, spike detection and resolution against closed-form mu peaks."""

import control
import numpy as np
import pytest

from oos_drake.analysis.stability import SweepOptions, certified_sweep
from oos_drake.analysis.tightening import (
    LowerCertificate,
    SubsetPoints,
    TightenOptions,
    neighbours,
    resolve_spikes,
)
from oos_drake.analysis.workers import ModelPool, PointTask
from oos_drake.lfr import feedback, ucomplex, ureal, usubs
from oos_drake.robust.lfr_analysis import model_matrices, subset_parts
from oos_drake.robust.sweep import local_spikes

FAST = SweepOptions(n_jobs=1, converge_passes=1, converge_iterations=60)


def _gain_array(gains):
    """k a / ((s+1)(s+2)(s+3)) in unit feedback, k = 40 +- 10 uncertain, one model per gain a.

    The loop is unstable from k a = 60 on (Routh), at omega = sqrt(11): the normalized
    destabilizing ``delta = (60 / a - 40) / 10`` and ``mu = 1 / delta`` in closed form.
    """
    k = ureal("k", 40.0, plusminus=10.0)
    a = ureal("a", 1.0, range=(0.1, 2.0))
    loop = feedback(k * a * control.tf(1, [1, 6, 11, 6]), 1)
    return usubs(loop, {"a": np.asarray(gains, dtype=float)})


def test_neighbours_match_brute_force():
    rng = np.random.default_rng(3)
    model = np.sort(rng.integers(0, 5, 60))
    omega = np.empty(60)
    for m in np.unique(model):
        sel = model == m
        omega[sel] = np.sort(rng.uniform(0.1, 10.0, sel.sum()))
    nb = neighbours(model, omega)
    for i in range(60):
        same = np.flatnonzero(model == model[i])
        pos = int(np.flatnonzero(same == i)[0])
        assert nb[i, 0] == (same[pos - 1] if pos > 0 else -1)
        assert nb[i, 1] == (same[pos + 1] if pos + 1 < same.size else -1)
        for col, other in ((2, model[i] - 1), (3, model[i] + 1)):
            cand = np.flatnonzero(model == other)
            if cand.size == 0:
                assert nb[i, col] == -1
            else:
                dist = np.abs(np.log(omega[cand]) - np.log(omega[i]))
                assert np.isclose(dist[np.flatnonzero(cand == nb[i, col])[0]], dist.min())


def test_local_spikes():
    u = np.array([1.0, 1.0, 3.0, 1.0, 1.05, 1.0, 2.0])
    np.testing.assert_array_equal(local_spikes(u, 1.1), [2, 6])
    assert local_spikes(np.array([1.0]), 1.1).size == 0


def test_certified_sweep_brackets_the_closed_form_peak():
    """Complex gain k = 40 + 10 delta in k a G: mu(omega) = |10 a G / (1 + 40 a G)| (closed form).

    The certified peak must bracket the dense closed-form maximum over the grid's span within
    the target gap, on the right model, with a perturbation that destabilizes.
    """
    gains = np.array([0.8, 1.0, 1.2, 1.4])
    k = ucomplex("k", 40.0, 10.0)
    a = ureal("a", 1.0, range=(0.1, 2.0))
    arr = usubs(feedback(k * a * control.tf(1, [1, 6, 11, 6]), 1), {"a": gains})
    omega = 2 * np.pi * np.geomspace(0.05, 5.0, 25)
    res = certified_sweep(
        arr, omega, {"k": ["k"]}, times=gains, options=FAST, progress=False, guarantee=True
    )
    cert = res.certificates["k"]
    dense = 2 * np.pi * np.geomspace(0.05, 5.0, 20001)
    s = 1j * dense
    G = 1.0 / ((s + 1) * (s + 2) * (s + 3))
    mu = np.abs(10 * gains[:, None] * G / (1 + 40 * gains[:, None] * G))
    assert cert.model == int(np.argmax(mu.max(axis=1)))
    exact = float(mu.max())
    assert cert.mu_lower <= exact * (1 + 1e-6)
    assert exact <= cert.mu_upper * (1 + 1e-3)
    assert cert.gap <= 0.03 + 1e-9
    np.testing.assert_allclose(cert.mu_lower, exact, rtol=2e-3)
    table = res.table
    assert np.all(table["mu lower [-]"] <= table["mu upper [-]"] * (1 + 1e-9))
    assert table["refined"].sum() >= 2  # peak refinement points
    # the certified perturbation destabilizes: k = 40 + 10 delta puts a pole on j omega
    value = cert.worst_case_normalized["k"]
    w = 2 * np.pi * cert.frequency
    kk = 40.0 + 10.0 * complex(np.asarray(value).ravel()[0])
    g = 1.0 / ((1j * w + 1) * (1j * w + 2) * (1j * w + 3))
    assert abs(1 + kk * gains[cert.model] * g) < 1e-6
    # the peak proved on the whole frequency axis, for every configuration: above the closed
    # form's maximum over [0, inf) (dense, far beyond the grid's span), within 2 % of it
    axis = 2 * np.pi * np.concatenate([[0.0], np.geomspace(1e-4, 1e3, 400001)])
    s = 1j * axis
    G = 1.0 / ((s + 1) * (s + 2) * (s + 3))
    mu_axis = np.abs(10 * gains[:, None] * G / (1 + 40 * gains[:, None] * G)).max(axis=1)
    guarantee = res.guarantees["k"]
    assert not guarantee.failures
    assert guarantee.covered and guarantee.reason == ""
    assert np.all(guarantee.levels >= mu_axis)
    assert mu_axis.max() <= guarantee.mu_upper <= 1.02 * mu_axis.max()
    assert "guarantee" in res.timings


def test_resolve_spikes_removes_an_inflated_bound():
    """A loose (but valid) upper bound planted on the grid is brought under (1 + gap) L*."""
    gains = np.array([1.0, 1.2])
    arr = _gain_array(gains)
    parts = subset_parts(arr, {"k": ["k"]})["k"]
    omega = 2 * np.pi * np.geomspace(0.2, 2.0, 9)
    models = np.repeat([0, 1], omega.size)
    freqs = np.tile(omega, 2)
    with ModelPool(model_matrices(arr), 1) as pool:
        first = pool.bounds(
            PointTask(models, freqs, None, *parts, 100, lower_restarts=2, lower_iterations=40)
        )
        pts = SubsetPoints(
            models,
            freqs,
            first.upper.copy(),
            first.lower.copy(),
            first.params.copy(),
            np.zeros(models.size, bool),
            np.zeros(models.size, bool),
        )
        pts.upper[13] = 5.0  # planted spike on model 1 (a valid, loose bound: mu <= 1 there)
        from oos_drake.analysis.stability import _analysis_model, _search_task

        def search(requests):
            out = []
            for m, w in requests:
                A, Bw, Cz, Dzw, blk, _, _ = _analysis_model(arr, m, ["k"])
                d = _search_task((A, Bw, Cz, Dzw, blk, [w / 2, w * 2], 8.0))
                out.append(LowerCertificate(d.mu_lower, m, d.omega, d.delta, "search"))
            return out

        options = TightenOptions(target_gap=0.03)
        lower, report = resolve_spikes(pool, pts, parts, LowerCertificate(), search, options)
    exact = 1.0 / ((60.0 / 1.2 - 40.0) / 10.0)
    np.testing.assert_allclose(lower.value, exact, rtol=1e-4)
    assert pts.upper.max() <= (1 + options.target_gap) * lower.value * (1 + 1e-9)
    assert report.spikes[0] >= 1 and report.spikes[-1] == 0


def test_bad_options_are_refused():
    with pytest.raises(ValueError, match="target_gap"):
        TightenOptions(target_gap=-0.1)
    with pytest.raises(ValueError, match="chunk_size"):
        SweepOptions(chunk_size=-1)


class _FlatRidgePool:
    """Stand-in for :class:`ModelPool`: every re-solved upper bound lands on a flat ridge.

    Whatever the start and the iterations, the bound of a point is ``ridge`` (its converged
    D-G value, above ``(1 + gap) L*``: the conservatism of the bound itself); no lower bound.
    Counts the points it was asked to solve.
    """

    def __init__(self, ridge):
        self.ridge = ridge
        self.solved = 0

    def bounds(self, task):
        from oos_drake.analysis.workers import PointBounds

        n = task.models.size
        self.solved += n
        p = 1 if task.x0 is None else task.x0.shape[1]
        return PointBounds(np.full(n, self.ridge), np.zeros((n, p)), np.zeros(n), -1, None)


PARTS = (np.array([0]), np.array([0]), np.array([[-1, 0]]))  # one real scalar (unused)


def _ridge_points(n_models, n_freq, ridge, inflated, rng):
    model = np.repeat(np.arange(n_models), n_freq)
    omega = np.tile(np.geomspace(0.1, 10.0, n_freq), n_models)
    upper = np.full(model.size, ridge)
    upper[rng.choice(model.size, inflated, replace=False)] = 1.5 * ridge
    z = np.zeros(model.size, bool)
    return SubsetPoints(model, omega, upper, np.zeros(model.size), np.zeros((model.size, 1)), z, z)


@pytest.mark.parametrize(
    ("n_models", "max_searches", "stop"), [(50, 6, "search budget"), (3, 8, "converged")]
)
def test_a_converged_ridge_stops_the_resolution_quickly(n_models, max_searches, stop):
    """Points on a ridge 10 % above the exact lower bound, 40 of them inflated stalls.

    Only the stalls (above the ridge) can change the gap of the peak: they are re-solved, the
    ridge is recognized as converged after one pass of ``converged_iterations``, and the
    resolution stops with every spike left reported: "converged" when every model with a spike
    was searched, "search budget" (a budget, flagged) when searches were left to do.
    """
    rng = np.random.default_rng(1)
    n_freq = 1000 // n_models
    pts = _ridge_points(n_models, n_freq, 1.10, 40, rng)
    pool = _FlatRidgePool(1.10)
    calls = []

    def search(requests):
        calls.extend(requests)
        return [LowerCertificate(1.0, m, w, np.zeros((1, 1)), "search") for m, w in requests]

    options = TightenOptions(target_gap=0.03, rounds=10, max_searches=max_searches, max_points=100)
    lower, report = resolve_spikes(pool, pts, PARTS, LowerCertificate(), search, options)
    assert lower.value == 1.0
    assert np.isclose(pts.upper.max(), 1.10)  # the stalls were resolved down to the ridge
    assert report.stop == stop
    assert report.budget_exhausted == (stop == "search budget")
    assert report.points_left == int(np.sum(pts.upper > 1.03)) >= n_models * n_freq
    assert report.converged >= 40
    # top-down: at most max_points spikes per pass (own + 4 neighbour starts) until the
    # pass of converged_iterations (the third), plus the refinement midpoints; resolving every
    # spike in every round would be 1000 x 5 x 10
    assert pool.solved <= 3 * options.max_points * 5 + 10 * 2 * (1 + options.refine_spikes)
    searched = [m for m, _ in calls]
    assert len(set(searched)) == len(searched) == min(max_searches, n_models)


def test_budgets_stop_the_resolution_and_say_so():
    """A zero-second time budget or a tiny work budget stops with the spikes reported."""
    rng = np.random.default_rng(2)

    def search(requests):
        return [LowerCertificate(1.0, m, w, np.zeros((1, 1)), "search") for m, w in requests]

    for options, reason in (
        (TightenOptions(time_budget=1e-9, peak_levels=0), "time budget"),
        (TightenOptions(max_work=1.0, peak_levels=0), "work budget"),
    ):
        pts = _ridge_points(10, 10, 1.10, 20, rng)
        _, report = resolve_spikes(
            _FlatRidgePool(1.10), pts, PARTS, LowerCertificate(), search, options
        )
        assert report.stop == reason and report.budget_exhausted
        assert report.points_left == int(np.sum(pts.upper > 1.03)) > 0


def test_budget_options_are_checked():
    with pytest.raises(ValueError, match="time_budget"):
        TightenOptions(time_budget=0.0)
    with pytest.raises(ValueError, match="max_points"):
        TightenOptions(max_points=-1)
