"""Certified sweeps: neighbours, spike detection and resolution against closed-form mu peaks."""

import control
import numpy as np
import pytest

from oos_drake.analysis.stability import (
    SweepOptions,
    certified_sweep,
    delta_matrices,
    local_spikes,
    subset_parts,
)
from oos_drake.analysis.tightening import (
    LowerCertificate,
    SubsetPoints,
    TightenOptions,
    neighbours,
    resolve_spikes,
)
from oos_drake.analysis.workers import ModelPool, PointTask
from oos_drake.lfr import feedback, ucomplex, ureal, usubs

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
    res = certified_sweep(arr, omega, {"k": ["k"]}, times=gains, options=FAST, progress=False)
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
    assert np.all(table["mu_lower"] <= table["mu_upper"] * (1 + 1e-9))
    assert table["refined"].sum() >= 2  # peak refinement points
    # the certified perturbation destabilizes: k = 40 + 10 delta puts a pole on j omega
    value = cert.worst_case_normalized["k"]
    w = 2 * np.pi * cert.frequency
    kk = 40.0 + 10.0 * complex(np.asarray(value).ravel()[0])
    g = 1.0 / ((1j * w + 1) * (1j * w + 2) * (1j * w + 3))
    assert abs(1 + kk * gains[cert.model] * g) < 1e-6


def test_resolve_spikes_removes_an_inflated_bound():
    """A loose (but valid) upper bound planted on the grid is brought under (1 + gap) L*."""
    gains = np.array([1.0, 1.2])
    arr = _gain_array(gains)
    parts = subset_parts(arr, {"k": ["k"]})["k"]
    omega = 2 * np.pi * np.geomspace(0.2, 2.0, 9)
    models = np.repeat([0, 1], omega.size)
    freqs = np.tile(omega, 2)
    with ModelPool(delta_matrices(arr), 1) as pool:
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
