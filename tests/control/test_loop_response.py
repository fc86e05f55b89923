"""Closed-loop responses from the plant's modal form vs the state-space closed loop."""

import numpy as np
import pytest
from slycot import ab13dd

from oos_drake.control.baseline import baseline_gains, inertia_from_plant
from oos_drake.control.interconnection import WeightedInterconnection, weighted_interconnection
from oos_drake.control.loop_response import OMEGA_MIN, LoopResponse, LoopSigma
from oos_drake.control.objective import peak_gradients
from oos_drake.control.plants import synthetic_flexible_plants
from oos_drake.robust.peak_gain import peak_gain


@pytest.fixture(scope="module")
def problem():
    plants = synthetic_flexible_plants(8, modes=3, uncertain=False)
    nominal = plants.nominal()
    W = weighted_interconnection(nominal)
    K0 = baseline_gains(inertia_from_plant(plants.evaluate([2]))[0])
    rng = np.random.default_rng(0)
    K = K0 * np.exp(0.5 * rng.normal(size=K0.shape)) * np.array([30, 30, 30, 5, 5, 5])
    return nominal, W, K


def test_loop_formula_equals_the_state_space_closed_loop(problem):
    nominal, W, K = problem
    omega = np.logspace(-5, 3.5, 200)
    exact = W.close(K).freqresp(omega)  # LU solves on the 30+ state closed loop
    ours = W.loop.response(K, np.broadcast_to(omega, (8, omega.size)))
    # relative to each model's peak (entries far below it carry the rounding of either method)
    scale = np.abs(exact).max(axis=(-3, -2, -1), keepdims=True)
    assert np.max(np.abs(ours - exact) / scale) < 1e-10
    # and entry-wise where the response matters (within 1e-3 of the peak)
    big = np.abs(exact) > 1e-3 * scale
    assert np.max(np.abs(ours - exact)[big] / np.abs(exact)[big]) < 1e-8


def test_dc_is_evaluated_at_omega_min(problem):
    _, W, K = problem
    M = W.close(K)
    dc = M.D - M.C @ np.linalg.solve(M.A, M.B)  # exact closed-loop DC gain
    ours = W.loop.response(K, np.zeros((8, 1)))[:, 0]
    np.testing.assert_allclose(ours, dc, rtol=1e-7, atol=1e-9 * np.abs(dc).max())
    assert OMEGA_MIN <= 1e-9


def test_peak_gain_with_the_loop_sampler_agrees_with_ab13dd(problem):
    nominal, W, K = problem
    M = W.close(K)
    result = peak_gain(M.A, M.B, M.C, M.D, evaluator=LoopSigma(W.loop, K))
    for i in range(M.A.shape[0]):
        A, B, C, D = M.A[i], M.B[i], M.C[i], M.D[i]
        n = A.shape[0]
        reference = ab13dd("C", "I", "N", "D", n, 9, 6, A, np.eye(n), B, C, D, tol=1e-10)[0]
        assert result.gamma[i] == pytest.approx(reference, rel=1e-8)


def test_loop_needs_a_plant_array(problem):
    nominal, W, _ = problem
    with pytest.raises(ValueError, match="array"):
        LoopResponse(nominal.take(0), W.spec)


def test_gain_sensitivity_equals_the_state_space_gradients(problem):
    _, W, K = problem
    plain = WeightedInterconnection(W.system, W.spec)  # no plant: LU solves on the closed loop
    assert plain.loop is None and W.loop is not None
    index = np.array([0, 3, 5, 7, 2])
    omega = np.array([0.0, 0.02, 0.7, 9.0, 150.0])
    for which in (0, 1):
        w = np.full(index.size, which)
        s_loop, g_loop = peak_gradients(W, K, index, omega, w)
        s_lu, g_lu = peak_gradients(plain, K, index, omega, w)
        np.testing.assert_allclose(s_loop, s_lu, rtol=1e-9)
        scale = np.abs(g_lu).max(axis=(1, 2), keepdims=True)
        assert np.max(np.abs(g_loop - g_lu) / scale) < 1e-7
